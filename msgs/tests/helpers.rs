//! Domain helpers: time and duration conversions, yaw of quaternions, planar poses, push ranges.

use std::f64::consts::{FRAC_1_SQRT_2, FRAC_PI_2, PI};

use dynlab_msgs::builtin_interfaces::{Duration, Time};
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::{Pose, Quaternion};

#[test]
fn time_from_nanos_keeps_nanosec_in_range_for_negative_times() {
    assert_eq!(
        Time::from_nanos(-1),
        Time {
            sec: -1,
            nanosec: 999_999_999
        }
    );
    assert_eq!(
        Time::from_nanos(-250_000_000),
        Time {
            sec: -1,
            nanosec: 750_000_000
        }
    );
    assert_eq!(
        Time::from_nanos(-1_000_000_000),
        Time {
            sec: -1,
            nanosec: 0
        }
    );
    assert_eq!(
        Time::from_nanos(1_500_000_001),
        Time {
            sec: 1,
            nanosec: 500_000_001
        }
    );
    for ns in [
        -3_000_000_007i64,
        -1,
        0,
        1,
        999_999_999,
        1_790_000_000_123_456_789,
    ] {
        assert_eq!(Time::from_nanos(ns).to_nanos(), ns);
        assert_eq!(Duration::from_nanos(ns).to_nanos(), ns);
    }
}

#[test]
fn nanos_out_of_int32_seconds_saturate_or_are_none() {
    let too_big = (i32::MAX as i64 + 1) * 1_000_000_000;
    assert_eq!(Time::checked_from_nanos(too_big), None);
    assert_eq!(Time::from_nanos(too_big), Time::MAX);
    assert_eq!(Time::from_nanos(i64::MIN), Time::MIN);
    assert_eq!(Duration::from_nanos(i64::MAX), Duration::MAX);
    assert_eq!(
        Time::checked_from_nanos(i32::MIN as i64 * 1_000_000_000),
        Some(Time::MIN)
    );
}

#[test]
fn seconds_as_float_round_to_the_nearest_nanosecond() {
    assert_eq!(
        Time::from_secs_f64(1.5),
        Time {
            sec: 1,
            nanosec: 500_000_000
        }
    );
    assert_eq!(
        Time::from_secs_f64(-0.25),
        Time {
            sec: -1,
            nanosec: 750_000_000
        }
    );
    assert_eq!(
        Duration::from_secs_f64(-1.75),
        Duration {
            sec: -2,
            nanosec: 250_000_000
        }
    );
    // 0.1 s is 0.1000000000000000055… in binary: rounds to exactly 100 ms.
    assert_eq!(
        Duration::from_secs_f64(0.1),
        Duration {
            sec: 0,
            nanosec: 100_000_000
        }
    );
    // Just below a whole second rounds up into the next one, not to nanosec = 1e9.
    assert_eq!(
        Time::from_secs_f64(2.999_999_999_9),
        Time { sec: 3, nanosec: 0 }
    );
    assert_eq!(Time::from_secs_f64(-1e-12), Time { sec: 0, nanosec: 0 });
    // An epoch-scale stamp keeps microsecond accuracy.
    let t = Time::from_secs_f64(1_790_000_000.123_456);
    assert_eq!(t.sec, 1_790_000_000);
    assert!((t.nanosec as i64 - 123_456_000).abs() < 1_000, "{t:?}");
}

#[test]
fn seconds_round_trip_through_float() {
    for (sec, nanosec) in [
        (0, 0),
        (1, 1),
        (-1, 999_999_999),
        (-5, 3),
        (86_400, 123_456_789),
    ] {
        let t = Time { sec, nanosec };
        assert_eq!(Time::from_secs_f64(t.as_secs_f64()), t);
        let d = Duration { sec, nanosec };
        assert_eq!(Duration::from_secs_f64(d.as_secs_f64()), d);
    }
    assert_eq!(
        Time {
            sec: -1,
            nanosec: 500_000_000
        }
        .as_secs_f64(),
        -0.5
    );
}

#[test]
fn non_finite_and_out_of_range_seconds() {
    assert_eq!(Time::checked_from_secs_f64(f64::NAN), None);
    assert_eq!(Time::checked_from_secs_f64(f64::INFINITY), None);
    assert_eq!(Time::checked_from_secs_f64(3e9), None);
    assert_eq!(Time::from_secs_f64(f64::NAN), Time::ZERO);
    assert_eq!(Time::from_secs_f64(f64::INFINITY), Time::MAX);
    assert_eq!(Duration::from_secs_f64(-1e300), Duration::MIN);
}

