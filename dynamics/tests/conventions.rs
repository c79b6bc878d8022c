//! Angle helpers, losses and metrics on hand-computed cases.
#![allow(clippy::needless_range_loop)] // index loops mirror the math

use dynlab_dynamics::conventions::*;
use std::f64::consts::PI;

#[test]
fn wrap_angle_maps_into_minus_pi_pi() {
    for (a, w) in [
        (0.0, 0.0),
        (PI, -PI),
        (-PI, -PI),
        (3.0 * PI / 2.0, -PI / 2.0),
        (7.0, 7.0 - 2.0 * PI),
        (-7.0, -7.0 + 2.0 * PI),
    ] {
        assert!(
            (wrap_angle(a) - w).abs() < 1e-12,
            "{a} → {} (want {w})",
            wrap_angle(a)
        );
    }
    let mut e = [0.0; 3];
    pose_error(&[1.0, 2.0, 3.1], &[0.5, 2.5, -3.1], &[2], &mut e);
    assert!((e[0] - 0.5).abs() < 1e-15 && (e[1] + 0.5).abs() < 1e-15);
    assert!((e[2] - (6.2 - 2.0 * PI)).abs() < 1e-12);
}

#[test]
fn yaw_from_quaternion_of_the_push_data() {
    // the first block pose of the Tu & Lin data: q = (0, 0, 0.309, 0.9511) is θ = 0.2π
    let y = yaw_from_quaternion(0.0, 0.0, (0.1 * PI).sin(), (0.1 * PI).cos());
    assert!((y - 0.2 * PI).abs() < 1e-12);
}

#[test]
fn relative_loss_matches_hand_computation() {
    // v = (1, −2, 0.5), v̂ = (0.5, −2.5, 0.5): L1 = 1 / (3.5 + ε)
    let v = [1.0, -2.0, 0.5];
    let p = [0.5, -2.5, 0.5];
    assert!((l_rel(&p, &v, 0.5, LossNorm::L1) - 1.0 / 4.0).abs() < 1e-15);
    let l2 = (0.5f64).sqrt() / ((5.25f64).sqrt() + 0.1);
    assert!((l_rel(&p, &v, 0.1, LossNorm::L2) - l2).abs() < 1e-15);
    let m = l_rel_mean(
        &[0.5, -2.5, 0.5, 1.0, -2.0, 0.5],
        &[1.0, -2.0, 0.5, 1.0, -2.0, 0.5],
        3,
        0.5,
        LossNorm::L1,
    );
    assert!((m - 0.125).abs() < 1e-15);
}

#[test]
fn tve_is_the_mean_l1_final_pose_error_with_wrapped_angle() {
    let finals = [
        ([1.0, 2.0, 3.1], [1.5, 2.0, -3.1]), // 0.5 + 0 + (2π − 6.2)
        ([0.0, 0.0, 0.0], [0.0, -1.0, 0.2]), // 1 + 0.2
    ];
    let want = (0.5 + (2.0 * PI - 6.2) + 1.2) / 2.0;
    assert!((tve(&finals) - want).abs() < 1e-12);
    assert_eq!(tve(&[]), 0.0);
}

#[test]
fn discounted_pose_loss_matches_hand_computation() {
    // two steps, weights (1, 1, 0.0408), γ = 0.9
    let pred = [0.1, 0.0, 0.0, 0.3, 0.1, 3.0];
    let meas = [0.0, 0.0, 0.0, 0.1, 0.1, -3.0];
    let w = [1.0, 1.0, 0.0408];
    let e_th = 6.0 - 2.0 * PI;
    let want = 0.01 + 0.9 * (0.04 + 0.0408 * e_th * e_th);
    assert!((discounted_pose_loss(&pred, &meas, &w, &[2], 0.9) - want).abs() < 1e-15);
}
