//! Forward pass against a naive f64 reference; VJP, JVP and input Jacobians against central
//! finite differences of that reference; VJP/JVP consistency; error reporting.
//!
//! Why an f64 reference rather than a generic f32/f64 module: the crate is `f32` only (its speed
//! comes from `f32` SIMD kernels), and finite differences of an `f32` network are dominated by
//! rounding (step h ≈ 1e-3 gives ~1e-4 relative noise). The reference evaluates the *same*
//! parameters (exactly representable in f64) with textbook loops and libm tanh / series erf, so
//! its central differences (h = 1e-6) are accurate to ~1e-9, and our `f32` derivatives must
//! match them to `f32` accuracy (tolerance 1e-4 relative to the largest entry; a wrong index,
//! transpose or missing term gives errors of order 1).

mod common;

use common::{Reference, data, max_rel_err};
use dynlab_nn::{Activation, Init, JacobianMode, Mlp, MlpSpec, NnError};

const ACTS: [Activation; 4] = [
    Activation::Tanh,
    Activation::Gelu,
    Activation::Relu,
    Activation::Identity,
];

fn net(sizes: &[usize], act: Activation, seed: u64) -> Mlp {
    let spec = MlpSpec::new(sizes, &vec![act; sizes.len() - 2]).unwrap();
    let mut mlp = Mlp::new(spec, Init::Auto, seed);
    // Non-zero biases so that bias handling is exercised.
    let shapes = mlp.layer_shapes().to_vec();
    let b = data(seed ^ 0xB1A5, mlp.n_params(), -0.3, 0.3);
    for s in shapes {
        for i in s.bias.clone() {
            mlp.params_mut()[i] = b[i];
        }
    }
    mlp
}

fn pushing(act: Activation) -> Mlp {
    net(&[6, 100, 100, 3], act, 11)
}

fn car() -> Mlp {
    net(
        &[8, 64, 64, 64, 64, 64, 64, 64, 64, 3],
        Activation::Gelu,
        12,
    )
}

#[test]
fn forward_matches_naive_f64_reference() {
    for act in ACTS {
        for mlp in [pushing(act), net(&[5, 7, 1], act, 3), net(&[4, 2], act, 4)] {
            let reference = Reference::of(&mlp);
            let mut ws = mlp.workspace();
            for batch in [1, 3, 17, 64] {
                let x = data(batch as u64, batch * mlp.n_in(), -2.0, 2.0);
                let y = mlp.forward(&x, &mut ws).unwrap().to_vec();
                let r = reference.eval_batch(&x);
                let err = max_rel_err(&y, &r, 1.0);
                assert!(
                    err < 2e-5,
                    "{act}, sizes {:?}, batch {batch}: rel err {err:.2e}",
                    mlp.sizes()
                );
            }
        }
    }
    let mlp = car();
    let x = data(9, 20 * 8, -1.5, 1.5);
    let y = mlp.forward(&x, &mut mlp.workspace()).unwrap().to_vec();
    assert!(max_rel_err(&y, &Reference::of(&mlp).eval_batch(&x), 1.0) < 2e-5);
}

#[test]
fn input_jacobians_match_finite_differences_in_both_modes() {
    let cases = [
        pushing(Activation::Tanh),
        pushing(Activation::Gelu),
        car(),
        net(&[2, 9, 9, 6], Activation::Tanh, 5),
    ];
    for mlp in cases {
        let reference = Reference::of(&mlp);
        let (n_in, n_out) = (mlp.n_in(), mlp.n_out());
        let batch = 5;
        let x = data(21, batch * n_in, -1.5, 1.5);
        let mut ws = mlp.workspace();
        for mode in [
            JacobianMode::Auto,
            JacobianMode::Reverse,
            JacobianMode::Forward,
        ] {
            let j = mlp.jacobian_with(&x, &mut ws, mode).unwrap().to_vec();
            assert_eq!(j.len(), batch * n_out * n_in);
            for b in 0..batch {
                let xb: Vec<f64> = x[b * n_in..(b + 1) * n_in]
                    .iter()
                    .map(|&v| f64::from(v))
                    .collect();
                let fd = reference.fd_jacobian(&xb, 1e-6);
                let err = max_rel_err(&j[b * n_out * n_in..(b + 1) * n_out * n_in], &fd, 1e-2);
                assert!(
                    err < 1e-4,
                    "sizes {:?} {mode:?} sample {b}: rel err {err:.2e}",
                    mlp.sizes()
                );
            }
            // The outputs are left in the workspace.
            assert_eq!(ws.output().len(), batch * n_out);
        }
    }
}

