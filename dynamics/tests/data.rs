//! The data pipeline: trajectories, command hold, Savitzky–Golay, windows, splits, normalisation.
#![allow(clippy::needless_range_loop)] // index loops mirror the math

use dynlab_dynamics::conventions::wrap_angle;
use dynlab_dynamics::data::*;

const MS: i64 = 1_000_000;

fn pose(t_ms: i64, x: f64, y: f64, yaw: f64) -> PoseSample {
    PoseSample {
        t_ns: t_ms * MS,
        x,
        y,
        yaw,
    }
}
fn cmd(t_ms: i64, u: &[f64]) -> CommandSample {
    CommandSample {
        t_ns: t_ms * MS,
        u: u.to_vec(),
    }
}

#[test]
fn gaps_split_trajectories_and_are_reported() {
    let mut poses: Vec<_> = (0..20).map(|i| pose(i * 10, i as f64, 0.0, 0.0)).collect();
    poses.extend((0..15).map(|i| pose(1000 + i * 10, 0.0, i as f64, 0.0)));
    let cmds = vec![cmd(0, &[0.1, 0.2])];
    let (trajs, rep) = build_trajectories(&poses, &cmds, &PipelineConfig::default()).unwrap();
    assert_eq!(trajs.len(), 2);
    assert_eq!((trajs[0].len(), trajs[1].len()), (20, 15));
    assert_eq!(
        rep.gaps,
        vec![Gap {
            from_ns: 190 * MS,
            to_ns: 1000 * MS
        }]
    );
    assert_eq!(rep.max_gap_ns, 50 * MS); // 5 × median interval
    assert!((trajs[0].dt - 0.01).abs() < 1e-12);
    // an explicit larger threshold keeps it whole
    let cfg = PipelineConfig {
        max_gap_ns: Some(2000 * MS),
        resample: Resample::Off,
        ..Default::default()
    };
    let (trajs, rep) = build_trajectories(&poses, &cmds, &cfg).unwrap();
    assert_eq!(trajs.len(), 1);
    assert!(rep.gaps.is_empty());
}

#[test]
fn yaw_is_unwrapped_across_the_branch_cut() {
    let yaws = [3.0, 3.1, -3.1, -3.0, 3.1];
    let poses: Vec<_> = yaws
        .iter()
        .enumerate()
        .map(|(i, &w)| pose(i as i64 * 10, 0.0, 0.0, w))
        .collect();
    let (trajs, _) =
        build_trajectories(&poses, &[cmd(0, &[0.0])], &PipelineConfig::default()).unwrap();
    let y: Vec<f64> = trajs[0].pose.iter().map(|p| p[2]).collect();
    for w in y.windows(2) {
        assert!((w[1] - w[0]).abs() < 0.3, "{y:?}");
    }
    for (a, b) in y.iter().zip(yaws) {
        assert!(wrap_angle(a - b).abs() < 1e-12);
    }
    assert!((y[2] - (2.0 * std::f64::consts::PI - 3.1)).abs() < 1e-12);
}

#[test]
fn zero_order_hold_never_uses_a_command_from_the_future() {
    // poses at 100 Hz from t = 0, commands at 30 Hz starting at t = 25 ms
    let poses: Vec<_> = (0..50).map(|i| pose(i * 10, 0.0, 0.0, 0.0)).collect();
    let cmds: Vec<_> = (0..17)
        .map(|k| cmd(25 + k * 33, &[k as f64, -(k as f64)]))
        .collect();
    let (trajs, rep) = build_trajectories(&poses, &cmds, &PipelineConfig::default()).unwrap();
    // poses at 0, 10, 20 ms have no command yet: dropped and counted
    assert_eq!(rep.poses_without_command, 3);
    let t = &trajs[0];
    assert_eq!(t.t_ns[0], 30 * MS);
    for (i, &tn) in t.t_ns.iter().enumerate() {
        let k = t.u[2 * i] as i64;
        let issued = (25 + k * 33) * MS;
        assert!(
            issued <= tn,
            "pose at {tn} got a command issued at {issued}"
        );
        // and it is the latest such command
        assert!(issued + 33 * MS > tn);
        assert_eq!(t.u[2 * i + 1], -(k as f64));
    }
}

