//! The one error type of the simulator library.

use std::path::PathBuf;

/// Everything that can go wrong when building or driving a simulated world.
///
/// Outcomes of a simulation (a push that lost contact, a car that left the floor) are data in
/// the returned structs, never errors; errors are bad inputs, each naming what to change.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A scenario value is impossible; `key` is the dotted TOML key.
    #[error("{key}: {message}")]
    Invalid {
        /// Dotted key in the scenario file, e.g. `effects.friction_patch.mu`.
        key: String,
        /// What is wrong and what to set instead.
        message: String,
    },
    /// The scenario file is not valid TOML or does not match the schema.
    #[error("scenario {origin}: {message}")]
    Parse {
        /// File name or `<string>`.
        origin: String,
        /// The key (when known), the line and what is expected.
        message: String,
    },
    /// A file could not be read.
    #[error("cannot read {path}: {source} (check the path and its permissions)")]
    Io {
        /// The path that failed.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A command or action given to a world is not usable (non-finite, out of range).
    #[error("invalid input {what}: {message}")]
    Input {
        /// Which input, e.g. `PushAction.location`.
        what: &'static str,
        /// What is wrong and what range is accepted.
        message: String,
    },
    /// A track file does not have the expected layout.
    #[error("track {origin}: {message}")]
    Track {
        /// File name or `<string>`.
        origin: String,
        /// What is wrong.
        message: String,
    },
}

impl SimError {
    /// Shorthand for [`SimError::Invalid`].
    pub(crate) fn invalid(key: impl Into<String>, message: impl Into<String>) -> Self {
        SimError::Invalid {
            key: key.into(),
            message: message.into(),
        }
    }

    /// The dotted scenario key this error is about, if any.
    pub fn key(&self) -> Option<&str> {
        match self {
            SimError::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }
}
