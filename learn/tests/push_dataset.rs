//! Pushing data load as one transition per push: a block pose streamed at 10 Hz during the
//! pushes collapses to the pose each push starts from plus the settled pose after the last;
//! data with one pose per push load unchanged.

use std::path::PathBuf;

use dynlab_learn::dynamics::data::{CommandSample, PoseSample, SavGol};
use dynlab_learn::{Dataset, Topics, World, load_bags};

/// `pushes` pushes of 2 s each, a pose every `pose_ns`, the block moving 1 cm in x per push
/// (linearly over the push's first second, then at rest).
fn stream(pushes: usize, pose_ns: i64) -> (Vec<PoseSample>, Vec<CommandSample>) {
    let push_ns = 2_000_000_000i64;
    let mut poses = Vec::new();
    let mut t = 0;
    while t <= pushes as i64 * push_ns {
        let k = (t / push_ns) as f64;
        let frac = ((t % push_ns) as f64 / 1e9).min(1.0);
        let x = 0.01 * (k + if (k as usize) < pushes { frac } else { 0.0 });
        poses.push(PoseSample {
            t_ns: t,
            x,
            y: 0.0,
            yaw: 0.0,
        });
        t += pose_ns;
    }
    let cmds = (0..pushes)
        .map(|k| CommandSample {
            t_ns: k as i64 * push_ns,
            u: vec![0.1 * k as f64, 0.0, 0.5],
        })
        .collect();
    (poses, cmds)
}

#[test]
fn a_ten_hertz_pose_stream_loads_as_one_state_per_push() {
    let (poses, cmds) = stream(5, 100_000_000);
    assert_eq!(poses.len(), 101);
    let d = Dataset::from_samples(World::Push, &poses, &cmds, &SavGol::default()).unwrap();
    assert_eq!(d.trajectories.len(), 1);
    let t = &d.trajectories[0];
    assert_eq!(t.len(), 6, "5 push starts + the settled pose");
    assert_eq!(d.transitions(), 5);
    for i in 0..6 {
        assert!((t.s[i * 3] - 0.01 * i as f64).abs() < 1e-12, "{:?}", t.s);
    }
    for i in 0..5 {
        assert_eq!(&t.u[i * 3..i * 3 + 3], &[0.1 * i as f64, 0.0, 0.5]);
    }
    assert!((d.pose_dt_s - 2.0).abs() < 1e-9, "{}", d.pose_dt_s);
}

#[test]
fn one_pose_per_push_loads_unchanged() {
    // one pose per push, the push published 1 ms after the pose it starts from
    let (poses, mut cmds) = stream(6, 2_000_000_000);
    assert_eq!(poses.len(), 7);
    cmds.iter_mut().for_each(|c| c.t_ns += 1_000_000);
    let d = Dataset::from_samples(World::Push, &poses, &cmds, &SavGol::default()).unwrap();
    let t = &d.trajectories[0];
    assert_eq!(t.len(), 7);
    let want: Vec<f64> = poses.iter().flat_map(|p| [p.x, p.y, p.yaw]).collect();
    assert_eq!(t.s, want);
}

#[test]
fn the_bundled_pushing_bag_has_one_transition_per_push() {
    let bag = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../bags/push_nominal");
    let d = load_bags(&[bag], None, &Topics::default(), &SavGol::default()).unwrap();
    assert_eq!(d.world, World::Push);
    // 40 episodes × 10 pushes, each episode its start poses plus the settled pose
    assert_eq!(d.transitions(), 400, "{:?}", d.lengths());
    assert!(d.trajectories.iter().all(|t| t.len() == 11));
}
