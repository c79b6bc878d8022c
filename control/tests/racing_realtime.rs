//! The racer's real-time paths: the solve budget (a deadline returns a plan), the recovery
//! starts on two threads (the same plans as on one), the racing QP settings (the same solution
//! as Clarabel's defaults, to the QP tolerance), the Jacobians batched over the horizon (equal to
//! per-point ones), and the defaults that must not change. No timing is asserted.

use std::time::{Duration, Instant};

use dynlab_control::racing::{
    Deadline, GdSettings, Input, InputLimits, Objective, Optimizer, Plant, Problem, Racer,
    RacerSettings, Regulariser, SolveStatus, SqpSettings, State, TrackTerms, solve_gd,
    solve_gd_until, solve_sqp, solve_sqp_until,
};
use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::dynamics::physics::PhysicsModel;
use dynlab_learn::{Model, ModelKind, Network, Normalization, World};
use dynlab_nn::{Activation, Init, Mlp, MlpSpec};
use dynlab_sim::Track;

fn physics_car() -> Model {
    Model::new(
        ModelKind::Physics,
        World::Car,
        0.01,
        None,
        None,
        Some(PhysicsModel::car(&[]).unwrap()),
        Solver::rk4(),
    )
    .unwrap()
}

fn node_car() -> Model {
    let spec = MlpSpec::uniform(5, &[16, 16], 3, Activation::Gelu).unwrap();
    let mut norm = Normalization::identity(5, 3);
    norm.input_mean = vec![0.5, 0.0, 0.1, 0.0, 0.3];
    norm.input_std = vec![1.5, 0.5, 2.0, 0.3, 0.6];
    norm.output_mean = vec![0.01, -0.02, 0.005];
    norm.output_std = vec![0.05, 0.02, 0.08];
    Model::new(
        ModelKind::NodeRk4,
        World::Car,
        0.01,
        None,
        Some(Network::new(Mlp::new(spec, Init::Auto, 9), norm)),
        None,
        Solver::rk4(),
    )
    .unwrap()
}

/// A racing problem on an oval from the start pose, moving at 1 m/s.
fn racing_problem<'a>(plant: Plant<'a>, track: &'a Track, reference: &'a [f64]) -> Problem<'a> {
    let p = track.start_pose();
    Problem {
        plant,
        s0: [p.x, p.y, p.theta, 1.0, 0.0, 0.0],
        objective: Objective {
            targets: Vec::new(),
            track: Some(TrackTerms {
                track,
                progress_weight: 0.0,
                margin: 0.03,
                margin_growth: 0.0,
                excursion_weight: 1000.0,
                reference_weight: 1.0,
                reference_step: 0.1,
                reference_progress: reference,
                slip_weight: 0.0,
            }),
            limits: InputLimits::default(),
            reg: Regulariser::default(),
            u_prev: None,
            start_segment: Some(track.locate([p.x, p.y]).segment),
        },
    }
}

#[test]
fn a_passed_deadline_still_returns_the_initial_plan_inside_the_track() {
    let model = physics_car();
    let track = Track::oval(1.5, 0.6, 0.2, 200).unwrap();
    let reference: Vec<f64> = (1..=10).map(|k| 0.1 * k as f64).collect();
    let plant = Plant::new(&model, 5).unwrap();
    let problem = racing_problem(plant, &track, &reference);
    // a throttle beyond the limit: the plan returned is clamped into them
    let initial: Vec<Input> = vec![[0.0, 1.5]; 10];
    let passed = Deadline::at(Instant::now() - Duration::from_millis(1));
    let sqp = solve_sqp_until(&problem, &initial, &SqpSettings::default(), Some(&passed)).unwrap();
    assert_eq!(sqp.status, SolveStatus::Deadline);
    assert_eq!(sqp.iterations, 0);
    let clamped: Vec<Input> = initial
        .iter()
        .map(|u| problem.objective.limits.clamp(*u))
        .collect();
    assert_eq!(sqp.inputs, clamped);
    assert_eq!(
        sqp.states,
        problem.plant.rollout(&problem.s0, &clamped).unwrap()
    );
    assert!(sqp.cost.is_finite());
    assert!(
        sqp.states.iter().all(|s| track.contains([s[0], s[1]])),
        "the plan left the track: {:?}",
        sqp.states
    );
    // GD: no iteration, the initial guess with its cost
    let gd = solve_gd_until(&problem, &clamped, &GdSettings::default(), Some(&passed)).unwrap();
    assert_eq!(gd.status, SolveStatus::Deadline);
    assert_eq!(gd.iterations, 0);
    assert_eq!(gd.inputs, clamped);
    assert!((gd.cost - sqp.cost).abs() <= 1e-9 * (1.0 + sqp.cost.abs()));
}

