//! The racing optimiser: exact gradients and Jacobians against finite differences, SQP against
//! gradient descent, an infeasible QP reported as a status.

use dynlab_control::racing::{
    GdSettings, Input, InputLimits, Manoeuvre, Objective, Optimizer, Plant, Problem, Racer,
    RacerSettings, Regulariser, SolveStatus, SpeedProfile, SqpSettings, State, Target, TrackTerms,
    gradient, solve_gd, solve_sqp,
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

fn residual_car() -> Model {
    let spec = MlpSpec::uniform(5, &[16, 16], 3, Activation::Gelu).unwrap();
    let mlp = Mlp::new(spec, Init::Auto, 3);
    let mut norm = Normalization::identity(5, 3);
    norm.output_std = vec![0.01; 3];
    Model::new(
        ModelKind::Residual,
        World::Car,
        0.01,
        None,
        Some(Network::new(mlp, norm)),
        None,
        Solver::rk4(),
    )
    .unwrap()
}

fn moving() -> State {
    [0.1, -0.05, 0.2, 1.2, 0.05, 0.3]
}

fn inputs(n: usize) -> Vec<Input> {
    (0..n)
        .map(|k| {
            [
                0.2 * (k as f64 * 0.7).sin(),
                0.4 + 0.2 * (k as f64 * 0.3).cos(),
            ]
        })
        .collect()
}

fn target_problem(plant: Plant<'_>) -> Problem<'_> {
    Problem {
        plant,
        s0: moving(),
        objective: Objective {
            targets: vec![
                Target {
                    step: 4,
                    state: [0.4, 0.1, 0.5, 1.0, 0.0, 0.0],
                    weight: [10.0, 10.0, 1.0, 0.1, 0.1, 0.01],
                },
                Target {
                    step: 8,
                    state: [0.8, 0.3, 1.0, 0.0, 0.0, 0.0],
                    weight: [10.0, 10.0, 1.0, 0.1, 0.1, 0.01],
                },
            ],
            track: None,
            limits: InputLimits::default(),
            reg: Regulariser::default(),
            u_prev: Some([0.0, 0.3]),
            start_segment: None,
        },
    }
}

/// Central differences of the plant's control-step map against the composed exact Jacobians.
fn check_linearization(model: &Model, tol: f64, h: f64) {
    let plant = Plant::new(model, 3).unwrap();
    let u = inputs(4);
    let s0 = moving();
    let lin = plant.linearize(&s0, &u).unwrap();
    let k = 2;
    let xk = lin.states[k];
    let f = |x: State, uk: Input| plant.rollout(&x, &[uk]).unwrap()[1];
    let mut worst: f64 = 0.0;
    for c in 0..6 {
        let (mut p, mut m) = (xk, xk);
        p[c] += h;
        m[c] -= h;
        let (fp, fm) = (f(p, u[k]), f(m, u[k]));
        for r in 0..6 {
            let fd = (fp[r] - fm[r]) / (2.0 * h);
            let ex = lin.a[k][r * 6 + c];
            worst = worst.max((fd - ex).abs() / (1.0 + ex.abs()));
        }
    }
    for c in 0..2 {
        let (mut p, mut m) = (u[k], u[k]);
        p[c] += h;
        m[c] -= h;
        let (fp, fm) = (f(xk, p), f(xk, m));
        for r in 0..6 {
            let fd = (fp[r] - fm[r]) / (2.0 * h);
            let ex = lin.b[k][r * 2 + c];
            worst = worst.max((fd - ex).abs() / (1.0 + ex.abs()));
        }
    }
    assert!(worst < tol, "worst relative Jacobian error {worst:e}");
}

#[test]
fn composed_step_jacobians_match_finite_differences() {
    check_linearization(&physics_car(), 1e-6, 1e-6);
    // the network runs in f32: looser step and tolerance
    check_linearization(&residual_car(), 2e-2, 1e-3);
}

fn check_gradient(model: &Model, tol: f64, h: f64) {
    let plant = Plant::new(model, 2).unwrap();
    let problem = target_problem(plant);
    let u = inputs(8);
    let (cost, grad, lin) = gradient(&problem, &u).unwrap();
    let direct = problem.objective.cost(&lin.states, &u);
    assert!((cost - direct).abs() <= 1e-9 * (1.0 + cost.abs()));
    let mut worst: f64 = 0.0;
    for k in 0..u.len() {
        for c in 0..2 {
            let eval = |d: f64| {
                let mut v = u.clone();
                v[k][c] += d;
                let s = plant.rollout(&problem.s0, &v).unwrap();
                problem.objective.cost(&s, &v)
            };
            let fd = (eval(h) - eval(-h)) / (2.0 * h);
            let scale = 1.0 + fd.abs().max(grad[k][c].abs());
            worst = worst.max((fd - grad[k][c]).abs() / scale);
        }
    }
    assert!(worst < tol, "worst relative gradient error {worst:e}");
}

#[test]
fn reverse_mode_gradient_matches_finite_differences() {
    check_gradient(&physics_car(), 1e-6, 1e-6);
    check_gradient(&residual_car(), 2e-2, 1e-3);
}

#[test]
fn racing_gradient_with_progress_and_excursion_matches_finite_differences() {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.15, 120).unwrap();
    let plant = Plant::new(&model, 5).unwrap();
    // start near the border so that excursion terms are active
    let problem = Problem {
        plant,
        s0: [0.0, -0.4, 0.3, 1.5, 0.0, 0.0],
        objective: Objective {
            targets: Vec::new(),
            track: Some(TrackTerms {
                track: &track,
                progress_weight: 10.0,
                margin: 0.03,
                margin_growth: 0.004,
                excursion_weight: 100.0,
                reference_weight: 1.0,
                reference_step: 0.1,
                reference_progress: &[],
                slip_weight: 2.0,
            }),
            limits: InputLimits::default(),
            reg: Regulariser::default(),
            u_prev: None,
            start_segment: None,
        },
    };
    let u = vec![[0.05, 0.6]; 6];
    let (_, grad, lin) = gradient(&problem, &u).unwrap();
    let excursions = lin.states[1..]
        .iter()
        .filter(|s| !track.contains([s[0], s[1]]))
        .count();
    assert!(excursions > 0, "the fixture should leave the track");
    let h = 1e-6;
    for k in 0..u.len() {
        for c in 0..2 {
            let eval = |d: f64| {
                let mut v = u.clone();
                v[k][c] += d;
                let s = plant.rollout(&problem.s0, &v).unwrap();
                problem.objective.cost(&s, &v)
            };
            let fd = (eval(h) - eval(-h)) / (2.0 * h);
            assert!(
                (fd - grad[k][c]).abs() <= 1e-4 * (1.0 + fd.abs()),
                "step {k} input {c}: fd {fd} exact {}",
                grad[k][c]
            );
        }
    }
}

#[test]
fn sqp_reaches_the_cost_of_gradient_descent_on_the_drifting_turn() {
    let model = physics_car();
    let plant = Plant::new(&model, 5).unwrap();
    let m = Manoeuvre::drifting_turn();
    let problem = m.problem(plant, [0.0; 6], InputLimits::default());
    let gd = solve_gd(
        &problem,
        &m.initial_inputs(),
        &GdSettings {
            iterations: 150,
            step_sizes: 64,
            ..GdSettings::default()
        },
    )
    .unwrap();
    let sqp = solve_sqp(&problem, &m.initial_inputs(), &SqpSettings::default()).unwrap();
    let initial = gd.history[0];
    assert!(gd.cost < initial, "gd {} initial {initial}", gd.cost);
    assert!(
        sqp.cost <= gd.cost * 1.001 + 1e-9,
        "sqp {} ({:?}, {} it) vs gd {} ({:?}, {} it)",
        sqp.cost,
        sqp.status,
        sqp.iterations,
        gd.cost,
        gd.status,
        gd.iterations
    );
    assert!(
        sqp.inputs
            .iter()
            .all(|u| u[0].abs() <= 0.35 + 1e-9 && (-0.1 - 1e-9..=1.0 + 1e-9).contains(&u[1]))
    );
}

#[test]
fn infeasible_track_qp_is_reported_as_a_status() {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.15, 120).unwrap();
    let plant = Plant::new(&model, 5).unwrap();
    // 1 m outside the track, nearly at rest: no input can reach the corridor in 0.25 s
    let problem = Problem {
        plant,
        s0: [0.0, -1.6, 0.0, 0.1, 0.0, 0.0],
        objective: Objective {
            targets: Vec::new(),
            track: Some(TrackTerms {
                track: &track,
                progress_weight: 1.0,
                margin: 0.0,
                margin_growth: 0.0,
                excursion_weight: 100.0,
                reference_weight: 1.0,
                reference_step: 0.1,
                reference_progress: &[],
                slip_weight: 0.0,
            }),
            limits: InputLimits::default(),
            reg: Regulariser::default(),
            u_prev: None,
            start_segment: None,
        },
    };
    let hard = SqpSettings {
        elastic_penalty: None,
        ..SqpSettings::default()
    };
    let sol = solve_sqp(&problem, &[[0.0, 0.5]; 5], &hard).unwrap();
    assert_eq!(sol.status, SolveStatus::Infeasible);
    assert_eq!(sol.iterations, 1);
    // with the elastic fallback the same problem solves, using slacks
    let sol = solve_sqp(&problem, &[[0.0, 0.5]; 5], &SqpSettings::default()).unwrap();
    assert_ne!(sol.status, SolveStatus::Infeasible);
    assert!(sol.elastic_qps > 0);
}

