//! Solvers against exact solutions, derivatives against finite differences, failure statuses.
#![allow(clippy::needless_range_loop)] // index loops mirror the math

mod common;
use common::{BlowUp, Linear, Pendulum, max_rel_diff};
use dynlab_dynamics::ode::*;

/// Harmonic oscillator `ẍ = −ω² x + u`: exact state at `t` from `(x0, v0)` with constant `u`.
fn oscillator_exact(w: f64, x0: f64, v0: f64, u: f64, t: f64) -> [f64; 2] {
    let xe = u / (w * w);
    let (s, c) = (w * t).sin_cos();
    let x = xe + (x0 - xe) * c + v0 / w * s;
    let v = -(x0 - xe) * w * s + v0 * c;
    [x, v]
}

fn oscillator(w: f64) -> Linear<f64> {
    Linear::new(2, 1, &[0.0, 1.0, -w * w, 0.0], &[0.0, 1.0])
}

fn error_with(solver: Solver, dt: f64) -> f64 {
    let f = oscillator(2.0);
    let mut out = [0.0; 2];
    let rep = integrate(&f, &solver, 1, &[1.0, 0.5], &[0.3], dt, &mut out);
    assert!(rep.is_success());
    let ex = oscillator_exact(2.0, 1.0, 0.5, 0.3, dt);
    ((out[0] - ex[0]).powi(2) + (out[1] - ex[1]).powi(2)).sqrt()
}

#[test]
fn scalar_linear_ode_with_input_matches_exact_solution() {
    // ṡ = λ s + u: s(t) = e^{λt} s0 + (e^{λt} − 1)/λ·u
    let (lam, s0, u, t) = (-0.7, 2.0, 0.4, 1.3);
    let f = Linear::<f64>::new(1, 1, &[lam], &[1.0]);
    let exact = (lam * t).exp() * s0 + ((lam * t).exp() - 1.0) / lam * u;
    for (solver, tol) in [
        (Solver::Euler { substeps: 2000 }, 1e-3),
        (Solver::Rk4 { substeps: 20 }, 1e-7),
        (Solver::dopri5(1e-10, 1e-12), 1e-9),
    ] {
        let mut out = [0.0];
        let rep = integrate(&f, &solver, 1, &[s0], &[u], t, &mut out);
        assert!(rep.is_success());
        assert!(
            (out[0] - exact).abs() < tol,
            "{}: {} vs {exact}",
            solver.name(),
            out[0]
        );
    }
}

#[test]
fn euler_converges_with_order_one_and_rk4_with_order_four() {
    let order = |mk: fn(u32) -> Solver, n: u32| {
        let e1 = error_with(mk(n), 2.0);
        let e2 = error_with(mk(2 * n), 2.0);
        (e1 / e2).log2()
    };
    let p_euler = order(|n| Solver::Euler { substeps: n }, 400);
    let p_rk4 = order(|n| Solver::Rk4 { substeps: n }, 20);
    assert!((p_euler - 1.0).abs() < 0.1, "Euler order {p_euler}");
    assert!((p_rk4 - 4.0).abs() < 0.2, "RK4 order {p_rk4}");
}

#[test]
fn dopri5_global_error_stays_within_tolerance_and_lands_on_dt() {
    for tol in [1e-4, 1e-6, 1e-8, 1e-10] {
        let solver = Solver::dopri5(tol, tol);
        // one model step of 1 time unit (the scale of a push) with the input held
        let err = error_with(solver, 1.0);
        assert!(err <= tol * 2.0, "tol {tol}: error {err}");
        let f = oscillator(2.0);
        let mut out = [0.0; 2];
        let rep = integrate(&f, &solver, 1, &[1.0, 0.5], &[0.3], 1.0, &mut out);
        assert_eq!(rep.t_reached, 1.0);
        assert!(rep.accepted >= 1);
    }
    // tighter tolerances take more steps
    let steps = |tol: f64| {
        let mut out = [0.0; 2];
        integrate(
            &oscillator(2.0),
            &Solver::dopri5(tol, tol),
            1,
            &[1.0, 0.5],
            &[0.3],
            5.0,
            &mut out,
        )
        .accepted
    };
    assert!(steps(1e-10) > steps(1e-5));
}

#[test]
fn solvers_work_in_f32() {
    let f = Linear::<f32>::new(2, 1, &[0.0, 1.0, -4.0, 0.0], &[0.0, 1.0]);
    let mut out = [0.0f32; 2];
    let rep = integrate(
        &f,
        &Solver::Rk4 { substeps: 10 },
        1,
        &[1.0, 0.5],
        &[0.3],
        1.0,
        &mut out,
    );
    assert!(rep.is_success());
    let ex = oscillator_exact(2.0, 1.0, 0.5, 0.3, 1.0);
    assert!((out[0] as f64 - ex[0]).abs() < 1e-4 && (out[1] as f64 - ex[1]).abs() < 1e-4);
}

