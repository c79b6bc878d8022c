//! Effects with state through the loop, on simulator data with a hidden motor lag: a physics
//! model trained with `motor_lag` beats the one without on held-out data, `compare` (with a
//! baseline) agrees with `evaluate`, and the live predictor of `model_server` keeps the same
//! effect states from the command stream as the offline pipeline rebuilds from the bag; a model
//! that has the lag is diagnosed with its lag state.

use dynlab_diagnose::compare::online::{OnlineConfig, OnlinePredictor, replay};
use dynlab_diagnose::compare::{CompareConfig, compare_with_baseline};
use dynlab_diagnose::diagnosis::simdata::car_scenario;
use dynlab_learn::dynamics::data::{CommandSample, PoseSample, SavGol};
use dynlab_learn::dynamics::physics::Effect;
use dynlab_learn::{Model, ModelKind, TimedDataset, TrainConfig, World, evaluate, train};
use dynlab_sim::CarExplorer;
use dynlab_sim::episode::{Record, concatenate, generate_car_episodes};

/// Poses and commands of simulated car episodes with the motor lag (τ = 0.2 s) on.
fn samples(seed: u64, episodes: u64) -> (Vec<PoseSample>, Vec<CommandSample>) {
    let scenario = car_scenario(Some(Effect::MotorLag), 1.0);
    let explorer = CarExplorer {
        duration: 12.0,
        ..CarExplorer::default()
    };
    let eps = generate_car_episodes(&scenario, &explorer, seed, episodes, 1).unwrap();
    let mut poses = Vec::new();
    let mut cmds = Vec::new();
    for s in concatenate(&eps, 0, 1_000_000_000) {
        let t_ns = s.t_ns as i64;
        match s.record {
            Record::CarPose(p) => poses.push(PoseSample {
                t_ns,
                x: p.x,
                y: p.y,
                yaw: p.theta,
            }),
            Record::CarCmd(u) => cmds.push(CommandSample {
                t_ns,
                u: vec![u.steering, u.throttle],
            }),
            _ => {}
        }
    }
    (poses, cmds)
}

fn timed(seed: u64, episodes: u64) -> TimedDataset {
    let (p, c) = samples(seed, episodes);
    TimedDataset::from_samples(World::Car, &p, &c, &SavGol::default()).unwrap()
}

fn physics(data: &TimedDataset, effects: &[&str]) -> Model {
    let cfg = TrainConfig {
        kind: ModelKind::Physics,
        steps: 10,
        effects: effects.iter().map(|s| s.to_string()).collect(),
        physics_iterations: 12,
        physics_max_windows: 300,
        ..Default::default()
    };
    train(&data.data, &cfg, &mut |_| {}).unwrap().model
}

#[test]
fn motor_lag_trained_on_lagged_simulator_data_beats_the_model_without_it_and_compares() {
    let fit = timed(7, 3);
    let held_out = timed(21, 2);
    let with = physics(&fit, &["motor_lag"]);
    let without = physics(&fit, &[]);
    let p = with.physics().unwrap();
    let tau = p.params()[p.param_index("motor_lag.tau").unwrap()];
    let k = 20;
    let ev_with = evaluate(&with, &held_out.data, k, 3.0).unwrap();
    let ev_without = evaluate(&without, &held_out.data, k, 3.0).unwrap();
    let (a, b) = (ev_with.k_step[3].rmse, ev_without.k_step[3].rmse);
    eprintln!("simulator τ 0.2, fitted {tau:.4}; held-out {k}-step vx RMSE {a:.3e} vs {b:.3e}");
    assert!((tau - 0.2).abs() < 0.05, "fitted τ = {tau}");
    // measured: 2.09e-2 vs 2.63e-2 (the explorer's smooth throttle excites the lag mildly)
    assert!(
        a < 0.9 * b,
        "{k}-step vx RMSE with motor_lag {a:.3e}, without {b:.3e}"
    );
    // no velocity is predicted worse (the relative loss, a mean of ratios over windows, is
    // decided by the few windows whose rollouts spin and is not compared)
    for (x, y) in ev_with.k_step.iter().zip(&ev_without.k_step).skip(3) {
        assert!(
            x.rmse <= 1.01 * y.rmse,
            "{k}-step {} RMSE with motor_lag {:.3e}, without {:.3e}",
            x.name,
            x.rmse,
            y.rmse
        );
    }
    // compare with the baseline: the same numbers as evaluate, and the error falls
    let cfg = CompareConfig {
        steps: k,
        ..Default::default()
    };
    let r = compare_with_baseline(
        ("with", &with),
        Some(("without", &without)),
        &held_out,
        &cfg,
    )
    .unwrap();
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * y.abs().max(1e-300);
    assert_eq!(r.model.eval.windows, ev_with.windows);
    for (x, y) in r.model.eval.k_step.iter().zip(&ev_with.k_step) {
        assert!(close(x.rmse, y.rmse), "{x:?} vs {y:?}");
    }
    let bl = r.baseline.as_ref().unwrap();
    for (x, y) in bl.eval.k_step.iter().zip(&ev_without.k_step) {
        assert!(close(x.rmse, y.rmse), "{x:?} vs {y:?}");
    }
    let (t1, t2) = (
        r.model.eval.tve.as_ref().unwrap(),
        ev_with.tve.as_ref().unwrap(),
    );
    assert!(close(t1.tve, t2.tve), "{t1:?} vs {t2:?}");
    assert!(r.model.eval.k_step[3].rmse < bl.eval.k_step[3].rmse);
}

