//! ROS 2 message types as plain serde structs with the exact CDR layout of ROS 2 Jazzy.
//!
//! Every message implements [`RosMessage`]: it knows its ROS type name
//! (`geometry_msgs/msg/PoseStamped`), its own `.msg` text, and its full definition — its own text
//! followed by the text of every type it depends on, concatenated exactly the way rosbag2 stores
//! `ros2msg` schemas in MCAP files (see [`definition`]). [`to_cdr`] and [`from_cdr`] convert between
//! messages and serialized payloads (a 4-byte encapsulation header followed by little-endian plain
//! CDR), the bytes that travel over DDS and that rosbag2 writes into bags.
//!
//! For tools that handle types by name (recorder, player, bag export), [`registry`] maps a type
//! name to its definition and to CDR ⇄ JSON converters. [`check_finite`] reports NaN and infinite
//! fields by path, so nodes can reject bad input with a clear message.
//!
//! ```
//! use dynlab_msgs::geometry_msgs::{PoseStamped, Quaternion};
//! use dynlab_msgs::{RosMessage, from_cdr, to_cdr};
//!
//! let mut msg = PoseStamped::default();
//! msg.header.frame_id = "table".into();
//! msg.pose.position.x = 0.4;
//! msg.pose.orientation = Quaternion::from_yaw(0.2 * std::f64::consts::PI);
//! let bytes = to_cdr(&msg)?;
//! assert_eq!(&bytes[..4], &[0x00, 0x01, 0x00, 0x00]); // little-endian plain CDR
//! let back: PoseStamped = from_cdr(&bytes)?;
//! assert_eq!(back, msg);
//! assert!((back.pose.orientation.yaw() - 0.2 * std::f64::consts::PI).abs() < 1e-12);
//! assert!(PoseStamped::definition().contains("\nMSG: std_msgs/Header\n"));
//! # Ok::<(), dynlab_msgs::CdrError>(())
//! ```
#![warn(missing_docs)]

use byteorder::LittleEndian;
use serde::{Serialize, de::DeserializeOwned};

/// Implements [`RosMessage`] for a type: its ROS name, its own `.msg` text, and a full definition
/// composed once, on first use, from the texts of all known types.
macro_rules! impl_ros_message {
    ($ty:ty, $type_name:literal, $text:expr) => {
        impl $crate::RosMessage for $ty {
            const TYPE_NAME: &'static str = $type_name;
            const MSG_TEXT: &'static str = $text;
            fn definition() -> &'static str {
                static FULL: std::sync::LazyLock<String> =
                    std::sync::LazyLock::new(|| $crate::definition::known_full_text($type_name));
                FULL.as_str()
            }
        }
    };
}

/// Calls `$m!` with every message type of this crate: the one list that the definition table and
/// the registry are built from.
macro_rules! with_all_message_types {
    ($m:ident) => {
        $m!(
            crate::builtin_interfaces::Time,
            crate::builtin_interfaces::Duration,
            crate::std_msgs::Header,
            crate::geometry_msgs::Point,
            crate::geometry_msgs::Quaternion,
            crate::geometry_msgs::Pose,
            crate::geometry_msgs::PoseStamped,
            crate::geometry_msgs::Vector3,
            crate::geometry_msgs::Twist,
            crate::geometry_msgs::TwistStamped,
            crate::geometry_msgs::PoseWithCovariance,
            crate::geometry_msgs::PoseWithCovarianceStamped,
            crate::geometry_msgs::TwistWithCovariance,
            crate::geometry_msgs::Transform,
            crate::geometry_msgs::TransformStamped,
            crate::nav_msgs::Odometry,
            crate::nav_msgs::Path,
            crate::ackermann_msgs::AckermannDrive,
            crate::ackermann_msgs::AckermannDriveStamped,
            crate::rosgraph_msgs::Clock,
            crate::tf2_msgs::TFMessage,
            crate::dynlab_msgs::PushAction,
        )
    };
}

pub mod ackermann_msgs;
pub mod builtin_interfaces;
pub mod definition;
pub mod dynlab_msgs;
pub mod finite;
mod float_serde;
pub mod geometry_msgs;
pub mod json;
pub mod nav_msgs;
pub mod registry;
pub mod rosgraph_msgs;
pub mod std_msgs;
pub mod tf2_msgs;

pub use finite::{NonFiniteError, NonFiniteField, check_finite, non_finite_fields};
pub use json::{from_json, to_json};
pub use registry::{MessageType, all, dds_to_ros_type_name, lookup, ros_to_dds_type_name};

/// Encapsulation header for little-endian plain CDR (`CDR_LE`), the first four bytes of every
/// serialized ROS 2 message.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Encapsulation identifier of big-endian plain CDR (`CDR_BE`), accepted by [`from_cdr`].
pub const CDR_BE_ID: [u8; 2] = [0x00, 0x00];