#[test]
fn jvp_matches_finite_differences() {
    for act in ACTS {
        let mlp = pushing(act);
        let reference = Reference::of(&mlp);
        let batch = 4;
        let x = data(31, batch * 6, -1.0, 1.0);
        let v = data(32, batch * 6, -1.0, 1.0);
        let mut ws = mlp.workspace();
        let (y, dy) = mlp.jvp(&x, &v, &mut ws).unwrap();
        let (y, dy) = (y.to_vec(), dy.to_vec());
        assert!(max_rel_err(&y, &reference.eval_batch(&x), 1.0) < 2e-5);
        for b in 0..batch {
            let h = 1e-6;
            let xp: Vec<f64> = (0..6)
                .map(|i| f64::from(x[b * 6 + i]) + h * f64::from(v[b * 6 + i]))
                .collect();
            let xm: Vec<f64> = (0..6)
                .map(|i| f64::from(x[b * 6 + i]) - h * f64::from(v[b * 6 + i]))
                .collect();
            let (fp, fm) = (
                reference.eval(&reference.params, &xp),
                reference.eval(&reference.params, &xm),
            );
            let fd: Vec<f64> = fp
                .iter()
                .zip(&fm)
                .map(|(p, m)| (p - m) / (2.0 * h))
                .collect();
            let err = max_rel_err(&dy[b * 3..(b + 1) * 3], &fd, 1e-2);
            assert!(err < 1e-4, "{act} sample {b}: rel err {err:.2e}");
        }
    }
}

#[test]
fn vjp_parameter_and_input_gradients_match_finite_differences() {
    for act in ACTS {
        for (mlp, stride) in [(net(&[3, 7, 5, 2], act, 41), 1), (pushing(act), 53)] {
            let reference = Reference::of(&mlp);
            let batch = 6;
            let x = data(42, batch * mlp.n_in(), -1.5, 1.5);
            let dy = data(43, batch * mlp.n_out(), -1.0, 1.0);
            let mut ws = mlp.workspace();
            mlp.forward(&x, &mut ws).unwrap();
            // grad accumulates: start from a known non-zero value.
            let mut grad = vec![0.5f32; mlp.n_params()];
            let mut dx = vec![f32::NAN; x.len()];
            mlp.backward(&mut ws, &dy, &mut grad, Some(&mut dx))
                .unwrap();
            let scale = (0..mlp.n_params())
                .step_by(stride)
                .map(|k| reference.fd_param_grad(&x, &dy, k, 1e-6).abs())
                .fold(1e-2, f64::max);
            for k in (0..mlp.n_params()).step_by(stride) {
                let fd = reference.fd_param_grad(&x, &dy, k, 1e-6);
                let got = f64::from(grad[k]) - 0.5;
                assert!(
                    (got - fd).abs() < 1e-4 * scale,
                    "{act} sizes {:?} param {k}: {got} vs finite difference {fd}",
                    mlp.sizes()
                );
            }
            // dx = Jᵀ·dy per sample.
            let (n_in, n_out) = (mlp.n_in(), mlp.n_out());
            for b in 0..batch {
                let xb: Vec<f64> = x[b * n_in..(b + 1) * n_in]
                    .iter()
                    .map(|&v| f64::from(v))
                    .collect();
                let j = reference.fd_jacobian(&xb, 1e-6);
                let want: Vec<f64> = (0..n_in)
                    .map(|i| {
                        (0..n_out)
                            .map(|o| j[o * n_in + i] * f64::from(dy[b * n_out + o]))
                            .sum()
                    })
                    .collect();
                let err = max_rel_err(&dx[b * n_in..(b + 1) * n_in], &want, 1e-2);
                assert!(err < 1e-4, "{act} dx sample {b}: rel err {err:.2e}");
            }
        }
    }
}

