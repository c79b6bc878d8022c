//! Effect states of the car model (`motor_lag`'s `d_f`, `steering_lag`'s `δ_w`): the steering
//! servo's field and its exact Jacobians, the rebuilt effect states against exact solutions,
//! and the solvers' shape contract.

use dynlab_dynamics::ode::{Solver, VectorField, integrate};
use dynlab_dynamics::physics::*;

fn servo(tau: f64, rate: f64, delta0: f64) -> PhysicsModel {
    let mut m = PhysicsModel::car(&[
        Effect::SteeringOffset,
        Effect::MotorLag,
        Effect::SteeringLag,
    ])
    .unwrap();
    m.set_param("steering_offset.delta0", delta0).unwrap();
    m.set_param("motor_lag.tau", 0.07).unwrap();
    m.set_param("steering_lag.tau", tau).unwrap();
    m.set_param("steering_lag.rate", rate).unwrap();
    m
}

/// The field's Jacobians wrt state, input and every parameter against central differences.
fn assert_exact_jacobians(m: &PhysicsModel, s: &[f64], u: &[f64]) {
    let (ds, du, np) = (m.dim_s(), m.dim_u(), m.n_params());
    let nz = ds + du + np;
    let (mut f, mut j) = (vec![0.0; ds], vec![0.0; ds * nz]);
    m.jacobian_full(s, u, &vec![true; m.effects().len()], true, &mut f, &mut j);
    let z: Vec<f64> = s.iter().chain(u).chain(m.params()).copied().collect();
    let eval = |z: &[f64]| -> Vec<f64> {
        let mut mm = m.clone();
        mm.set_params(&z[ds + du..]).unwrap();
        let mut out = vec![0.0; ds];
        mm.eval_one(&z[..ds], &z[ds..ds + du], &mut out);
        out
    };
    for c in 0..nz {
        let h = 1e-6 * z[c].abs().max(1e-2);
        let (mut p, mut q) = (z.clone(), z.clone());
        p[c] += h;
        q[c] -= h;
        let (fp, fq) = (eval(&p), eval(&q));
        for r in 0..ds {
            let fd = (fp[r] - fq[r]) / (2.0 * h);
            let ex = j[r * nz + c];
            assert!(
                (fd - ex).abs() < 1e-5 * fd.abs().max(1.0),
                "∂f{r}/∂z{c}: exact {ex} vs FD {fd}"
            );
        }
    }
}

#[test]
fn steering_lag_is_a_rate_limited_first_order_servo_with_exact_jacobians() {
    let m = servo(0.05, 2.0, 0.03);
    assert_eq!(m.state_names()[6..], ["d_f", "delta_w"]);
    assert_eq!(m.effect_state_names(), vec!["d_f", "delta_w"]);
    assert_eq!(m.dim_effect_states(), 2);
    assert!(!Effect::SteeringLag.linear_in_params());
    let specs = Effect::SteeringLag.params();
    assert_eq!((specs[0].name, specs[0].unit), ("tau", "s"));
    assert_eq!((specs[1].name, specs[1].unit), ("rate", "rad/s"));
    let s = [0.9, 0.1, 0.4, 1.2, 0.15, 2.0, 0.3, 0.1];
    let u = [0.2, 0.5];
    let mut f = vec![0.0; 8];
    m.eval_one(&s, &u, &mut f);
    // δ̇_w = r·tanh((δ + δ₀ − δ_w)/(r·τ_s))
    let want = 2.0 * ((0.2 + 0.03 - 0.1) / (2.0 * 0.05f64)).tanh();
    assert!((f[7] - want).abs() < 1e-14, "{} vs {want}", f[7]);
    // the wheels follow δ_w, not the command: the same car with the command at δ_w and no servo
    let mut plain = PhysicsModel::car(&[Effect::MotorLag]).unwrap();
    plain.set_param("motor_lag.tau", 0.07).unwrap();
    let mut g = vec![0.0; 7];
    plain.eval_one(&s[..7], &[0.1, 0.5], &mut g);
    assert!(f[..7].iter().zip(&g).all(|(a, b)| (a - b).abs() < 1e-12));
    // small errors: a first-order lag of τ_s; large ones: at most the rate
    let small = servo(0.05, 50.0, 0.0);
    small.eval_one(
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.19],
        &[0.2, 0.0],
        &mut f,
    );
    assert!((f[7] - 0.01 / 0.05).abs() < 1e-4, "{}", f[7]);
    m.eval_one(
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -0.4],
        &[0.4, 0.0],
        &mut f,
    );
    assert!(f[7] < 2.0 && f[7] > 1.99, "{}", f[7]);
    // Jacobians wrt state, input and parameters against central differences (the ellipse's
    // weight inside its range [0, 1])
    let mut m = m;
    m.set_param("ellipse", 0.8).unwrap();
    assert_exact_jacobians(&m, &s, &u);
    let ds = m.dim_s();
    // its contribution: what the servo changes, with exact Jacobians
    let t = m.effect_term(Effect::SteeringLag, &s, &u).unwrap();
    assert_eq!(t.d_params.len(), ds * 2);
    assert!((t.contribution[7] - want).abs() < 1e-14);
    let text = m.equations();
    assert!(
        text.contains("δ̇_w = 2.000·tanh((δ + δ₀ − δ_w)/(2.000·0.05000))"),
        "{text}"
    );
    assert!(text.contains("F_fy·sin δ_w"), "{text}");
}

