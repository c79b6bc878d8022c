//! Small exact multilayer perceptrons for learned robot dynamics: batched forward pass, reverse
//! mode (vector–Jacobian products for training), forward mode (Jacobian–vector products), batched
//! input Jacobians, Adam, and safetensors checkpoints — in `f32` on the `matrixmultiply` GEMM,
//! without an ML framework.
//!
//! The networks here are tiny (the pushing model 6 → 100 → 100 → 3 has 11k parameters), so the
//! cost is in the element-wise activations and in per-call overhead, not in matrix products. The
//! crate therefore evaluates tanh with a branch-free rational approximation ([`math::tanh`], max
//! abs error 3.5e-7) compiled for AVX2 + FMA and selected at run time ([`simd_level`]), keeps every
//! buffer in a reusable [`Workspace`], and splits large batches over threads with results
//! independent of the thread count ([`parallel`]).
//!
//! ```
//! use dynlab_nn::{Activation, Adam, AdamConfig, Init, Mlp, MlpSpec};
//!
//! let spec = MlpSpec::uniform(2, &[16, 16], 1, Activation::Tanh)?;
//! let mut mlp = Mlp::new(spec, Init::Auto, 7);
//! let mut ws = mlp.workspace();
//! let mut adam = Adam::new(mlp.n_params(), AdamConfig { lr: 1e-2, ..Default::default() })?;
//! let mut grad = vec![0.0; mlp.n_params()];
//! // Fit y = x0·x1 on four points.
//! let x = [0.5, 0.5, -0.5, 0.5, 0.5, -0.5, -0.5, -0.5];
//! let target = [0.25, -0.25, -0.25, 0.25];
//! for _ in 0..300 {
//!     let y = mlp.forward(&x, &mut ws)?;
//!     let dy: Vec<f32> = y.iter().zip(&target).map(|(y, t)| 2.0 * (y - t) / 4.0).collect();
//!     grad.fill(0.0);
//!     mlp.backward(&mut ws, &dy, &mut grad, None)?;
//!     let params = mlp.params_mut();
//!     adam.step(params, &grad)?;
//! }
//! let y = mlp.forward(&x, &mut ws)?;
//! assert!((y[0] - 0.25).abs() < 0.02);
//! # Ok::<(), dynlab_nn::NnError>(())
//! ```
#![warn(missing_docs)]

mod activation;
mod adam;
mod error;
mod io;
mod kernels;
pub mod math;
mod mlp;
pub mod parallel;
pub mod rng;

pub use activation::Activation;
pub use adam::{Adam, AdamConfig, WeightDecay};
pub use error::NnError;
pub use io::{METADATA_ACTIVATIONS, METADATA_SIZES};
pub use kernels::{simd_level, use_avx512, use_fma};
pub use mlp::{Init, JacobianMode, LayerShape, LayerView, Mlp, MlpSpec, Workspace};
