//! The physics fits leave out windows whose rollout is chaotic in the parameters, from the
//! forward-difference Jacobian of their residuals.

use dynlab_learn::fit::{SENSITIVITY_LIMIT, calm_windows, forward_jacobian};

#[test]
fn the_forward_jacobian_skips_fixed_parameters_and_trials_that_fail() {
    // r(θ) = (θ₀ + 2θ₁, θ₀², 3θ₂); θ₂ > 1 makes the model invalid (no residuals)
    let resid = |t: &[f64]| -> Vec<f64> {
        if t[2] > 1.0 {
            return Vec::new();
        }
        vec![t[0] + 2.0 * t[1], t[0] * t[0], 3.0 * t[2]]
    };
    let theta = [1.5, -0.5, 0.2];
    let r0 = resid(&theta);
    let h = 1e-6;
    let j = forward_jacobian(&theta, &r0, &|c| if c == 1 { 0.0 } else { h }, &resid);
    assert_eq!(j.len(), 9);
    // column 0 by forward differences, column 1 fixed (step 0), column 2 exact (linear)
    assert!((j[0] - 1.0).abs() < 1e-6 && (j[3] - 3.0).abs() < 1e-5 && j[6].abs() < 1e-12);
    assert!(
        j[1] == 0.0 && j[4] == 0.0 && j[7] == 0.0,
        "a fixed column was filled: {j:?}"
    );
    assert!((j[8] - 3.0).abs() < 1e-6, "{j:?}");
    // a step that leaves the valid region leaves its column 0
    let j = forward_jacobian(&theta, &r0, &|c| if c == 2 { 0.9 } else { h }, &resid);
    assert!(j[2] == 0.0 && j[5] == 0.0 && j[8] == 0.0, "{j:?}");
    assert!((j[1] - 2.0).abs() < 1e-6);
}

#[test]
fn a_window_far_more_sensitive_than_the_median_is_left_out() {
    let mut s = vec![1.0, 2.0, 0.5, 1.5, 1.0, 0.8, 1.2];
    s.push(1e6); // a rollout through a spin
    s.push(f64::NAN); // a rollout that failed
    s.push(0.9 * SENSITIVITY_LIMIT); // sensitive, but within the limit of the median (1.0)
    let keep = calm_windows(&s, SENSITIVITY_LIMIT);
    assert_eq!(keep.len(), s.len());
    assert!(!keep[7], "the spin window is kept");
    assert!(!keep[8], "the failed window is kept");
    assert!(keep[9], "a window within the limit is dropped");
    assert_eq!(keep.iter().filter(|&&k| k).count(), 8);
}

#[test]
fn every_window_stays_when_fewer_than_half_would() {
    // half of the data near a bifurcation: the median moves with it, nothing is singled out,
    // and with most windows non-finite the fit keeps them all rather than fitting a remnant
    let s = vec![f64::NAN, f64::NAN, f64::NAN, 1.0, 1.0];
    assert_eq!(calm_windows(&s, SENSITIVITY_LIMIT), vec![true; 5]);
    assert_eq!(calm_windows(&[], SENSITIVITY_LIMIT), Vec::<bool>::new());
    assert_eq!(
        calm_windows(&[f64::INFINITY, f64::NAN], SENSITIVITY_LIMIT),
        vec![true, true]
    );
}