#[test]
fn the_live_predictor_keeps_the_effect_states_of_the_offline_pipeline() {
    let (poses, cmds) = samples(5, 2);
    let data = TimedDataset::from_samples(World::Car, &poses, &cmds, &SavGol::default()).unwrap();
    let mut model = physics(&data, &[]);
    // a motor_lag model with the simulator's τ (the fit is tested above)
    let mut p = dynlab_learn::train::physics_model(World::Car, &["motor_lag".into()]).unwrap();
    p.set_params(
        &model
            .physics()
            .unwrap()
            .params()
            .iter()
            .copied()
            .chain([0.2])
            .collect::<Vec<_>>(),
    )
    .unwrap();
    model = Model::new(
        ModelKind::Physics,
        World::Car,
        model.dt(),
        None,
        None,
        Some(p),
        model.physics_solver(),
    )
    .unwrap();
    let mut online = OnlinePredictor::new(model.clone(), OnlineConfig::default()).unwrap();
    let outcomes = replay(&mut online, &poses, &cmds);
    // offline: the effect states at every state of every trajectory, by stamp
    let mut offline = std::collections::HashMap::new();
    for (t, stamps) in data.data.trajectories.iter().zip(&data.stamps.t_ns) {
        let e = model.extra_states_along(&t.u);
        for (i, ts) in stamps.iter().enumerate() {
            offline.insert(*ts, (e[i], t.u[i * 2..i * 2 + 2].to_vec()));
        }
    }
    let mut matched = 0;
    let mut worst: f64 = 0.0;
    let mut next = vec![0.0; 6];
    let mut e_next = vec![0.0; 1];
    for (t, o) in &outcomes {
        let Some(pr) = &o.prediction else { continue };
        assert_eq!(pr.extra.len(), 1);
        // the one-step prediction is the model's step from the state and effect states
        model
            .step_with_extra(&pr.state, &pr.extra, &pr.command, &mut next, &mut e_next)
            .unwrap();
        assert_eq!(next, pr.next);
        if let Some((e, u)) = offline.get(t) {
            assert_eq!(u, &pr.command, "the command held at {t}");
            worst = worst.max((e - pr.extra[0]).abs());
            matched += 1;
        }
    }
    eprintln!("{matched} predictions matched offline stamps; worst d_f difference {worst:e}");
    assert!(
        matched > 1000,
        "only {matched} predictions at offline stamps"
    );
    assert!(worst < 1e-9, "online d_f differs from offline by {worst:e}");
}

/// A physics model that already has `motor_lag` is diagnosed with its lag state carried
/// through every window: on lagged data its baseline error is far below that of the model
/// without the lag (the model's own step restarts the state at every step, which is no lag).
#[test]
fn a_model_with_motor_lag_is_diagnosed_with_its_lag_state() {
    use dynlab_diagnose::diagnosis::simdata::car_dataset;
    use dynlab_diagnose::diagnosis::{DiagnoseConfig, diagnose};
    use dynlab_learn::dynamics::physics::PhysicsModel;
    use dynlab_learn::train::default_physics_solver;
    let data = car_dataset(&car_scenario(Some(Effect::MotorLag), 1.0), 3, 15.0, 311, 2).unwrap();
    let model = |p: PhysicsModel| {
        Model::new(
            ModelKind::Physics,
            World::Car,
            data.pose_dt_s,
            None,
            None,
            Some(p),
            default_physics_solver(World::Car),
        )
        .unwrap()
    };
    let mut lagged = PhysicsModel::car(&[Effect::MotorLag]).unwrap();
    lagged.set_param("motor_lag.tau", 0.2).unwrap();
    let cfg = DiagnoseConfig {
        seed: 1,
        fit_windows: 300,
        score_windows: 1000,
        bootstrap: 200,
        effects: Some(vec![Effect::MotorLag]),
        discover: false,
        ..DiagnoseConfig::default()
    };
    let without = diagnose(&model(PhysicsModel::car(&[]).unwrap()), &data, &cfg).unwrap();
    let with = diagnose(&model(lagged), &data, &cfg).unwrap();
    assert_eq!(
        without.verdict.as_deref(),
        Some("motor_lag"),
        "{}",
        without.table()
    );
    assert!(
        with.baseline_error < 0.6 * without.baseline_error,
        "baseline with the lag {:.4}, without {:.4}\n{}",
        with.baseline_error,
        without.baseline_error,
        with.table()
    );
    // what the lag removes in the first diagnosis is what the lagged model starts without
    let after = without.joint.as_ref().unwrap().error_after;
    assert!(
        (with.baseline_error - after).abs() <= 0.25 * after,
        "lagged model {:.4}, the diagnosis's fitted lag {:.4}",
        with.baseline_error,
        after
    );
    assert!(with.effects.is_empty(), "{}", with.table());
}