#[test]
fn effect_states_along_commands_match_the_exact_lag_and_the_integrated_model() {
    let mut m = PhysicsModel::car(&[Effect::MotorLag, Effect::SteeringLag]).unwrap();
    m.set_param("motor_lag.tau", 0.08).unwrap();
    m.set_param("steering_lag.tau", 0.04).unwrap();
    m.set_param("steering_lag.rate", 1.5).unwrap();
    let dt = 0.01;
    let u: Vec<f64> = (0..60)
        .flat_map(|i| {
            let k = i / 15;
            [0.3 * if k % 2 == 0 { 1.0 } else { -1.0 }, 0.2 * k as f64]
        })
        .collect();
    let e = m.effect_states_along(&u, dt);
    assert_eq!(e.len(), 60 * 2);
    // settled at the first command
    assert_eq!(&e[..2], &[0.0, 0.3]);
    // d_f: the exact solution of the first-order lag under zero-order hold
    let thr: Vec<f64> = (0..60).map(|i| u[i * 2 + 1]).collect();
    let exact = PhysicsModel::motor_lag_filter(&thr, dt, 0.08, thr[0]);
    for i in 0..60 {
        assert!(
            (e[i * 2] - exact[i]).abs() < 1e-7,
            "{i}: {} vs {}",
            e[i * 2],
            exact[i]
        );
    }
    // the same as integrating the whole model (the effect states ignore the car's state)
    let mut s: Vec<f64> = [0.0, 0.0, 0.3, 1.0, 0.1, 0.2].to_vec();
    s.extend_from_slice(&e[..2]);
    let solver = Solver::Rk4 { substeps: 8 };
    for i in 0..59 {
        let mut next = vec![0.0; 8];
        integrate(&m, &solver, 1, &s, &u[i * 2..i * 2 + 2], dt, &mut next);
        for c in 0..2 {
            let (a, b) = (next[6 + c], e[(i + 1) * 2 + c]);
            assert!(
                (a - b).abs() < 1e-8,
                "step {i} state {c}: model {a} vs along {b}"
            );
        }
        s = next;
    }
    // the wheel never turns faster than the rate limit
    for i in 1..60 {
        let rate = (e[i * 2 + 1] - e[(i - 1) * 2 + 1]) / dt;
        assert!(rate.abs() <= 1.5 + 1e-12, "wheel rate {rate}");
    }
    // from a history: the last entry advanced by the last command
    let hist = &u[..40 * 2];
    let from = m.effect_states_from_history(hist, &u[80..82], dt);
    for c in 0..2 {
        assert!((from[c] - e[40 * 2 + c]).abs() < 1e-15);
    }
    assert_eq!(
        m.effect_states_from_history(&[], &[0.1, 0.4], dt),
        vec![0.4, 0.1]
    );
    // derivatives wrt τ by dual numbers through the same recursion
    let j = m.settled_effect_states_jacobian(&[0.1, 0.4]);
    assert_eq!(j, vec![0.0, 1.0, 1.0, 0.0]);
    // a model without effect states has none
    let plain = PhysicsModel::car(&[]).unwrap();
    assert!(plain.effect_states_along(&u, dt).is_empty());
    assert_eq!(plain.dim_effect_states(), 0);
}

#[test]
#[should_panic(expected = "n × dim_s = 1 × 7")]
fn a_state_without_its_effect_states_is_a_shape_error_not_a_slice_panic() {
    let m = PhysicsModel::car(&[Effect::MotorLag]).unwrap();
    let mut out = vec![0.0; 6];
    integrate(
        &m,
        &Solver::rk4(),
        1,
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        &[0.0, 0.5],
        0.01,
        &mut out,
    );
}

