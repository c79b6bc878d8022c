//! `rosgraph_msgs` messages: [`Clock`], the simulated time published on `/clock`.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// `rosgraph_msgs/msg/Clock`: the current simulated time; nodes with `use_sim_time` follow it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Clock {
    /// The current time.
    pub clock: Time,
}

/// `Clock.msg` text.
pub(crate) const CLOCK_MSG: &str = "\
# The current time of a simulated clock, published on /clock.
# Nodes with use_sim_time set take their time from it.

builtin_interfaces/Time clock
";

impl_ros_message!(Clock, "rosgraph_msgs/msg/Clock", CLOCK_MSG);
