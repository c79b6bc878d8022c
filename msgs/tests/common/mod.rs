//! Seeded sample messages for the tests: every type, with varied and extreme values.
#![allow(dead_code)]

use dynlab_msgs::ackermann_msgs::{AckermannDrive, AckermannDriveStamped};
use dynlab_msgs::builtin_interfaces::{Duration, Time};
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::{
    Point, Pose, PoseStamped, PoseWithCovariance, PoseWithCovarianceStamped, Quaternion, Transform,
    TransformStamped, Twist, TwistStamped, TwistWithCovariance, Vector3,
};
use dynlab_msgs::nav_msgs::{Odometry, Path};
use dynlab_msgs::rosgraph_msgs::Clock;
use dynlab_msgs::std_msgs::Header;
use dynlab_msgs::tf2_msgs::TFMessage;

/// SplitMix64: a tiny seeded generator, the same stream on every platform.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Mostly ordinary values, sometimes extreme finite ones (never NaN or infinite: those
    /// compare unequal or are tested separately).
    pub fn f64(&mut self) -> f64 {
        match self.below(10) {
            0 => [
                0.0,
                -0.0,
                f64::MAX,
                f64::MIN,
                f64::MIN_POSITIVE,
                5e-324,
                -1e-300,
                1e300,
            ][self.below(8) as usize],
            1 => f64::from_bits(self.next_u64() & !(0x7ff << 52) | (self.below(0x7fe) << 52)),
            _ => (self.unit() - 0.5) * 200.0,
        }
    }
    pub fn f32(&mut self) -> f32 {
        match self.below(10) {
            0 => [
                0.0,
                -0.0,
                f32::MAX,
                f32::MIN,
                f32::MIN_POSITIVE,
                1e-45,
                -3.3e38,
            ][self.below(7) as usize],
            _ => ((self.unit() - 0.5) * 20.0) as f32,
        }
    }
    pub fn string(&mut self) -> String {
        const PIECES: [&str; 8] = [
            "",
            "world",
            "table",
            "ü",
            "ロボット",
            "🚗",
            "base_link/",
            " ",
        ];
        let n = self.below(4);
        (0..n)
            .map(|_| PIECES[self.below(PIECES.len() as u64) as usize])
            .collect()
    }
}

/// A seeded sample of a message type.
pub trait Sample: Sized {
    fn sample(rng: &mut Rng) -> Self;
}

impl Sample for Time {
    fn sample(rng: &mut Rng) -> Self {
        match rng.below(4) {
            0 => Time {
                sec: i32::MIN,
                nanosec: 999_999_999,
            },
            1 => Time {
                sec: i32::MAX,
                nanosec: 0,
            },
            _ => Time {
                sec: rng.next_u64() as i32,
                nanosec: rng.below(1_000_000_000) as u32,
            },
        }
    }
}

impl Sample for Duration {
    fn sample(rng: &mut Rng) -> Self {
        let t = Time::sample(rng);
        Duration {
            sec: t.sec,
            nanosec: t.nanosec,
        }
    }
}

impl Sample for Header {
    fn sample(rng: &mut Rng) -> Self {
        Header {
            stamp: Time::sample(rng),
            frame_id: rng.string(),
        }
    }
}

impl Sample for Point {
    fn sample(rng: &mut Rng) -> Self {
        Point {
            x: rng.f64(),
            y: rng.f64(),
            z: rng.f64(),
        }
    }
}

impl Sample for Vector3 {
    fn sample(rng: &mut Rng) -> Self {
        Vector3 {
            x: rng.f64(),
            y: rng.f64(),
            z: rng.f64(),
        }
    }
}

impl Sample for Quaternion {
    fn sample(rng: &mut Rng) -> Self {
        Quaternion {
            x: rng.f64(),
            y: rng.f64(),
            z: rng.f64(),
            w: rng.f64(),
        }
    }
}

impl Sample for Pose {
    fn sample(rng: &mut Rng) -> Self {
        Pose {
            position: Point::sample(rng),
            orientation: Quaternion::sample(rng),
        }
    }
}

impl Sample for PoseStamped {
    fn sample(rng: &mut Rng) -> Self {
        PoseStamped {
            header: Header::sample(rng),
            pose: Pose::sample(rng),
        }
    }
}

impl Sample for Twist {
    fn sample(rng: &mut Rng) -> Self {
        Twist {
            linear: Vector3::sample(rng),
            angular: Vector3::sample(rng),
        }
    }
}

impl Sample for TwistStamped {
    fn sample(rng: &mut Rng) -> Self {
        TwistStamped {
            header: Header::sample(rng),
            twist: Twist::sample(rng),
        }
    }
}

fn covariance(rng: &mut Rng) -> [f64; 36] {
    std::array::from_fn(|_| rng.f64())
}