#[test]
fn push_actions_issued_after_their_pose_are_held_over_the_following_interval() {
    // the Tu & Lin layout: pose every 2 s, the push published 1 ms after the pose it starts from
    let poses: Vec<_> = (0..4)
        .map(|i| pose(i * 2000, 0.4 + 0.01 * i as f64, 0.0, 0.0))
        .collect();
    let cmds: Vec<_> = (0..3)
        .map(|i| cmd(i * 2000 + 1, &[i as f64, 0.0, 0.5]))
        .collect();
    let cfg = PipelineConfig {
        hold: CommandHold::BeforeNextPose,
        ..Default::default()
    };
    let (trajs, rep) = build_trajectories(&poses, &cmds, &cfg).unwrap();
    assert_eq!(rep.poses_without_command, 0);
    let u0: Vec<f64> = trajs[0].u.chunks(3).map(|c| c[0]).collect();
    assert_eq!(u0, vec![0.0, 1.0, 2.0, 2.0]);
    // the strict hold at the pose stamp would miss the first push
    let (trajs, rep) = build_trajectories(&poses, &cmds, &PipelineConfig::default()).unwrap();
    assert_eq!(rep.poses_without_command, 1);
    assert_eq!(trajs[0].u[0], 0.0);
}

#[test]
fn jittery_stamps_are_resampled_to_the_median_step() {
    let jitter = [0, 3, -4, 2, 0, -3, 4, 1, -2, 0, 3, -1];
    let poses: Vec<_> = jitter
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let t = i as i64 * 10 + j;
            pose(t, 2.0 * t as f64 * 1e-3, 0.0, 0.0)
        })
        .collect();
    let (trajs, rep) =
        build_trajectories(&poses, &[cmd(0, &[1.0])], &PipelineConfig::default()).unwrap();
    assert_eq!(rep.resampled_trajectories, 1);
    assert!(rep.max_jitter > 0.5);
    let t = &trajs[0];
    assert!(t.resampled);
    for w in t.t_ns.windows(2) {
        assert_eq!(w[1] - w[0], t.t_ns[1] - t.t_ns[0]);
    }
    // x = 2 m/s × t is linear, so interpolation is exact
    for (tn, p) in t.t_ns.iter().zip(&t.pose) {
        assert!((p[0] - 2.0 * *tn as f64 * 1e-9).abs() < 1e-12);
    }
}

#[test]
fn bad_input_gets_clear_errors() {
    let poses: Vec<_> = (0..5).map(|i| pose(i * 10, 0.0, 0.0, 0.0)).collect();
    let e = build_trajectories(&poses, &[], &PipelineConfig::default()).unwrap_err();
    assert_eq!(e, DataError::NoCommands { poses: 5 });
    assert!(e.to_string().contains("no commands"));
    let strict = PipelineConfig {
        strict: true,
        ..Default::default()
    };
    let mut bad = poses.clone();
    bad[3].yaw = f64::NAN;
    let e = build_trajectories(&bad, &[cmd(0, &[0.0])], &strict).unwrap_err();
    assert!(
        matches!(&e, DataError::NonFinite { field, t_ns, .. } if field == "pose.yaw" && *t_ns == 30 * MS),
        "{e}"
    );
    let e = build_trajectories(&poses, &[cmd(0, &[0.0]), cmd(5, &[f64::INFINITY])], &strict)
        .unwrap_err();
    assert!(
        e.to_string().contains("command[0] at t = 5000000 ns"),
        "{e}"
    );
    let e =
        build_trajectories(&poses, &[cmd(100, &[0.0])], &PipelineConfig::default()).unwrap_err();
    assert!(matches!(e, DataError::NoPoseWithCommand { .. }), "{e}");
    let e = windows(&[3, 4, 2], 5).unwrap_err();
    assert_eq!(
        e.to_string(),
        "too little data: need at least 6 poses per trajectory for a window of 5 steps; the longest trajectory has 4 (3 trajectories); record longer runs or lower the number of steps"
    );
    assert!(build_trajectories(&[], &[cmd(0, &[0.0])], &PipelineConfig::default()).is_err());
}

