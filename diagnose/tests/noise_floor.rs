//! The part of the held-out error the poses' noise alone gives (`Diagnosis::noise_floor`),
//! against what it is: the same drive recorded without noise and with mocap-like noise
//! (1 mm, 0.004 rad), diagnosed with the same model. The noise's part is the difference of
//! their baseline errors; the estimate sees only the noisy data.

use dynlab_diagnose::diagnosis::simdata::{car_dataset, car_scenario, nominal_model};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, Diagnosis, diagnose};
use dynlab_learn::World;
use dynlab_learn::dynamics::physics::Effect;

/// The nominal model diagnosed on 3 × 15 s of the steering offset's drive (seeded) with the
/// simulator's noise scaled by `noise` (1: 0.5 mm, 0.002 rad).
fn run(noise: f64) -> Diagnosis {
    let scenario = car_scenario(Some(Effect::SteeringOffset), noise);
    let data = car_dataset(&scenario, 3, 15.0, 321, 2).unwrap();
    let model = nominal_model(World::Car, data.pose_dt_s).unwrap();
    let cfg = DiagnoseConfig {
        seed: 3,
        fit_windows: 250,
        score_windows: 1000,
        bootstrap: 500,
        effects: Some(vec![Effect::SteeringOffset]),
        ..DiagnoseConfig::default()
    };
    diagnose(&model, &data, &cfg).unwrap()
}

#[test]
fn the_noise_floor_is_what_the_noise_adds_to_the_error() {
    let (noisy, clean) = (run(2.0), run(0.0));
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
