//! `bounded_least_squares`: an exponential fitted to exact data, a bound that excludes the truth
//! kept, nothing moved when nothing is free.

use dynlab_learn::fit::bounded_least_squares;

/// `y = a·exp(b·x)` at 20 points: the residuals and, when asked, the Jacobian (rows × 2).
fn eval(th: &[f64], with_j: bool) -> (Vec<f64>, Vec<f64>) {
    let xs = (0..20).map(|i| i as f64 * 0.1);
    let (a, b) = (th[0], th[1]);
    let mut r = Vec::new();
    let mut j = Vec::new();
    for x in xs {
        let y = 2.0 * (-0.7 * x).exp();
        let e = (b * x).exp();
        r.push(a * e - y);
        if with_j {
            j.extend([e, a * x * e]);
        }
    }
    (r, j)
}

/// `bounded_least_squares` of [`eval`] from (1, 0) within a ≥ 0 and b ≥ `b_min`.
fn fit(b_min: f64, free: [bool; 2]) -> dynlab_learn::fit::LsqResult {
    bounded_least_squares(
        &[1.0, 0.0],
        &[0.0, b_min],
        &[10.0, 5.0],
        &free,
        50,
        &mut eval,
    )
}

#[test]
fn an_exponential_is_fitted_within_its_bounds() {
    let res = fit(-5.0, [true, true]);
    assert!((res.theta[0] - 2.0).abs() < 1e-6, "{:?}", res.theta);
    assert!((res.theta[1] + 0.7).abs() < 1e-6, "{:?}", res.theta);
    assert!(
        res.cost < 1e-20 && res.cost < res.initial_cost,
        "{}",
        res.cost
    );
    // a bound that excludes the truth holds
    let held = fit(-0.5, [true, true]);
    let bh = held.theta[1];
    assert!((-0.5..-0.5 + 1e-6).contains(&bh), "{bh}");
    // nothing free: nothing fitted
    let fixed = fit(-5.0, [false, false]);
    assert_eq!(fixed.theta, vec![1.0, 0.0]);
    assert_eq!((fixed.iterations, fixed.cost), (0, fixed.initial_cost));
}