#[test]
fn savgol_is_exact_on_polynomials_with_irregular_stamps_including_edges() {
    // cubic, irregular stamps: a degree-3 fit reproduces value and slope everywhere
    let t: Vec<f64> = (0..40)
        .map(|i| i as f64 * 0.01 + 0.003 * ((i * 7 % 5) as f64 - 2.0))
        .collect();
    let y: Vec<f64> = t
        .iter()
        .map(|&t| 1.0 - 2.0 * t + 3.0 * t * t - 5.0 * t * t * t)
        .collect();
    let (v, d) = savgol(
        &t,
        &y,
        &SavGol {
            window: 9,
            order: 3,
            ..SavGol::default()
        },
    )
    .unwrap();
    for i in 0..t.len() {
        let dy = -2.0 + 6.0 * t[i] - 15.0 * t[i] * t[i];
        assert!((v[i] - y[i]).abs() < 1e-10, "value at {i}");
        assert!((d[i] - dy).abs() < 1e-8, "slope at {i}: {} vs {dy}", d[i]);
    }
}

#[test]
fn savgol_on_equidistant_stamps_is_the_classic_filter() {
    // window 5, order 2: smoothing coefficients (−3, 12, 17, 12, −3)/35, derivative (−2, −1, 0, 1, 2)/10
    let t: Vec<f64> = (0..9).map(|i| i as f64 * 0.5).collect();
    let y = [0.3, -1.0, 2.5, 0.7, 1.9, -0.4, 0.0, 1.1, 3.0];
    let (v, d) = savgol(
        &t,
        &y,
        &SavGol {
            window: 5,
            order: 2,
            ..SavGol::default()
        },
    )
    .unwrap();
    let i = 4;
    let sm = (-3.0 * y[2] + 12.0 * y[3] + 17.0 * y[4] + 12.0 * y[5] - 3.0 * y[6]) / 35.0;
    let de = (-2.0 * y[2] - y[3] + y[5] + 2.0 * y[6]) / 10.0 / 0.5;
    assert!((v[i] - sm).abs() < 1e-12);
    assert!((d[i] - de).abs() < 1e-12);
    assert!(
        savgol(
            &t,
            &y,
            &SavGol {
                window: 4,
                order: 2,
                ..SavGol::default()
            }
        )
        .is_err()
    );
    assert!(
        savgol(
            &t[..3],
            &y[..3],
            &SavGol {
                window: 5,
                order: 2,
                ..SavGol::default()
            }
        )
        .is_err()
    );
}

#[test]
fn car_states_recover_body_velocities_on_a_circle() {
    // constant speed v on a circle of radius R, heading tangent, 200 Hz with jitter-free stamps
    let (v, r) = (1.5, 2.0);
    let w = v / r;
    let poses: Vec<_> = (0..200)
        .map(|i| {
            let t = i as f64 * 0.005;
            let a = w * t;
            PoseSample {
                t_ns: (t * 1e9).round() as i64,
                x: r * a.sin(),
                y: r * (1.0 - a.cos()),
                yaw: wrap_angle(a),
            }
        })
        .collect();
    let (trajs, _) =
        build_trajectories(&poses, &[cmd(0, &[0.1, 0.3])], &PipelineConfig::default()).unwrap();
    let s = car_states(
        &trajs[0],
        &SavGol {
            window: 11,
            order: 3,
            ..SavGol::default()
        },
    )
    .unwrap();
    for st in &s {
        assert!((st[3] - v).abs() < 1e-3, "vx {}", st[3]);
        assert!(st[4].abs() < 1e-3, "vy {}", st[4]);
        assert!((st[5] - w).abs() < 1e-3, "ω {}", st[5]);
    }
    let st = StateTrajectory::car(&trajs[0], &SavGol::default()).unwrap();
    assert_eq!((st.len(), st.dim_s, st.dim_u), (200, 6, 2));
}

#[test]
fn windows_never_cross_trajectory_boundaries_and_gather_is_step_major() {
    let lens = [5, 2, 7];
    let ws = windows(&lens, 3).unwrap();
    assert_eq!(ws.len(), (5 - 3) + (7 - 3));
    for w in &ws {
        assert!(w.start + 3 < lens[w.trajectory]);
    }
    let trajs: Vec<StateTrajectory> = lens
        .iter()
        .enumerate()
        .map(|(ti, &n)| StateTrajectory {
            s: (0..n).flat_map(|i| [ti as f64, i as f64]).collect(),
            u: (0..n).map(|i| 100.0 * ti as f64 + i as f64).collect(),
            dim_s: 2,
            dim_u: 1,
            dt: 0.1,
        })
        .collect();
    let b = gather(&trajs, &ws, 3);
    assert_eq!((b.n, b.k), (6, 3));
    for (i, w) in ws.iter().enumerate() {
        assert_eq!(
            b.s0[2 * i..2 * i + 2],
            [w.trajectory as f64, w.start as f64]
        );
        for j in 0..3 {
            assert_eq!(
                b.u[j * 6 + i],
                100.0 * w.trajectory as f64 + (w.start + j) as f64
            );
            assert_eq!(b.target[(j * 6 + i) * 2 + 1], (w.start + j + 1) as f64);
            assert_eq!(b.target[(j * 6 + i) * 2], w.trajectory as f64);
        }
    }
}