#[test]
fn racer_drives_forward_on_an_oval_without_leaving_it() {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    for optimizer in [Optimizer::Sqp, Optimizer::Gd] {
        let mut racer = Racer::new(
            &model,
            &track,
            RacerSettings {
                optimizer,
                gd: GdSettings {
                    iterations: 3,
                    step_sizes: 64,
                    ..GdSettings::default()
                },
                ..RacerSettings::default()
            },
        )
        .unwrap();
        let plant = Plant::new(&model, 5).unwrap();
        let mut s = {
            let p = track.start_pose();
            [p.x, p.y, p.theta, 0.0, 0.0, 0.0]
        };
        for _ in 0..20 {
            let step = racer.step(s).unwrap();
            s = plant.rollout(&s, &[step.input]).unwrap()[1];
            assert!(
                track.contains([s[0], s[1]]),
                "{optimizer:?} left the track at {s:?}"
            );
        }
        let progress = track.locate([s[0], s[1]]).arc;
        assert!(
            progress > 0.5,
            "{optimizer:?} progressed only {progress} m in 1 s"
        );
    }
}

/// Standing still near the left border, facing the right border and slightly backwards:
/// steering has no first-order effect at standstill, so the warm start alone stays put; the
/// recovery starts find the turn.
#[test]
fn a_stalled_racer_recovers_from_facing_the_border_with_the_recovery_starts() {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    let plant = Plant::new(&model, 5).unwrap();
    let drive = |recovery_fraction: f64| {
        let mut racer = Racer::new(
            &model,
            &track,
            RacerSettings {
                recovery_fraction,
                initial: [0.0, -0.1],
                ..RacerSettings::default()
            },
        )
        .unwrap();
        let mut s: State = [0.0, -0.4, -1.7, 0.0, 0.0, 0.0];
        let mut recovered = 0;
        for _ in 0..30 {
            let step = racer.step(s).unwrap();
            recovered += usize::from(step.recovered);
            s = plant.rollout(&s, &[step.input]).unwrap()[1];
        }
        (track.locate([s[0], s[1]]).arc, recovered, s)
    };
    let (stuck, none, s_stuck) = drive(0.0);
    let (moved, recovered, s_moved) = drive(0.5);
    println!("without {stuck} {s_stuck:?}; with {moved} ({recovered} recoveries) {s_moved:?}");
    assert_eq!(none, 0);
    assert!(recovered > 0);
    assert!(
        moved > stuck + 0.5,
        "without {stuck} m, with recovery {moved} m"
    );
}

