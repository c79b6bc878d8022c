//! The data sets checked into `bags/` read back with our reader: topics, types, counts, frames,
//! QoS, episode layout, and the hidden effects they are documented to hold.

use std::path::PathBuf;

use dynlab_bag::Bag;
use dynlab_msgs::ackermann_msgs::AckermannDriveStamped;
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_msgs::nav_msgs::Odometry;
use dynlab_sim::{CarScenario, PushScenario};
use dynlab_simbridge::messages::{OfferedQos, SimWorld, sim_topics};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn open(name: &str) -> Bag {
    let path = repo().join("bags").join(name);
    Bag::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Start times of the episodes: stamps after a gap of more than `gap_ns`.
fn episode_starts(stamps: &[u64], gap_ns: u64) -> Vec<u64> {
    let mut starts = vec![stamps[0]];
    for w in stamps.windows(2) {
        if w[1] - w[0] > gap_ns {
            starts.push(w[1]);
        }
    }
    starts
}

fn check_layout(bag: &Bag, world: SimWorld) {
    let topics = sim_topics(world, false);
    let names: Vec<&str> = bag.topics().iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, topics.iter().map(|t| t.name).collect::<Vec<_>>());
    for (info, spec) in bag.topics().iter().zip(&topics) {
        assert_eq!(info.type_name, spec.type_name);
        assert_eq!(info.qos, [spec.qos.recorded_profile()], "{}", info.name);
    }
    assert_eq!(
        bag.topic(world.pose_topic()).unwrap().qos[0].reliability,
        OfferedQos::SensorData.recorded_profile().reliability
    );
}

#[test]
fn push_bags_hold_forty_episodes_of_ten_pushes() {
    for name in ["push_nominal", "push_friction_patch", "push_com_offset"] {
        let bag = open(name);
        check_layout(&bag, SimWorld::Push);
        let poses = bag.read::<PoseStamped>("/push/block_pose").unwrap();
        let actions = bag.read::<PushAction>("/push/action").unwrap();
        assert_eq!((poses.len(), actions.len()), (40 * 201, 400), "{name}");
        assert!(poses.iter().all(|p| p.msg.header.frame_id == "table"));
        assert!(actions.iter().all(|a| a.msg.in_range()));
        // stamps are simulation time, equal to log times, from 0, episodes 1 s apart
        assert!(
            poses
                .iter()
                .all(|p| p.msg.header.stamp.to_nanos() as u64 == p.log_time_ns)
        );
        let stamps: Vec<u64> = poses.iter().map(|p| p.log_time_ns).collect();
        let starts = episode_starts(&stamps, 500_000_000);
        assert_eq!(starts.len(), 40, "{name}");
        assert_eq!(starts[0], 0);
        assert_eq!(starts[1], 20_000_000_000 + 1_000_000_000);
        // mocap noise: no two consecutive poses of a block at rest are equal
        assert!(poses.windows(2).all(|w| w[0].msg.pose != w[1].msg.pose));
    }
}

#[test]
fn car_bags_hold_ninety_seconds_of_driving_with_drifts() {
    for name in ["car_nominal", "car_aero_drag", "car_steering_offset"] {
        let bag = open(name);
        check_layout(&bag, SimWorld::Car);
        let poses = bag.read::<PoseStamped>("/car/pose").unwrap();
        let cmds = bag.read::<AckermannDriveStamped>("/car/cmd").unwrap();
        let odom = bag.read::<Odometry>("/car/odom").unwrap();
        assert_eq!((poses.len(), cmds.len(), odom.len()), (9003, 4500, 9003));
        assert!(poses.iter().all(|p| p.msg.header.frame_id == "world"));
        assert!(odom.iter().all(|o| o.msg.child_frame_id == "car"));
        let stamps: Vec<u64> = poses.iter().map(|p| p.log_time_ns).collect();
        assert_eq!(episode_starts(&stamps, 50_000_000).len(), 3);
        // the explorer drives fast and drifts: sideslip past 20° at speed somewhere
        let drifting = odom.iter().any(|o| {
            let v = &o.msg.twist.twist.linear;
            v.x.hypot(v.y) > 0.5 && v.y.atan2(v.x).abs() > 20f64.to_radians()
        });
        assert!(drifting, "{name}: no drift");
        // and stays on the 3 × 3 m floor
        assert!(
            odom.iter().all(|o| o.msg.pose.pose.position.x.abs() < 1.5
                && o.msg.pose.pose.position.y.abs() < 1.5)
        );
        assert!(cmds.iter().any(|c| c.msg.drive.acceleration >= 0.99));
    }
}

#[test]
fn bundled_scenarios_switch_on_the_documented_effects() {
    let dir = repo().join("launch_scripts/scenarios");
    let push = |f: &str| {
        PushScenario::from_file(dir.join(f))
            .unwrap()
            .effects
            .active()
    };
    let car = |f: &str| {
        CarScenario::from_file(dir.join(f))
            .unwrap()
            .effects
            .active()
    };
    assert!(push("push_nominal.toml").is_empty());
    assert_eq!(push("push_friction_patch.toml"), ["friction_patch"]);
    assert_eq!(push("push_com_offset.toml"), ["com_offset"]);
    assert!(car("car_nominal.toml").is_empty());
    assert_eq!(car("car_aero_drag.toml"), ["aero_drag"]);
    assert_eq!(car("car_steering_offset.toml"), ["steering_offset"]);
    assert_eq!(car("car_motor_lag.toml"), ["motor_lag"]);
}
