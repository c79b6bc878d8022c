//! Damaged bags as they come: what was recovered against what the bag declares, `repair`
//! rewriting them whole, and poses of tf frames composed from `/tf` and `/tf_static`.

use std::path::{Path, PathBuf};

use dynlab_bag::tf::{TfError, lookup_series};
use dynlab_bag::{Bag, BagWriter, Compression, QosProfile, RepairOptions, WriterOptions, repair};
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::geometry_msgs::{PoseStamped, Transform, TransformStamped};
use dynlab_msgs::std_msgs::Header;
use dynlab_msgs::tf2_msgs::TFMessage;

const T0: u64 = 1_700_000_000_000_000_000;
const STEP: u64 = 10_000_000;

fn pose(i: u64, x: f64) -> PoseStamped {
    let mut p = PoseStamped::default();
    p.header.stamp = Time::from_nanos((T0 + i * STEP) as i64);
    p.header.frame_id = "world".into();
    p.pose.position.x = x;
    p.pose.position.y = 0.5 * i as f64;
    p
}

/// 1000 poses at 100 Hz in small uncompressed chunks, pose 400's x is NaN (an occluded body).
fn write_bag(dir: &Path) -> u64 {
    let options = WriterOptions {
        compression: Compression::None,
        chunk_size: 4096,
        ..Default::default()
    };
    let mut w = BagWriter::create(dir, options).unwrap();
    let p = w
        .add_typed_topic::<PoseStamped>("/mocap/pose", &[QosProfile::sensor_data()])
        .unwrap();
    for i in 0..1000u64 {
        let x = if i == 400 { f64::NAN } else { i as f64 * 0.01 };
        w.write(p, T0 + i * STEP, &pose(i, x)).unwrap();
    }
    w.finish().unwrap().message_count
}

fn mcap_in(dir: &Path) -> PathBuf {
    dir.join(format!(
        "{}_0.mcap",
        dir.file_name().unwrap().to_str().unwrap()
    ))
}

/// The bag at `dir` with its file cut to `fraction` of its length, in a copy.
fn cut_copy(dir: &Path, to: &Path, fraction: f64) {
    std::fs::create_dir_all(to).unwrap();
    std::fs::copy(dir.join("metadata.yaml"), to.join("metadata.yaml")).unwrap();
    let bytes = std::fs::read(mcap_in(dir)).unwrap();
    let keep = (bytes.len() as f64 * fraction) as usize;
    std::fs::write(to.join(mcap_in(dir).file_name().unwrap()), &bytes[..keep]).unwrap();
}

#[test]
fn truncated_bag_recovery_names_messages_chunks_and_time_against_the_declared() {
    let tmp = tempfile::tempdir().unwrap();
    let whole = tmp.path().join("whole");
    let total = write_bag(&whole);
    let chunks_whole = Bag::open(&whole).unwrap().info().files[0].chunks;
    let cut = tmp.path().join("whole_cut");
    cut_copy(&whole, &cut, 0.5);
    let bag = Bag::open(&cut).unwrap();
    let r = bag.recovery().expect("a cut bag is damaged");
    let n = bag.message_count();
    assert!(n > 0 && n < total, "{n}");
    assert_eq!(r.messages, n);
    assert_eq!(r.declared.messages, Some(total));
    assert_eq!(r.declared.duration_ns, Some(999 * STEP));
    assert!(
        r.chunks > 0 && r.chunks < chunks_whole,
        "{} of {chunks_whole}",
        r.chunks
    );
    // the cut file lost its statistics record: the chunk count is not declared
    assert_eq!(r.declared.chunks, None);
    let (first, last) = r.span_ns.unwrap();
    assert_eq!(first, T0);
    assert_eq!(last, T0 + (n - 1) * STEP);
    let line = r.summary();
    let pct = 100.0 * n as f64 / total as f64;
    let span = (n - 1) as f64 * 0.01;
    assert_eq!(
        line,
        format!(
            "recovered {n} of {total} messages ({pct:.1} %), {} chunks, {span:.3} s of 9.990 s",
            r.chunks
        )
    );
    assert!(r.to_string().starts_with(&format!("damaged bag: {line}\n")));
    // the sound original has nothing to report
    let whole_bag = Bag::open(&whole).unwrap();
    assert!(whole_bag.recovery().is_none());
}

#[test]
fn repair_rewrites_everything_recoverable_into_a_sound_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let whole = tmp.path().join("whole");
    write_bag(&whole);
    let cut = tmp.path().join("cut");
    cut_copy(&whole, &cut, 0.7);
    let damaged = Bag::open(&cut).unwrap();
    assert!(damaged.recovery().is_some());
    let out = tmp.path().join("repaired");
    let report = repair(&cut, &out, &RepairOptions::default()).unwrap();
    assert_eq!(report.read, damaged.message_count());
    assert_eq!(report.kept(), damaged.message_count());
    assert!(report.dropped.is_empty());
    assert!(report.recovery.is_some());
    let text = report.to_string();
    assert!(text.contains("damaged bag: recovered"), "{text}");
    assert!(
        text.contains(&format!("kept {0} of {0} messages", report.read)),
        "{text}"
    );

    // the new bag is sound and holds exactly what was recoverable, times, types and QoS too
    let fixed = Bag::open(&out).unwrap();
    assert!(fixed.recovery().is_none(), "{:?}", fixed.recovery());
    assert!(fixed.info().files[0].complete);
    let a: Vec<_> = damaged.messages().collect();
    let b: Vec<_> = fixed.messages().collect();
    assert_eq!(a, b);
    assert_eq!(fixed.topics()[0].qos, damaged.topics()[0].qos);
    assert_eq!(fixed.topics()[0].definition, damaged.topics()[0].definition);
    assert_eq!(fixed.topics()[0].type_hash, damaged.topics()[0].type_hash);
    // and it can be repaired again into the same messages (nothing was lost the second time)
    let again = repair(&out, tmp.path().join("again"), &RepairOptions::default()).unwrap();
    assert!(again.recovery.is_none());
    assert_eq!(again.kept(), report.kept());
}