#[test]
fn a_deadline_not_reached_gives_bitwise_the_unbounded_solve() {
    let model = node_car();
    let track = Track::oval(1.5, 0.6, 0.2, 200).unwrap();
    let reference: Vec<f64> = (1..=10).map(|k| 0.1 * k as f64).collect();
    let plant = Plant::new(&model, 5).unwrap();
    let problem = racing_problem(plant, &track, &reference);
    let initial: Vec<Input> = vec![[0.05, 0.5]; 10];
    let far = Deadline::after(Duration::from_secs(3600));
    let settings = RacerSettings::default().sqp;
    let bounded = solve_sqp_until(&problem, &initial, &settings, Some(&far)).unwrap();
    let free = solve_sqp(&problem, &initial, &settings).unwrap();
    assert_eq!(bounded, free);
    assert!(free.iterations > 0);
    assert!(far.longest_iteration() > Duration::ZERO);
    let gd_settings = GdSettings {
        iterations: 3,
        step_sizes: 32,
        ..GdSettings::default()
    };
    let bounded = solve_gd_until(&problem, &initial, &gd_settings, Some(&far)).unwrap();
    let free = solve_gd(&problem, &initial, &gd_settings).unwrap();
    assert_eq!(bounded, free);
}

#[test]
fn a_deadline_allows_an_iteration_only_while_the_longest_one_fits() {
    let d = Deadline::after(Duration::from_secs(3600));
    assert!(d.allows_iteration());
    d.record(Duration::from_secs(10));
    d.record(Duration::from_secs(1));
    assert_eq!(d.longest_iteration(), Duration::from_secs(10));
    assert!(d.allows_iteration());
    // a share for one of 4 solves: a quarter of the time left, the longest iteration carried
    let share = d.share(4);
    assert!(share.instant() <= Instant::now() + Duration::from_secs(900));
    assert!(share.instant() > Instant::now() + Duration::from_secs(800));
    assert_eq!(share.longest_iteration(), Duration::from_secs(10));
    d.record(Duration::from_secs(7200));
    assert!(!d.allows_iteration());
    assert!(!Deadline::at(Instant::now() - Duration::from_secs(1)).allows_iteration());
}

/// Standing still near the left border facing the right one (the recovery test's start): the
/// racer stalls and solves its recovery starts.
fn stalled_drive(settings: RacerSettings, cycles: usize) -> Vec<dynlab_control::racing::RaceStep> {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    let plant = Plant::new(&model, 5).unwrap();
    let mut racer = Racer::new(
        &model,
        &track,
        RacerSettings {
            initial: [0.0, -0.1],
            ..settings
        },
    )
    .unwrap();
    let mut s: State = [0.0, -0.4, -1.7, 0.0, 0.0, 0.0];
    let mut steps = Vec::new();
    for _ in 0..cycles {
        let step = racer.step(s).unwrap();
        s = plant.rollout(&s, &[step.input]).unwrap()[1];
        steps.push(step);
    }
    steps
}

