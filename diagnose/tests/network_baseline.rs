//! Diagnosis with a network baseline (`dynlab diagnose --model <residual or node-rk4 model>`):
//! the effect is added on top of the network as its contribution relative to the nominal
//! physics. Small networks trained briefly on simulator data, both worlds.

use std::time::Instant;

use dynlab_diagnose::diagnosis::simdata::{car_dataset, car_scenario, push_dataset, push_scenario};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, diagnose};
use dynlab_learn::dynamics::physics::Effect;
use dynlab_learn::train::{TrainConfig, train};
use dynlab_learn::{Dataset, Model, ModelKind};

fn net(data: &Dataset, kind: ModelKind, steps: usize) -> Model {
    let cfg = TrainConfig {
        kind,
        steps,
        epochs: 3,
        hidden: Some(vec![16, 16]),
        max_samples: Some(4000),
        seed: 1,
        ..TrainConfig::default()
    };
    train(data, &cfg, &mut |_| {}).unwrap().model
}

#[test]
fn a_network_model_is_diagnosed_on_pushing_data() {
    let data = push_dataset(
        &push_scenario(Some(Effect::PusherFriction), 1.0),
        12,
        10,
        71,
        2,
    )
    .unwrap();
    for kind in [ModelKind::Residual, ModelKind::NodeRk4] {
        let model = net(&data, kind, 1);
        let t0 = Instant::now();
        let d = diagnose(&model, &data, &DiagnoseConfig::default()).unwrap();
        eprintln!(
            "{kind:?}: {:.1} s\n{}",
            t0.elapsed().as_secs_f64(),
            d.table()
        );
        assert_eq!(d.model_kind, kind.name());
        // the nominal parameters of a network are not refitted; every candidate is scored
        assert!(d.nominal_refit.is_empty());
        // every pushing effect of the library
        let push_effects = dynlab_learn::dynamics::physics::PhysicsModel::available_effects(
            dynlab_learn::dynamics::physics::Robot::Pushing,
        );
        assert_eq!(d.candidates.len(), push_effects.len(), "{}", d.table());
        assert!(push_effects.contains(&"flat_pusher"));
        assert!(d.baseline_error.is_finite() && d.baseline_error > 0.0);
        assert!(d.candidates.iter().all(|c| c.error_after.is_finite()));
    }
}

#[test]
fn a_network_model_is_diagnosed_on_car_data() {
    let data = car_dataset(
        &car_scenario(Some(Effect::SteeringOffset), 1.0),
        2,
        6.0,
        72,
        2,
    )
    .unwrap();
    let model = net(&data, ModelKind::Residual, 2);
    let cfg = DiagnoseConfig {
        steps: Some(10),
        fit_windows: 200,
        score_windows: 600,
        ..DiagnoseConfig::default()
    };
    let t0 = Instant::now();
    let d = diagnose(&model, &data, &cfg).unwrap();
    eprintln!("{:.1} s\n{}", t0.elapsed().as_secs_f64(), d.table());
    assert_eq!(d.model_kind, "residual");
    // every car effect of the library
    let car_effects = dynlab_learn::dynamics::physics::PhysicsModel::available_effects(
        dynlab_learn::dynamics::physics::Robot::Car,
    );
    assert_eq!(d.candidates.len(), car_effects.len(), "{}", d.table());
    assert!(car_effects.contains(&"command_delay"));
    assert!(d.candidates.iter().all(|c| c.error_after.is_finite()));
}

#[test]
fn car_data_at_another_rate_than_the_model_get_a_clear_error() {
    use dynlab_diagnose::diagnosis::DiagnosisError;
    use dynlab_learn::World;
    use dynlab_learn::dynamics::physics::PhysicsModel;
    use dynlab_learn::train::default_physics_solver;
    let data = car_dataset(&car_scenario(None, 1.0), 1, 3.0, 73, 2).unwrap();
    // a model stepping twice the data's pose interval
    let model = Model::new(
        ModelKind::Physics,
        World::Car,
        2.0 * data.pose_dt_s,
        None,
        None,
        Some(PhysicsModel::car(&[]).unwrap()),
        default_physics_solver(World::Car),
    )
    .unwrap();
    let err = diagnose(&model, &data, &DiagnoseConfig::default()).unwrap_err();
    assert!(matches!(err, DiagnosisError::StepMismatch { .. }), "{err}");
    assert!(err.to_string().contains("resampled"), "{err}");
}