#[test]
fn a_term_on_a_lagged_command_carries_the_lagged_commands_as_effect_states() {
    // δ += −τ·δ̇_τ is the lag itself: the wheels see δ_τ = δ − τ·(δ − δ_τ)/τ
    let lag = CustomEffect::from_toml(
        "name = \"steering_delay\"\n[[term]]\nstate = \"delta\"\nfeature = \"delta_rate(0.1)\"\ncoefficient = -0.1\n",
    )
    .unwrap();
    assert!(lag.uses_input_lags());
    let mut plain = PhysicsModel::car(&[Effect::MotorLag]).unwrap();
    plain.set_param("motor_lag.tau", 0.07).unwrap();
    // the ellipse's weight inside its range [0, 1], for the central differences
    plain.set_param("ellipse", 0.8).unwrap();
    let mut m = plain.clone();
    m.add_custom(lag.clone()).unwrap();
    let mut names = vec!["d_f"];
    names.extend_from_slice(&features::INPUT_LAG_STATES);
    assert_eq!(m.effect_state_names(), names);
    assert_eq!(m.dim_state(), 7 + 6);
    // the lagged copies, each unlike its command
    let s = [
        0.9, 0.1, 0.4, 1.2, 0.15, 2.0, 0.3, 0.05, 0.2, -0.1, 0.4, 0.12, 0.25,
    ];
    let u = [0.2, 0.5];
    let (delta_01, d_01) = (s[7 + 2], s[7 + 3]);
    assert_eq!(features::input_lag_index(0, 1), 4);
    let mut f = vec![0.0; 13];
    m.eval_one(&s, &u, &mut f);
    let mut g = vec![0.0; 7];
    plain.eval_one(&s[..7], &[delta_01, u[1]], &mut g);
    for r in 0..7 {
        assert!((f[r] - g[r]).abs() < 1e-12, "row {r}: {} vs {}", f[r], g[r]);
    }
    // each copy follows its command with its time constant
    for (k, tau) in features::INPUT_LAGS_S.iter().enumerate() {
        for (i, ui) in u.iter().enumerate() {
            let j = 7 + 2 * k + i;
            assert!((f[j] - (ui - s[j]) / tau).abs() < 1e-12, "{}", names[j - 6]);
        }
    }
    assert!((f[7 + 3] - (u[1] - d_01) / 0.1).abs() < 1e-12);
    assert_exact_jacobians(&m, &s, &u);
    // the copies are the exact lag of the commands, rebuilt from the command history
    let dt = 0.01;
    let cmd: Vec<f64> = (0..80)
        .flat_map(|i| [0.25 * ((i / 20) as f64 - 1.5), 0.1 * (i / 10) as f64])
        .collect();
    let e = m.effect_states_along(&cmd, dt);
    assert_eq!(e.len(), 80 * 7);
    for (k, &tau) in features::INPUT_LAGS_S.iter().enumerate() {
        for i in 0..2 {
            let seq: Vec<f64> = (0..80).map(|a| cmd[a * 2 + i]).collect();
            let exact = PhysicsModel::motor_lag_filter(&seq, dt, tau, seq[0]);
            for a in 0..80 {
                let got = e[a * 7 + 1 + 2 * k + i];
                assert!((got - exact[a]).abs() < 1e-6, "τ {tau} input {i} step {a}");
            }
        }
    }
    // a library effect added later keeps the copies last; the equations name them
    let more = m.with_effects(&[Effect::SteeringLag]).unwrap();
    assert_eq!(more.state_names()[6..8], ["d_f", "delta_w"]);
    assert_eq!(more.state_names()[8..], features::INPUT_LAG_STATES);
    let text = m.equations();
    assert!(text.contains("δ += −0.1000 · δ̇_{0.1 s}   [θ: s]"), "{text}");
    assert!(text.contains("lagged commands"), "{text}");
    // the pusher has no lagged commands
    let e = CustomEffect::from_toml(
        "name = \"p\"\n[[term]]\nstate = \"x\"\nfeature = \"d_rate(0.1)\"\ncoefficient = 0\n",
    )
    .unwrap_err();
    assert!(e.to_string().contains("d_rate(0.1)"), "{e}");
}