#[test]
fn trajectory_splits_are_disjoint_seeded_and_reproducible() {
    let s = split_trajectories(100, 0.2, 42).unwrap();
    assert_eq!((s.train.len(), s.validation.len()), (80, 20));
    let mut all: Vec<usize> = s.train.iter().chain(&s.validation).copied().collect();
    all.sort_unstable();
    assert_eq!(all, (0..100).collect::<Vec<_>>());
    assert_eq!(s, split_trajectories(100, 0.2, 42).unwrap());
    assert_ne!(s, split_trajectories(100, 0.2, 43).unwrap());
    assert_eq!(split_trajectories(2, 0.01, 1).unwrap().validation.len(), 1);
    assert!(split_trajectories(1, 0.2, 1).is_err());
    assert!(split_trajectories(10, 1.0, 1).is_err());
    // the paper's overlapping-window split, for comparison: windows of one trajectory on both sides
    let ws = windows(&[11; 100], 1).unwrap();
    let o = split_windows_overlapping(&ws, 0.2, 42).unwrap();
    assert_eq!((o.train.len(), o.validation.len()), (800, 200));
    let shared = o
        .validation
        .iter()
        .filter(|v| o.train.iter().any(|t| t.trajectory == v.trajectory))
        .count();
    assert!(
        shared > 150,
        "overlapping split shares trajectories ({shared})"
    );
}

#[test]
fn splitmix_stream_is_fixed_across_platforms() {
    // reference values of SplitMix64 from seed 0 (Vigna's reference implementation)
    let mut r = SplitMix64::new(0);
    assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
    assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
}

#[test]
fn normalizer_guards_constant_dimensions_and_round_trips() {
    let rows = [1.0, 5.0, 2.0, 3.0, 5.0, 2.0, 5.0, 5.0, 2.0];
    let n = Normalizer::fit(&rows, 3, 1e-9).unwrap();
    assert_eq!(n.constant_dims, vec![1, 2]);
    assert_eq!(n.std[1], 1.0);
    assert!((n.mean[0] - 3.0).abs() < 1e-15);
    assert!((n.std[0] - (8.0f64 / 3.0).sqrt()).abs() < 1e-15);
    let mut x = rows;
    n.normalize(&mut x);
    assert!(x.iter().all(|v| v.is_finite()));
    assert!((x[0] + x[3] + x[6]).abs() < 1e-12);
    assert_eq!(x[1], 0.0);
    n.denormalize(&mut x);
    for (a, b) in x.iter().zip(rows) {
        assert!((a - b).abs() < 1e-12);
    }
    assert!(Normalizer::fit(&[], 3, 1e-9).is_err());
}

/// 100 Hz poses of a body moving at 1 m/s in x; commands from t = 0.
fn line(n: i64) -> Vec<PoseSample> {
    (0..n)
        .map(|i| pose(i * 10, i as f64 * 0.01, 0.0, 0.0))
        .collect()
}

