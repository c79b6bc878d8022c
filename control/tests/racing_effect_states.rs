//! The racing optimiser over car models with effect states (`motor_lag`'s filtered throttle,
//! `steering_lag`'s wheel angle): the plant carries them, its linearisation over the augmented
//! state and the reverse-mode gradient match finite differences, and the racer keeps them from
//! its own command history.

use dynlab_control::racing::{
    CarDynamics, GdSettings, Input, InputLimits, MAX_EXTRA, Objective, Optimizer, Plant, Problem,
    Racer, RacerSettings, Regulariser, SqpSettings, State, Target, gradient, solve_sqp,
};
use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::dynamics::physics::{CustomEffect, Effect, PhysicsModel};
use dynlab_learn::{Model, ModelKind, World};
use dynlab_sim::Track;

fn lagged_car(effects: &[Effect]) -> Model {
    car_model(lagged_physics(effects))
}

fn lagged_physics(effects: &[Effect]) -> PhysicsModel {
    let mut p = PhysicsModel::car(effects).unwrap();
    if effects.contains(&Effect::MotorLag) {
        p.set_param("motor_lag.tau", 0.1).unwrap();
    }
    if effects.contains(&Effect::SteeringLag) {
        p.set_param("steering_lag.tau", 0.06).unwrap();
        p.set_param("steering_lag.rate", 3.0).unwrap();
    }
    if effects.contains(&Effect::CommandDelay) {
        p.set_param("command_delay.delay", 0.05).unwrap();
    }
    p
}