#[test]
fn a_command_delay_is_a_pade_filter_per_command_ahead_of_the_servo_and_the_motor() {
    let mut m = PhysicsModel::car(&[
        Effect::SteeringOffset,
        Effect::MotorLag,
        Effect::SteeringLag,
        Effect::CommandDelay,
    ])
    .unwrap();
    m.set_param("steering_offset.delta0", 0.02).unwrap();
    m.set_param("motor_lag.tau", 0.07).unwrap();
    m.set_param("steering_lag.tau", 0.04).unwrap();
    m.set_param("steering_lag.rate", 3.0).unwrap();
    m.set_param("command_delay.delay", 0.09).unwrap();
    // the ellipse's weight inside its range [0, 1], for the central differences
    m.set_param("ellipse", 0.8).unwrap();
    assert_eq!(
        m.effect_state_names(),
        vec!["d_f", "delta_w", "delta_c", "delta_c_dot", "d_c", "d_c_dot"]
    );
    let s = [
        0.9, 0.1, 0.4, 1.2, 0.15, 2.0, 0.3, 0.1, 0.25, 1.5, 0.45, -0.6,
    ];
    let u = [0.2, 0.5];
    let mut f = vec![0.0; 12];
    m.eval_one(&s, &u, &mut f);
    // what reaches the car: c − (t_d/3)·ċ
    let (steer, throttle) = (0.25 - 0.03 * 1.5, 0.45 + 0.03 * 0.6);
    let k = 6.0 / (0.09f64 * 0.09);
    let want = [
        (throttle - 0.3) / 0.07, // the motor lags the delayed throttle
        3.0 * ((steer - 0.1) / (3.0 * 0.04f64)).tanh(), // the servo the delayed steering
        1.5,
        (0.2 + 0.02 - 0.25 - 0.06 * 1.5) * k, // the filter takes the trimmed command
        -0.6,
        (0.5 - 0.45 + 0.06 * 0.6) * k,
    ];
    for (i, w) in want.iter().enumerate() {
        assert!(
            (f[6 + i] - w).abs() < 1e-9 * w.abs().max(1.0),
            "state {}: {} vs {w}",
            6 + i,
            f[6 + i]
        );
    }
    assert_exact_jacobians(&m, &s, &u);
    // the equations name what reaches the car and what the lags follow
    let eq = m.equations();
    for line in [
        "δ̃ = δ_c − ",
        "d̃ = d_c − ",
        "ḋ_f = (d̃ − d_f)",
        "tanh((δ̃ − δ_w)",
    ] {
        assert!(eq.contains(line), "{line} not in\n{eq}");
    }

    // along commands: the filter integrated finely under zero-order hold
    let mut delay = PhysicsModel::car(&[Effect::CommandDelay]).unwrap();
    let td = 0.06;
    delay.set_param("command_delay.delay", td).unwrap();
    let dt = 0.01;
    let n = 120;
    let u: Vec<f64> = (0..n)
        .flat_map(|i| if i < 10 { [0.0, 0.1] } else { [0.3, 0.4] })
        .collect();
    let e = delay.effect_states_along(&u, dt);
    assert_eq!(
        &e[..4],
        &[0.0, 0.0, 0.1, 0.0],
        "settled at the first command"
    );
    let mut x = [[0.0, 0.0], [0.1, 0.0]];
    let fine = 200;
    let h = dt / fine as f64;
    for i in 0..n {
        for c in 0..2 {
            for j in 0..2 {
                let (got, want) = (e[i * 4 + 2 * c + j], x[c][j]);
                assert!(
                    (got - want).abs() < 1e-5 * want.abs().max(1.0),
                    "sample {i}, command {c}, state {j}: {got} vs {want}"
                );
            }
            let v = u[i * 2 + c];
            // classic RK4 of (ċ, c̈)
            let rate = |[a, b]: [f64; 2]| [b, 6.0 / (td * td) * (v - a - 2.0 * td / 3.0 * b)];
            let add = |x: [f64; 2], k: [f64; 2], w: f64| [x[0] + w * k[0], x[1] + w * k[1]];
            for _ in 0..fine {
                let k1 = rate(x[c]);
                let k2 = rate(add(x[c], k1, 0.5 * h));
                let k3 = rate(add(x[c], k2, 0.5 * h));
                let k4 = rate(add(x[c], k3, h));
                for j in 0..2 {
                    x[c][j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
                }
            }
        }
    }
    // the steering step at sample 10 as it reaches the car
    let seen: Vec<f64> = (0..n).map(|i| e[i * 4] - td / 3.0 * e[i * 4 + 1]).collect();
    // it arrives 60 ms late on average: ∫(1 − response)
    let lag: f64 = (10..n).map(|i| (1.0 - seen[i] / 0.3) * dt).sum();
    assert!((lag - td).abs() < 0.006, "mean delay {lag}");
    // nothing reaches the car at once, the filter's undershoot (a Padé filter's, 17 % of the step
    // 10 ms after it) stays below a fifth of the step, and it settles
    assert!(seen[11].abs() < 0.2 * 0.3, "{}", seen[11]);
    assert!(seen.iter().all(|&y| y > -0.2 * 0.3), "{seen:?}");
    assert!((seen[n - 1] - 0.3).abs() < 1e-3);
}
