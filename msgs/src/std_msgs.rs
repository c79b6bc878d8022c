//! `std_msgs` messages.

use serde::{Deserialize, Serialize};

use crate::RosMessage;
use crate::builtin_interfaces::Time;

/// `std_msgs/msg/Header`: stamp and coordinate frame of a stamped message.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// Time of the data.
    pub stamp: Time,
    /// Coordinate frame the data is expressed in.
    pub frame_id: String,
}

impl RosMessage for Header {
    const TYPE_NAME: &'static str = "std_msgs/msg/Header";
    const DEFINITION: &'static str = concat!(
        "builtin_interfaces/Time stamp\nstring frame_id\n",
        "================================================================================\n",
        "MSG: builtin_interfaces/Time\n",
        "int32 sec\nuint32 nanosec\n"
    );
}
