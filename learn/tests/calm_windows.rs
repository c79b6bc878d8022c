//! The physics fits leave out windows whose rollout is chaotic in the parameters.

use dynlab_learn::fit::{SENSITIVITY_LIMIT, calm_windows};

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