#[test]
fn vjp_and_jvp_are_adjoint() {
    // dyᵀ·(J·v) = (Jᵀ·dy)ᵀ·v, per sample, with the f32 JVP and VJP.
    for act in ACTS {
        for mlp in [pushing(act), car()] {
            if act != Activation::Gelu && mlp.n_in() == 8 {
                continue;
            }
            let (n_in, n_out) = (mlp.n_in(), mlp.n_out());
            let batch = 7;
            let x = data(51, batch * n_in, -1.5, 1.5);
            let v = data(52, batch * n_in, -1.0, 1.0);
            let w = data(53, batch * n_out, -1.0, 1.0);
            let mut ws = mlp.workspace();
            let jv = mlp.jvp(&x, &v, &mut ws).unwrap().1.to_vec();
            let mut grad = vec![0.0; mlp.n_params()];
            let mut jtw = vec![0.0; x.len()];
            mlp.backward(&mut ws, &w, &mut grad, Some(&mut jtw))
                .unwrap();
            for b in 0..batch {
                let lhs: f64 = (0..n_out)
                    .map(|o| f64::from(w[b * n_out + o]) * f64::from(jv[b * n_out + o]))
                    .sum();
                let rhs: f64 = (0..n_in)
                    .map(|i| f64::from(jtw[b * n_in + i]) * f64::from(v[b * n_in + i]))
                    .sum();
                // Rounding scales with the magnitude of the terms, not of their (possibly
                // cancelling) sum.
                let scale: f64 = (0..n_out)
                    .map(|o| f64::from((w[b * n_out + o] * jv[b * n_out + o]).abs()))
                    .sum::<f64>()
                    + (0..n_in)
                        .map(|i| f64::from((jtw[b * n_in + i] * v[b * n_in + i]).abs()))
                        .sum::<f64>();
                assert!(
                    (lhs - rhs).abs() < 1e-5 * scale,
                    "{act} sample {b}: {lhs} vs {rhs}"
                );
            }
        }
    }
}

#[test]
fn rows_are_independent_of_the_rest_of_the_batch() {
    // Row r of a batch evaluation equals the evaluation of row r alone, bit for bit.
    let mlp = pushing(Activation::Tanh);
    let x = data(61, 300 * 6, -2.0, 2.0);
    let mut ws = mlp.workspace();
    let all = mlp.forward(&x, &mut ws).unwrap().to_vec();
    let mut ws1 = mlp.workspace();
    for r in [0, 1, 150, 299] {
        let one = mlp.forward(&x[r * 6..(r + 1) * 6], &mut ws1).unwrap();
        assert_eq!(one, &all[r * 3..(r + 1) * 3], "row {r}");
    }
}

#[test]
fn a_single_row_forward_is_bitwise_that_row_of_a_batch_at_every_width() {
    // A batch of one runs its own kernel path (whole 64- or 32-column rows as independent
    // accumulators, for the sequential rollouts of the controllers); it must give every bit of
    // the same row evaluated in a batch.
    for width in [64, 96, 128, 40, 16, 3] {
        for act in [
            Activation::Gelu,
            Activation::Tanh,
            Activation::Relu,
            Activation::Identity,
        ] {
            let spec = MlpSpec::uniform(5, &[width, width, width], 3, act).unwrap();
            let mlp = Mlp::new(spec, Init::Auto, 7);
            let x = data(13, 37 * 5, -2.0, 2.0);
            let mut ws = mlp.workspace();
            let all = mlp.forward(&x, &mut ws).unwrap().to_vec();
            let mut ws1 = mlp.workspace();
            for r in [0, 1, 18, 36] {
                let one = mlp.forward(&x[r * 5..(r + 1) * 5], &mut ws1).unwrap();
                assert_eq!(
                    one,
                    &all[r * 3..(r + 1) * 3],
                    "width {width}, {act}, row {r}"
                );
            }
        }
    }
}