impl Sample for PoseWithCovariance {
    fn sample(rng: &mut Rng) -> Self {
        PoseWithCovariance {
            pose: Pose::sample(rng),
            covariance: covariance(rng),
        }
    }
}

impl Sample for PoseWithCovarianceStamped {
    fn sample(rng: &mut Rng) -> Self {
        PoseWithCovarianceStamped {
            header: Header::sample(rng),
            pose: PoseWithCovariance::sample(rng),
        }
    }
}

impl Sample for TwistWithCovariance {
    fn sample(rng: &mut Rng) -> Self {
        TwistWithCovariance {
            twist: Twist::sample(rng),
            covariance: covariance(rng),
        }
    }
}

impl Sample for Odometry {
    fn sample(rng: &mut Rng) -> Self {
        Odometry {
            header: Header::sample(rng),
            child_frame_id: rng.string(),
            pose: PoseWithCovariance::sample(rng),
            twist: TwistWithCovariance::sample(rng),
        }
    }
}

impl Sample for Path {
    fn sample(rng: &mut Rng) -> Self {
        let n = [0, 1, 2, 7, 60][rng.below(5) as usize];
        Path {
            header: Header::sample(rng),
            poses: (0..n).map(|_| PoseStamped::sample(rng)).collect(),
        }
    }
}

impl Sample for Transform {
    fn sample(rng: &mut Rng) -> Self {
        Transform {
            translation: Vector3::sample(rng),
            rotation: Quaternion::sample(rng),
        }
    }
}

impl Sample for TransformStamped {
    fn sample(rng: &mut Rng) -> Self {
        TransformStamped {
            header: Header::sample(rng),
            child_frame_id: rng.string(),
            transform: Transform::sample(rng),
        }
    }
}

impl Sample for TFMessage {
    fn sample(rng: &mut Rng) -> Self {
        let n = [0, 1, 2, 5][rng.below(4) as usize];
        TFMessage {
            transforms: (0..n).map(|_| TransformStamped::sample(rng)).collect(),
        }
    }
}

impl Sample for AckermannDrive {
    fn sample(rng: &mut Rng) -> Self {
        AckermannDrive {
            steering_angle: rng.f32(),
            steering_angle_velocity: rng.f32(),
            speed: rng.f32(),
            acceleration: rng.f32(),
            jerk: rng.f32(),
        }
    }
}

impl Sample for AckermannDriveStamped {
    fn sample(rng: &mut Rng) -> Self {
        AckermannDriveStamped {
            header: Header::sample(rng),
            drive: AckermannDrive::sample(rng),
        }
    }
}

impl Sample for Clock {
    fn sample(rng: &mut Rng) -> Self {
        Clock {
            clock: Time::sample(rng),
        }
    }
}

impl Sample for PushAction {
    fn sample(rng: &mut Rng) -> Self {
        PushAction {
            header: Header::sample(rng),
            location: rng.f64(),
            angle: rng.f64(),
            length: rng.f64(),
        }
    }
}

/// Calls `$body!(Type)` for every message type.
#[macro_export]
macro_rules! for_every_type {
    ($body:ident) => {
        $body!(dynlab_msgs::builtin_interfaces::Time);
        $body!(dynlab_msgs::builtin_interfaces::Duration);
        $body!(dynlab_msgs::std_msgs::Header);
        $body!(dynlab_msgs::geometry_msgs::Point);
        $body!(dynlab_msgs::geometry_msgs::Quaternion);
        $body!(dynlab_msgs::geometry_msgs::Pose);
        $body!(dynlab_msgs::geometry_msgs::PoseStamped);
        $body!(dynlab_msgs::geometry_msgs::Vector3);
        $body!(dynlab_msgs::geometry_msgs::Twist);
        $body!(dynlab_msgs::geometry_msgs::TwistStamped);
        $body!(dynlab_msgs::geometry_msgs::PoseWithCovariance);
        $body!(dynlab_msgs::geometry_msgs::PoseWithCovarianceStamped);
        $body!(dynlab_msgs::geometry_msgs::TwistWithCovariance);
        $body!(dynlab_msgs::geometry_msgs::Transform);
        $body!(dynlab_msgs::geometry_msgs::TransformStamped);
        $body!(dynlab_msgs::nav_msgs::Odometry);
        $body!(dynlab_msgs::nav_msgs::Path);
        $body!(dynlab_msgs::ackermann_msgs::AckermannDrive);
        $body!(dynlab_msgs::ackermann_msgs::AckermannDriveStamped);
        $body!(dynlab_msgs::rosgraph_msgs::Clock);
        $body!(dynlab_msgs::tf2_msgs::TFMessage);
        $body!(dynlab_msgs::dynlab_msgs::PushAction);
    };
}
