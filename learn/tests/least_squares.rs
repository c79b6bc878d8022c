//! `bounded_least_squares`: an exponential fitted to exact data, a bound that excludes the truth
//! kept, nothing moved when nothing is free; by forward differences, the same fit with no point
//! evaluated twice in a row.

use std::cell::Cell;

use dynlab_learn::fit::{ForwardDifferences, bounded_least_squares, forward_jacobian};

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

#[test]
fn forward_differences_fit_as_a_fresh_evaluation_does_without_evaluating_a_point_twice() {
    // the exponential's residuals, counted; Jacobians by forward differences
    let calls = Cell::new(0usize);
    let resid = |th: &[f64]| {
        calls.set(calls.get() + 1);
        eval(th, false).0
    };
    let step = |th: &[f64], c: usize| 1e-7 * th[c].abs().max(1e-3);
    let (lower, upper, free) = ([0.0, -5.0], [10.0, 5.0], [true, true]);
    // every request evaluated afresh
    let mut fresh = |th: &[f64], with_j: bool| {
        let r = resid(th);
        match with_j {
            true => {
                let jac = forward_jacobian(th, &r, &|c| step(th, c), &resid);
                (r, jac)
            }
            false => (r, Vec::new()),
        }
    };
    let plain = bounded_least_squares(&[1.0, 0.0], &lower, &upper, &free, 50, &mut fresh);
    let plain_at_result = fresh(&plain.theta, true);
    let plain_calls = calls.replace(0);
    let mut fd = ForwardDifferences::new(&resid, &step);
    let res = bounded_least_squares(&[1.0, 0.0], &lower, &upper, &free, 50, &mut |th, j| {
        fd.eval(th, j)
    });
    let during_fit = calls.get();
    let at_result = fd.eval(&res.theta, true);
    // bit for bit the same fit, residuals and Jacobian at the result
    assert_eq!(res, plain);
    assert_eq!(at_result, plain_at_result);
    assert!((res.theta[1] + 0.7).abs() < 1e-6, "{:?}", res.theta);
    // the fit just evaluated its result with the Jacobian: asked again, nothing is evaluated
    assert_eq!(calls.get(), during_fit);
    // each accepted step's residuals served the Jacobian there (one evaluation fewer in every
    // iteration but the last, which accepted none), and the n + 1 at the result; the trials
    // that round back to the result at the end are not evaluated again either
    assert!(res.iterations >= 3, "{}", res.iterations);
    assert!(
        plain_calls >= during_fit + res.iterations + 2,
        "{plain_calls} {during_fit}"
    );
    // another point is evaluated (its residuals, then its Jacobian's two columns)
    let other = [res.theta[0] + 0.5, res.theta[1]];
    let (r, jac) = fd.eval(&other, true);
    assert_eq!((r.len(), jac.len(), calls.get()), (20, 40, during_fit + 3));
    assert_eq!(fd.eval(&other, false).0, r);
    assert_eq!(calls.get(), during_fit + 3);
}
