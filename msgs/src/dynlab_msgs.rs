//! dynlab's own messages: [`PushAction`], one push of the planar-pushing task (Tu & Lin).

use serde::{Deserialize, Serialize};

use crate::std_msgs::Header;

/// `dynlab_msgs/msg/PushAction`: one quasi-static push of the block, in the normalised action
/// space of Tu & Lin: `(p, φ, ℓ)`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PushAction {
    /// Stamp (when the push starts) and the frame of the block pose it refers to.
    pub header: Header,
    /// Contact location `p ∈ [−1, 1]` along the pushed edge of the block (0 = edge centre).
    #[serde(with = "crate::float_serde::f64_field")]
    pub location: f64,
    /// Push angle `φ ∈ [−π/2, π/2]` \[rad\] from the inward normal of the pushed edge.
    #[serde(with = "crate::float_serde::f64_field")]
    pub angle: f64,
    /// Push length `ℓ ∈ [0, 1]`, in units of 0.1 m (ℓ = 1 pushes 0.1 m).
    #[serde(with = "crate::float_serde::f64_field")]
    pub length: f64,
}

impl PushAction {
    /// Bounds of [`PushAction::location`].
    pub const LOCATION_RANGE: (f64, f64) = (-1.0, 1.0);
    /// Bounds of [`PushAction::angle`] \[rad\].
    pub const ANGLE_RANGE: (f64, f64) = (-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
    /// Bounds of [`PushAction::length`].
    pub const LENGTH_RANGE: (f64, f64) = (0.0, 1.0);
    /// Metres of push per unit of [`PushAction::length`].
    pub const LENGTH_UNIT_M: f64 = 0.1;

    /// Whether all three action values are finite and within their documented ranges.
    pub fn in_range(&self) -> bool {
        let within = |v: f64, (lo, hi): (f64, f64)| (lo..=hi).contains(&v);
        within(self.location, Self::LOCATION_RANGE)
            && within(self.angle, Self::ANGLE_RANGE)
            && within(self.length, Self::LENGTH_RANGE)
    }
}

/// `PushAction.msg` text.
pub(crate) const PUSH_ACTION_MSG: &str = "\
# One quasi-static push of the block by the pusher (planar pushing, Tu & Lin),
# in the normalised action space (p, phi, l).

# Stamp: when the push starts. Frame: the frame of the block pose the push refers to.
std_msgs/Header header

# p in [-1, 1]: contact location along the pushed edge of the block (0 = edge centre).
float64 location

# phi in [-pi/2, pi/2] rad: push direction, measured from the inward normal of the pushed edge.
float64 angle

# l in [0, 1]: push length in units of 0.1 m (l = 1 pushes 0.1 m).
float64 length
";

impl_ros_message!(PushAction, "dynlab_msgs/msg/PushAction", PUSH_ACTION_MSG);
