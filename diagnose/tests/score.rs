//! What the k-step error compares (`DiagnoseConfig::score`): on a drive recorded with noisy
//! poses the car's velocities are estimates whose own error is a large part of the state
//! error; scored on the poses alone, the same diagnosis credits the hidden effect with more of
//! the error and the noise's part is smaller.

use dynlab_diagnose::diagnosis::simdata::{car_dataset, car_scenario, nominal_model};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, Diagnosis, Score, diagnose};
use dynlab_learn::World;
use dynlab_learn::dynamics::physics::Effect;
use dynlab_sim::car::SteeringOffset;

/// The nominal model diagnosed on 3 × 15 s of the steering offset's drive (seeded) with four
/// times the simulator's pose noise (2 mm, 0.008 rad), the error scored as `score` says.
fn run(score: Score) -> Diagnosis {
    let scenario = car_scenario(Some(Effect::SteeringOffset), 4.0);
    let data = car_dataset(&scenario, 3, 15.0, 321, 2).unwrap();
    let model = nominal_model(World::Car, data.pose_dt_s).unwrap();
    let cfg = DiagnoseConfig {
        seed: 3,
        fit_windows: 250,
        score_windows: 1000,
        bootstrap: 500,
        effects: Some(vec![Effect::SteeringOffset, Effect::AeroDrag]),
        discover: false,
        drift: false,
        score,
        ..DiagnoseConfig::default()
    };
    diagnose(&model, &data, &cfg).unwrap()
}

#[test]
fn scored_on_the_poses_the_offset_takes_more_of_the_error_and_the_noise_less() {
    let (states, poses) = (run(Score::States), run(Score::Poses));
    let (ts, tp) = (states.table(), poses.table());
    assert_eq!(states.windows, poses.windows, "the same held-out windows");
    let truth = SteeringOffset::default().offset;
    for (d, t) in [(&states, &ts), (&poses, &tp)] {
        assert_eq!(d.effects, vec!["steering_offset".to_string()], "{t}");
        let joint = d.joint.as_ref().expect("a joint fit");
        let (delta0, std) = (
            joint.params["steering_offset.delta0"],
            joint.param_std["steering_offset.delta0"],
        );
        assert!(
            (delta0 - truth).abs() < 3.0 * std && std < 0.2 * truth,
            "δ₀ {delta0} ± {std} against {truth}\n{t}"
        );
    }
    let removed = |d: &Diagnosis| d.joint.as_ref().unwrap().reduction_vs_model;
    let share = |d: &Diagnosis| d.noise_floor.as_ref().unwrap().share;
    eprintln!(
        "removed: states {:.3}, poses {:.3}; noise share: states {:.3}, poses {:.3}",
        removed(&states),
        removed(&poses),
        share(&states),
        share(&poses)
    );
    assert!(removed(&poses) > removed(&states) + 0.05, "{ts}\n{tp}");
    assert!(share(&poses) < share(&states), "{ts}\n{tp}");
    assert!(
        tp.contains("scored on the poses") && !ts.contains("scored on"),
        "{tp}"
    );
}
