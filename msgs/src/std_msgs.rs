//! `std_msgs` messages: [`Header`].

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// `std_msgs/msg/Header`: stamp and coordinate frame of a stamped message.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Header {
    /// Time of the data.
    pub stamp: Time,
    /// Coordinate frame the data is expressed in.
    pub frame_id: String,
}

impl Header {
    /// A header with the given stamp and frame.
    pub fn new(stamp: Time, frame_id: impl Into<String>) -> Self {
        Header {
            stamp,
            frame_id: frame_id.into(),
        }
    }
}

/// `Header.msg` text.
pub(crate) const HEADER_MSG: &str = "\
# Metadata of stamped data: when it was measured and in which frame it is expressed.

# Time of the data (sensor acquisition time when known).
builtin_interfaces/Time stamp

# Coordinate frame the data is expressed in.
string frame_id
";

impl_ros_message!(Header, "std_msgs/msg/Header", HEADER_MSG);
