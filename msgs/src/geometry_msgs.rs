//! `geometry_msgs` messages.

use serde::{Deserialize, Serialize};

use crate::RosMessage;
use crate::std_msgs::Header;

/// `geometry_msgs/msg/Point`: a position in free space.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x [m].
    pub x: f64,
    /// y [m].
    pub y: f64,
    /// z [m].
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`: an orientation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
    /// w (scalar) component.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

/// `geometry_msgs/msg/Pose`: position and orientation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`: a pose with a header.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}


impl RosMessage for PoseStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseStamped";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nPose pose\n",
        "================================================================================\n",
        "MSG: std_msgs/Header\n",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
        "================================================================================\n",
        "MSG: builtin_interfaces/Time\n",
        "int32 sec\nuint32 nanosec\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Pose\n",
        "Point position\nQuaternion orientation\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Point\n",
        "float64 x\nfloat64 y\nfloat64 z\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Quaternion\n",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    );
}

