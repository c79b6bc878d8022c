//! Hidden-layer activation functions.

use std::fmt;
use std::str::FromStr;

use crate::NnError;

/// The nonlinearity applied after a hidden layer's affine map. The output layer is always linear.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Activation {
    /// Hyperbolic tangent, evaluated with the rational approximation [`crate::math::tanh`]
    /// (max abs error 3.5e-7); its derivative is computed from the output as 1 − y².
    Tanh,
    /// Gaussian error linear unit in its exact form x·Φ(x) = ½x(1 + erf(x/√2)), as PyTorch's
    /// default `nn.GELU()` (not the tanh approximation, which differs by up to 5e-4 and would make
    /// a model trained with PyTorch evaluate differently here). See [`crate::math::gelu`].
    Gelu,
    /// max(0, x); its derivative is taken as 0 at x = 0 (as PyTorch does).
    Relu,
    /// No nonlinearity.
    Identity,
}

impl Activation {
    /// The name used in files and on the command line: `tanh`, `gelu`, `relu`, `identity`.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Tanh => "tanh",
            Activation::Gelu => "gelu",
            Activation::Relu => "relu",
            Activation::Identity => "identity",
        }
    }

    /// Whether the backward pass needs the pre-activation z (GELU) rather than the output y.
    pub(crate) fn needs_preactivation(self) -> bool {
        matches!(self, Activation::Gelu)
    }

    /// Gain used by Xavier initialisation for this nonlinearity (PyTorch's `calculate_gain`).
    pub(crate) fn xavier_gain(self) -> f64 {
        match self {
            Activation::Tanh => 5.0 / 3.0,
            Activation::Relu | Activation::Gelu => std::f64::consts::SQRT_2,
            Activation::Identity => 1.0,
        }
    }
}

impl fmt::Display for Activation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Activation {
    type Err = NnError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "tanh" => Ok(Activation::Tanh),
            "gelu" => Ok(Activation::Gelu),
            "relu" => Ok(Activation::Relu),
            "identity" | "linear" | "none" => Ok(Activation::Identity),
            _ => Err(NnError::UnknownActivation(s.to_string())),
        }
    }
}
