//! ROS 2 message types as plain serde structs with the exact CDR layout of ROS 2 Jazzy.
//!
//! Every message implements [`RosMessage`]: it knows its ROS type name
//! (`geometry_msgs/msg/PoseStamped`) and its full `.msg` definition with the definitions of every
//! type it depends on, concatenated the way rosbag2 stores `ros2msg` schemas in MCAP files.
//! [`to_cdr`] and [`from_cdr`] convert between messages and serialized payloads (a 4-byte
//! encapsulation header followed by little-endian plain CDR), the bytes that travel over DDS and
//! that rosbag2 writes into bags.
#![warn(missing_docs)]

use byteorder::LittleEndian;
use serde::{Serialize, de::DeserializeOwned};

pub mod builtin_interfaces;
pub mod geometry_msgs;
pub mod std_msgs;

/// Encapsulation header for little-endian plain CDR (`CDR_LE`), the first four bytes of every
/// serialized ROS 2 message.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A ROS 2 message type.
pub trait RosMessage: Serialize + DeserializeOwned + Clone + std::fmt::Debug + PartialEq {
    /// The full ROS type name, e.g. `geometry_msgs/msg/PoseStamped`.
    const TYPE_NAME: &'static str;
    /// The `.msg` definition followed by every dependency's definition, separated as rosbag2
    /// separates them (a line of 80 `=` and a `MSG: package/Type` line).
    const DEFINITION: &'static str;
}

/// Errors from decoding a serialized message.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    /// The payload is shorter than the 4-byte encapsulation header.
    #[error("CDR payload of {0} bytes is too short for the 4-byte encapsulation header")]
    TooShort(usize),
    /// The encapsulation header names a representation other than plain CDR.
    #[error("unsupported CDR encapsulation {0:02x?}: only plain CDR (little or big endian) is supported")]
    Encapsulation([u8; 2]),
    /// The body does not decode as the expected type.
    #[error("payload does not decode as {type_name}: {source}")]
    Decode {
        /// The type the payload was decoded as.
        type_name: &'static str,
        /// What the CDR decoder reported.
        source: cdr_encoding::Error,
    },
    /// Encoding failed (only for values serde cannot express in CDR).
    #[error("cannot encode {type_name}: {source}")]
    Encode {
        /// The type being encoded.
        type_name: &'static str,
        /// What the CDR encoder reported.
        source: cdr_encoding::Error,
    },
}

/// Serializes a message to a CDR payload with its encapsulation header (little endian).
pub fn to_cdr<T: RosMessage>(msg: &T) -> Result<Vec<u8>, CdrError> {
    let mut out = CDR_LE_HEADER.to_vec();
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut out, msg).map_err(|source| {
        CdrError::Encode { type_name: T::TYPE_NAME, source }
    })?;
    Ok(out)
}

/// Decodes a CDR payload (with its encapsulation header, either endianness) into a message.
pub fn from_cdr<T: RosMessage>(bytes: &[u8]) -> Result<T, CdrError> {
    if bytes.len() < 4 {
        return Err(CdrError::TooShort(bytes.len()));
    }
    let body = &bytes[4..];
    let decoded = match [bytes[0], bytes[1]] {
        [0x00, 0x01] => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        [0x00, 0x00] => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body),
        other => return Err(CdrError::Encapsulation(other)),
    };
    decoded
        .map(|(msg, _)| msg)
        .map_err(|source| CdrError::Decode { type_name: T::TYPE_NAME, source })
}
