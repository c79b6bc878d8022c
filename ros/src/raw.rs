//! Serialized messages that keep their bytes: RustDDS adapters that neither decode on receipt nor
//! encode on publishing, for the recorder and the player.
//!
//! ros2-client only offers typed subscriptions, so raw readers and writers are RustDDS entities
//! created on the node's participant with [`RawAdapter`]. On receipt the adapter rebuilds the
//! 4-byte encapsulation header from the RTPS representation identifier in front of the payload,
//! giving exactly the bytes rosbag2 stores. The two representation-option bytes are not passed
//! up by RustDDS and are written as zero (readers ignore them for plain CDR).

use std::convert::Infallible;

use ros2_client::dds::rustdds::{
    RepresentationIdentifier,
    bytes::Bytes,
    no_key::{Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter},
};

/// A serialized message: the 4-byte encapsulation header followed by the CDR body.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SerializedMessage {
    /// Header and body, as rosbag2 stores them.
    pub data: Vec<u8>,
}

/// The encapsulation header our raw publishers send: little-endian plain CDR. RustDDS writes one
/// representation per writer type, so raw publishing takes little-endian plain CDR only, which is
/// what every ROS 2 middleware on x86 and ARM produces.
pub const PUBLISHED_REPRESENTATION: [u8; 2] = [0x00, 0x01];

/// The RustDDS adapter for [`SerializedMessage`].
pub struct RawAdapter;

/// Decoder for [`RawAdapter`] (stateless).
#[derive(Clone, Copy)]
pub struct RawDecoder;

const ACCEPTED: &[RepresentationIdentifier] = &[
    RepresentationIdentifier::CDR_LE,
    RepresentationIdentifier::CDR_BE,
    RepresentationIdentifier::PL_CDR_LE,
    RepresentationIdentifier::PL_CDR_BE,
    RepresentationIdentifier::CDR2_LE,
    RepresentationIdentifier::CDR2_BE,
    RepresentationIdentifier::D_CDR2_LE,
    RepresentationIdentifier::D_CDR2_BE,
    RepresentationIdentifier::PL_CDR2_LE,
    RepresentationIdentifier::PL_CDR2_BE,
];

impl DeserializerAdapter<SerializedMessage> for RawAdapter {
    type Error = Infallible;
    type Decoded = SerializedMessage;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        ACCEPTED
    }

    fn transform_decoded(decoded: SerializedMessage) -> SerializedMessage {
        decoded
    }
}

impl DefaultDecoder<SerializedMessage> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

impl<'de> Decode<'de, SerializedMessage> for RawDecoder {
    type Error = Infallible;

    fn decode_bytes(
        self,
        input_bytes: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<SerializedMessage, Infallible> {
        let mut data = Vec::with_capacity(4 + input_bytes.len());
        data.extend_from_slice(&encoding.to_bytes());
        data.extend_from_slice(&[0, 0]);
        data.extend_from_slice(input_bytes);
        Ok(SerializedMessage { data })
    }
}

impl SerializerAdapter<SerializedMessage> for RawAdapter {
    type Error = Infallible;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    /// The body after the header; [`crate::RawPublisher::publish`] checks the header first.
    fn to_bytes(value: &SerializedMessage) -> Result<Bytes, Infallible> {
        Ok(Bytes::copy_from_slice(value.data.get(4..).unwrap_or(&[])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_rebuilds_the_header_and_encode_strips_it() {
        let body = [1u8, 2, 3, 4, 5];
        let msg = RawDecoder
            .decode_bytes(&body, RepresentationIdentifier::CDR_LE)
            .unwrap();
        assert_eq!(msg.data, [0, 1, 0, 0, 1, 2, 3, 4, 5]);
        let be = RawDecoder
            .decode_bytes(&body, RepresentationIdentifier::CDR_BE)
            .unwrap();
        assert_eq!(&be.data[..4], &[0, 0, 0, 0]);
        assert_eq!(RawAdapter::to_bytes(&msg).unwrap().as_ref(), &body);
        assert_eq!(
            RawAdapter::output_encoding().to_bytes(),
            PUBLISHED_REPRESENTATION
        );
    }
}