#[test]
fn a_nan_pose_in_the_middle_is_skipped_counted_and_splits_the_trajectory() {
    // a motion capture loses the body for one frame at t = 200 ms (x NaN) and for three frames
    // at 500–520 ms (the whole pose NaN)
    let mut poses = line(100);
    poses[20].x = f64::NAN;
    for p in &mut poses[50..53] {
        *p = pose(p.t_ns / MS, f64::NAN, f64::NAN, f64::NAN);
    }
    let (trajs, rep) =
        build_trajectories(&poses, &[cmd(0, &[0.5])], &PipelineConfig::default()).unwrap();
    assert_eq!(rep.non_finite_poses, 4);
    assert_eq!(rep.out_of_order_poses, 0);
    assert_eq!(rep.splits_at_skipped, 2);
    assert_eq!(
        rep.skipped.iter().map(|s| s.t_ns / MS).collect::<Vec<_>>(),
        [200, 500, 510, 520]
    );
    assert!(
        rep.skipped
            .iter()
            .all(|s| s.reason == SkipReason::NonFinite)
    );
    // three pieces: 0–190 ms, 210–490 ms, 530–990 ms; no transition spans a skipped pose
    let spans: Vec<(i64, i64, usize)> = trajs
        .iter()
        .map(|t| (t.t_ns[0] / MS, t.t_ns[t.len() - 1] / MS, t.len()))
        .collect();
    assert_eq!(spans, [(0, 190, 20), (210, 490, 29), (530, 990, 47)]);
    assert!(
        rep.gaps.is_empty(),
        "a skipped pose is not a gap: {:?}",
        rep.gaps
    );
    assert_eq!(rep.poses_out, 96);
    assert!(
        trajs
            .iter()
            .flat_map(|t| &t.pose)
            .all(|p| p.iter().all(|v| v.is_finite()))
    );
    // strict: refused, naming the first bad field and stamp
    let strict = PipelineConfig {
        strict: true,
        ..Default::default()
    };
    let e = build_trajectories(&poses, &[cmd(0, &[0.5])], &strict).unwrap_err();
    assert!(
        matches!(&e, DataError::NonFinite { field, t_ns, value } if field == "pose.x" && *t_ns == 200 * MS && value.is_nan()),
        "{e}"
    );
    assert!(
        e.to_string()
            .starts_with("non-finite value in pose.x at t = 200000000 ns"),
        "{e}"
    );
}

#[test]
fn a_pose_whose_stamp_goes_back_is_skipped_and_splits_the_trajectory() {
    // pose 30 arrives with the stamp of pose 10 (a stale repeat), pose 60 with a stamp 5 ms
    // before pose 59
    let mut poses = line(100);
    poses[30] = pose(100, 0.1, 0.0, 0.0);
    poses[60].t_ns = 585 * MS;
    let (trajs, rep) =
        build_trajectories(&poses, &[cmd(0, &[0.5])], &PipelineConfig::default()).unwrap();
    assert_eq!(rep.out_of_order_poses, 2);
    assert_eq!(rep.non_finite_poses, 0);
    assert_eq!(rep.splits_at_skipped, 2);
    assert_eq!(
        rep.skipped,
        [
            SkippedPose {
                t_ns: 100 * MS,
                reason: SkipReason::OutOfOrder
            },
            SkippedPose {
                t_ns: 585 * MS,
                reason: SkipReason::OutOfOrder
            }
        ]
    );
    let spans: Vec<(i64, i64)> = trajs
        .iter()
        .map(|t| (t.t_ns[0] / MS, t.t_ns[t.len() - 1] / MS))
        .collect();
    assert_eq!(spans, [(0, 290), (310, 590), (610, 990)]);
    // every trajectory's stamps increase
    assert!(trajs.iter().all(|t| t.t_ns.windows(2).all(|w| w[1] > w[0])));
    // strict refuses, naming both stamps
    let strict = PipelineConfig {
        strict: true,
        ..Default::default()
    };
    let e = build_trajectories(&poses, &[cmd(0, &[0.5])], &strict).unwrap_err();
    assert_eq!(
        e,
        DataError::OutOfOrder {
            t_ns: 100 * MS,
            previous_ns: 290 * MS
        }
    );
    assert!(e.to_string().contains("--strict"), "{e}");
}

#[test]
fn nonfinite_commands_are_skipped_and_the_one_before_stays_held() {
    let poses = line(10);
    let cmds = [cmd(0, &[1.0]), cmd(45, &[f64::NAN]), cmd(70, &[3.0])];
    let (trajs, rep) = build_trajectories(&poses, &cmds, &PipelineConfig::default()).unwrap();
    assert_eq!(rep.non_finite_commands, 1);
    assert_eq!(trajs.len(), 1);
    assert_eq!(
        trajs[0].u,
        [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 3.0, 3.0, 3.0]
    );
    // only NaN poses: a clear error
    let nan: Vec<_> = (0..5).map(|i| pose(i * 10, f64::NAN, 0.0, 0.0)).collect();
    let e = build_trajectories(&nan, &cmds, &PipelineConfig::default()).unwrap_err();
    assert!(
        e.to_string()
            .contains("all 5 poses were skipped (5 with NaN or infinite values"),
        "{e}"
    );
}

