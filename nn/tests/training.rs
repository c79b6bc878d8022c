//! Adam on a quadratic, an MLP fitting a smooth function, and backpropagation through an RK4
//! unroll (the NeuralODE training path) against finite differences.

mod common;

use common::data;
use common::rk4::Rk4Tape;
use dynlab_nn::{Activation, Adam, AdamConfig, Init, Mlp, MlpSpec, NnError, WeightDecay};

#[test]
fn adam_converges_on_an_ill_conditioned_quadratic() {
    // f(θ) = ½ Σ c_i (θ_i − t_i)², condition number 1e4.
    let n = 50;
    let c: Vec<f32> = (0..n)
        .map(|i| 10f32.powf(-2.0 + 4.0 * i as f32 / (n - 1) as f32))
        .collect();
    let t = data(1, n, -2.0, 2.0);
    let mut theta = vec![0.0f32; n];
    let mut adam = Adam::new(
        n,
        AdamConfig {
            lr: 0.05,
            ..Default::default()
        },
    )
    .unwrap();
    let mut g = vec![0.0; n];
    for _ in 0..3000 {
        for i in 0..n {
            g[i] = c[i] * (theta[i] - t[i]);
        }
        adam.step(&mut theta, &g).unwrap();
    }
    let worst = theta
        .iter()
        .zip(&t)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(worst < 1e-3, "max |θ − θ*| = {worst}");
    assert_eq!(adam.steps(), 3000);
}

#[test]
fn adam_first_step_is_lr_times_sign_of_gradient() {
    // With bias correction the first step is −lr·g/(|g| + ε/…) ≈ −lr·sign(g).
    let mut adam = Adam::new(
        3,
        AdamConfig {
            lr: 0.1,
            ..Default::default()
        },
    )
    .unwrap();
    let mut p = vec![1.0f32, 1.0, 1.0];
    adam.step(&mut p, &[3.0, -0.001, 0.0]).unwrap();
    assert!(
        (p[0] - 0.9).abs() < 1e-6 && (p[1] - 1.1).abs() < 1e-5 && p[2] == 1.0,
        "{p:?}"
    );
}

#[test]
fn adam_weight_decay_variants() {
    // Zero gradient: L2 decay acts through the moments, decoupled decay shrinks θ by lr·λ.
    let cfg = |wd| AdamConfig {
        lr: 0.1,
        weight_decay: wd,
        ..Default::default()
    };
    let mut p = vec![2.0f32];
    Adam::new(1, cfg(WeightDecay::Decoupled(0.5)))
        .unwrap()
        .step(&mut p, &[0.0])
        .unwrap();
    assert!((p[0] - 2.0 * (1.0 - 0.05)).abs() < 1e-6, "{p:?}");
    let mut p = vec![2.0f32];
    Adam::new(1, cfg(WeightDecay::L2(0.5)))
        .unwrap()
        .step(&mut p, &[0.0])
        .unwrap();
    assert!((p[0] - 1.9).abs() < 1e-5, "{p:?}");
}

#[test]
fn adam_rejects_bad_settings_and_lengths() {
    for cfg in [
        AdamConfig {
            lr: 0.0,
            ..Default::default()
        },
        AdamConfig {
            lr: f32::NAN,
            ..Default::default()
        },
        AdamConfig {
            beta1: 1.0,
            ..Default::default()
        },
        AdamConfig {
            beta2: -0.1,
            ..Default::default()
        },
        AdamConfig {
            eps: 0.0,
            ..Default::default()
        },
        AdamConfig {
            weight_decay: WeightDecay::L2(-1.0),
            ..Default::default()
        },
    ] {
        assert!(
            matches!(
                Adam::new(3, cfg),
                Err(NnError::InvalidHyperparameter { .. })
            ),
            "{cfg:?}"
        );
    }
    let mut adam = Adam::new(3, AdamConfig::default()).unwrap();
    assert!(matches!(
        adam.step(&mut [0.0; 2], &[0.0; 3]),
        Err(NnError::ShapeMismatch { what: "params", .. })
    ));
}

/// Mean squared error and its gradient wrt the outputs.
fn mse(y: &[f32], t: &[f32], dy: &mut [f32]) -> f64 {
    let n = y.len() as f32;
    let mut l = 0.0f64;
    for ((d, &y), &t) in dy.iter_mut().zip(y).zip(t) {
        l += f64::from((y - t) * (y - t));
        *d = 2.0 * (y - t) / n;
    }
    l / y.len() as f64
}

#[test]
fn mlp_fits_a_smooth_function_loss_falls_100x() {
    // y = (sin(2x0)·cos(x1), x0·x1 − 0.5·x2²) on [−1, 1]³, 256 samples, full batch.
    let n = 256;
    let x = data(7, n * 3, -1.0, 1.0);
    let t: Vec<f32> = x
        .chunks(3)
        .flat_map(|r| {
            [
                (2.0 * r[0]).sin() * r[1].cos(),
                r[0] * r[1] - 0.5 * r[2] * r[2],
            ]
        })
        .collect();
    for act in [Activation::Tanh, Activation::Gelu] {
        let mut mlp = Mlp::new(
            MlpSpec::uniform(3, &[32, 32], 2, act).unwrap(),
            Init::Auto,
            3,
        );
        let mut ws = mlp.workspace();
        let mut adam = Adam::new(
            mlp.n_params(),
            AdamConfig {
                lr: 3e-3,
                ..Default::default()
            },
        )
        .unwrap();
        let mut grad = vec![0.0; mlp.n_params()];
        let mut dy = vec![0.0; n * 2];
        let first = mse(mlp.forward(&x, &mut ws).unwrap(), &t, &mut dy);
        let mut last = first;
        for _ in 0..1500 {
            last = mse(mlp.forward(&x, &mut ws).unwrap(), &t, &mut dy);
            grad.fill(0.0);
            mlp.backward(&mut ws, &dy, &mut grad, None).unwrap();
            adam.step(mlp.params_mut(), &grad).unwrap();
        }
        assert!(last < first / 100.0, "{act}: loss {first:.3e} → {last:.3e}");
    }
}

