//! The crate's error type.

use safetensors::SafeTensorError;

/// Everything that can go wrong building, running, training or loading a network. Each message
/// names the problem and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum NnError {
    /// The layer sizes or activations do not describe a valid network.
    #[error("invalid network architecture: {reason}")]
    InvalidArchitecture {
        /// What is wrong.
        reason: String,
    },
    /// An activation name that is not one of `tanh`, `gelu`, `relu`, `identity`.
    #[error("unknown activation `{0}`: use one of tanh, gelu, relu, identity")]
    UnknownActivation(String),
    /// A slice passed in has the wrong length for the network and batch.
    #[error(
        "{what} has {got} values but {expected} were expected \
         (row-major batch × width; check the batch size and the network's layer sizes)"
    )]
    ShapeMismatch {
        /// Which argument.
        what: &'static str,
        /// Length needed.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// The batch length is not a multiple of the input width.
    #[error(
        "input has {len} values, not a multiple of the network's input width {n_in}: \
         pass batch × {n_in} values, row-major"
    )]
    RaggedBatch {
        /// Length given.
        len: usize,
        /// Network input width.
        n_in: usize,
    },
    /// A workspace made for another architecture.
    #[error(
        "workspace was made for a network with layer sizes {workspace:?}, this one has {network:?}: \
         create it with `mlp.workspace()`"
    )]
    WorkspaceMismatch {
        /// Sizes the workspace was made for.
        workspace: Vec<usize>,
        /// Sizes of the network.
        network: Vec<usize>,
    },
    /// `backward` without a preceding `forward` on the same workspace.
    #[error(
        "the workspace holds no forward pass to differentiate: call `forward(x, ws)` on it \
         (with the same parameters) before `backward`"
    )]
    NoTape,
    /// A parallel call without any workspace.
    #[error("parallel evaluation needs at least one workspace (one per thread)")]
    NoWorkspaces,
    /// An optimiser setting out of range.
    #[error("invalid optimiser setting {name} = {value}: {reason}")]
    InvalidHyperparameter {
        /// Setting name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What the valid range is.
        reason: &'static str,
    },
    /// The bytes are not a readable safetensors file.
    #[error("cannot read the safetensors data: {0} (is the file complete and really safetensors?)")]
    Safetensors(#[from] SafeTensorError),
    /// A tensor the architecture needs is absent.
    #[error(
        "tensor `{name}` is missing from the file: it does not hold this architecture's \
         parameters (check the layer sizes and the name prefix)"
    )]
    MissingTensor {
        /// Tensor name.
        name: String,
    },
    /// A tensor named like one of this network's but not part of it (for example one layer too many).
    #[error(
        "tensor `{name}` is not part of a network with layer sizes {sizes:?}: the file holds a \
         different architecture"
    )]
    UnexpectedTensor {
        /// Tensor name.
        name: String,
        /// This network's sizes.
        sizes: Vec<usize>,
    },
    /// A tensor with the wrong shape.
    #[error(
        "tensor `{name}` has shape {got:?} but the architecture needs {expected:?} \
         (weights are [out, in] as in PyTorch's nn.Linear)"
    )]
    TensorShape {
        /// Tensor name.
        name: String,
        /// Shape needed.
        expected: Vec<usize>,
        /// Shape found.
        got: Vec<usize>,
    },
    /// A tensor that is not 32-bit float.
    #[error(
        "tensor `{name}` has dtype {got}, but parameters must be F32: convert it with `.float()` before saving"
    )]
    TensorDtype {
        /// Tensor name.
        name: String,
        /// Dtype found.
        got: String,
    },
    /// A NaN or infinite parameter.
    #[error(
        "tensor `{name}` holds a non-finite value ({value}) at flat index {index}: the model diverged or the file is corrupt"
    )]
    NonFinite {
        /// Tensor name.
        name: String,
        /// Flat index in the tensor.
        index: usize,
        /// The value.
        value: f32,
    },
    /// Architecture metadata missing from a file loaded without a declared architecture.
    #[error(
        "the file has no `{key}` metadata, so its architecture is unknown: load it into a network \
         you construct with `Mlp::load_safetensors`"
    )]
    MissingMetadata {
        /// Metadata key.
        key: &'static str,
    },
    /// Unparseable architecture metadata.
    #[error("metadata `{key}` = `{value}` is invalid: {reason}")]
    BadMetadata {
        /// Metadata key.
        key: &'static str,
        /// Value found.
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A file could not be read or written.
    #[error("cannot access `{path}`: {source}")]
    Io {
        /// Path.
        path: std::path::PathBuf,
        /// Cause.
        source: std::io::Error,
    },
}
