//! Real-robot data as it comes, end to end on simulated bags: poses from tf and from Odometry
//! topics load exactly as from the PoseStamped topic; a NaN pose and a pose whose stamp goes
//! back are skipped, counted, split the trajectory and are reported (and refused with
//! `--strict`); a truncated bag is used with a warning that says how much was read;
//! `dynlab bag repair` rewrites a damaged bag whole.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dynlab_bag::{Bag, BagWriter, WriterOptions};
use dynlab_learn::dynamics::data::SavGol;
use dynlab_learn::{LoadOptions, TfFrames, TimedDataset, Topics, World, load_bags_with};
use dynlab_msgs::geometry_msgs::{
    PoseStamped, PoseWithCovarianceStamped, Transform, TransformStamped, Vector3,
};
use dynlab_msgs::nav_msgs::Odometry;
use dynlab_msgs::{RosMessage, from_cdr, to_cdr};

fn dynlab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(args)
        .output()
        .expect("run dynlab")
}

fn ok(args: &[&str]) -> Output {
    let o = dynlab(args);
    assert!(
        o.status.success(),
        "dynlab {args:?} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A simulated bag with /tf and /tf_static, as `dynlab collect --tf` writes it.
fn collect(dir: &Path, world: &str) -> PathBuf {
    let out = dir.join(format!("{world}_tf"));
    let o = out.to_str().unwrap();
    ok(&[
        "collect",
        world,
        "--episodes",
        "1",
        "--seed",
        "3",
        "--tf",
        "--out",
        o,
    ]);
    out
}

fn load(bag: &Path, opts: &LoadOptions) -> TimedDataset {
    load_bags_with(&[bag.to_path_buf()], None, opts, &SavGol::default(), None)
        .unwrap_or_else(|e| panic!("{opts:?}: {e}"))
}

fn tf(pair: &str) -> LoadOptions {
    LoadOptions {
        pose_tf: Some(TfFrames::parse(pair).unwrap()),
        ..Default::default()
    }
}

/// Copies `src` into a new bag `dst`, letting `change` rewrite (or drop, with `None`) each
/// message of `topic`; `rename` moves `topic` to another name and type (given as the new
/// message's CDR).
fn rewrite(
    src: &Path,
    dst: &Path,
    topic: &str,
    new_topic: Option<(&str, &str, &str)>,
    mut change: impl FnMut(usize, &[u8]) -> Option<(u64, Vec<u8>)>,
) {
    let bag = Bag::open(src).unwrap();
    let mut w = BagWriter::create(dst, WriterOptions::default()).unwrap();
    let mut ids = std::collections::HashMap::new();
    for t in bag.topics() {
        let id = match (t.name == topic, new_topic) {
            (true, Some((name, type_name, def))) => w.add_topic(name, type_name, def, &t.qos),
            _ => w.add_topic(&t.name, &t.type_name, &t.definition, &t.qos),
        }
        .unwrap();
        ids.insert(t.name.clone(), id);
    }
    let mut k = 0;
    for m in bag.messages() {
        let id = ids[m.topic];
        if m.topic == topic {
            if let Some((log, data)) = change(k, m.data) {
                w.write_raw(id, log, log, &data).unwrap();
            }
            k += 1;
        } else {
            w.write_raw(id, m.log_time_ns, m.publish_time_ns, m.data)
                .unwrap();
        }
    }
    w.finish().unwrap();
}

#[test]
fn tf_and_odometry_pose_sources_give_the_same_trajectories_as_pose_stamped() {
    let tmp = tempfile::tempdir().unwrap();
    // car: world → car on /tf; the same poses as nav_msgs/Odometry on another topic
    let car = collect(tmp.path(), "car");
    // the same poses as the other pose types real robots publish, each on a topic of its own
    type Convert = fn(&PoseStamped) -> Vec<u8>;
    let conversions: [(&str, &str, &str, Convert); 3] = [
        (
            "/mocap/odom",
            Odometry::TYPE_NAME,
            Odometry::definition(),
            |p| {
                let mut o = Odometry {
                    header: p.header.clone(),
                    child_frame_id: "car".into(),
                    ..Default::default()
                };
                o.pose.pose = p.pose;
                to_cdr(&o).unwrap()
            },
        ),
        (
            "/amcl_pose",
            PoseWithCovarianceStamped::TYPE_NAME,
            PoseWithCovarianceStamped::definition(),
            |p| {
                let mut o = PoseWithCovarianceStamped {
                    header: p.header.clone(),
                    ..Default::default()
                };
                o.pose.pose = p.pose;
                to_cdr(&o).unwrap()
            },
        ),
        (
            "/vicon/car/car",
            TransformStamped::TYPE_NAME,
            TransformStamped::definition(),
            |p| {
                let pos = p.pose.position;
                let t = TransformStamped {
                    header: p.header.clone(),
                    child_frame_id: "car".into(),
                    transform: Transform {
                        translation: Vector3 {
                            x: pos.x,
                            y: pos.y,
                            z: pos.z,
                        },
                        rotation: p.pose.orientation,
                    },
                };
                to_cdr(&t).unwrap()
            },
        ),
    ];
    let reference = load(&car, &LoadOptions::default());
    assert_eq!(reference.data.world, World::Car);
    assert!(reference.data.transitions() > 2000);
    let from_tf = load(&car, &tf("world:car"));
    assert_eq!(from_tf.data.trajectories, reference.data.trajectories);
    assert_eq!(from_tf.stamps, reference.stamps);
    let notes = &from_tf.data.reports[0].source_notes;
    assert!(
        notes[0].starts_with("poses from tf world → car (chain world → car"),
        "{notes:?}"
    );
    for (topic, type_name, definition, convert) in conversions {
        let other = tmp.path().join(topic.replace('/', "_"));
        rewrite(
            &car,
            &other,
            "/car/pose",
            Some((topic, type_name, definition)),
            |_, data| {
                let p: PoseStamped = from_cdr(data).unwrap();
                Some((p.header.stamp.to_nanos() as u64, convert(&p)))
            },
        );
        let d = load(
            &other,
            &LoadOptions {
                topics: Topics {
                    pose: Some(topic.into()),
                    cmd: None,
                },
                ..Default::default()
            },
        );
        assert_eq!(
            d.data.trajectories, reference.data.trajectories,
            "{type_name}"
        );
        assert_eq!(d.stamps, reference.stamps, "{type_name}");
        assert!(d.data.reports[0].source_notes[0].contains(type_name));
    }

    // pushing: table → block directly, and world → block through the static world → table
    let push = collect(tmp.path(), "push");
    let reference = load(&push, &LoadOptions::default());
    assert_eq!(reference.data.world, World::Push);
    let d = load(&push, &tf("table:block"));
    assert_eq!(d.data.trajectories, reference.data.trajectories);
    // composed through a link: equal to rounding
    let d = load(&push, &tf("world:block"));
    assert_eq!(d.data.lengths(), reference.data.lengths());
    for (a, b) in d.data.trajectories.iter().zip(&reference.data.trajectories) {
        assert!(a.s.iter().zip(&b.s).all(|(x, y)| (x - y).abs() < 1e-12));
        assert_eq!(a.u, b.u);
    }
    // the axle frames are static children of the car: the front axle's track is the car's,
    // lf ahead of the centre of mass
    let axle = load(&car, &tf("world:car/front_axle"));
    let lf = dynlab_sim::CarScenario::floor().car.lf;
    let reference = load(&car, &LoadOptions::default());
    let (a, c) = (
        &axle.data.trajectories[0].s,
        &reference.data.trajectories[0].s,
    );
    let mid = 6 * (a.len() / 12);
    let d = (a[mid] - c[mid]).hypot(a[mid + 1] - c[mid + 1]);
    assert!(
        (d - lf).abs() < 0.1 * lf,
        "axle {d} m from the centre, lf = {lf}"
    );
}

/// The car bag with pose 1000's x NaN and pose 2000 stamped 10 ms before pose 1999.
fn damaged_poses(car: &Path, out: &Path) {
    rewrite(car, out, "/car/pose", None, |k, data| {
        let mut p: PoseStamped = from_cdr(data).unwrap();
        let log = p.header.stamp.to_nanos() as u64;
        if k == 1000 {
            p.pose.position.x = f64::NAN;
        }
        if k == 2000 {
            p.header.stamp = dynlab_msgs::builtin_interfaces::Time::from_nanos(19_890_000_000);
        }
        Some((log, to_cdr(&p).unwrap()))
    });
}

#[test]
fn nan_and_out_of_order_poses_are_skipped_split_and_reported_or_refused_with_strict() {
    let tmp = tempfile::tempdir().unwrap();
    let car = collect(tmp.path(), "car");
    let bad = tmp.path().join("car_bad");
    damaged_poses(&car, &bad);
    let clean = load(&car, &LoadOptions::default());
    let d = load(&bad, &LoadOptions::default());
    let r = &d.data.reports[0];
    assert_eq!((r.non_finite_poses, r.out_of_order_poses), (1, 1));
    assert_eq!(r.splits_at_skipped, 2);
    assert_eq!(d.data.trajectories.len(), clean.data.trajectories.len() + 2);
    assert_eq!(
        d.data.transitions(),
        clean.data.transitions() - 2 - 2,
        "two poses and the two transitions over the splits"
    );

    // train: a warning on the terminal; compare: the same in the report's data notes
    let bad_s = bad.to_str().unwrap();
    let model = tmp.path().join("m");
    let model_s = model.to_str().unwrap();
    let o = ok(&[
        "train", "--bag", bad_s, "--kind", "residual", "--epochs", "1", "--quiet", "--out", model_s,
    ]);
    let err = text(&o.stderr);
    let want = "skipped 1 poses with NaN or infinite values (first at 10.000 s) and 1 poses whose \
                stamp goes back (first at 19.890 s); the data are split there (2 split(s))";
    assert!(err.contains(&format!("warning: {bad_s}: {want}")), "{err}");
    let cmp = tmp.path().join("cmp");
    let o = ok(&[
        "compare",
        "--model",
        model_s,
        "--bag",
        bad_s,
        "--out",
        cmp.to_str().unwrap(),
    ]);
    assert!(text(&o.stderr).contains(want));
    let report = std::fs::read_to_string(cmp.join("report.json")).unwrap();
    assert!(
        report.contains(want),
        "report.json has no note of the skipped poses"
    );

    // --strict keeps the refusal
    let m2 = tmp.path().join("m2");
    for cmd in [
        vec![
            "train", "--bag", bad_s, "--kind", "residual", "--epochs", "1", "--out",
        ],
        vec!["eval-model", "--model", model_s, "--bag", bad_s],
    ] {
        let mut args = cmd.clone();
        if args[0] == "train" {
            args.push(m2.to_str().unwrap());
        }
        args.push("--strict");
        let o = dynlab(&args);
        assert!(
            !o.status.success(),
            "{args:?} accepted a NaN pose with --strict"
        );
        let err = text(&o.stderr);
        assert!(
            err.contains("non-finite value in pose.x at t = 10000000000 ns (NaN)"),
            "{err}"
        );
    }
}

#[test]
fn a_truncated_bag_is_used_with_a_warning_that_says_how_much_was_read() {
    let tmp = tempfile::tempdir().unwrap();
    let car = collect(tmp.path(), "car");
    let cut = tmp.path().join("car_cut");
    std::fs::create_dir(&cut).unwrap();
    std::fs::copy(car.join("metadata.yaml"), cut.join("metadata.yaml")).unwrap();
    let file = std::fs::read(car.join("car_tf_0.mcap")).unwrap();
    std::fs::write(cut.join("car_tf_0.mcap"), &file[..file.len() * 6 / 10]).unwrap();
    let recovery = Bag::open(&cut).unwrap().recovery().cloned().unwrap();
    let total = Bag::open(&car).unwrap().message_count();
    assert!(recovery.messages < total);
    let summary = recovery.summary();
    assert!(
        summary.starts_with(&format!(
            "recovered {} of {total} messages (",
            recovery.messages
        )),
        "{summary}"
    );
    assert!(summary.contains(" s of 30.000 s"), "{summary}");
    let cut_s = cut.to_str().unwrap();
    let model = tmp.path().join("m");
    let model_s = model.to_str().unwrap();
    let warning = format!("warning: {cut_s}: damaged bag: {summary}");
    let o = ok(&[
        "train", "--bag", cut_s, "--kind", "residual", "--epochs", "1", "--quiet", "--out", model_s,
    ]);
    assert!(text(&o.stderr).contains(&warning), "{}", text(&o.stderr));
    let o = ok(&["eval-model", "--model", model_s, "--bag", cut_s]);
    assert!(text(&o.stderr).contains(&warning), "{}", text(&o.stderr));
    // compare and diagnose: on the terminal and in the reports' data notes
    let cmp = tmp.path().join("cmp");
    let o = ok(&[
        "compare",
        "--model",
        model_s,
        "--bag",
        cut_s,
        "--out",
        cmp.to_str().unwrap(),
    ]);
    assert!(text(&o.stderr).contains(&warning), "{}", text(&o.stderr));
    let report = std::fs::read_to_string(cmp.join("report.json")).unwrap();
    assert!(report.contains(&format!("damaged bag: {summary}")));
    let diag = tmp.path().join("diag");
    let o = ok(&[
        "diagnose",
        "--model",
        model_s,
        "--bag",
        cut_s,
        "--effects",
        "aero_drag",
        "--steps",
        "5",
        "--out",
        diag.to_str().unwrap(),
    ]);
    assert!(text(&o.stderr).contains(&warning), "{}", text(&o.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(diag.join("diagnosis.json")).unwrap())
            .unwrap();
    let first_note = json["data_notes"][0][0].as_str().unwrap();
    assert!(
        first_note.starts_with(&format!("damaged bag: {summary}")),
        "{first_note}"
    );
    // a sound bag: no warning at all
    let o = ok(&[
        "eval-model",
        "--model",
        model_s,
        "--bag",
        car.to_str().unwrap(),
    ]);
    assert!(!text(&o.stderr).contains("warning"), "{}", text(&o.stderr));
}

#[test]
fn bag_repair_rewrites_what_is_recoverable_and_drops_nonfinite_poses() {
    let tmp = tempfile::tempdir().unwrap();
    let car = collect(tmp.path(), "car");
    let bad = tmp.path().join("car_bad");
    damaged_poses(&car, &bad);
    let cut = tmp.path().join("car_bad_cut");
    std::fs::create_dir(&cut).unwrap();
    std::fs::copy(bad.join("metadata.yaml"), cut.join("metadata.yaml")).unwrap();
    let file = std::fs::read(bad.join("car_bad_0.mcap")).unwrap();
    std::fs::write(cut.join("car_bad_0.mcap"), &file[..file.len() * 8 / 10]).unwrap();
    let damaged = Bag::open(&cut).unwrap();
    let n = damaged.message_count();
    let out = tmp.path().join("fixed");
    let o = ok(&[
        "bag",
        "repair",
        cut.to_str().unwrap(),
        out.to_str().unwrap(),
        "--drop-nonfinite",
    ]);
    let report = text(&o.stdout);
    assert!(report.contains("damaged bag: recovered"), "{report}");
    assert!(
        report.contains(&format!("kept {} of {n} messages", n - 1)),
        "{report}"
    );
    assert!(
        report.contains("dropped 1 with non-finite fields"),
        "{report}"
    );
    assert!(
        report.contains("dropped /car/pose at 10.000000000: pose.position.x is NaN"),
        "{report}"
    );
    let fixed = Bag::open(&out).unwrap();
    assert!(fixed.recovery().is_none());
    let want: Vec<_> = damaged
        .messages()
        .filter(|m| !(m.topic == "/car/pose" && m.log_time_ns == 10_000_000_000))
        .collect();
    assert_eq!(fixed.messages().collect::<Vec<_>>(), want);
    // and the tools read the repaired bag without a warning about damage
    let d = load(&out, &LoadOptions::default());
    assert!(d.data.reports[0].source_notes.is_empty());
    assert_eq!(d.data.reports[0].non_finite_poses, 0);
}
