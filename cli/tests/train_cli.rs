//! `dynlab train` and `dynlab eval-model` end to end, and their errors for bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dynlab_bag::{BagWriter, QosProfile, WriterOptions};
use dynlab_learn::dynamics::data::SplitMix64;
use dynlab_learn::dynamics::ode::{Solver, integrate};
use dynlab_learn::dynamics::physics::PhysicsModel;
use dynlab_msgs::ackermann_msgs::AckermannDriveStamped;
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::{Pose, PoseStamped};
use dynlab_msgs::std_msgs::Header;

fn dynlab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(args)
        .output()
        .expect("run dynlab")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn uniform(rng: &mut SplitMix64, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

/// A pushing bag from the quasi-static pusher–slider; `with_actions = false` leaves out
/// `/push/action`.
fn push_bag(dir: &Path, name: &str, trajs: usize, pushes: usize, with_actions: bool) -> PathBuf {
    let path = dir.join(name);
    let model = PhysicsModel::pushing(&[]).unwrap();
    let mut w = BagWriter::create(&path, WriterOptions::default()).unwrap();
    let qos = [QosProfile::default_profile()];
    let tp = w
        .add_typed_topic::<PoseStamped>("/push/block_pose", &qos)
        .unwrap();
    let ta = w
        .add_typed_topic::<PushAction>("/push/action", &qos)
        .unwrap();
    let mut rng = SplitMix64::new(11);
    for tr in 0..trajs {
        let t0 = 1_000_000_000i64 + tr as i64 * 60_000_000_000;
        let mut s = [0.4, 0.0, uniform(&mut rng, -1.0, 1.0)];
        for i in 0..=pushes {
            let t = t0 + i as i64 * 2_000_000_000;
            let pose = PoseStamped {
                header: Header::new(Time::from_nanos(t), "table"),
                pose: Pose::planar(s[0], s[1], s[2]),
            };
            w.write(tp, t as u64, &pose).unwrap();
            if i == pushes {
                break;
            }
            let u = [
                uniform(&mut rng, -1.0, 1.0),
                uniform(&mut rng, -1.2, 1.2),
                uniform(&mut rng, 0.2, 1.0),
            ];
            if with_actions {
                let msg = PushAction {
                    header: Header::new(Time::from_nanos(t + 1_000_000), "table"),
                    location: u[0],
                    angle: u[1],
                    length: u[2],
                };
                w.write(ta, (t + 1_000_000) as u64, &msg).unwrap();
            }
            let mut next = [0.0; 3];
            integrate(&model, &Solver::rk4(), 1, &s, &u, 1.0, &mut next);
            s = next;
        }
    }
    w.finish().unwrap();
    path
}

fn car_bag(dir: &Path) -> PathBuf {
    let path = dir.join("car");
    let mut w = BagWriter::create(&path, WriterOptions::default()).unwrap();
    let qos = [QosProfile::default_profile()];
    let tp = w.add_typed_topic::<PoseStamped>("/car/pose", &qos).unwrap();
    let tc = w
        .add_typed_topic::<AckermannDriveStamped>("/car/cmd", &qos)
        .unwrap();
    for i in 0..400 {
        let t = 1_000_000_000i64 + i * 10_000_000;
        let x = i as f64 * 0.01;
        let pose = PoseStamped {
            header: Header::new(Time::from_nanos(t), "world"),
            pose: Pose::planar(x, 0.0, 0.0),
        };
        w.write(tp, t as u64, &pose).unwrap();
        w.write(tc, t as u64, &AckermannDriveStamped::default())
            .unwrap();
    }
    w.finish().unwrap();
    path
}

#[test]
fn train_then_eval_model_writes_the_model_curve_and_a_json_report() {
    let tmp = tempfile::tempdir().unwrap();
    let bag = push_bag(tmp.path(), "push", 12, 10, true);
    let out = tmp.path().join("model");
    let o = dynlab(&[
        "train",
        "--bag",
        bag.to_str().unwrap(),
        "--kind",
        "node-rk4",
        "--steps",
        "2",
        "--epochs",
        "5",
        "--seed",
        "3",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    assert_eq!(meta["kind"], "node-rk4");
    assert_eq!(meta["world"], "push");
    assert_eq!(meta["training"]["config"]["seed"], 3);
    assert_eq!(
        meta["training"]["bags"][0]["sha256"]
            .as_str()
            .unwrap()
            .len(),
        64
    );
    assert!(out.join("weights.safetensors").exists());
    let csv = std::fs::read_to_string(out.join("curve.csv")).unwrap();
    assert_eq!(csv.lines().count(), 6, "{csv}");
    let png = std::fs::read(out.join("curve.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let o = dynlab(&[
        "eval-model",
        "--model",
        out.to_str().unwrap(),
        "--bag",
        bag.to_str().unwrap(),
        "--steps",
        "3",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rep: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(rep["steps"], 3);
    assert_eq!(rep["one_step"].as_array().unwrap().len(), 3);
    assert!(
        rep["k_step"][0]["rmse"].as_f64().unwrap()
            > rep["one_step"][0]["rmse"].as_f64().unwrap() * 0.5
    );
    let o = dynlab(&[
        "eval-model",
        "--model",
        out.to_str().unwrap(),
        "--bag",
        bag.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("RMSE 1-step"));
}

#[test]
fn bad_input_gets_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let good = push_bag(tmp.path(), "push", 12, 10, true);
    let out = tmp.path().join("m");
    let o_ = out.to_str().unwrap();
    // a bag that does not exist
    let o = dynlab(&[
        "train",
        "--bag",
        "/nonexistent/bag",
        "--kind",
        "residual",
        "--out",
        o_,
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/nonexistent/bag"), "{}", stderr(&o));
    // an unknown kind
    let o = dynlab(&[
        "train",
        "--bag",
        good.to_str().unwrap(),
        "--kind",
        "lstm",
        "--out",
        o_,
    ]);
    assert!(
        stderr(&o).contains("unknown model kind 'lstm'"),
        "{}",
        stderr(&o)
    );
    // no commands in the bag
    let poses_only = push_bag(tmp.path(), "poses_only", 3, 10, false);
    let o = dynlab(&[
        "train",
        "--bag",
        poses_only.to_str().unwrap(),
        "--kind",
        "residual",
        "--out",
        o_,
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no commands"), "{}", stderr(&o));
    // too little data
    let tiny = push_bag(tmp.path(), "tiny", 2, 2, true);
    let o = dynlab(&[
        "train",
        "--bag",
        tiny.to_str().unwrap(),
        "--kind",
        "residual",
        "--out",
        o_,
    ]);
    assert!(stderr(&o).contains("too little data"), "{}", stderr(&o));
    // a limit surface that does not exist, and one for the car
    let o = dynlab(&[
        "train",
        "--bag",
        good.to_str().unwrap(),
        "--kind",
        "physics",
        "--limit-surface",
        "cube",
        "--out",
        o_,
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--limit-surface cube: choose ellipsoid or support_points"),
        "{}",
        stderr(&o)
    );
    let car_dir = tmp.path().join("limit_surface");
    std::fs::create_dir(&car_dir).unwrap();
    let car = car_bag(&car_dir);
    let o = dynlab(&[
        "train",
        "--bag",
        car.to_str().unwrap(),
        "--kind",
        "physics",
        "--limit-surface",
        "support_points",
        "--out",
        o_,
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("the car has none"), "{}", stderr(&o));
    // effects on a network-only kind
    let o = dynlab(&[
        "train",
        "--bag",
        good.to_str().unwrap(),
        "--kind",
        "node-rk4",
        "--effects",
        "com_offset",
        "--out",
        o_,
    ]);
    assert!(
        stderr(&o).contains("use --kind physics or hybrid"),
        "{}",
        stderr(&o)
    );
    // topics the bag does not have
    let o = dynlab(&[
        "train",
        "--bag",
        good.to_str().unwrap(),
        "--kind",
        "residual",
        "--pose-topic",
        "/mocap/block",
        "--out",
        o_,
    ]);
    assert!(stderr(&o).contains("/mocap/block"), "{}", stderr(&o));
    // eval-model with something that is not a model
    let o = dynlab(&[
        "eval-model",
        "--model",
        good.to_str().unwrap(),
        "--bag",
        good.to_str().unwrap(),
    ]);
    assert!(stderr(&o).contains("model.json"), "{}", stderr(&o));
    // a pushing model on a car bag
    let o = dynlab(&[
        "train",
        "--bag",
        good.to_str().unwrap(),
        "--kind",
        "residual",
        "--epochs",
        "1",
        "--out",
        o_,
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let car = car_bag(tmp.path());
    let o = dynlab(&["eval-model", "--model", o_, "--bag", car.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/push/block_pose"), "{}", stderr(&o));
}