#[test]
fn a_batch_integrates_like_its_samples_for_fixed_step_solvers() {
    let f = Pendulum {
        theta: [9.0, 0.3, 1.5],
    };
    let s = [0.4, -0.2, 1.2, 0.7];
    let u = [0.5, -1.0];
    for solver in [Solver::euler(), Solver::Rk4 { substeps: 3 }] {
        let mut batch = [0.0; 4];
        integrate(&f, &solver, 2, &s, &u, 0.1, &mut batch);
        for i in 0..2 {
            let mut one = [0.0; 2];
            integrate(
                &f,
                &solver,
                1,
                &s[2 * i..2 * i + 2],
                &u[i..i + 1],
                0.1,
                &mut one,
            );
            assert_eq!(&batch[2 * i..2 * i + 2], &one);
        }
    }
}

/// L = c · s(dt); gradient wrt (s0, u, θ) by central differences.
fn fd_gradient(
    solver: &Solver,
    s0: [f64; 2],
    u: f64,
    theta: [f64; 3],
    c: [f64; 2],
    dt: f64,
) -> Vec<f64> {
    let loss = |s0: [f64; 2], u: f64, th: [f64; 3]| {
        let f = Pendulum { theta: th };
        let mut out = [0.0; 2];
        integrate(&f, solver, 1, &s0, &[u], dt, &mut out);
        c[0] * out[0] + c[1] * out[1]
    };
    let h = 1e-6;
    let mut g = Vec::new();
    for k in 0..6 {
        let mut plus = (s0, u, theta);
        let mut minus = (s0, u, theta);
        match k {
            0 | 1 => {
                plus.0[k] += h;
                minus.0[k] -= h;
            }
            2 => {
                plus.1 += h;
                minus.1 -= h;
            }
            _ => {
                plus.2[k - 3] += h;
                minus.2[k - 3] -= h;
            }
        }
        g.push((loss(plus.0, plus.1, plus.2) - loss(minus.0, minus.1, minus.2)) / (2.0 * h));
    }
    g
}

fn solvers_for_gradients() -> Vec<Solver> {
    vec![
        Solver::Euler { substeps: 3 },
        Solver::Rk4 { substeps: 2 },
        Solver::dopri5(1e-11, 1e-12),
    ]
}

#[test]
fn reverse_mode_through_every_solver_matches_finite_differences() {
    let (s0, u, theta, c, dt) = ([0.8, -0.3], 0.6, [9.0, 0.4, 2.0], [1.0, -0.5], 0.7);
    for solver in solvers_for_gradients() {
        let f = Pendulum { theta };
        let mut tape = SolverTape::default();
        let mut out = [0.0; 2];
        let rep = integrate_taped(&f, &solver, 1, &s0, &[u], dt, &mut out, &mut tape);
        assert!(rep.is_success());
        let (mut sb, mut ub, mut pb) = ([0.0; 2], [0.0; 1], [0.0; 3]);
        integrate_vjp(&f, &tape, &c, &mut sb, &mut ub, &mut pb);
        let got = [sb[0], sb[1], ub[0], pb[0], pb[1], pb[2]];
        let fd = fd_gradient(&solver, s0, u, theta, c, dt);
        let d = max_rel_diff(&got, &fd);
        assert!(d < 1e-6, "{}: reverse {got:?} vs FD {fd:?}", solver.name());
    }
}

#[test]
fn taped_integration_gives_the_same_state_as_untaped() {
    let f = Pendulum {
        theta: [9.0, 0.4, 2.0],
    };
    for solver in solvers_for_gradients() {
        let mut a = [0.0; 2];
        let mut b = [0.0; 2];
        let mut tape = SolverTape::default();
        let r1 = integrate(&f, &solver, 1, &[0.8, -0.3], &[0.6], 0.7, &mut a);
        let r2 = integrate_taped(&f, &solver, 1, &[0.8, -0.3], &[0.6], 0.7, &mut b, &mut tape);
        assert_eq!(a, b);
        assert_eq!(r1.accepted, tape.steps());
        assert_eq!(r1, r2);
    }
}