#[test]
fn durations_between_times_and_std_conversion() {
    let a = Time {
        sec: 10,
        nanosec: 100,
    };
    let b = Time {
        sec: 9,
        nanosec: 200,
    };
    assert_eq!(
        a.since(b),
        Duration {
            sec: 0,
            nanosec: 999_999_900
        }
    );
    assert_eq!(
        b.since(a),
        Duration {
            sec: -1,
            nanosec: 100
        }
    );
    assert_eq!(b.since(a).to_nanos(), -999_999_900);
    assert_eq!(
        a.since(b).to_std(),
        Some(std::time::Duration::new(0, 999_999_900))
    );
    assert_eq!(b.since(a).to_std(), None);
    assert_eq!(
        Duration::from_std(std::time::Duration::from_millis(1500)).as_secs_f64(),
        1.5
    );
}

#[test]
fn from_yaw_matches_known_quaternions() {
    let close = |q: Quaternion, x: f64, y: f64, z: f64, w: f64| {
        assert!(
            (q.x - x).abs() < 1e-15
                && (q.y - y).abs() < 1e-15
                && (q.z - z).abs() < 1e-15
                && (q.w - w).abs() < 1e-15,
            "{q:?} != ({x}, {y}, {z}, {w})"
        );
    };
    close(Quaternion::from_yaw(0.0), 0.0, 0.0, 0.0, 1.0);
    close(
        Quaternion::from_yaw(FRAC_PI_2),
        0.0,
        0.0,
        FRAC_1_SQRT_2,
        FRAC_1_SQRT_2,
    );
    close(
        Quaternion::from_yaw(-FRAC_PI_2),
        0.0,
        0.0,
        -FRAC_1_SQRT_2,
        FRAC_1_SQRT_2,
    );
    close(Quaternion::from_yaw(PI), 0.0, 0.0, 1.0, 0.0);
}

#[test]
fn yaw_of_known_quaternions() {
    let q = |x, y, z, w| Quaternion { x, y, z, w };
    assert_eq!(q(0.0, 0.0, 0.0, 1.0).yaw(), 0.0);
    assert!((q(0.0, 0.0, FRAC_1_SQRT_2, FRAC_1_SQRT_2).yaw() - FRAC_PI_2).abs() < 1e-15);
    assert!((q(0.0, 0.0, 1.0, 0.0).yaw().abs() - PI).abs() < 1e-15);
    // -q is the same rotation.
    assert!((q(0.0, 0.0, -FRAC_1_SQRT_2, -FRAC_1_SQRT_2).yaw() - FRAC_PI_2).abs() < 1e-15);
    // Scale does not matter.
    assert!((q(0.0, 0.0, 2.0, 2.0).yaw() - FRAC_PI_2).abs() < 1e-15);
    // A pure roll of 90° (about x) has no yaw.
    assert!(q(FRAC_1_SQRT_2, 0.0, 0.0, FRAC_1_SQRT_2).yaw().abs() < 1e-15);
    // Yaw 30° then roll 20° (intrinsic z-y'-x''): q = q_z(30°) * q_x(20°); yaw stays 30°.
    let (sz, cz) = (15f64.to_radians().sin(), 15f64.to_radians().cos());
    let (sx, cx) = (10f64.to_radians().sin(), 10f64.to_radians().cos());
    let yaw_roll = q(cz * sx, sz * sx, sz * cx, cz * cx);
    assert!(
        (yaw_roll.yaw() - 30f64.to_radians()).abs() < 1e-14,
        "{}",
        yaw_roll.yaw()
    );
}

#[test]
fn yaw_round_trips_over_the_circle() {
    for i in -999..=1000 {
        let theta = i as f64 * PI / 1000.0;
        let back = Quaternion::from_yaw(theta).yaw();
        let diff = (back - theta + PI).rem_euclid(2.0 * PI) - PI;
        assert!(diff.abs() < 1e-14, "θ = {theta}: yaw {back}");
        assert!(back > -PI - 1e-15 && back <= PI + 1e-15);
    }
}

#[test]
fn planar_pose_helpers() {
    let pose = Pose::planar(0.4, -0.1, 0.2 * PI);
    assert_eq!(pose.position.z, 0.0);
    let (x, y, yaw) = pose.planar_xy_yaw();
    assert_eq!((x, y), (0.4, -0.1));
    assert!((yaw - 0.2 * PI).abs() < 1e-15);
    assert_eq!(Quaternion::default(), Quaternion::IDENTITY);
}

#[test]
fn push_action_range_check() {
    let mut a = PushAction {
        location: -1.0,
        angle: FRAC_PI_2,
        length: 1.0,
        ..Default::default()
    };
    assert!(a.in_range());
    a.length = 1.01;
    assert!(!a.in_range());
    a.length = 0.5;
    a.location = f64::NAN;
    assert!(!a.in_range());
}