#[test]
fn repair_drops_nonfinite_messages_and_lists_them() {
    let tmp = tempfile::tempdir().unwrap();
    let whole = tmp.path().join("whole");
    let total = write_bag(&whole);
    let out = tmp.path().join("finite");
    let options = RepairOptions {
        drop_nonfinite: true,
        ..Default::default()
    };
    let report = repair(&whole, &out, &options).unwrap();
    assert!(report.recovery.is_none());
    assert_eq!(report.kept(), total - 1);
    assert_eq!(report.topics[0].dropped_nonfinite, 1);
    assert_eq!(report.dropped.len(), 1);
    assert_eq!(report.dropped[0].log_time_ns, T0 + 400 * STEP);
    assert_eq!(report.dropped[0].reason, "pose.position.x is NaN");
    let text = report.to_string();
    assert!(text.contains("dropped 1 with non-finite fields"), "{text}");
    assert!(
        text.contains("dropped /mocap/pose at 1700000004.000000000: pose.position.x is NaN"),
        "{text}"
    );
    let poses = Bag::open(&out)
        .unwrap()
        .read::<PoseStamped>("/mocap/pose")
        .unwrap();
    assert_eq!(poses.len() as u64, total - 1);
    assert!(poses.iter().all(|p| p.msg.pose.position.x.is_finite()));
    // the output must be a new directory
    let e = repair(&whole, &out, &options).unwrap_err();
    assert!(e.to_string().contains("not empty"), "{e}");
}

fn tf(t_ns: u64, parent: &str, child: &str, x: f64, y: f64, yaw: f64) -> TransformStamped {
    TransformStamped {
        header: Header::new(Time::from_nanos(t_ns as i64), parent),
        child_frame_id: child.into(),
        transform: Transform::planar(x, y, yaw),
    }
}

/// A tree `map → world → odom → base` with `world → marker` static: `odom → base` moves at 100 Hz,
/// `world → odom` at 10 Hz (drift correction), `map → world` static.
fn write_tf_bag(dir: &Path) {
    let mut w = BagWriter::create(dir, WriterOptions::default()).unwrap();
    let dynamic = w
        .add_typed_topic::<TFMessage>("/tf", &[QosProfile::default_profile()])
        .unwrap();
    let fixed = w
        .add_typed_topic::<TFMessage>("/tf_static", &[QosProfile::default_profile()])
        .unwrap();
    let statics = TFMessage {
        transforms: vec![
            tf(T0, "map", "world", 10.0, 0.0, std::f64::consts::FRAC_PI_2),
            tf(T0, "world", "marker", 1.0, 1.0, 0.0),
        ],
    };
    w.write(fixed, T0, &statics).unwrap();
    for i in 0..100u64 {
        let t = T0 + i * STEP;
        let mut msg = TFMessage::default();
        if i % 10 == 5 {
            msg.transforms
                .push(tf(t, "/world", "odom", 0.1 * i as f64, 0.0, 0.0));
        }
        msg.transforms
            .push(tf(t, "odom", "base", 0.01 * i as f64, 0.0, 0.02 * i as f64));
        w.write(dynamic, t, &msg).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn tf_chains_compose_through_intermediate_and_upward_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tf");
    write_tf_bag(&dir);
    let bag = Bag::open(&dir).unwrap();

    // world → odom → base: stamps of the 100 Hz link, world → odom held (first at step 5)
    let s = lookup_series(&bag, "world", "base").unwrap();
    assert_eq!(s.chain, ["world", "odom", "base"]);
    assert_eq!(s.driving_link, "odom → base");
    assert_eq!(s.skipped_before_chain, 5);
    assert_eq!(s.samples.len(), 95);
    for smp in &s.samples {
        let i = (smp.t_ns as u64 - T0) / STEP;
        let held = 0.1 * (((i - 5) / 10) * 10 + 5) as f64;
        let want = held + 0.01 * i as f64;
        assert!((smp.transform.translation.x - want).abs() < 1e-12, "{i}");
        assert!((smp.transform.rotation.yaw() - 0.02 * i as f64).abs() < 1e-12);
    }
    assert!(
        s.notes.iter().any(|n| n.contains("also moves")),
        "{:?}",
        s.notes
    );

    // map → … → base through the static link (a 90° turn): x of the chain becomes y in map
    let m = lookup_series(&bag, "map", "base").unwrap();
    let (a, b) = (&m.samples[10], &s.samples[10]);
    assert!((a.transform.translation.x - 10.0).abs() < 1e-12);
    assert!((a.transform.translation.y - b.transform.translation.x).abs() < 1e-12);

    // marker → base goes up to world and down again: the inverse of the static marker link
    let k = lookup_series(&bag, "marker", "base").unwrap();
    assert_eq!(k.chain, ["marker", "world", "odom", "base"]);
    let (a, b) = (&k.samples[0], &s.samples[0]);
    assert!((a.transform.translation.x - (b.transform.translation.x - 1.0)).abs() < 1e-12);
    assert!((a.transform.translation.y + 1.0).abs() < 1e-12);

    // errors name the frames the bag has
    let e = lookup_series(&bag, "world", "car").unwrap_err();
    assert!(matches!(e, TfError::UnknownFrame { .. }));
    assert!(e.to_string().contains("odom → base"), "{e}");
    let e = lookup_series(&bag, "map", "marker").unwrap_err();
    assert!(matches!(e, TfError::Static { .. }), "{e}");
}