#[test]
fn forward_mode_agrees_with_reverse_mode_and_finite_differences() {
    let f = Pendulum {
        theta: [9.0, 0.4, 2.0],
    };
    let (s0, u, dt) = ([0.8, -0.3], [0.6], 0.7);
    let sdot = [0.3, -1.1];
    let udot = [0.7];
    let ybar = [0.9, 0.25];
    for solver in solvers_for_gradients() {
        // integrate_jvp (state + tangent together)
        let (mut out, mut od) = ([0.0; 2], [0.0; 2]);
        integrate_jvp(&f, &solver, 1, &s0, &u, dt, &sdot, &udot, &mut out, &mut od);
        // tangent along a tape
        let mut tape = SolverTape::default();
        let mut out2 = [0.0; 2];
        integrate_taped(&f, &solver, 1, &s0, &u, dt, &mut out2, &mut tape);
        let mut od2 = [0.0; 2];
        tape_jvp(&f, &tape, &sdot, &udot, &mut od2);
        assert!(
            max_rel_diff(&od, &od2) < 1e-9,
            "{}: {od:?} vs {od2:?}",
            solver.name()
        );
        // ⟨ȳ, J v⟩ = ⟨Jᵀ ȳ, v⟩
        let (mut sb, mut ub) = ([0.0; 2], [0.0; 1]);
        integrate_vjp(&f, &tape, &ybar, &mut sb, &mut ub, &mut []);
        let lhs = ybar[0] * od2[0] + ybar[1] * od2[1];
        let rhs = sb[0] * sdot[0] + sb[1] * sdot[1] + ub[0] * udot[0];
        assert!(
            (lhs - rhs).abs() < 1e-12 * lhs.abs().max(1.0),
            "{}: {lhs} vs {rhs}",
            solver.name()
        );
        // against central differences along the direction
        let h = 1e-6;
        let shift = |sign: f64| {
            let s = [s0[0] + sign * h * sdot[0], s0[1] + sign * h * sdot[1]];
            let uu = [u[0] + sign * h * udot[0]];
            let mut o = [0.0; 2];
            integrate(&f, &solver, 1, &s, &uu, dt, &mut o);
            o
        };
        let (p, m) = (shift(1.0), shift(-1.0));
        let fd = [(p[0] - m[0]) / (2.0 * h), (p[1] - m[1]) / (2.0 * h)];
        assert!(
            max_rel_diff(&od, &fd) < 1e-6,
            "{}: {od:?} vs {fd:?}",
            solver.name()
        );
    }
}

#[test]
fn step_jacobians_match_finite_differences_for_a_batch() {
    let f = Pendulum {
        theta: [9.0, 0.4, 2.0],
    };
    let s = [0.8, -0.3, -1.2, 0.5];
    let u = [0.6, -0.4];
    let solver = Solver::Rk4 { substeps: 2 };
    let (mut out, mut js, mut ju) = ([0.0; 4], [0.0; 8], [0.0; 4]);
    step_jacobians(&f, &solver, 2, &s, &u, 0.3, &mut out, &mut js, &mut ju);
    let h = 1e-6;
    for b in 0..2 {
        for j in 0..3 {
            let eval = |sign: f64| {
                let mut ss = [s[2 * b], s[2 * b + 1]];
                let mut uu = [u[b]];
                if j < 2 {
                    ss[j] += sign * h;
                } else {
                    uu[0] += sign * h;
                }
                let mut o = [0.0; 2];
                integrate(&f, &solver, 1, &ss, &uu, 0.3, &mut o);
                o
            };
            let (p, m) = (eval(1.0), eval(-1.0));
            for i in 0..2 {
                let fd = (p[i] - m[i]) / (2.0 * h);
                let got = if j < 2 {
                    js[b * 4 + i * 2 + j]
                } else {
                    ju[b * 2 + i]
                };
                assert!(
                    (got - fd).abs() < 1e-7,
                    "sample {b} ∂s{i}/∂z{j}: {got} vs {fd}"
                );
            }
        }
    }
}

#[test]
fn adjoint_method_matches_discrete_reverse_mode_to_solver_accuracy() {
    let f = Pendulum {
        theta: [9.0, 0.4, 2.0],
    };
    let (s0, u, dt, c) = ([0.8, -0.3], [0.6], 0.7, [1.0, -0.5]);
    let solver = Solver::dopri5(1e-10, 1e-12);
    let mut tape = SolverTape::default();
    let mut s1 = [0.0; 2];
    integrate_taped(&f, &solver, 1, &s0, &u, dt, &mut s1, &mut tape);
    let (mut sb, mut ub, mut pb) = ([0.0; 2], [0.0; 1], [0.0; 3]);
    integrate_vjp(&f, &tape, &c, &mut sb, &mut ub, &mut pb);
    let (mut sa, mut ua, mut pa) = ([0.0; 2], [0.0; 1], [0.0; 3]);
    let rep = adjoint_vjp(&f, &solver, 1, &s1, &u, dt, &c, &mut sa, &mut ua, &mut pa);
    assert!(rep.is_success());
    let disc = [sb[0], sb[1], ub[0], pb[0], pb[1], pb[2]];
    let adj = [sa[0], sa[1], ua[0], pa[0], pa[1], pa[2]];
    assert!(
        max_rel_diff(&adj, &disc) < 1e-7,
        "adjoint {adj:?} vs discrete {disc:?}"
    );
    // with RK4 substeps the adjoint converges to the same gradient too
    let (mut sr, mut ur, mut pr) = ([0.0; 2], [0.0; 1], [0.0; 3]);
    adjoint_vjp(
        &f,
        &Solver::Rk4 { substeps: 50 },
        1,
        &s1,
        &u,
        dt,
        &c,
        &mut sr,
        &mut ur,
        &mut pr,
    );
    let rk = [sr[0], sr[1], ur[0], pr[0], pr[1], pr[2]];
    assert!(
        max_rel_diff(&rk, &disc) < 1e-6,
        "adjoint RK4 {rk:?} vs {disc:?}"
    );
}