/// The most bytes a payload may carry after the message body: DDS implementations pad the
/// serialized message to a multiple of 4 bytes (and say so in the encapsulation options).
pub const MAX_TRAILING_PADDING: usize = 3;

/// A ROS 2 message type.
pub trait RosMessage: Serialize + DeserializeOwned + Clone + std::fmt::Debug + PartialEq {
    /// The full ROS type name, e.g. `geometry_msgs/msg/PoseStamped`.
    const TYPE_NAME: &'static str;
    /// This type's own `.msg` text, without the definitions of the types it uses.
    const MSG_TEXT: &'static str;
    /// The `.msg` text followed by every dependency's text, separated and ordered as rosbag2
    /// (Jazzy) stores a `ros2msg` schema in MCAP: see [`definition::compose`].
    fn definition() -> &'static str;

    /// Checks that no floating-point field is NaN or infinite; the error names every such field
    /// by path (`pose.position.x is NaN`).
    fn check_finite(&self) -> Result<(), NonFiniteError> {
        finite::check_finite(self)
    }
}

/// Errors from encoding, decoding and converting messages.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    /// The payload is shorter than the 4-byte encapsulation header.
    #[error(
        "CDR payload of {0} bytes is too short for the 4-byte encapsulation header: \
         a serialized ROS 2 message starts with 00 01 00 00 (little endian) or 00 00 00 00"
    )]
    TooShort(usize),
    /// The encapsulation header names a representation other than plain CDR.
    #[error(
        "unsupported CDR encapsulation {0:02x?}: only plain CDR is supported (00 01 little endian, \
         00 00 big endian); XCDR2 and parameter lists are not"
    )]
    Encapsulation([u8; 2]),
    /// The body does not decode as the expected type.
    #[error(
        "payload does not decode as {type_name}: {source} \
         (is the payload cut short, or of another type?)"
    )]
    Decode {
        /// The type the payload was decoded as.
        type_name: &'static str,
        /// What the CDR decoder reported.
        source: cdr_encoding::Error,
    },
    /// More bytes follow the message than alignment padding can explain.
    #[error(
        "payload decodes as {type_name} but {extra} bytes are left over (at most \
         {MAX_TRAILING_PADDING} bytes of padding may follow a message): the payload is probably \
         of another type"
    )]
    TrailingBytes {
        /// The type the payload was decoded as.
        type_name: &'static str,
        /// How many bytes were left after the message.
        extra: usize,
    },
    /// Encoding failed (only for values serde cannot express in CDR).
    #[error("cannot encode {type_name}: {source}")]
    Encode {
        /// The type being encoded.
        type_name: &'static str,
        /// What the CDR encoder reported.
        source: cdr_encoding::Error,
    },
    /// A JSON value does not have the shape of the message.
    #[error(
        "JSON value is not a {type_name}: {source} (give every field by its ROS name; \
         non-finite floats as the strings \"NaN\", \"Infinity\", \"-Infinity\")"
    )]
    Json {
        /// The type the value was converted to or from.
        type_name: &'static str,
        /// What serde_json reported.
        source: serde_json::Error,
    },
    /// A string is not a ROS 2 or DDS type name.
    #[error(
        "`{0}` is not a ROS 2 type name: expected `package/msg/Type` \
         (e.g. `geometry_msgs/msg/PoseStamped`) or its DDS form \
         `package::msg::dds_::Type_`"
    )]
    InvalidTypeName(String),
}

/// Serializes a message to a CDR payload with its encapsulation header (little endian).
pub fn to_cdr<T: RosMessage>(msg: &T) -> Result<Vec<u8>, CdrError> {
    let mut out = CDR_LE_HEADER.to_vec();
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut out, msg).map_err(|source| {
        CdrError::Encode {
            type_name: T::TYPE_NAME,
            source,
        }
    })?;
    Ok(out)
}

/// Decodes a CDR payload (with its encapsulation header, either endianness) into a message.
///
/// Up to [`MAX_TRAILING_PADDING`] bytes after the message are accepted as alignment padding; more
/// is an error, since it means the payload holds something else.
pub fn from_cdr<T: RosMessage>(bytes: &[u8]) -> Result<T, CdrError> {
    let Some((header, body)) = bytes.split_first_chunk::<4>() else {
        return Err(CdrError::TooShort(bytes.len()));
    };
    let decoded = match [header[0], header[1]] {
        [0x00, 0x01] => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        CDR_BE_ID => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body),
        other => return Err(CdrError::Encapsulation(other)),
    };
    let (msg, used) = decoded.map_err(|source| CdrError::Decode {
        type_name: T::TYPE_NAME,
        source,
    })?;
    let extra = body.len().saturating_sub(used);
    if extra > MAX_TRAILING_PADDING {
        return Err(CdrError::TrailingBytes {
            type_name: T::TYPE_NAME,
            extra,
        });
    }
    Ok(msg)
}
