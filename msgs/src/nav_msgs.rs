//! `nav_msgs` messages: [`Odometry`] and [`Path`].

use serde::{Deserialize, Serialize};

use crate::geometry_msgs::{PoseStamped, PoseWithCovariance, TwistWithCovariance};
use crate::std_msgs::Header;

/// `nav_msgs/msg/Odometry`: an estimate of pose and velocity.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Odometry {
    /// Stamp, and the frame the pose is expressed in.
    pub header: Header,
    /// The frame the twist is expressed in (usually the body frame).
    pub child_frame_id: String,
    /// Estimated pose in `header.frame_id`.
    pub pose: PoseWithCovariance,
    /// Estimated velocity in `child_frame_id`.
    pub twist: TwistWithCovariance,
}

/// `nav_msgs/msg/Path`: a sequence of poses for a robot to follow (or that it followed).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Path {
    /// Stamp and frame of the path.
    pub header: Header,
    /// The poses, in order (a sequence: serialized with a length prefix).
    pub poses: Vec<PoseStamped>,
}

/// `Odometry.msg` text.
pub(crate) const ODOMETRY_MSG: &str = "\
# An estimate of pose and velocity in free space.
# The pose is expressed in header.frame_id, the twist in child_frame_id.

std_msgs/Header header

# The frame the twist is expressed in.
string child_frame_id

# Estimated pose, usually relative to a fixed world frame.
geometry_msgs/PoseWithCovariance pose

# Estimated linear and angular velocity relative to child_frame_id.
geometry_msgs/TwistWithCovariance twist
";

/// `Path.msg` text.
pub(crate) const PATH_MSG: &str = "\
# A sequence of poses for a robot to follow.

# The frame of the path.
std_msgs/Header header

# The poses, in order.
geometry_msgs/PoseStamped[] poses
";

impl_ros_message!(Odometry, "nav_msgs/msg/Odometry", ODOMETRY_MSG);
impl_ros_message!(Path, "nav_msgs/msg/Path", PATH_MSG);