fn car_model(p: PhysicsModel) -> Model {
    Model::new(
        ModelKind::Physics,
        World::Car,
        0.01,
        None,
        None,
        Some(p),
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

#[test]
fn the_augmented_linearization_matches_finite_differences() {
    // a steering delay as a custom term on the lagged steering rate: six lagged commands more
    let delay_term = || {
        CustomEffect::from_toml(
            "name = \"delay\"\n[[term]]\nstate = \"delta\"\nfeature = \"delta_rate(0.1)\"\ncoefficient = -0.06\n",
        )
        .unwrap()
    };
    let mut delayed = lagged_physics(&[Effect::MotorLag]);
    delayed.add_custom(delay_term()).unwrap();
    // every stateful effect at once: the plant's most effect states
    let mut every = lagged_physics(&[Effect::MotorLag, Effect::SteeringLag, Effect::CommandDelay]);
    every.add_custom(delay_term()).unwrap();
    assert_eq!(every.dim_effect_states(), MAX_EXTRA);
    for (effects, model) in [
        ("motor_lag", lagged_car(&[Effect::MotorLag])),
        (
            "motor_lag, steering_lag",
            lagged_car(&[Effect::MotorLag, Effect::SteeringLag]),
        ),
        ("motor_lag, steering delay", car_model(delayed)),
        (
            "motor_lag, steering_lag, command_delay, steering delay",
            car_model(every),
        ),
    ] {
        let ne = model.dim_extra();
        let e0 = vec![0.2; ne];
        let plant = Plant::new(&model, 3).unwrap().with_extra(&e0).unwrap();
        assert_eq!(plant.nx(), 6 + ne);
        let u = inputs(4);
        let lin = plant.linearize(&moving(), &u).unwrap();
        let nx = lin.nx;
        // the control-step map from an augmented state x = [s, e]
        let fine = plant.rollout_fine(&moving(), &u).unwrap();
        let k = 2;
        let xk = fine[k * 3 * nx..(k * 3 + 1) * nx].to_vec();
        let f = |x: &[f64], uk: Input| -> Vec<f64> {
            let mut s = [0.0; 6];
            s.copy_from_slice(&x[..6]);
            let p = plant.with_extra(&x[6..]).unwrap();
            p.rollout_fine(&s, &[uk]).unwrap()[3 * nx..4 * nx].to_vec()
        };
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for c in 0..nx + 2 {
            let (mut xp, mut xm, mut up, mut um) = (xk.clone(), xk.clone(), u[k], u[k]);
            if c < nx {
                xp[c] += h;
                xm[c] -= h;
            } else {
                up[c - nx] += h;
                um[c - nx] -= h;
            }
            let (fp, fm) = (f(&xp, up), f(&xm, um));
            for r in 0..nx {
                let fd = (fp[r] - fm[r]) / (2.0 * h);
                let ex = if c < nx {
                    lin.a[k][r * nx + c]
                } else {
                    lin.b[k][r * 2 + c - nx]
                };
                worst = worst.max((fd - ex).abs() / (1.0 + ex.abs()));
            }
        }
        assert!(
            worst < 1e-6,
            "{effects}: worst relative Jacobian error {worst:e}"
        );
        // the throttle acts on the filtered throttle, not directly on the car (behind a delay
        // the Padé filter's first response to a step is a dip against it: no sign to check)
        let ie = 6; // first effect state: d_f
        assert!(
            effects.contains("command_delay") || lin.b[k][ie * 2 + 1] > 0.0,
            "{effects}: ∂d_f/∂d = {}",
            lin.b[k][ie * 2 + 1]
        );
    }
}

#[test]
fn the_gradient_through_effect_states_matches_finite_differences() {
    let model = lagged_car(&[Effect::MotorLag, Effect::SteeringLag]);
    let plant = Plant::new(&model, 2)
        .unwrap()
        .with_extra(&[0.35, -0.05])
        .unwrap();
    let problem = target_problem(plant);
    let u = inputs(8);
    let (cost, grad, lin) = gradient(&problem, &u).unwrap();
    let direct = problem.objective.cost(&lin.states, &u);
    assert!((cost - direct).abs() <= 1e-9 * (1.0 + cost.abs()));
    let h = 1e-6;
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
    assert!(worst < 1e-6, "worst relative gradient error {worst:e}");
    // the effect states matter: the same problem from other effect states costs differently
    let other = target_problem(plant.with_extra(&[0.0, 0.1]).unwrap());
    let s_other = other.plant.rollout(&other.s0, &u).unwrap();
    assert!((other.objective.cost(&s_other, &u) - cost).abs() > 1e-6 * cost.abs());
    // and SQP, which uses the same linearisation, lowers the cost
    let sol = solve_sqp(&problem, &u, &SqpSettings::default()).unwrap();
    assert!(sol.cost < cost, "SQP {} vs start {cost}", sol.cost);
}

#[test]
fn a_racer_with_a_motor_lag_model_keeps_the_effect_states_of_its_own_commands() {
    let model = lagged_car(&[Effect::MotorLag]);
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    for optimizer in [Optimizer::Sqp, Optimizer::Gd] {
        let settings = RacerSettings {
            optimizer,
            gd: GdSettings {
                iterations: 3,
                step_sizes: 64,
                ..GdSettings::default()
            },
            ..RacerSettings::default()
        };
        let hold = settings.hold;
        let mut racer = Racer::new(&model, &track, settings).unwrap();
        let mut s = {
            let p = track.start_pose();
            [p.x, p.y, p.theta, 0.0, 0.0, 0.0]
        };
        // before any command: settled at the warm start's first input
        let first = racer.extra_states();
        assert_eq!(first.len(), 1);
        // the true car: the same model, its effect states carried from the applied inputs
        let mut e_true = first.clone();
        for _ in 0..15 {
            let e_before = racer.extra_states();
            // equal up to the model step's RK4 error (advance_extra takes finer substeps)
            assert!((e_before[0] - e_true[0]).abs() < 1e-6, "{optimizer:?}");
            let step = racer.step(s).unwrap();
            assert!(step.cost.is_finite(), "{optimizer:?}: {:?}", step.status);
            let plant = Plant::new(&model, hold)
                .unwrap()
                .with_extra(&e_true)
                .unwrap();
            let fine = plant.rollout_fine(&s, &[step.input]).unwrap();
            let last = &fine[hold * 7..(hold + 1) * 7];
            s.copy_from_slice(&last[..6]);
            e_true = vec![last[6]];
            // the racer's own record: its input advanced over the control period
            let mut e = e_before.clone();
            for _ in 0..hold {
                CarDynamics::advance_extra(&model, &mut e, &step.input);
            }
            assert!((racer.extra_states()[0] - e[0]).abs() < 1e-12);
            assert!((e[0] - e_true[0]).abs() < 1e-6, "{} vs {}", e[0], e_true[0]);
            assert!(track.contains([s[0], s[1]]), "{optimizer:?} left the track");
        }
        let progress = track.locate([s[0], s[1]]).arc;
        assert!(progress > 0.2, "{optimizer:?} progressed only {progress} m");
        racer.reset();
        assert_eq!(racer.extra_states(), first);
    }
    // wrong effect states are refused with the setting named
    let plant = Plant::new(&model, 1).unwrap();
    let e = plant.with_extra(&[0.1, 0.2]).unwrap_err();
    assert!(e.to_string().contains("effect states"), "{e}");
}
