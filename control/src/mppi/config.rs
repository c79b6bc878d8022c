//! Typed, validated, defaulted MPPI settings.

use serde::{Deserialize, Serialize};

use super::MppiError;

/// Lower bounds of Tu & Lin's action space `[p, φ, ℓ]`.
pub const ACTION_MIN: [f64; 3] = [-1.0, -std::f64::consts::FRAC_PI_2, 0.0];
/// Upper bounds of Tu & Lin's action space `[p, φ, ℓ]`.
pub const ACTION_MAX: [f64; 3] = [1.0, std::f64::consts::FRAC_PI_2, 1.0];

/// MPPI settings. Every field has a default (`#[serde(default)]`), so a YAML or TOML file needs
/// only the keys it changes; [`MppiConfig::validate`] names a bad key and what to set.
///
/// The defaults are the settings tuned on our simulator (see `control/README.md`); Tu & Lin's
/// were `samples = 100`, `horizon = 10`, `lambda = 0.01`, `sigma = 0.63` on every dimension
/// (covariance 0.4·I), `q = [1, 1, 0.1]`, `collision_cost = 100`, no terminal cost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MppiConfig {
    /// Samples per step `K`. Default 1000.
    pub samples: usize,
    /// Horizon `T` (pushes). Default 15.
    pub horizon: usize,
    /// Temperature `λ` of the importance weights `exp(−(S − S_min)/λ)`. Default 0.005.
    pub lambda: f64,
    /// Noise standard deviation per action dimension `[σ_p, σ_φ, σ_ℓ]`. Default `[0.5, 0.6, 0.3]`.
    pub sigma: [f64; 3],
    /// Goal weights `Q = diag(q)` on `(x, y, θ)` per step (angle error wrapped). Default
    /// `[1, 1, 0.1]` (Tu & Lin).
    pub q: [f64; 3],
    /// Terminal weights `Q_f = diag(q_terminal)` on the last predicted state. Default
    /// `[10, 10, 1]`.
    pub q_terminal: [f64; 3],
    /// Cost of one predicted state in collision (Tu & Lin: 100). Default 100.
    pub collision_cost: f64,
    /// Obstacles are inflated by this margin \[m\] in the cost (model error). Default 0.01.
    pub obstacle_margin: f64,
    /// Also test the midpoint between consecutive predicted poses for collision (a push moves
    /// the block up to 0.1 m, as far as an obstacle is thick). Default true.
    pub swept_collision: bool,
    /// Lower action bounds `[p, φ, ℓ]`; samples are clamped into them. Default Tu & Lin's.
    pub action_min: [f64; 3],
    /// Upper action bounds `[p, φ, ℓ]`. Default Tu & Lin's.
    pub action_max: [f64; 3],
    /// Correlation `β ∈ [0, 1)` of the noise between consecutive steps of a sample
    /// (`ε_t = β ε_{t−1} + √(1−β²) n_t`): smoother sampled sequences, SMPPI-style. Default 0.
    pub noise_correlation: f64,
    /// Keep one unperturbed sample (the warm-started sequence itself). Default true.
    pub keep_nominal: bool,
    /// Seed of the sampling noise. Default 0.
    pub seed: u64,
    /// Threads of the batched rollout (results do not depend on it). Default 2.
    pub threads: usize,
}

impl Default for MppiConfig {
    fn default() -> Self {
        Self {
            samples: 1000,
            horizon: 15,
            lambda: 0.005,
            sigma: [0.5, 0.6, 0.3],
            q: [1.0, 1.0, 0.1],
            q_terminal: [10.0, 10.0, 1.0],
            collision_cost: 100.0,
            obstacle_margin: 0.01,
            swept_collision: true,
            action_min: ACTION_MIN,
            action_max: ACTION_MAX,
            noise_correlation: 0.0,
            keep_nominal: true,
            seed: 0,
            threads: 2,
        }
    }
}

impl MppiConfig {
    /// Tu & Lin's controller: K = 100, T = 10, λ = 0.01, σ² = 0.4, Q = diag(1, 1, 0.1),
    /// collision penalty 100, no terminal cost, no margin, no swept test.
    pub fn tu_lin() -> Self {
        let s = 0.4f64.sqrt();
        Self {
            samples: 100,
            horizon: 10,
            lambda: 0.01,
            sigma: [s, s, s],
            q_terminal: [0.0; 3],
            obstacle_margin: 0.0,
            swept_collision: false,
            keep_nominal: false,
            ..Self::default()
        }
    }

    /// Checks every field; the error names the key and the fix.
    pub fn validate(&self) -> Result<(), MppiError> {
        let bad = |key: &'static str, value: String, fix: &'static str| {
            Err(MppiError::Setting { key, value, fix })
        };
        if self.samples < 2 {
            return bad(
                "samples",
                self.samples.to_string(),
                "set samples (K) to at least 2",
            );
        }
        if self.horizon == 0 {
            return bad(
                "horizon",
                self.horizon.to_string(),
                "set horizon (T) to at least 1",
            );
        }
        if !(self.lambda.is_finite() && self.lambda > 0.0) {
            return bad(
                "lambda",
                self.lambda.to_string(),
                "set lambda to a finite temperature > 0",
            );
        }
        for (key, v) in [
            ("sigma", self.sigma),
            ("q", self.q),
            ("q_terminal", self.q_terminal),
        ] {
            if v.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
                return bad(key, format!("{v:?}"), "every entry must be finite and ≥ 0");
            }
        }
        if !(self.collision_cost.is_finite() && self.collision_cost >= 0.0) {
            return bad(
                "collision_cost",
                self.collision_cost.to_string(),
                "set a finite cost ≥ 0",
            );
        }
        if !(self.obstacle_margin.is_finite() && self.obstacle_margin >= 0.0) {
            return bad(
                "obstacle_margin",
                self.obstacle_margin.to_string(),
                "set a finite margin ≥ 0 (m)",
            );
        }
        for d in 0..3 {
            let (lo, hi) = (self.action_min[d], self.action_max[d]);
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return bad(
                    "action_min/action_max",
                    format!("{:?} / {:?}", self.action_min, self.action_max),
                    "bounds must be finite with action_min ≤ action_max in every dimension",
                );
            }
        }
        if !(self.noise_correlation.is_finite() && (0.0..1.0).contains(&self.noise_correlation)) {
            return bad(
                "noise_correlation",
                self.noise_correlation.to_string(),
                "set β within [0, 1)",
            );
        }
        if self.threads == 0 {
            return bad("threads", "0".into(), "set threads to at least 1");
        }
        Ok(())
    }
}
