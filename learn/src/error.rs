//! The error type of the crate: every message names the problem and what to do about it.

use std::path::PathBuf;

use dynlab_bag::BagError;
use dynlab_dynamics::data::DataError;
use dynlab_dynamics::physics::ModelError;
use dynlab_nn::NnError;
use thiserror::Error;

/// Errors of loading data, building, training, saving and loading models.
#[derive(Debug, Error)]
pub enum LearnError {
    /// A bag could not be read.
    #[error("reading bag {path}: {source}")]
    Bag {
        /// The bag.
        path: PathBuf,
        /// What went wrong.
        #[source]
        source: BagError,
    },
    /// The data pipeline rejected the data (too little, NaN, no commands, …).
    #[error("{0}")]
    Data(#[from] DataError),
    /// The physics model rejected a setting (unknown effect, parameter out of bounds, …).
    #[error("physics model: {0}")]
    Physics(#[from] ModelError),
    /// The network module rejected an input or a weights file.
    #[error("network: {0}")]
    Nn(#[from] NnError),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The world (push or car) could not be inferred from a bag's topics.
    #[error(
        "cannot tell whether {path} holds pushing or car data: it has neither /push/block_pose nor /car/pose (topics: {topics}); pass --world push|car with --pose-topic and --cmd-topic"
    )]
    UnknownWorld {
        /// The bag.
        path: PathBuf,
        /// Topics it has.
        topics: String,
    },
    /// Data or a model of one world used with the other.
    #[error("world mismatch: {what} is {found}, expected {expected}; {hint}")]
    WorldMismatch {
        /// What was checked (`the model`, `bag x`).
        what: String,
        /// Its world.
        found: String,
        /// The world required.
        expected: String,
        /// What to do.
        hint: String,
    },
    /// A model file of another kind than the one asked for.
    #[error(
        "model file {path} holds a {found} model, not a {expected} model; train a {expected} model or load it without requiring a kind"
    )]
    KindMismatch {
        /// The model directory.
        path: PathBuf,
        /// Kind in the file.
        found: String,
        /// Kind required.
        expected: String,
    },
    /// A model file written by a newer dynlab.
    #[error(
        "model file {path} has format version {found}, this dynlab reads up to version {supported}; update dynlab to load it"
    )]
    NewerFormat {
        /// The model directory.
        path: PathBuf,
        /// Version in the file.
        found: u32,
        /// Newest version this build reads.
        supported: u32,
    },
    /// A model file that does not parse or does not agree with itself.
    #[error("model file {path} is invalid: {reason}; re-train or re-save the model")]
    CorruptModel {
        /// The file or directory.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// An unknown model kind name.
    #[error(
        "unknown model kind '{name}'; choose one of residual, node-euler, node-rk4, node-dopri5, physics, hybrid"
    )]
    UnknownKind {
        /// The name given.
        name: String,
    },
    /// A setting out of range or inconsistent with the others.
    #[error("invalid setting {name} = {value}: {hint}")]
    InvalidSetting {
        /// Setting name.
        name: &'static str,
        /// The value.
        value: String,
        /// What is allowed.
        hint: String,
    },
    /// Array arguments of inconsistent lengths.
    #[error("{what} has length {got}, expected {expected} ({hint})")]
    Shape {
        /// Which argument.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
        /// The layout expected.
        hint: &'static str,
    },
    /// A NaN or infinite value in a model input.
    #[error("non-finite value in {what} at index {index} ({value}); check the input for NaN")]
    NonFinite {
        /// Which argument.
        what: &'static str,
        /// Index of the value.
        index: usize,
        /// The value.
        value: f64,
    },
    /// The training loss became NaN or infinite.
    #[error(
        "training diverged at epoch {epoch} (loss {loss}); lower the learning rate (--lr) or check the data for outliers"
    )]
    Diverged {
        /// Epoch (1-based).
        epoch: usize,
        /// The loss.
        loss: f64,
    },
}

impl LearnError {
    pub(crate) fn setting(
        name: &'static str,
        value: impl ToString,
        hint: impl Into<String>,
    ) -> Self {
        LearnError::InvalidSetting {
            name,
            value: value.to_string(),
            hint: hint.into(),
        }
    }
}