#[test]
fn the_speed_profile_slows_for_bends_and_brakes_into_them_in_time() {
    let (straight, radius) = (3.0, 0.4);
    let track = Track::oval(straight, radius, 0.2, 300).unwrap();
    let (vmax, alat, brake) = (2.0, 1.0, 2.0);
    let p = SpeedProfile::new(&track, vmax, alat, brake, brake, 0.0).unwrap();
    // in the middle of a bend: √(a_lat · r)
    let mid_bend = straight + 0.5 * std::f64::consts::PI * radius;
    let bend_speed = (alat * radius).sqrt();
    assert!(
        (p.speed_at(mid_bend) - bend_speed).abs() < 0.02,
        "{}",
        p.speed_at(mid_bend)
    );
    assert!((p.min_speed() - bend_speed).abs() < 0.02);
    // the middle of a 3 m straight is fast: v² ≤ v_bend² + 2 a d with d = 1.5 m → capped at 2
    assert!((p.speed_at(0.5 * straight) - vmax).abs() < 1e-9);
    // braking: 0.2 m before the bend no faster than √(v_bend² + 2 a d) (d with two 3 cm
    // segments of slack: the discrete curvature reaches 1/r one point after the joint)
    let before = p.speed_at(straight - 0.2);
    assert!(
        before <= (bend_speed.powi(2) + 2.0 * brake * 0.26).sqrt(),
        "{before}"
    );
    assert!(before > bend_speed + 0.1, "{before}");
    // reference progress integrates the speed: on the straight at v_max
    let prog = p.progress(1.0, 0.05, 10);
    assert_eq!(prog.len(), 10);
    assert!(
        (prog[0] - 0.1).abs() < 1e-6 && (prog[9] - 1.0).abs() < 1e-6,
        "{prog:?}"
    );
    // from a standing start the reference speed ramps up at the acceleration (2 m/s²) until it
    // meets the profile: 0.5 · 2 · 0.5² = 0.25 m after 0.5 s
    let ramp = p.progress_from_speed(1.0, 0.0, 0.05, 10);
    assert!((ramp[9] - 0.25).abs() < 1e-6, "{ramp:?}");
    // a car already at the profile's speed gets the profile itself
    assert_eq!(p.progress_from_speed(1.0, vmax, 0.05, 10), prog);
    // unlimited accelerations: constant speed
    let flat = SpeedProfile::new(
        &track,
        vmax,
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        0.0,
    )
    .unwrap();
    assert_eq!(flat.min_speed(), vmax);
    assert!(SpeedProfile::new(&track, 0.0, 1.0, 1.0, 1.0, 0.0).is_err());
}

