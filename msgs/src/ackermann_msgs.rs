//! `ackermann_msgs` messages: drive commands for car-like vehicles with Ackermann steering.
//!
//! In dynlab's topic contract (`/car/cmd`), `drive.steering_angle` is the front wheel angle \[rad\]
//! and `drive.acceleration` carries the normalised throttle command (−1…1); the other fields are
//! unused. All fields are `float32` on the wire.

use serde::{Deserialize, Serialize};

use crate::std_msgs::Header;

/// `ackermann_msgs/msg/AckermannDrive`: a drive command for an Ackermann-steered vehicle.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AckermannDrive {
    /// Desired angle of a virtual wheel at the centre of the front axle \[rad\], positive left.
    #[serde(with = "crate::float_serde::f32_field")]
    pub steering_angle: f32,
    /// Desired rate of change of the steering angle \[rad/s\]; 0 means as fast as possible.
    #[serde(with = "crate::float_serde::f32_field")]
    pub steering_angle_velocity: f32,
    /// Desired forward speed \[m/s\]; negative means reverse.
    #[serde(with = "crate::float_serde::f32_field")]
    pub speed: f32,
    /// Desired acceleration magnitude \[m/s²\]; 0 means as fast as possible.
    #[serde(with = "crate::float_serde::f32_field")]
    pub acceleration: f32,
    /// Desired jerk magnitude \[m/s³\]; 0 means as fast as possible.
    #[serde(with = "crate::float_serde::f32_field")]
    pub jerk: f32,
}

/// `ackermann_msgs/msg/AckermannDriveStamped`: a drive command with a header.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AckermannDriveStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The command.
    pub drive: AckermannDrive,
}

/// `AckermannDrive.msg` text.
pub(crate) const ACKERMANN_DRIVE_MSG: &str = "\
# Drive command for a car-like vehicle with Ackermann front-wheel steering.
#
# The steering angle is that of a virtual wheel at the centre of the front axle (as on a
# tricycle), positive to the left. A zero limit (steering_angle_velocity, acceleration, jerk)
# means: change as quickly as possible; a positive one bounds the rate of change in magnitude.
# Speed, acceleration and jerk are measured at the vehicle's centre of rotation; a negative
# speed means reverse.

float32 steering_angle          # desired virtual wheel angle [rad]
float32 steering_angle_velocity # desired steering rate [rad/s]

float32 speed                   # desired forward speed [m/s]
float32 acceleration            # desired acceleration [m/s^2]
float32 jerk                    # desired jerk [m/s^3]
";

/// `AckermannDriveStamped.msg` text.
pub(crate) const ACKERMANN_DRIVE_STAMPED_MSG: &str = "\
# A time-stamped drive command for a vehicle with Ackermann steering.

std_msgs/Header header
AckermannDrive drive
";

impl_ros_message!(
    AckermannDrive,
    "ackermann_msgs/msg/AckermannDrive",
    ACKERMANN_DRIVE_MSG
);
impl_ros_message!(
    AckermannDriveStamped,
    "ackermann_msgs/msg/AckermannDriveStamped",
    ACKERMANN_DRIVE_STAMPED_MSG
);
