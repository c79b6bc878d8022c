//! The Adam optimiser (Kingma & Ba 2015) over one flat parameter slice.

use crate::{NnError, kernels};

/// Weight decay variants.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum WeightDecay {
    /// No decay.
    #[default]
    None,
    /// λ·θ added to the gradient before the moments (PyTorch `Adam(weight_decay=λ)`).
    L2(f32),
    /// θ ← θ·(1 − lr·λ) before the Adam step, decoupled from the moments (PyTorch `AdamW`).
    Decoupled(f32),
}

/// Adam settings. The defaults are the paper's (and PyTorch's): lr 1e-3, β1 0.9, β2 0.999,
/// ε 1e-8, no weight decay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamConfig {
    /// Learning rate (step size) α > 0.
    pub lr: f32,
    /// Decay of the first-moment estimate, in [0, 1).
    pub beta1: f32,
    /// Decay of the second-moment estimate, in [0, 1).
    pub beta2: f32,
    /// Added to √v̂ to avoid division by zero, > 0.
    pub eps: f32,
    /// Optional weight decay.
    pub weight_decay: WeightDecay,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: WeightDecay::None,
        }
    }
}

impl AdamConfig {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), NnError> {
        let bad = |name, value: f32, reason| {
            Err(NnError::InvalidHyperparameter {
                name,
                value: f64::from(value),
                reason,
            })
        };
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad(
                "lr",
                self.lr,
                "the learning rate must be finite and > 0 (typical 1e-3)",
            );
        }
        if !(0.0..1.0).contains(&self.beta1) {
            return bad("beta1", self.beta1, "must be in [0, 1) (default 0.9)");
        }
        if !(0.0..1.0).contains(&self.beta2) {
            return bad("beta2", self.beta2, "must be in [0, 1) (default 0.999)");
        }
        if !(self.eps.is_finite() && self.eps > 0.0) {
            return bad("eps", self.eps, "must be finite and > 0 (default 1e-8)");
        }
        match self.weight_decay {
            WeightDecay::L2(l) | WeightDecay::Decoupled(l) if !(l.is_finite() && l >= 0.0) => {
                bad("weight_decay", l, "must be finite and ≥ 0")
            }
            _ => Ok(()),
        }
    }
}

/// Adam state: first and second moments per parameter and the step count.
#[derive(Debug, Clone, PartialEq)]
pub struct Adam {
    config: AdamConfig,
    m: Vec<f32>,
    v: Vec<f32>,
    t: u64,
    beta1_t: f64,
    beta2_t: f64,
}

impl Adam {
    /// Fresh state for `n_params` parameters.
    pub fn new(n_params: usize, config: AdamConfig) -> Result<Self, NnError> {
        config.validate()?;
        Ok(Self {
            config,
            m: vec![0.0; n_params],
            v: vec![0.0; n_params],
            t: 0,
            beta1_t: 1.0,
            beta2_t: 1.0,
        })
    }

    /// The settings.
    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// Changes the learning rate (for a schedule).
    pub fn set_lr(&mut self, lr: f32) -> Result<(), NnError> {
        let config = AdamConfig { lr, ..self.config };
        config.validate()?;
        self.config = config;
        Ok(())
    }

    /// Number of steps taken.
    pub fn steps(&self) -> u64 {
        self.t
    }

    /// First- and second-moment estimates (for checkpointing).
    pub fn moments(&self) -> (&[f32], &[f32]) {
        (&self.m, &self.v)
    }

    /// One step: updates `params` in place from `grads` (both the optimiser's length).
    ///
    /// θ ← θ − lr·m̂/(√v̂ + ε) with m̂ = m/(1 − β1ᵗ), v̂ = v/(1 − β2ᵗ), computed as PyTorch does:
    /// (lr/(1 − β1ᵗ))·m / (√v/√(1 − β2ᵗ) + ε). The powers βᵗ are running products in `f64`.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32]) -> Result<(), NnError> {
        let n = self.m.len();
        for (what, len) in [("params", params.len()), ("grads", grads.len())] {
            if len != n {
                return Err(NnError::ShapeMismatch {
                    what,
                    expected: n,
                    got: len,
                });
            }
        }
        self.t += 1;
        self.beta1_t *= f64::from(self.config.beta1);
        self.beta2_t *= f64::from(self.config.beta2);
        let lr = f64::from(self.config.lr);
        let step = (lr / (1.0 - self.beta1_t)) as f32;
        let inv_sqrt_bc2 = (1.0 / (1.0 - self.beta2_t).sqrt()) as f32;
        let (l2, decoupled) = match self.config.weight_decay {
            WeightDecay::None => (0.0, 0.0),
            WeightDecay::L2(l) => (l, 0.0),
            WeightDecay::Decoupled(l) => (0.0, (lr * f64::from(l)) as f32),
        };
        let coefs = [
            self.config.beta1,
            self.config.beta2,
            step,
            inv_sqrt_bc2,
            self.config.eps,
            l2,
            decoupled,
        ];
        kernels::adam_update(params, grads, &mut self.m, &mut self.v, coefs);
        Ok(())
    }
}