#[test]
fn training_is_bitwise_reproducible() {
    let run = || {
        let x = data(8, 64 * 6, -1.0, 1.0);
        let t = data(9, 64 * 3, -1.0, 1.0);
        let mut mlp = Mlp::new(
            MlpSpec::uniform(6, &[100, 100], 3, Activation::Tanh).unwrap(),
            Init::Auto,
            5,
        );
        let mut ws = mlp.workspace();
        let mut adam = Adam::new(mlp.n_params(), AdamConfig::default()).unwrap();
        let mut grad = vec![0.0; mlp.n_params()];
        let mut dy = vec![0.0; t.len()];
        for _ in 0..20 {
            mse(mlp.forward(&x, &mut ws).unwrap(), &t, &mut dy);
            grad.fill(0.0);
            mlp.backward(&mut ws, &dy, &mut grad, None).unwrap();
            adam.step(mlp.params_mut(), &grad).unwrap();
        }
        mlp
    };
    assert_eq!(run().params(), run().params());
}

#[test]
fn rk4_unroll_gradients_match_finite_differences() {
    // NeuralODE vector field 6 → 32 → 32 → 3 (state 3, action 3), k = 3 RK4 steps, loss
    // L = Σ_n γ^{n−1} Σ w_n·s_n with fixed weights w_n; compare ∂L/∂θ and ∂L/∂s0 with central
    // differences of the f32 rollout evaluated in f64 sums (h large enough for f32).
    let spec = MlpSpec::uniform(6, &[32, 32], 3, Activation::Tanh).unwrap();
    let mut mlp = Mlp::new(spec, Init::Auto, 17);
    let batch = 4;
    let steps = 3;
    let dt = 0.3f32;
    let s0 = data(1, batch * 3, -1.0, 1.0);
    let actions: Vec<Vec<f32>> = (0..steps)
        .map(|n| data(10 + n as u64, batch * 3, -1.0, 1.0))
        .collect();
    let action_refs: Vec<&[f32]> = actions.iter().map(|a| a.as_slice()).collect();
    let w: Vec<Vec<f32>> = (0..steps)
        .map(|n| data(20 + n as u64, batch * 3, -1.0, 1.0))
        .collect();
    let gamma = 0.9f32;
    let d_states: Vec<Vec<f32>> = w
        .iter()
        .enumerate()
        .map(|(n, w)| w.iter().map(|v| v * gamma.powi(n as i32)).collect())
        .collect();
    let d_refs: Vec<&[f32]> = d_states.iter().map(|d| d.as_slice()).collect();

    let mut tape = Rk4Tape::new(&mlp, 3, 3);
    let loss = |mlp: &Mlp, s0: &[f32], tape: &mut Rk4Tape| -> f64 {
        tape.forward(mlp, s0, &action_refs, dt).unwrap();
        (0..steps)
            .map(|n| {
                tape.states[n + 1]
                    .iter()
                    .zip(&d_states[n])
                    .map(|(s, d)| f64::from(*s) * f64::from(*d))
                    .sum::<f64>()
            })
            .sum()
    };
    loss(&mlp, &s0, &mut tape);
    let mut grad = vec![0.0; mlp.n_params()];
    let mut ds0 = vec![0.0; s0.len()];
    tape.backward(&mlp, dt, &d_refs, &mut grad, &mut ds0)
        .unwrap();

    let h = 1e-2f32;
    let mut worst = 0.0f64;
    let scale = grad.iter().fold(0.0f32, |m, g| m.max(g.abs())) as f64;
    for k in (0..mlp.n_params()).step_by(7) {
        let p = mlp.params()[k];
        mlp.params_mut()[k] = p + h;
        let lp = loss(&mlp, &s0, &mut tape);
        mlp.params_mut()[k] = p - h;
        let lm = loss(&mlp, &s0, &mut tape);
        mlp.params_mut()[k] = p;
        let fd = (lp - lm) / (2.0 * f64::from(h));
        worst = worst.max((fd - f64::from(grad[k])).abs());
    }
    assert!(
        worst < 2e-3 * scale,
        "parameter gradient error {worst:.3e} (scale {scale:.3e})"
    );
    for i in 0..s0.len() {
        let mut sp = s0.clone();
        let mut sm = s0.clone();
        sp[i] += h;
        sm[i] -= h;
        let fd = (loss(&mlp, &sp, &mut tape) - loss(&mlp, &sm, &mut tape)) / (2.0 * f64::from(h));
        assert!(
            (fd - f64::from(ds0[i])).abs() < 2e-3 * fd.abs().max(1.0),
            "ds0[{i}]: {} vs {fd}",
            ds0[i]
        );
    }
}
