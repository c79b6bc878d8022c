//! Car states re-estimated with a physics model (`smooth::model_states`) and windows' start
//! states fitted by the model that rolls them out (`smooth::StartFits`) against the
//! Savitzky–Golay estimates, on a simulated drive whose true states are known.

use dynlab_dynamics::data::{SavGol, SplitMix64, StateTrajectory, Trajectory};
use dynlab_dynamics::ode::Solver;
use dynlab_dynamics::physics::PhysicsModel;
use dynlab_learn::smooth::{StartFits, model_states};

const RATE_HZ: f64 = 100.0;
const STD: [f64; 3] = [1e-3, 1e-3, 4e-3];

fn uniform(rng: &mut SplitMix64) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

fn normal(rng: &mut SplitMix64) -> f64 {
    let (a, b) = (uniform(rng).max(1e-300), uniform(rng));
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

/// `seconds` of the car `p` under steering and throttle steps every 0.3 s: the poses with
/// white noise of [`STD`], and the true states.
fn drive(p: &PhysicsModel, seconds: f64, seed: u64) -> (Trajectory, Vec<[f64; 6]>) {
    let mut rng = SplitMix64::new(seed);
    let dt = 1.0 / RATE_HZ;
    let n = (seconds * RATE_HZ) as usize;
    let solver = Solver::Rk4 { substeps: 4 };
    let mut s = vec![0.0, 0.0, 0.3, 1.0, 0.0, 0.0];
    let (mut pose, mut u, mut truth) = (Vec::new(), Vec::new(), Vec::new());
    let mut cmd = [0.0, 0.3];
    for i in 0..n {
        if i % 30 == 0 {
            cmd = [0.6 * uniform(&mut rng) - 0.3, 0.1 + 0.5 * uniform(&mut rng)];
        }
        truth.push([s[0], s[1], s[2], s[3], s[4], s[5]]);
        pose.push([0, 1, 2].map(|c| s[c] + STD[c] * normal(&mut rng)));
        u.extend_from_slice(&cmd);
        let mut next = vec![0.0; 6];
        p.integrate_step(&solver, 1, &s, &cmd, dt, &mut next);
        s = next;
    }
    let traj = Trajectory {
        t_ns: (0..n).map(|i| (i as f64 * dt * 1e9) as i64).collect(),
        pose,
        u,
        dim_u: 2,
        dt,
        resampled: false,
    };
    (traj, truth)
}

/// The car with a steering offset of 0.03 rad.
fn offset_car() -> PhysicsModel {
    let mut car =
        PhysicsModel::car(&PhysicsModel::parse_effects(&["steering_offset"]).unwrap()).unwrap();
    car.set_param("steering_offset.delta0", 0.03).unwrap();
    car
}

/// RMS errors of `[vx, vy, ω]` against the truth, 0.5 s away from the ends.
fn velocity_rms(t: &StateTrajectory, truth: &[[f64; 6]]) -> [f64; 3] {
    let inner = 50..truth.len() - 50;
    let m = inner.len() as f64;
    let mut e = [0.0; 3];
    for i in inner {
        for c in 0..3 {
            e[c] += (t.s[i * 6 + 3 + c] - truth[i][3 + c]).powi(2) / m;
        }
    }
    e.map(f64::sqrt)
}

#[test]
fn the_true_model_estimates_the_velocities_of_a_quick_car_better_than_savitzky_golay() {
    let p = PhysicsModel::car(&[]).unwrap();
    let solver = Solver::Rk4 { substeps: 4 };
    for seed in [1, 2] {
        let (traj, truth) = drive(&p, 8.0, seed);
        let sg = StateTrajectory::car(
            &traj,
            &SavGol {
                window: 27,
                yaw_window: Some(15),
                ..SavGol::default()
            },
        )
        .unwrap();
        let before = velocity_rms(&sg, &truth);
        let half = (0.05 * RATE_HZ) as usize;
        let after = model_states(&p, &solver, std::slice::from_ref(&sg), STD, half);
        assert_eq!(after[0].s.len(), sg.s.len());
        assert_eq!(after[0].u, sg.u);
        let after = velocity_rms(&after[0], &truth);
        eprintln!("seed {seed}: Savitzky–Golay {before:?}, the model {after:?}");
        // the yaw rate that follows a steering step within tens of milliseconds most
        assert!(
            after[2] < 0.7 * before[2],
            "seed {seed}: {after:?} against {before:?}"
        );
        for c in [0, 1] {
            assert!(
                after[c] < before[c],
                "seed {seed}: {after:?} against {before:?}"
            );
        }
    }
}

#[test]
fn a_model_without_the_cars_steering_offset_still_estimates_its_yaw_rate_better() {
    // the fits' constant accelerations take what the model misses, not the states
    let car = offset_car();
    let model = PhysicsModel::car(&[]).unwrap();
    let (traj, truth) = drive(&car, 8.0, 4);
    let sg = StateTrajectory::car(&traj, &SavGol::default()).unwrap();
    let before = velocity_rms(&sg, &truth);
    let after = model_states(&model, &Solver::Rk4 { substeps: 4 }, &[sg], STD, 5);
    let after = velocity_rms(&after[0], &truth);
    eprintln!("Savitzky–Golay {before:?}, the model without the offset {after:?}");
    assert!(after[2] < 0.7 * before[2], "{after:?} against {before:?}");
    assert!(after[1] < before[1], "{after:?} against {before:?}");
}

#[test]
fn a_trajectory_shorter_than_the_fits_is_kept_as_estimated() {
    let p = PhysicsModel::car(&[]).unwrap();
    let (traj, _) = drive(&p, 0.1, 3);
    let sg = StateTrajectory::car(&traj, &SavGol::default()).unwrap();
    let after = model_states(
        &p,
        &Solver::Rk4 { substeps: 4 },
        std::slice::from_ref(&sg),
        STD,
        8,
    );
    assert_eq!(after, vec![sg]);
}

/// RMS errors of `[vx, vy, ω]` of the states `s` (`dim_state` each, car state first) at the
/// samples `at` against the truth.
fn start_rms(s: &[f64], dim: usize, at: &[usize], truth: &[[f64; 6]]) -> [f64; 3] {
    let mut e = [0.0; 3];
    for (r, &i) in at.iter().enumerate() {
        for c in 0..3 {
            e[c] += (s[r * dim + 3 + c] - truth[i][3 + c]).powi(2) / at.len() as f64;
        }
    }
    e.map(f64::sqrt)
}

#[test]
fn fitted_starts_of_the_true_model_are_nearer_the_truth_than_savitzky_golay_and_a_wrong_model() {
    let car = offset_car();
    let without = PhysicsModel::car(&[]).unwrap();
    let solver = Solver::Rk4 { substeps: 4 };
    let (traj, truth) = drive(&car, 8.0, 5);
    let sg = StateTrajectory::car(&traj, &SavGol::default()).unwrap();
    let trajs = std::slice::from_ref(&sg);
    let history = vec![Vec::new()];
    // window starts, the first before a whole fit's span
    let at: Vec<usize> = (3..sg.len() - 60).step_by(7).collect();
    let windows = || at.iter().map(|&i| (0, i));
    let dt = 1.0 / RATE_HZ;
    let fits = StartFits::new(&without, &solver, (trajs, &history), windows(), 10, STD, dt);
    let estimated: Vec<f64> = at
        .iter()
        .flat_map(|&i| sg.s[i * 6..(i + 1) * 6].to_vec())
        .collect();
    let before = start_rms(&estimated, 6, &at, &truth);
    let own = fits.states(&car, &solver, (trajs, &history), windows(), dt);
    let own = start_rms(&own, car.dim_state(), &at, &truth);
    let wrong = fits.states(&without, &solver, (trajs, &history), windows(), dt);
    let wrong = start_rms(&wrong, without.dim_state(), &at, &truth);
    eprintln!("Savitzky–Golay {before:?}, the true model {own:?}, without the offset {wrong:?}");
    // the gains of the model without the offset serve the true model's fits as well
    assert!(own[2] < 0.7 * before[2], "{own:?} against {before:?}");
    assert!(own[1] < before[1], "{own:?} against {before:?}");
    // the yaw rate of the model without the offset takes up what the offset turns
    assert!(own[2] < wrong[2], "{own:?} against {wrong:?}");
}

#[test]
fn a_window_without_a_fit_starts_from_its_state_as_estimated() {
    let p = PhysicsModel::car(&[]).unwrap();
    let solver = Solver::Rk4 { substeps: 4 };
    let (traj, _) = drive(&p, 1.0, 6);
    let sg = StateTrajectory::car(&traj, &SavGol::default()).unwrap();
    let trajs = std::slice::from_ref(&sg);
    let history = vec![Vec::new()];
    let fits = StartFits::new(&p, &solver, (trajs, &history), [(0, 40)], 10, STD, 0.01);
    // (the last sample: a start with no poses after it)
    let last = sg.len() - 1;
    let at = [(0, 40), (0, 70), (0, last)];
    let s = fits.states(&p, &solver, (trajs, &history), at, 0.01);
    assert_eq!(s[6..12], sg.s[70 * 6..71 * 6]);
    assert_eq!(s[12..], sg.s[last * 6..(last + 1) * 6]);
    assert_ne!(s[..6], sg.s[40 * 6..41 * 6]);
}
