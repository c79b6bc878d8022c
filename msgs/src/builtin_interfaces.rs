//! `builtin_interfaces` messages.

use serde::{Deserialize, Serialize};

use crate::RosMessage;

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds since the epoch of the clock in use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds within the second, `0..1_000_000_000`.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch.
    pub fn from_nanos(ns: i64) -> Self {
        Time { sec: ns.div_euclid(1_000_000_000) as i32, nanosec: ns.rem_euclid(1_000_000_000) as u32 }
    }

    /// Nanoseconds since the epoch.
    pub fn to_nanos(self) -> i64 {
        self.sec as i64 * 1_000_000_000 + self.nanosec as i64
    }
}

pub(crate) const TIME_DEF: &str = "int32 sec\nuint32 nanosec\n";

impl RosMessage for Time {
    const TYPE_NAME: &'static str = "builtin_interfaces/msg/Time";
    const DEFINITION: &'static str = TIME_DEF;
}