#[test]
fn the_plants_rollout_equals_the_models_rollout_bit_for_bit() {
    for kind in [
        ModelKind::Residual,
        ModelKind::NodeRk4,
        ModelKind::NodeEuler,
    ] {
        let spec = MlpSpec::uniform(5, &[16, 16], 3, Activation::Gelu).unwrap();
        let mut norm = Normalization::identity(5, 3);
        norm.output_std = vec![0.05; 3];
        let model = Model::new(
            kind,
            World::Car,
            0.01,
            None,
            Some(Network::new(Mlp::new(spec, Init::Auto, 5), norm)),
            None,
            if kind == ModelKind::NodeEuler {
                Solver::euler()
            } else {
                Solver::rk4()
            },
        )
        .unwrap();
        let plant = Plant::new(&model, 3).unwrap();
        let s0: State = [0.1, -0.2, 0.3, 1.2, 0.1, -0.4];
        let inputs: Vec<Input> = (0..7).map(|k| [0.05 * k as f64 - 0.1, 0.6]).collect();
        let fine = plant.rollout_fine(&s0, &inputs).unwrap();
        let actions: Vec<f64> = (0..21).flat_map(|j| inputs[j / 3]).collect();
        let mut out = vec![0.0; 21 * 6];
        model.rollout(&s0, &actions, &mut out).unwrap();
        assert_eq!(&fine[6..], &out[..], "{kind:?}");
        assert!(out.iter().all(|v| v.is_finite()));
        assert_eq!(plant.coarse(&fine), plant.rollout(&s0, &inputs).unwrap());
    }
}

fn node_car(kind: ModelKind, solver: Solver) -> Model {
    let spec = MlpSpec::uniform(5, &[16, 16], 3, Activation::Gelu).unwrap();
    let mut norm = Normalization::identity(5, 3);
    norm.input_mean = vec![0.5, 0.0, 0.1, 0.0, 0.3];
    norm.input_std = vec![1.5, 0.5, 2.0, 0.3, 0.6];
    norm.output_mean = vec![0.01, -0.02, 0.005];
    norm.output_std = vec![0.05, 0.02, 0.08];
    Model::new(
        kind,
        World::Car,
        0.01,
        None,
        Some(Network::new(Mlp::new(spec, Init::Auto, 9), norm)),
        None,
        solver,
    )
    .unwrap()
}

