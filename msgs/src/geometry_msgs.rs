//! `geometry_msgs` messages: points, orientations, poses and velocities, plain and stamped,
//! with and without covariance.

use serde::{Deserialize, Serialize};

use crate::std_msgs::Header;

/// `geometry_msgs/msg/Point`: a position in free space.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point {
    /// x \[m\].
    #[serde(with = "crate::float_serde::f64_field")]
    pub x: f64,
    /// y \[m\].
    #[serde(with = "crate::float_serde::f64_field")]
    pub y: f64,
    /// z \[m\].
    #[serde(with = "crate::float_serde::f64_field")]
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`: an orientation as a unit quaternion `w + xi + yj + zk`.
/// The default is the identity (`w = 1`), as in ROS.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Quaternion {
    /// x component.
    #[serde(with = "crate::float_serde::f64_field")]
    pub x: f64,
    /// y component.
    #[serde(with = "crate::float_serde::f64_field")]
    pub y: f64,
    /// z component.
    #[serde(with = "crate::float_serde::f64_field")]
    pub z: f64,
    /// w (scalar) component.
    #[serde(with = "crate::float_serde::f64_field")]
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion::IDENTITY
    }
}

impl Quaternion {
    /// No rotation.
    pub const IDENTITY: Quaternion = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// The rotation by `yaw` radians about the z axis (counter-clockwise seen from above):
    /// `(0, 0, sin(θ/2), cos(θ/2))`.
    pub fn from_yaw(yaw: f64) -> Self {
        let (s, c) = (0.5 * yaw).sin_cos();
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }

    /// The yaw (rotation about z, in `(-π, π]`) of the z-y'-x'' Euler decomposition,
    /// `atan2(2(wz + xy), w² + x² − y² − z²)`. The formula is invariant to the quaternion's scale,
    /// so a slightly denormalised measurement gives the same yaw as its normalised form.
    pub fn yaw(&self) -> f64 {
        let Quaternion { x, y, z, w } = *self;
        (2.0 * (w * z + x * y)).atan2(w * w + x * x - y * y - z * z)
    }
}

/// `geometry_msgs/msg/Pose`: position and orientation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

impl Pose {
    /// A pose in the plane `z = 0`: position `(x, y)` and heading `yaw` \[rad\] about z.
    pub fn planar(x: f64, y: f64, yaw: f64) -> Self {
        Pose {
            position: Point { x, y, z: 0.0 },
            orientation: Quaternion::from_yaw(yaw),
        }
    }

    /// The planar part `(x, y, yaw)` of the pose (z and any roll and pitch are dropped).
    pub fn planar_xy_yaw(&self) -> (f64, f64, f64) {
        (self.position.x, self.position.y, self.orientation.yaw())
    }
}

/// `geometry_msgs/msg/PoseStamped`: a pose with a header.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `geometry_msgs/msg/Vector3`: a free vector (a direction and magnitude, not a position).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vector3 {
    /// x component.
    #[serde(with = "crate::float_serde::f64_field")]
    pub x: f64,
    /// y component.
    #[serde(with = "crate::float_serde::f64_field")]
    pub y: f64,
    /// z component.
    #[serde(with = "crate::float_serde::f64_field")]
    pub z: f64,
}

/// `geometry_msgs/msg/Twist`: linear \[m/s\] and angular \[rad/s\] velocity.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Twist {
    /// Linear velocity \[m/s\].
    pub linear: Vector3,
    /// Angular velocity \[rad/s\].
    pub angular: Vector3,
}

/// `geometry_msgs/msg/TwistStamped`: a twist with a header.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwistStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The twist.
    pub twist: Twist,
}

/// `geometry_msgs/msg/Transform`: the pose of a child frame in its parent frame, as tf2 stores it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transform {
    /// The child frame's origin in the parent frame \[m\].
    pub translation: Vector3,
    /// The child frame's orientation in the parent frame.
    pub rotation: Quaternion,
}

impl Transform {
    /// The transform of a planar pose: translation `(x, y, 0)`, rotation `yaw` about z.
    pub fn planar(x: f64, y: f64, yaw: f64) -> Self {
        Transform {
            translation: Vector3 { x, y, z: 0.0 },
            rotation: Quaternion::from_yaw(yaw),
        }
    }

    /// The same transform as a [`Pose`] (position = translation, orientation = rotation).
    pub fn as_pose(&self) -> Pose {
        Pose {
            position: Point {
                x: self.translation.x,
                y: self.translation.y,
                z: self.translation.z,
            },
            orientation: self.rotation,
        }
    }
}

/// `geometry_msgs/msg/TransformStamped`: the transform from `header.frame_id` (parent) to
/// `child_frame_id` at `header.stamp`, one edge of the tf tree.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child frame's pose in the parent frame.
    pub transform: Transform,
}

/// A row-major 6×6 covariance over (x, y, z, rotation about x, about y, about z).
pub type Covariance6 = [f64; 36];

/// `geometry_msgs/msg/PoseWithCovariance`: a pose with its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6×6 covariance (`float64[36]`, serialized without a length prefix).
    #[serde(with = "crate::float_serde::f64_array")]
    pub covariance: Covariance6,
}

impl Default for PoseWithCovariance {
    fn default() -> Self {
        PoseWithCovariance {
            pose: Pose::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/msg/PoseWithCovarianceStamped`: a pose with its uncertainty and a header (what
/// localisation such as AMCL publishes).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseWithCovarianceStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose and its covariance.
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/msg/TwistWithCovariance`: a twist with its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Row-major 6×6 covariance (`float64[36]`, serialized without a length prefix).
    #[serde(with = "crate::float_serde::f64_array")]
    pub covariance: Covariance6,
}

impl Default for TwistWithCovariance {
    fn default() -> Self {
        TwistWithCovariance {
            twist: Twist::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `Point.msg` text.
pub(crate) const POINT_MSG: &str = "\
# A position in free space [m].

float64 x
float64 y
float64 z
";

/// `Quaternion.msg` text (the defaults make the identity rotation).
pub(crate) const QUATERNION_MSG: &str = "\
# An orientation in free space as a quaternion w + xi + yj + zk.

float64 x 0
float64 y 0
float64 z 0
float64 w 1
";

/// `Pose.msg` text.
pub(crate) const POSE_MSG: &str = "\
# A pose in free space: position and orientation.

Point position
Quaternion orientation
";

/// `PoseStamped.msg` text.
pub(crate) const POSE_STAMPED_MSG: &str = "\
# A pose with a time stamp and the frame it is expressed in.

std_msgs/Header header
Pose pose
";

/// `Vector3.msg` text.
pub(crate) const VECTOR3_MSG: &str = "\
# A free vector: a direction and magnitude, not a position.
# Use Point for positions: transforming a Vector3 applies only the rotation.

float64 x
float64 y
float64 z
";

/// `Twist.msg` text.
pub(crate) const TWIST_MSG: &str = "\
# Velocity in free space: linear [m/s] and angular [rad/s] parts.

Vector3 linear
Vector3 angular
";

/// `TwistStamped.msg` text.
pub(crate) const TWIST_STAMPED_MSG: &str = "\
# A twist with a time stamp and the frame it is expressed in.

std_msgs/Header header
Twist twist
";

/// `PoseWithCovariance.msg` text.
pub(crate) const POSE_WITH_COVARIANCE_MSG: &str = "\
# A pose with its uncertainty.

Pose pose

# Row-major 6x6 covariance of (x, y, z, rotation about X, rotation about Y, rotation about Z);
# the rotations are about fixed axes.
float64[36] covariance
";

/// `PoseWithCovarianceStamped.msg` text.
pub(crate) const POSE_WITH_COVARIANCE_STAMPED_MSG: &str = "\
# A pose with its uncertainty, with a time stamp and the frame it is expressed in.

std_msgs/Header header
PoseWithCovariance pose
";

/// `TwistWithCovariance.msg` text.
pub(crate) const TWIST_WITH_COVARIANCE_MSG: &str = "\
# A twist with its uncertainty.

Twist twist

# Row-major 6x6 covariance of (x, y, z, rotation about X, rotation about Y, rotation about Z);
# the rotations are about fixed axes.
float64[36] covariance
";

/// `Transform.msg` text.
pub(crate) const TRANSFORM_MSG: &str = "\
# The transform between two coordinate frames in free space: the pose of the child frame
# in the parent frame.

Vector3 translation
Quaternion rotation
";

/// `TransformStamped.msg` text.
pub(crate) const TRANSFORM_STAMPED_MSG: &str = "\
# The transform from coordinate frame header.frame_id (the parent)
# to coordinate frame child_frame_id at the time of header.stamp.
# tf2 publishes these on /tf and /tf_static.

std_msgs/Header header

# The frame this transform gives the pose of.
string child_frame_id

Transform transform
";

impl_ros_message!(Point, "geometry_msgs/msg/Point", POINT_MSG);
impl_ros_message!(Quaternion, "geometry_msgs/msg/Quaternion", QUATERNION_MSG);
impl_ros_message!(Pose, "geometry_msgs/msg/Pose", POSE_MSG);
impl_ros_message!(
    PoseStamped,
    "geometry_msgs/msg/PoseStamped",
    POSE_STAMPED_MSG
);
impl_ros_message!(Vector3, "geometry_msgs/msg/Vector3", VECTOR3_MSG);
impl_ros_message!(Twist, "geometry_msgs/msg/Twist", TWIST_MSG);
impl_ros_message!(
    TwistStamped,
    "geometry_msgs/msg/TwistStamped",
    TWIST_STAMPED_MSG
);
impl_ros_message!(
    PoseWithCovariance,
    "geometry_msgs/msg/PoseWithCovariance",
    POSE_WITH_COVARIANCE_MSG
);
impl_ros_message!(
    PoseWithCovarianceStamped,
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    POSE_WITH_COVARIANCE_STAMPED_MSG
);
impl_ros_message!(
    TwistWithCovariance,
    "geometry_msgs/msg/TwistWithCovariance",
    TWIST_WITH_COVARIANCE_MSG
);
impl_ros_message!(Transform, "geometry_msgs/msg/Transform", TRANSFORM_MSG);
impl_ros_message!(
    TransformStamped,
    "geometry_msgs/msg/TransformStamped",
    TRANSFORM_STAMPED_MSG
);
