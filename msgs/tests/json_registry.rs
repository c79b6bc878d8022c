//! The JSON form, the registry of types by name, DDS type names, and the non-finite check.

mod common;

use common::{Rng, Sample};
use dynlab_msgs::ackermann_msgs::AckermannDrive;
use dynlab_msgs::geometry_msgs::{Point, PoseStamped, PoseWithCovariance};
use dynlab_msgs::nav_msgs::{Odometry, Path};
use dynlab_msgs::{
    CdrError, RosMessage, all, check_finite, dds_to_ros_type_name, from_json, lookup,
    non_finite_fields, ros_to_dds_type_name, to_cdr, to_json,
};
use serde_json::json;

#[test]
fn every_type_round_trips_through_json_bit_exactly() {
    macro_rules! check {
        ($t:ty) => {{
            let mut rng = Rng::new(3);
            let entry = lookup(<$t>::TYPE_NAME).unwrap();
            for _ in 0..30 {
                let msg = <$t>::sample(&mut rng);
                let cdr = to_cdr(&msg).unwrap();
                let value = (entry.to_json)(&cdr).unwrap();
                // Through text too, as the tools exchange it.
                let text = serde_json::to_string(&value).unwrap();
                let reparsed: serde_json::Value = serde_json::from_str(&text).unwrap();
                assert_eq!(
                    (entry.from_json)(&reparsed).unwrap(),
                    cdr,
                    "{}: {text}",
                    <$t>::TYPE_NAME
                );
                assert_eq!(from_json::<$t>(&value).unwrap(), msg);
            }
        }};
    }
    for_every_type!(check);
}

#[test]
fn json_form_uses_ros_field_names() {
    let mut msg = PoseStamped::default();
    msg.header.frame_id = "world".into();
    msg.header.stamp.sec = -3;
    assert_eq!(
        to_json(&msg).unwrap(),
        json!({
            "header": {"stamp": {"sec": -3, "nanosec": 0}, "frame_id": "world"},
            "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
                     "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
        })
    );
    let path = Path {
        poses: vec![msg],
        ..Path::default()
    };
    assert_eq!(
        to_json(&path).unwrap()["poses"][0]["header"]["frame_id"],
        "world"
    );
}

#[test]
fn non_finite_floats_are_strings_in_json() {
    let mut odom = Odometry::default();
    odom.pose.pose.position.x = f64::NAN;
    odom.twist.twist.angular.z = f64::INFINITY;
    odom.pose.covariance[35] = f64::NEG_INFINITY;
    let v = to_json(&odom).unwrap();
    assert_eq!(v["pose"]["pose"]["position"]["x"], "NaN");
    assert_eq!(v["twist"]["twist"]["angular"]["z"], "Infinity");
    assert_eq!(v["pose"]["covariance"][35], "-Infinity");
    let back: Odometry = from_json(&v).unwrap();
    assert!(back.pose.pose.position.x.is_nan());
    assert_eq!(back.twist.twist.angular.z, f64::INFINITY);
    assert_eq!(back.pose.covariance[35], f64::NEG_INFINITY);
    let drive = AckermannDrive {
        speed: f32::NAN,
        jerk: f32::NEG_INFINITY,
        ..Default::default()
    };
    let v = to_json(&drive).unwrap();
    assert_eq!(
        (v["speed"].clone(), v["jerk"].clone()),
        (json!("NaN"), json!("-Infinity"))
    );
    // Accepted spellings on input.
    let p: Point = from_json(&json!({"x": "nan", "y": "-inf", "z": "+Infinity"})).unwrap();
    assert!(p.x.is_nan() && p.y == f64::NEG_INFINITY && p.z == f64::INFINITY);
    // Integers are accepted for floats.
    let p: Point = from_json(&json!({"x": 1, "y": -2, "z": 0})).unwrap();
    assert_eq!((p.x, p.y, p.z), (1.0, -2.0, 0.0));
}

#[test]
fn json_input_is_strict() {
    let err = |v: serde_json::Value| from_json::<Point>(&v).unwrap_err().to_string();
    assert!(err(json!({"x": 1.0, "y": 2.0})).contains("missing field `z`"));
    assert!(err(json!({"x": 1.0, "y": 2.0, "z": 3.0, "w": 4.0})).contains("unknown field `w`"));
    assert!(err(json!({"x": "one", "y": 2.0, "z": 3.0})).contains("\"NaN\""));
    let short = json!({"pose": to_json(&dynlab_msgs::geometry_msgs::Pose::default()).unwrap(),
                       "covariance": vec![0.0; 35]});
    let e = from_json::<PoseWithCovariance>(&short)
        .unwrap_err()
        .to_string();
    assert!(e.contains("exactly 36"), "{e}");
    let long = json!({"pose": short["pose"], "covariance": vec![0.0; 37]});
    assert!(from_json::<PoseWithCovariance>(&long).is_err());
    let big = json!({"steering_angle": 1e39, "steering_angle_velocity": 0, "speed": 0,
                     "acceleration": 0, "jerk": 0});
    let e = from_json::<AckermannDrive>(&big).unwrap_err().to_string();
    assert!(e.contains("out of range for float32"), "{e}");
    let time = json!({"sec": 3_000_000_000u64, "nanosec": 0});
    assert!(from_json::<dynlab_msgs::builtin_interfaces::Time>(&time).is_err());
    assert!(matches!(
        from_json::<Point>(&json!("point")),
        Err(CdrError::Json { .. })
    ));
}