#[test]
fn same_seed_same_network_different_seed_different_network() {
    let spec = MlpSpec::uniform(6, &[100, 100], 3, Activation::Tanh).unwrap();
    let a = Mlp::new(spec.clone(), Init::Auto, 1);
    let b = Mlp::new(spec.clone(), Init::Auto, 1);
    let c = Mlp::new(spec.clone(), Init::Auto, 2);
    assert_eq!(a.params(), b.params());
    assert_ne!(a.params(), c.params());
    // Xavier bound for the first tanh layer: 5/3·√(6/106); output layer gain 1: √(6/103).
    let l0 = a.layer(0).unwrap();
    let bound0 = 5.0 / 3.0 * (6.0f32 / 106.0).sqrt();
    assert!(l0.weight.iter().all(|w| w.abs() <= bound0));
    assert!(l0.weight.iter().any(|w| w.abs() > 0.9 * bound0));
    assert!(l0.bias.iter().all(|&b| b == 0.0));
    let l2 = a.layer(2).unwrap();
    assert!(l2.weight.iter().all(|w| w.abs() <= (6.0f32 / 103.0).sqrt()));
    // Kaiming for GELU: √2·√(3/8).
    let g = Mlp::new(
        MlpSpec::uniform(8, &[64], 3, Activation::Gelu).unwrap(),
        Init::Auto,
        1,
    );
    let bound = 2f32.sqrt() * (3.0f32 / 8.0).sqrt();
    assert!(g.layer(0).unwrap().weight.iter().all(|w| w.abs() <= bound));
    assert!(
        g.layer(0)
            .unwrap()
            .weight
            .iter()
            .any(|w| w.abs() > 0.9 * bound)
    );
}

#[test]
fn splitmix64_reference_stream() {
    // Published SplitMix64 outputs for seed 0 (the first value is the well-known 0xE220A8397B1DCDAF);
    // they pin the initialisation stream on every platform.
    let mut rng = dynlab_nn::rng::SplitMix64::new(0);
    assert_eq!(rng.next_u64(), 0xE220_A839_7B1D_CDAF);
    assert_eq!(rng.next_u64(), 0x6E78_9E6A_A1B9_65F4);
    assert_eq!(rng.next_u64(), 0x06C4_5D18_8009_454F);
}

#[test]
fn bad_shapes_and_misuse_are_errors_not_panics() {
    let mlp = pushing(Activation::Tanh);
    let mut ws = mlp.workspace();
    assert!(matches!(
        mlp.forward(&[0.0; 7], &mut ws),
        Err(NnError::RaggedBatch { len: 7, n_in: 6 })
    ));
    assert!(matches!(
        mlp.backward(&mut ws, &[0.0; 3], &mut vec![0.0; mlp.n_params()], None),
        Err(NnError::NoTape)
    ));
    mlp.forward(&[0.0; 12], &mut ws).unwrap();
    let mut grad = vec![0.0; mlp.n_params()];
    assert!(matches!(
        mlp.backward(&mut ws, &[0.0; 3], &mut grad, None),
        Err(NnError::ShapeMismatch {
            what: "dy",
            expected: 6,
            got: 3
        })
    ));
    assert!(matches!(
        mlp.backward(&mut ws, &[0.0; 6], &mut grad[1..], None),
        Err(NnError::ShapeMismatch { what: "grad", .. })
    ));
    assert!(matches!(
        mlp.jvp(&[0.0; 6], &[0.0; 5], &mut ws),
        Err(NnError::ShapeMismatch { what: "dx", .. })
    ));
    let other = car();
    let err = other.forward(&[0.0; 8], &mut ws).unwrap_err();
    assert!(matches!(err, NnError::WorkspaceMismatch { .. }));
    assert!(err.to_string().contains("mlp.workspace()"), "{err}");
    assert!(MlpSpec::new(&[3], &[]).is_err());
    assert!(MlpSpec::new(&[3, 0, 2], &[Activation::Tanh]).is_err());
    let e = MlpSpec::new(&[3, 4, 2], &[]).unwrap_err();
    assert!(e.to_string().contains("need 1 activations"), "{e}");
    assert!("softplus".parse::<Activation>().is_err());
    assert_eq!("GELU".parse::<Activation>().unwrap(), Activation::Gelu);
    // An empty batch is valid and gives an empty output.
    assert!(mlp.forward(&[], &mut ws).unwrap().is_empty());
}

