//! The part of the held-out error the poses' noise alone gives (`Diagnosis::noise_floor`),
//! against what it is: the same drive recorded without noise and with mocap-like noise
//! (1 mm, 0.004 rad), diagnosed with the same model. The noise's part is the difference of
//! their baseline errors; the estimate sees only the noisy data. And what the k-step error
//! compares (`DiagnoseConfig::score`): on noisy poses the car's velocities are estimates whose
//! own error is most of the state error; scored on the poses alone, the same diagnosis credits
//! the hidden effect with more of the error and the noise's part is smaller.

use dynlab_diagnose::diagnosis::simdata::{car_dataset, car_scenario, nominal_model};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, Diagnosis, Score, diagnose};
use dynlab_learn::World;
use dynlab_learn::dynamics::physics::Effect;
use dynlab_sim::car::SteeringOffset;

/// The nominal model diagnosed on 3 × 15 s of the steering offset's drive (seeded) with the
/// simulator's noise scaled by `noise` (1: 0.5 mm, 0.002 rad), the error scored as `score` says.
fn run(noise: f64, score: Score) -> Diagnosis {
    let scenario = car_scenario(Some(Effect::SteeringOffset), noise);
    let data = car_dataset(&scenario, 3, 15.0, 321, 2).unwrap();
    let model = nominal_model(World::Car, data.pose_dt_s).unwrap();
    let cfg = DiagnoseConfig {
        seed: 3,
        fit_windows: 250,
        score_windows: 1000,
        bootstrap: 500,
        effects: Some(vec![Effect::SteeringOffset]),
        score,
        ..DiagnoseConfig::default()
    };
    diagnose(&model, &data, &cfg).unwrap()
}

#[test]
fn the_noise_floor_is_what_the_noise_adds_to_the_error() {
    let (noisy, clean) = (run(2.0, Score::States), run(0.0, Score::States));
    let (t, c) = (noisy.table(), clean.table());
    let floor = noisy
        .noise_floor
        .as_ref()
        .expect("car data have a noise floor");
    // the poses' noise itself, from the poses
    for (got, truth) in floor.pose_std.iter().zip([0.001, 0.001, 0.004]) {
        assert!(
            (got / truth - 1.0).abs() < 0.2,
            "σ {got} against {truth}\n{t}"
        );
    }
    let quiet = clean
        .noise_floor
        .as_ref()
        .expect("car data have a noise floor");
    assert!(quiet.pose_std[0] < 2e-4 && quiet.pose_std[2] < 8e-4, "{c}");
    // the same drive and windows: the error the noise adds
    assert_eq!(noisy.windows, clean.windows);
    let added = noisy.baseline_error - clean.baseline_error;
    assert!(added > 0.0, "{t}\n{c}");
    let ratio = floor.error / added;
    eprintln!(
        "σ {:?} (clean {:?}); floor {:.5}, added by the noise {added:.5}, ratio {ratio:.3}",
        floor.pose_std, quiet.pose_std, floor.error
    );
    assert!(
        (0.7..1.4).contains(&ratio),
        "floor {} against {added} added by the noise\n{t}\n{c}",
        floor.error
    );
    assert!(t.contains("alone gives ≈"), "{t}");
    assert!(dynlab_diagnose::diagnosis::diagnosis_html(&noisy).contains("alone gives ≈"));
}

/// With four times the simulator's noise (2 mm, 0.008 rad).
#[test]
fn scored_on_the_poses_the_offset_takes_more_of_the_error_and_the_noise_less() {
    let (states, poses) = (run(4.0, Score::States), run(4.0, Score::Poses));
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