#[test]
fn parameter_gradients_of_the_linear_field_match_the_exact_sensitivity() {
    // ṡ = a s + b u, s(t) = e^{at} s0 + (e^{at} − 1)/a·b u: ∂s/∂b = (e^{at} − 1)/a·u
    let (a, b, s0, u, t) = (-0.5, 2.0, 1.0, 0.3, 1.0);
    let f = Linear::<f64>::new(1, 1, &[a], &[b]);
    let mut tape = SolverTape::default();
    let mut out = [0.0];
    integrate_taped(
        &f,
        &Solver::dopri5(1e-12, 1e-14),
        1,
        &[s0],
        &[u],
        t,
        &mut out,
        &mut tape,
    );
    let (mut sb, mut ub, mut pb) = ([0.0], [0.0], [0.0; 2]);
    integrate_vjp(&f, &tape, &[1.0], &mut sb, &mut ub, &mut pb);
    let e = (a * t).exp();
    assert!((sb[0] - e).abs() < 1e-9);
    assert!((ub[0] - (e - 1.0) / a * b).abs() < 1e-9);
    assert!((pb[1] - (e - 1.0) / a * u).abs() < 1e-9);
    let dsda = t * e * s0 + b * u * (t * e / a - (e - 1.0) / (a * a));
    assert!((pb[0] - dsda).abs() < 1e-9, "{} vs {dsda}", pb[0]);
}

#[test]
fn a_diverging_ode_reports_a_status_instead_of_nan() {
    // ṡ = s², s0 = 1 blows up at t = 1; integrate to t = 2
    let mut out = [0.0];
    let rep = integrate(
        &BlowUp,
        &Solver::dopri5(1e-6, 1e-9),
        1,
        &[1.0],
        &[],
        2.0,
        &mut out,
    );
    assert_ne!(rep.status, OdeStatus::Success);
    assert!(out[0].is_finite(), "state must be the last finite one");
    assert!(
        rep.t_reached < 1.01 && rep.t_reached > 0.9,
        "t_reached {}",
        rep.t_reached
    );

    let rep = integrate(
        &BlowUp,
        &Solver::Rk4 { substeps: 4 },
        1,
        &[1e100],
        &[],
        2.0,
        &mut out,
    );
    assert_eq!(rep.status, OdeStatus::NonFinite);
    assert!(out[0].is_finite());

    let rep = integrate(
        &BlowUp,
        &Solver::Euler { substeps: 1000 },
        1,
        &[1.0],
        &[],
        2.0,
        &mut out,
    );
    assert_eq!(rep.status, OdeStatus::NonFinite);
    assert!(out[0].is_finite());
}

#[test]
fn dopri5_reports_exceeding_its_step_limit() {
    let f = oscillator(50.0);
    let o = Dopri5Options {
        rtol: 1e-10,
        atol: 1e-12,
        max_steps: 5,
        ..Default::default()
    };
    let mut out = [0.0; 2];
    let rep = integrate(
        &f,
        &Solver::Dopri5(o),
        1,
        &[1.0, 0.0],
        &[0.0],
        10.0,
        &mut out,
    );
    assert_eq!(rep.status, OdeStatus::MaxStepsExceeded);
    assert!(rep.t_reached < 10.0);
    assert!(out.iter().all(|x| x.is_finite()));
}

#[test]
fn solver_settings_round_trip_through_json() {
    for s in [
        Solver::euler(),
        Solver::Rk4 { substeps: 4 },
        Solver::dopri5(1e-5, 1e-7),
    ] {
        let j = serde_json::to_string(&s).unwrap();
        let back: Solver = serde_json::from_str(&j).unwrap();
        assert_eq!(back, s);
    }
    let s: Solver = serde_json::from_str(r#"{"method":"dopri5","rtol":1e-4}"#).unwrap();
    assert_eq!(
        s,
        Solver::Dopri5(Dopri5Options {
            rtol: 1e-4,
            ..Default::default()
        })
    );
}