#[test]
fn recovery_starts_on_two_threads_give_the_plans_of_one_thread() {
    let one = stalled_drive(
        RacerSettings {
            recovery_threads: 1,
            ..RacerSettings::default()
        },
        20,
    );
    let two = stalled_drive(RacerSettings::default(), 20);
    assert!(one.iter().any(|s| s.recovery_solves == 3));
    assert!(one.iter().any(|s| s.recovered));
    assert_eq!(one, two);
    assert!(one.iter().all(|s| !s.deadline));
}

#[test]
fn a_racer_out_of_budget_sends_a_plan_within_the_limits_and_says_so() {
    for optimizer in [Optimizer::Sqp, Optimizer::Gd] {
        let steps = stalled_drive(
            RacerSettings {
                optimizer,
                // a nanosecond: spent before the first iteration can start
                solve_budget: 1e-9,
                ..RacerSettings::default()
            },
            5,
        );
        let limits = InputLimits::default();
        // stalled three cycles in a row: the next solves its warm and recovery starts in full
        assert!(!steps[3].deadline, "{optimizer:?}: {:?}", steps[3]);
        assert_eq!(steps[3].recovery_solves, 3, "{optimizer:?}");
        for s in &steps[..3] {
            assert!(s.deadline, "{optimizer:?}: {s:?}");
            assert_eq!(s.status, SolveStatus::Deadline);
            // the recovery starts are skipped: no time for them
            assert_eq!(s.recovery_solves, 0);
            assert_eq!(limits.clamp(s.input), s.input);
            assert!(s.cost.is_finite());
            assert_eq!(s.predicted.len(), RacerSettings::default().horizon + 1);
        }
    }
}

#[test]
fn the_racing_qp_settings_give_the_steps_of_clarabels_defaults() {
    let model = node_car();
    let track = Track::oval(1.5, 0.6, 0.2, 200).unwrap();
    let reference: Vec<f64> = (1..=10).map(|k| 0.12 * k as f64).collect();
    let plant = Plant::new(&model, 5).unwrap();
    let problem = racing_problem(plant, &track, &reference);
    let initial: Vec<Input> = vec![[0.05, 0.5]; 10];
    let prev = SqpSettings {
        iterations: 3,
        ..SqpSettings::default()
    };
    let fast = prev.fast_qp();
    let a = solve_sqp(&problem, &initial, &prev).unwrap();
    let b = solve_sqp(&problem, &initial, &fast).unwrap();
    assert_eq!(a.iterations, b.iterations);
    assert!(
        (a.cost - b.cost).abs() <= 1e-4 * (1.0 + a.cost.abs()),
        "{} vs {}",
        a.cost,
        b.cost
    );
    for (x, y) in a.inputs.iter().zip(&b.inputs) {
        assert!((x[0] - y[0]).abs() < 1e-3 && (x[1] - y[1]).abs() < 1e-3);
    }
}

#[test]
fn sticky_elastic_qps_solve_an_infeasible_start_as_the_hard_first_path() {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.15, 120).unwrap();
    let plant = Plant::new(&model, 5).unwrap();
    // outside the track, nearly at rest: every QP of the solve needs the slacks
    let mut problem = racing_problem(plant, &track, &[]);
    problem.s0 = [0.0, -1.6, 0.0, 0.1, 0.0, 0.0];
    problem.objective.start_segment = None;
    let prev = SqpSettings {
        iterations: 5,
        ..SqpSettings::default()
    };
    let sticky = SqpSettings {
        sticky_elastic: true,
        ..prev
    };
    let a = solve_sqp(&problem, &[[0.0, 0.5]; 5], &prev).unwrap();
    let b = solve_sqp(&problem, &[[0.0, 0.5]; 5], &sticky).unwrap();
    assert!(a.elastic_qps > 0 && b.elastic_qps > 0);
    assert_eq!(a.elastic_qps, b.elastic_qps);
    assert!((a.cost - b.cost).abs() <= 1e-6 * (1.0 + a.cost.abs()));
}