#[test]
fn stamps_that_go_back_and_stay_back_start_a_new_trajectory() {
    // a clock reset: after pose 49 (490 ms) the stamps restart at 100 ms and go on
    let mut poses = line(50);
    poses.extend((0..30).map(|i| pose(100 + i * 10, 1.0 + i as f64 * 0.01, 0.0, 0.0)));
    let (trajs, rep) =
        build_trajectories(&poses, &[cmd(0, &[0.5])], &PipelineConfig::default()).unwrap();
    assert_eq!(rep.stamp_resets, [100 * MS]);
    assert_eq!(rep.out_of_order_poses, 0);
    assert!(rep.skipped.is_empty(), "{:?}", rep.skipped);
    assert_eq!(trajs.len(), 2);
    assert_eq!((trajs[0].len(), trajs[1].len()), (50, 30));
    assert_eq!(trajs[1].t_ns[0], 100 * MS);

    // one pose stamped 100 s in the future: the poses after it start a new trajectory, the
    // glitch is left alone (too short) instead of every later pose being skipped
    let mut poses = line(60);
    poses[30].t_ns = 100_000 * MS;
    let (trajs, rep) =
        build_trajectories(&poses, &[cmd(0, &[0.5])], &PipelineConfig::default()).unwrap();
    assert_eq!(rep.stamp_resets, [310 * MS]);
    assert_eq!(rep.out_of_order_poses, 0);
    assert_eq!(rep.short_trajectories_dropped, 1);
    let spans: Vec<(i64, i64)> = trajs
        .iter()
        .map(|t| (t.t_ns[0] / MS, t.t_ns[t.len() - 1] / MS))
        .collect();
    assert_eq!(spans, [(0, 290), (310, 590)]);

    // fewer than STAMP_RESET_RUN poses behind: skipped, as before
    let mut poses = line(60);
    for (k, p) in poses[30..30 + STAMP_RESET_RUN - 1].iter_mut().enumerate() {
        p.t_ns = (10 + k as i64) * MS;
    }
    let (_, rep) =
        build_trajectories(&poses, &[cmd(0, &[0.5])], &PipelineConfig::default()).unwrap();
    assert_eq!(rep.out_of_order_poses, STAMP_RESET_RUN - 1);
    assert!(rep.stamp_resets.is_empty());
}