#[test]
fn stagewise_node_jacobians_equal_forward_mode_and_finite_differences() {
    let n = 5;
    let s: Vec<f64> = (0..n)
        .flat_map(|i| {
            let t = i as f64;
            [
                0.1 * t,
                -0.2,
                0.3 - 0.1 * t,
                1.2 + 0.2 * t,
                0.1,
                -0.4 + 0.15 * t,
            ]
        })
        .collect();
    let u: Vec<f64> = (0..n)
        .flat_map(|i| [0.05 * i as f64 - 0.1, 0.6 - 0.05 * i as f64])
        .collect();
    for (kind, solver) in [
        (ModelKind::NodeRk4, Solver::rk4()),
        (ModelKind::NodeRk4, Solver::Rk4 { substeps: 3 }),
        (ModelKind::NodeEuler, Solver::euler()),
        (ModelKind::NodeEuler, Solver::Euler { substeps: 2 }),
    ] {
        let model = node_car(kind, solver);
        let fast = model.jacobians_stagewise(&s, &u).unwrap();
        let reference = model.jacobians(&s, &u).unwrap();
        // the next states come from the same stage arithmetic as the model step
        let mut out = vec![0.0; n * 6];
        model.rollout(&s, &u, &mut out).unwrap();
        assert_eq!(fast.next, out, "{solver:?}");
        assert_eq!(fast.next, reference.next, "{solver:?}");
        // the Jacobians agree with forward mode to f32 rounding
        for (a, b) in fast
            .ds
            .iter()
            .zip(&reference.ds)
            .chain(fast.du.iter().zip(&reference.du))
        {
            assert!(
                (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
                "{solver:?}: {a} vs {b}"
            );
        }
        assert!(
            fast.ds
                .iter()
                .chain(&fast.du)
                .any(|v| *v != 0.0 && *v != 1.0)
        );
    }
    // and the plant's composed linearisation matches finite differences
    check_linearization(&node_car(ModelKind::NodeRk4, Solver::rk4()), 2e-2, 1e-3);
}

#[test]
fn bad_racer_settings_are_refused_with_the_setting_named() {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    let bad = [
        (
            "slip_weight",
            RacerSettings {
                slip_weight: -1.0,
                ..RacerSettings::default()
            },
        ),
        (
            "slip_weight",
            RacerSettings {
                slip_weight: f64::NAN,
                ..RacerSettings::default()
            },
        ),
        (
            "recovery_fraction",
            RacerSettings {
                recovery_fraction: 1.5,
                ..RacerSettings::default()
            },
        ),
        (
            "recovery_throttle",
            RacerSettings {
                recovery_throttle: f64::INFINITY,
                ..RacerSettings::default()
            },
        ),
    ];
    for (name, settings) in bad {
        let err = match Racer::new(&model, &track, settings) {
            Ok(_) => panic!("{name}: bad settings must be refused"),
            Err(e) => e.to_string(),
        };
        assert!(err.contains(name), "{name}: {err}");
    }
    assert!(Racer::new(&model, &track, RacerSettings::default()).is_ok());
}

/// The margin grows along the horizon: the excursion cost starts `k · margin_growth` further
/// in at step k, and a racer with a growing margin plans its far steps further from the
/// borders than with the constant margin.
#[test]
fn a_growing_margin_keeps_the_far_plan_further_from_the_borders() {
    let model = physics_car();
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    let terms = TrackTerms {
        track: &track,
        progress_weight: 0.0,
        margin: 0.03,
        margin_growth: 0.002,
        excursion_weight: 1000.0,
        reference_weight: 1.0,
        reference_step: 0.1,
        reference_progress: &[],
        slip_weight: 0.0,
    };
    assert!((terms.margin_at(0) - 0.03).abs() < 1e-15);
    assert!((terms.margin_at(20) - 0.07).abs() < 1e-12);
    // the far end of the plan, entering the first bend at speed, from the start of the oval
    let far_border = |growth: f64| {
        let mut racer = Racer::new(
            &model,
            &track,
            RacerSettings {
                margin_growth: growth,
                ..RacerSettings::default()
            },
        )
        .unwrap();
        let plant = Plant::new(&model, 5).unwrap();
        let p = track.start_pose();
        let mut s = [p.x, p.y, p.theta, 0.0, 0.0, 0.0];
        let mut worst = f64::INFINITY;
        for _ in 0..30 {
            let step = racer.step(s).unwrap();
            for x in &step.predicted[15..] {
                let l = track.locate([x[0], x[1]]);
                worst = worst.min(l.half_width - l.lateral.abs());
            }
            s = plant.rollout(&s, &[step.input]).unwrap()[1];
        }
        worst
    };
    let (flat, grown) = (far_border(0.0), far_border(0.06));
    // 0.06 m/s: steps 15–20 (0.75–1 s ahead) keep 0.075–0.09 m
    assert!(
        grown > flat + 0.01,
        "far plan border distance {grown} vs {flat}"
    );
    eprintln!("far plan border distance {grown} vs {flat}");
    assert!(
        Racer::new(
            &model,
            &track,
            RacerSettings {
                margin_growth: -0.1,
                ..RacerSettings::default()
            }
        )
        .unwrap_err()
        .to_string()
        .contains("margin_growth")
    );
}