#[test]
fn lookup_accepts_ros_short_and_dds_names() {
    let full = lookup("geometry_msgs/msg/PoseStamped").unwrap();
    assert_eq!(full.type_name, "geometry_msgs/msg/PoseStamped");
    assert_eq!(full.definition, PoseStamped::definition());
    assert!(std::ptr::eq(
        lookup("geometry_msgs/PoseStamped").unwrap(),
        full
    ));
    assert!(std::ptr::eq(
        lookup("geometry_msgs::msg::dds_::PoseStamped_").unwrap(),
        full
    ));
    assert!(lookup("geometry_msgs/msg/Nope").is_none());
    assert!(lookup("geometry_msgs/srv/PoseStamped").is_none());
    assert!(lookup("PoseStamped").is_none());
    assert!(lookup("").is_none());
}

#[test]
fn registry_lists_every_type_once() {
    let names: std::collections::BTreeSet<_> = all().iter().map(|t| t.type_name).collect();
    assert_eq!(names.len(), all().len());
    for required in [
        "builtin_interfaces/msg/Time",
        "builtin_interfaces/msg/Duration",
        "std_msgs/msg/Header",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/PoseStamped",
        "geometry_msgs/msg/Vector3",
        "geometry_msgs/msg/Twist",
        "geometry_msgs/msg/TwistStamped",
        "geometry_msgs/msg/PoseWithCovariance",
        "geometry_msgs/msg/TwistWithCovariance",
        "nav_msgs/msg/Odometry",
        "nav_msgs/msg/Path",
        "ackermann_msgs/msg/AckermannDrive",
        "ackermann_msgs/msg/AckermannDriveStamped",
        "rosgraph_msgs/msg/Clock",
        "geometry_msgs/msg/Transform",
        "geometry_msgs/msg/TransformStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "tf2_msgs/msg/TFMessage",
        "dynlab_msgs/msg/PushAction",
    ] {
        assert!(names.contains(required), "{required} missing");
    }
}

#[test]
fn registry_converters_report_bad_payloads() {
    let t = lookup("nav_msgs/msg/Path").unwrap();
    assert!(matches!(
        (t.to_json)(&[0, 1, 0, 0, 1]),
        Err(CdrError::Decode { .. })
    ));
    assert!(matches!(
        (t.from_json)(&json!({"header": 1})),
        Err(CdrError::Json { .. })
    ));
}

#[test]
fn dds_type_names() {
    assert_eq!(
        ros_to_dds_type_name("geometry_msgs/msg/PoseStamped").unwrap(),
        "geometry_msgs::msg::dds_::PoseStamped_"
    );
    assert_eq!(
        ros_to_dds_type_name("rosgraph_msgs/Clock").unwrap(),
        "rosgraph_msgs::msg::dds_::Clock_"
    );
    assert_eq!(
        ros_to_dds_type_name("std_srvs/srv/Empty_Request").unwrap(),
        "std_srvs::srv::dds_::Empty_Request_"
    );
    assert_eq!(
        dds_to_ros_type_name("ackermann_msgs::msg::dds_::AckermannDriveStamped_").unwrap(),
        "ackermann_msgs/msg/AckermannDriveStamped"
    );
    for t in all() {
        assert_eq!(
            dds_to_ros_type_name(&t.dds_type_name()).unwrap(),
            t.type_name
        );
    }
    for bad in ["PoseStamped", "geometry_msgs/msg/", "a b/msg/C", ""] {
        let e = ros_to_dds_type_name(bad).unwrap_err();
        assert!(matches!(e, CdrError::InvalidTypeName(_)), "{bad}");
        assert!(e.to_string().contains("package/msg/Type"));
    }
    for bad in [
        "geometry_msgs::msg::PoseStamped_",
        "geometry_msgs::msg::dds_::PoseStamped",
        "a::b::dds_::_",
    ] {
        assert!(dds_to_ros_type_name(bad).is_err(), "{bad}");
    }
}

#[test]
fn non_finite_fields_are_reported_by_path() {
    let mut path = Path {
        poses: vec![PoseStamped::default(); 4],
        ..Default::default()
    };
    path.poses[3].pose.orientation.w = f64::NEG_INFINITY;
    path.poses[1].pose.position.x = f64::NAN;
    let found: Vec<String> = non_finite_fields(&path)
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(
        found,
        [
            "poses[1].pose.position.x is NaN",
            "poses[3].pose.orientation.w is -inf"
        ]
    );

    let mut odom = Odometry::default();
    odom.pose.covariance[7] = f64::INFINITY;
    let err = check_finite(&odom).unwrap_err();
    assert_eq!(err.type_name, "nav_msgs/msg/Odometry");
    assert_eq!(
        err.to_string(),
        "nav_msgs/msg/Odometry has non-finite fields: pose.covariance[7] is +inf"
    );

    let drive = AckermannDrive {
        speed: f32::NAN,
        ..Default::default()
    };
    assert_eq!(drive.check_finite().unwrap_err().fields[0].path, "speed");
    assert!(PoseStamped::default().check_finite().is_ok());

    // Many bad fields: the message stays short.
    let all_nan = PoseWithCovariance {
        covariance: [f64::NAN; 36],
        ..Default::default()
    };
    let msg = all_nan.check_finite().unwrap_err().to_string();
    assert!(msg.ends_with("and 28 more"), "{msg}");

    // The registry offers the same on payloads.
    let t = lookup("nav_msgs/msg/Odometry").unwrap();
    let fields = (t.non_finite_fields)(&to_cdr(&odom).unwrap()).unwrap();
    assert_eq!(fields.len(), 1);
    assert_eq!(fields[0].path, "pose.covariance[7]");
}
