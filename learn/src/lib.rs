//! Learned and fitted dynamics models of the two robots: every model kind behind one [`Model`]
//! type, one model file format, training from bags, and evaluation.
//!
//! | module | what |
//! |---|---|
//! | [`world`] | the two robots: states, actions, topics, the part of the state a network learns |
//! | [`dataset`] | bags → model-state trajectories (topic contract, world inference, bag hashes) |
//! | [`net`] | the MLP with its normalisation, as a vector field for the ODE solvers |
//! | [`model`] | [`Model`]: `residual`, `node-euler`, `node-rk4`, `node-dopri5`, `physics`, `hybrid`; steps, rollouts, exact input Jacobians, the fast batched rollout for MPPI |
//! | [`file`](mod@file) | the model directory: `model.json` + `weights.safetensors`, validated on load |
//! | [`train`](mod@train) | discounted multi-step training (Adam, seeded, best-validation checkpoint), physics fitting (bounded Levenberg–Marquardt) |
//! | [`eval`] | one-step and k-step errors per dimension, TVE |
//!
//! No wall clock and no unseeded randomness: seeds are inputs, and the same seed on the same data
//! gives a bit-identical model file on any number of threads.
#![warn(missing_docs)]
#![allow(clippy::needless_range_loop)]

pub mod augment;
pub mod dataset;
mod error;
pub mod eval;
pub mod file;
pub mod fit;
pub mod model;
pub mod net;
pub mod smooth;
pub mod train;
pub mod world;

pub use dataset::{
    BagSource, Dataset, LoadOptions, Stamps, TfFrames, TimedDataset, Topics, data_warnings,
    excitation_warnings, load_bags, load_bags_timed, load_bags_timed_at, load_bags_with,
    pipeline_notes, smoothing_note,
};
pub use dynlab_dynamics as dynamics;
pub use error::LearnError;

pub use model::{Model, ModelKind, RolloutWorkspace, StepJacobians};
pub use net::{Network, Normalization};

pub use eval::{EvalReport, evaluate};
pub use file::{ModelFile, load_model, save_model};
pub use train::{
    CAR_JUDGED_STEPS, KindDefaults, Loss, Progress, Split, TrainConfig, TrainOutcome, train,
};
pub use world::World;