/// A car drive at 100 Hz with smoothly varying body velocities (`vy` a twentieth of `vx`, as a
/// car that slides a little; their frequencies scaled by `pace`), integrated exactly enough for
/// the test, with white pose noise of `sigma` (m) and `sigma_yaw` (rad): the noisy poses and the
/// true `[vx, vy, ω]` at each.
fn noisy_drive(
    sigma: f64,
    sigma_yaw: f64,
    pace: f64,
    seed: u64,
) -> (Vec<PoseSample>, Vec<[f64; 3]>) {
    let mut rng = SplitMix64::new(seed);
    let mut normal = || {
        // Box–Muller from two uniforms in (0, 1]
        let u = |r: &mut SplitMix64| ((r.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64;
        let (a, b) = (u(&mut rng), u(&mut rng));
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    };
    let (dt, sub) = (0.01, 20);
    let vel = |t: f64| {
        [
            1.0 + 0.3 * (0.7 * pace * t).sin(),
            0.05 * (1.3 * pace * t).sin(),
            1.5 * (0.9 * pace * t).sin(),
        ]
    };
    let (mut x, mut y, mut psi) = (0.0f64, 0.0f64, 0.0f64);
    let mut poses = Vec::new();
    let mut truth = Vec::new();
    for i in 0..2000 {
        let t = i as f64 * dt;
        poses.push(PoseSample {
            t_ns: (t * 1e9).round() as i64,
            x: x + sigma * normal(),
            y: y + sigma * normal(),
            yaw: wrap_angle(psi + sigma_yaw * normal()),
        });
        truth.push(vel(t));
        let h = dt / sub as f64;
        for j in 0..sub {
            let [vx, vy, w] = vel(t + (j as f64 + 0.5) * h);
            let (s, c) = psi.sin_cos();
            x += h * (c * vx - s * vy);
            y += h * (s * vx + c * vy);
            psi += h * w;
        }
    }
    (poses, truth)
}

/// RMS error of the estimated `[vx, vy, ω]` against the truth, away from the edges.
fn velocity_rms(states: &[[f64; 6]], truth: &[[f64; 3]]) -> [f64; 3] {
    let inner = 40..states.len() - 40;
    let n = inner.len() as f64;
    let mut e = [0.0; 3];
    for i in inner {
        for c in 0..3 {
            e[c] += (states[i][3 + c] - truth[i][c]).powi(2) / n;
        }
    }
    e.map(f64::sqrt)
}

/// The RMS velocity errors against the truth of `adapted`'s windows, and the smallest of the
/// windows [`SavGol::adapted`] tries (15 to 45 in steps of 6), for the position's `vy` (the
/// yaw's window as adapted) and the yaw's `ω` (the position's as adapted).
fn against_every_window(
    traj: &dynlab_dynamics::data::Trajectory,
    adapted: SavGol,
    truth: &[[f64; 3]],
) -> ([f64; 3], [f64; 2]) {
    let rms = |sg: SavGol| velocity_rms(&car_states(traj, &sg).unwrap(), truth);
    let yaw = adapted.yaw_window.unwrap_or(adapted.window);
    let best = |f: &dyn Fn(usize) -> f64| (15..=45).step_by(6).map(f).fold(f64::INFINITY, f64::min);
    let vy = best(&|w| {
        rms(SavGol {
            window: w,
            yaw_window: Some(yaw),
            ..adapted
        })[1]
    });
    let omega = best(&|w| {
        rms(SavGol {
            yaw_window: Some(w),
            ..adapted
        })[2]
    });
    (rms(adapted), [vy, omega])
}

#[test]
fn noisy_poses_on_a_smooth_drive_widen_the_windows_to_near_the_best_for_the_truth() {
    let (poses, truth) = noisy_drive(1e-3, 0.004, 1.0, 3);
    let (trajs, rep) =
        build_trajectories(&poses, &[cmd(0, &[0.1, 0.3])], &PipelineConfig::default()).unwrap();
    let std = rep.pose_std.expect("the noise is estimated");
    let adapted = SavGol::adaptive().adapted(&trajs, std);
    assert!(!adapted.adaptive);
    adapted.validate().unwrap();
    assert!(adapted.window > 15, "{adapted:?}");
    let (got, best) = against_every_window(&trajs[0], adapted, &truth);
    let plain = velocity_rms(&car_states(&trajs[0], &SavGol::default()).unwrap(), &truth);
    eprintln!("{adapted:?}: {got:?}; best tried vy, ω {best:?}; 15 poses {plain:?}");
    assert!(got[1] <= 1.15 * best[0], "vy: {got:?}, best {best:?}");
    assert!(got[2] <= 1.15 * best[1], "ω: {got:?}, best {best:?}");
    assert!(got[1] < 0.7 * plain[1], "vy: {got:?} against {plain:?}");
    assert!(got[0] < plain[0], "vx: {got:?} against {plain:?}");
}

#[test]
fn quicker_motion_narrows_the_windows_to_near_the_best_and_a_bad_yaw_window_is_refused() {
    // quiet poses; velocities that change faster and faster: a wide fit bends them more
    let mut windows = Vec::new();
    for pace in [6.0, 12.0, 25.0] {
        let (poses, truth) = noisy_drive(1e-4, 4e-4, pace, 4);
        let (trajs, rep) =
            build_trajectories(&poses, &[cmd(0, &[0.1, 0.3])], &PipelineConfig::default()).unwrap();
        let adapted = SavGol::adaptive().adapted(&trajs, rep.pose_std.unwrap());
        let (got, best) = against_every_window(&trajs[0], adapted, &truth);
        eprintln!("pace {pace}: {adapted:?}: {got:?}; best tried vy, ω {best:?}");
        assert!(
            got[1] <= 1.15 * best[0],
            "pace {pace}: vy {got:?}, best {best:?}"
        );
        assert!(
            got[2] <= 1.15 * best[1],
            "pace {pace}: ω {got:?}, best {best:?}"
        );
        windows.push(adapted.window);
    }
    assert!(windows.is_sorted_by(|a, b| a >= b), "{windows:?}");
    assert_eq!(windows[2], 15, "the quickest motion keeps the default");
    let err = SavGol {
        yaw_window: Some(14),
        ..SavGol::default()
    }
    .validate()
    .unwrap_err();
    assert!(err.to_string().contains("odd"), "{err}");
}