#[test]
fn backward_rows_do_not_depend_on_the_batch_block_shape() {
    // The reverse-mode kernels process 8, 4 or 1 rows per register block; a row's input gradient
    // must be the same bits whatever block it falls in, and the parameter gradient of a batch the
    // sum of its rows' gradients (up to the order of the sum). Batches of 37 and 13 rows exercise
    // every block shape and the column tails (widths 100, 64, 6, 3).
    for mlp in [
        pushing(Activation::Tanh),
        pushing(Activation::Gelu),
        pushing(Activation::Relu),
        car(),
    ] {
        let (n_in, n_out) = (mlp.n_in(), mlp.n_out());
        for batch in [13, 37] {
            let x = data(61 + batch as u64, batch * n_in, -1.5, 1.5);
            let dy = data(62 + batch as u64, batch * n_out, -1.0, 1.0);
            let mut ws = mlp.workspace();
            mlp.forward(&x, &mut ws).unwrap();
            let mut grad = vec![0.0f32; mlp.n_params()];
            let mut dx = vec![0.0f32; batch * n_in];
            mlp.backward(&mut ws, &dy, &mut grad, Some(&mut dx))
                .unwrap();
            let mut sum = vec![0.0f64; mlp.n_params()];
            for b in 0..batch {
                let mut ws1 = mlp.workspace();
                mlp.forward(&x[b * n_in..(b + 1) * n_in], &mut ws1).unwrap();
                let mut g1 = vec![0.0f32; mlp.n_params()];
                let mut dx1 = vec![0.0f32; n_in];
                mlp.backward(
                    &mut ws1,
                    &dy[b * n_out..(b + 1) * n_out],
                    &mut g1,
                    Some(&mut dx1),
                )
                .unwrap();
                assert_eq!(
                    dx1,
                    dx[b * n_in..(b + 1) * n_in],
                    "sizes {:?} batch {batch} row {b}",
                    mlp.sizes()
                );
                for (s, g) in sum.iter_mut().zip(&g1) {
                    *s += f64::from(*g);
                }
            }
            let err = max_rel_err(&grad, &sum, 1e-2);
            assert!(
                err < 1e-5,
                "sizes {:?} batch {batch}: rel err {err:.2e}",
                mlp.sizes()
            );
        }
    }
}

#[test]
fn packed_weights_follow_every_parameter_change() {
    // A workspace keeps the packed weights between calls; a parameter write, a clone that is then
    // changed, or another network of the same shape must never see stale packed weights.
    let mut mlp = pushing(Activation::Tanh);
    let other = net(&[6, 100, 100, 3], Activation::Tanh, 99);
    let x = data(5, 9 * 6, -1.0, 1.0);
    let dy = data(6, 9 * 3, -1.0, 1.0);
    let mut ws = mlp.workspace();
    let fresh = |m: &Mlp| {
        let mut w = m.workspace();
        let y = m.forward(&x, &mut w).unwrap().to_vec();
        let mut g = vec![0.0; m.n_params()];
        let mut dx = vec![0.0; x.len()];
        m.backward(&mut w, &dy, &mut g, Some(&mut dx)).unwrap();
        (y, g, dx)
    };
    let cached = |m: &Mlp, ws: &mut dynlab_nn::Workspace| {
        let y = m.forward(&x, ws).unwrap().to_vec();
        let mut g = vec![0.0; m.n_params()];
        let mut dx = vec![0.0; x.len()];
        m.backward(ws, &dy, &mut g, Some(&mut dx)).unwrap();
        (y, g, dx)
    };
    assert_eq!(cached(&mlp, &mut ws), fresh(&mlp));
    let before = mlp.clone();
    for p in mlp.params_mut().iter_mut() {
        *p *= 0.5;
    }
    let changed = cached(&mlp, &mut ws);
    assert_eq!(changed, fresh(&mlp));
    assert_ne!(changed.0, fresh(&before).0);
    assert_eq!(cached(&before, &mut ws), fresh(&before));
    assert_eq!(cached(&other, &mut ws), fresh(&other));
    assert_eq!(cached(&mlp, &mut ws), changed);
}
