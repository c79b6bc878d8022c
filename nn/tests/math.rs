//! Accuracy of the vectorisable tanh, exp and GELU against f64 references on dense grids.

mod common;

use common::{gelu_derivative64, gelu64};
use dynlab_nn::math;

/// Dense grid over [−lo, hi] plus large and special magnitudes.
fn grid(lo: f32, hi: f32, n: usize) -> Vec<f32> {
    let mut xs: Vec<f32> = (0..=n)
        .map(|i| lo + (hi - lo) * i as f32 / n as f32)
        .collect();
    xs.extend([
        0.0,
        -0.0,
        1e-30,
        -1e-30,
        1e-8,
        8.99,
        9.0,
        9.01,
        20.0,
        -20.0,
        88.0,
        1e6,
        -1e6,
        f32::MAX,
        f32::MIN,
    ]);
    xs
}

#[test]
fn tanh_max_abs_error_below_4e7_everywhere() {
    let mut worst = (0.0f64, 0.0f32);
    for x in grid(-30.0, 30.0, 2_000_000) {
        for y in [
            math::tanh::<true>(x),
            math::tanh::<false>(x),
            math::tanh_f32(x),
        ] {
            let err = (f64::from(y) - f64::from(x).tanh()).abs();
            if err > worst.0 {
                worst = (err, x);
            }
            assert!(y.abs() <= 1.0, "|tanh({x})| = {y} > 1");
        }
    }
    assert!(
        worst.0 < 4e-7,
        "max abs error {:.3e} at x = {}",
        worst.0,
        worst.1
    );
}

#[test]
fn tanh_is_odd_and_relatively_accurate_near_zero() {
    for x in grid(-1.0, 1.0, 200_000) {
        let y = math::tanh::<true>(x);
        assert_eq!(y, -math::tanh::<true>(-x), "not odd at {x}");
        let t = f64::from(x).tanh();
        if t != 0.0 {
            let rel = (f64::from(y) - t).abs() / t.abs();
            assert!(rel < 1e-6, "relative error {rel:.3e} at {x}");
        }
    }
}

#[test]
fn tanh_saturates_within_one_step_of_one_and_propagates_nan() {
    let below_one = 1.0 - f32::EPSILON / 2.0;
    assert!(math::tanh::<true>(50.0) >= below_one);
    assert!(math::tanh::<false>(-50.0) <= -below_one);
    assert!(math::tanh::<true>(f32::INFINITY) >= below_one);
    assert!(math::tanh::<true>(f32::NAN).is_nan());
}

#[test]
fn tanh_derivative_from_output_matches_exact_derivative() {
    // The backward pass uses 1 − y² with y the approximate tanh.
    for x in grid(-10.0, 10.0, 100_000) {
        let y = math::tanh_f32(x);
        let d = 1.0 - y * y;
        let exact = 1.0 / f64::from(x).cosh().powi(2);
        assert!(
            (f64::from(d) - exact).abs() < 1.5e-6,
            "at {x}: {d} vs {exact}"
        );
    }
}

#[test]
fn exp_relative_error_below_3e7() {
    for x in grid(-87.0, 88.0, 1_000_000) {
        if !(-87.0..=88.0).contains(&x) {
            continue;
        }
        for y in [math::exp::<true>(x), math::exp::<false>(x)] {
            let e = f64::from(x).exp();
            let rel = (f64::from(y) - e).abs() / e;
            assert!(rel < 3e-7, "exp({x}) = {y}, rel err {rel:.3e}");
        }
    }
    assert!(math::exp_f32(-1000.0) < 2e-38);
    assert!(math::exp_f32(1000.0).is_finite());
}

#[test]
fn gelu_matches_exact_erf_form() {
    for x in grid(-12.0, 12.0, 400_000) {
        let r = gelu64(f64::from(x));
        for y in [
            math::gelu::<true>(x),
            math::gelu::<false>(x),
            math::gelu_f32(x),
        ] {
            let err = (f64::from(y) - r).abs();
            assert!(
                err <= 4e-7 * r.abs().max(1.0),
                "gelu({x}) = {y}, reference {r}, err {err:.3e}"
            );
        }
    }
    // Large |x|: GELU(x) → x for x → ∞, → 0 for x → −∞, no NaN.
    assert_eq!(math::gelu_f32(1e6), 1e6);
    assert_eq!(math::gelu_f32(-1e6), 0.0);
    assert_eq!(math::gelu_f32(-30.0), 0.0);
}

#[test]
fn gelu_is_not_the_tanh_approximation() {
    // At x = −3 the tanh-form GELU differs from the erf form by ≈ 3.7e-4.
    let x = -3.0f64;
    let tanh_form =
        0.5 * x * (1.0 + ((2.0 / std::f64::consts::PI).sqrt() * (x + 0.044715 * x.powi(3))).tanh());
    let ours = f64::from(math::gelu_f32(-3.0));
    assert!((ours - gelu64(x)).abs() < 1e-7);
    assert!((ours - tanh_form).abs() > 1e-4);
}

#[test]
fn gelu_derivative_matches_reference() {
    for x in grid(-12.0, 12.0, 400_000) {
        let r = gelu_derivative64(f64::from(x));
        for d in [
            math::gelu_derivative::<true>(x),
            math::gelu_derivative::<false>(x),
        ] {
            let err = (f64::from(d) - r).abs();
            assert!(err < 6e-7, "gelu'({x}) = {d}, reference {r}, err {err:.3e}");
        }
    }
}