#[test]
#[allow(clippy::needless_range_loop)] // index loops mirror the matrix products
fn jacobians_batched_over_the_horizon_equal_per_point_ones() {
    let model = node_car();
    let plant = Plant::new(&model, 5).unwrap();
    let s0: State = [0.1, -0.05, 0.2, 1.2, 0.05, 0.3];
    let inputs: Vec<Input> = (0..20)
        .map(|k| [0.2 * (k as f64 * 0.7).sin(), 0.5 + 0.2 * (k as f64).cos()])
        .collect();
    // the plant's linearisation: one batched Jacobian call over all 100 model steps
    let fine = plant.rollout_fine(&s0, &inputs).unwrap();
    let batched = plant.linearize_fine(&fine, &inputs).unwrap();
    // the same steps one point at a time, composed over each hold
    for k in 0..inputs.len() {
        let mut a = [[0.0; 6]; 6];
        for (i, row) in a.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        let mut b = [[0.0; 2]; 6];
        for j in 0..5 {
            let idx = k * 5 + j;
            let jac = model
                .jacobians_stagewise(&fine[idx * 6..idx * 6 + 6], &inputs[k])
                .unwrap();
            let mut na = [[0.0; 6]; 6];
            let mut nb = [[0.0; 2]; 6];
            for r in 0..6 {
                for c in 0..6 {
                    na[r][c] = (0..6).map(|m| jac.ds[r * 6 + m] * a[m][c]).sum();
                }
                for c in 0..2 {
                    nb[r][c] = jac.du[r * 2 + c]
                        + (0..6).map(|m| jac.ds[r * 6 + m] * b[m][c]).sum::<f64>();
                }
            }
            (a, b) = (na, nb);
        }
        for r in 0..6 {
            for c in 0..6 {
                let d = (batched.a[k][r * 6 + c] - a[r][c]).abs();
                assert!(d <= 1e-9 * (1.0 + a[r][c].abs()), "A_{k}[{r}][{c}]: {d}");
            }
            for c in 0..2 {
                let d = (batched.b[k][r * 2 + c] - b[r][c]).abs();
                assert!(d <= 1e-9 * (1.0 + b[r][c].abs()), "B_{k}[{r}][{c}]: {d}");
            }
        }
    }
}

#[test]
fn racer_defaults_are_the_racing_settings() {
    let d = RacerSettings::default();
    assert_eq!((d.horizon, d.hold), (20, 5));
    assert_eq!(d.optimizer, Optimizer::Sqp);
    assert_eq!(d.sqp.iterations, 3);
    assert_eq!((d.recovery_fraction, d.recovery_throttle), (0.5, 0.4));
    assert_eq!(d.recovery_threads, 2);
    // no wall-clock budget in the library: laps in simulation time stay reproducible
    assert!(d.solve_budget.is_infinite());
    // the racer's QPs are the fast ones; offline solves keep Clarabel's defaults
    let o = SqpSettings::default();
    assert_eq!(
        (
            o.sticky_elastic,
            o.qp_tolerance,
            o.qp_refinement,
            o.qp_equilibrate
        ),
        (false, 1e-8, true, true)
    );
    assert_eq!(d.sqp, SqpSettings { iterations: 3, ..o }.fast_qp());
    assert_eq!(
        (
            d.sqp.trust_steering,
            d.sqp.trust_throttle,
            d.sqp.elastic_penalty
        ),
        (o.trust_steering, o.trust_throttle, o.elastic_penalty)
    );
    // TOML keys
    let s: RacerSettings = toml::from_str("solve_budget = 0.02\nrecovery_threads = 1\n").unwrap();
    assert_eq!((s.solve_budget, s.recovery_threads), (0.02, 1));
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    for bad in [
        RacerSettings {
            solve_budget: 0.0,
            ..d
        },
        RacerSettings {
            solve_budget: f64::NAN,
            ..d
        },
        RacerSettings {
            recovery_threads: 0,
            ..d
        },
    ] {
        let e = Racer::new(&model, &track, bad).unwrap_err().to_string();
        assert!(
            e.contains("solve_budget") || e.contains("recovery_threads"),
            "{e}"
        );
    }
}
