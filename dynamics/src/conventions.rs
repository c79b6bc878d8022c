//! State and action conventions of the two robots, angle helpers, and the losses and metrics of
//! the papers as plain functions.
//!
//! | robot | state | input | step |
//! |---|---|---|---|
//! | pushing (Tu & Lin) | block pose `(x, y, θ)` \[m, m, rad\] in the table frame | one push `(p, φ, ℓ)`: location on the pushed edge ∈ [−1, 1], angle ∈ [−π/2, π/2], length ∈ [0, 1] × 0.1 m | one push (normalised time 0 → 1) |
//! | car (Kohler et al.) | `(x, y, ψ, vx, vy, ω)`: world pose and body-frame velocities \[m/s, m/s, rad/s\] | `(δ, d)`: front wheel angle \[rad\], normalised throttle | `dt` \[s\] |

use std::f64::consts::PI;

/// Dimension of the pushing state `(x, y, θ)`.
pub const PUSH_STATE_DIM: usize = 3;
/// Dimension of the pushing action `(p, φ, ℓ)`.
pub const PUSH_ACTION_DIM: usize = 3;
/// Index of the block angle θ in the pushing state.
pub const PUSH_ANGLE_INDEX: usize = 2;
/// Maximum push length: `ℓ = 1` pushes 0.1 m (Tu & Lin).
pub const PUSH_MAX_LENGTH_M: f64 = 0.1;
/// Dimension of the car state `(x, y, ψ, vx, vy, ω)`.
pub const CAR_STATE_DIM: usize = 6;
/// Dimension of the car input `(δ, d)`.
pub const CAR_INPUT_DIM: usize = 2;
/// Index of the heading ψ in the car state.
pub const CAR_ANGLE_INDEX: usize = 2;

/// Block pose on the table.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PushState {
    /// Position x \[m\].
    pub x: f64,
    /// Position y \[m\].
    pub y: f64,
    /// Orientation θ \[rad\].
    pub theta: f64,
}

/// One push, held over one model step.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PushAction {
    /// Location p ∈ [−1, 1] along the block's pushed edge.
    pub p: f64,
    /// Angle φ ∈ [−π/2, π/2] of the push from the edge normal \[rad\].
    pub phi: f64,
    /// Length ℓ ∈ [0, 1], a fraction of [`PUSH_MAX_LENGTH_M`].
    pub length: f64,
}

/// Car state: world pose and body-frame velocities.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CarState {
    /// Position x \[m\].
    pub x: f64,
    /// Position y \[m\].
    pub y: f64,
    /// Heading ψ \[rad\].
    pub psi: f64,
    /// Longitudinal body velocity vx \[m/s\].
    pub vx: f64,
    /// Lateral body velocity vy \[m/s\].
    pub vy: f64,
    /// Yaw rate ω \[rad/s\].
    pub omega: f64,
}

/// Car input, held over one model step.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CarInput {
    /// Front wheel angle δ \[rad\].
    pub delta: f64,
    /// Normalised throttle d (−1 … 1).
    pub d: f64,
}

impl PushState {
    /// As an array `[x, y, θ]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.theta]
    }
    /// From an array `[x, y, θ]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        Self {
            x: a[0],
            y: a[1],
            theta: a[2],
        }
    }
}
impl PushAction {
    /// As an array `[p, φ, ℓ]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.p, self.phi, self.length]
    }
    /// From an array `[p, φ, ℓ]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        Self {
            p: a[0],
            phi: a[1],
            length: a[2],
        }
    }
}
impl CarState {
    /// As an array `[x, y, ψ, vx, vy, ω]`.
    pub fn to_array(self) -> [f64; 6] {
        [self.x, self.y, self.psi, self.vx, self.vy, self.omega]
    }
    /// From an array `[x, y, ψ, vx, vy, ω]`.
    pub fn from_array(a: [f64; 6]) -> Self {
        Self {
            x: a[0],
            y: a[1],
            psi: a[2],
            vx: a[3],
            vy: a[4],
            omega: a[5],
        }
    }
}
impl CarInput {
    /// As an array `[δ, d]`.
    pub fn to_array(self) -> [f64; 2] {
        [self.delta, self.d]
    }
    /// From an array `[δ, d]`.
    pub fn from_array(a: [f64; 2]) -> Self {
        Self {
            delta: a[0],
            d: a[1],
        }
    }
}

/// Wraps an angle to `[−π, π)`.
pub fn wrap_angle(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    // rem_euclid can return 2π for tiny negative inputs through rounding
    if w >= PI { w - 2.0 * PI } else { w }
}

/// Unwraps a sequence of angles in place: adds multiples of 2π so consecutive samples never
/// jump by more than π.
pub fn unwrap_angles(a: &mut [f64]) {
    for i in 1..a.len() {
        let d = wrap_angle(a[i] - a[i - 1]);
        a[i] = a[i - 1] + d;
    }
}

/// Yaw of a unit quaternion `(x, y, z, w)` (rotation about z; roll and pitch ignored).
pub fn yaw_from_quaternion(x: f64, y: f64, z: f64, w: f64) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// Pose error `predicted − measured` with the listed angle dimensions wrapped to `[−π, π)`.
pub fn pose_error(predicted: &[f64], measured: &[f64], angle_dims: &[usize], out: &mut [f64]) {
    for (i, o) in out.iter_mut().enumerate() {
        let e = predicted[i] - measured[i];
        *o = if angle_dims.contains(&i) {
            wrap_angle(e)
        } else {
            e
        };
    }
}

/// Norm used by [`l_rel`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum LossNorm {
    /// Sum of absolute values (Kohler et al. eq. 11 as published).
    L1,
    /// Euclidean norm.
    L2,
}

fn norm(v: impl Iterator<Item = f64>, n: LossNorm) -> f64 {
    match n {
        LossNorm::L1 => v.map(f64::abs).sum(),
        LossNorm::L2 => v.map(|x| x * x).sum::<f64>().sqrt(),
    }
}

/// Relative loss of Kohler et al. (eq. 11) for one sample:
/// `L_rel = ‖v_{i+1} − v̂_{i+1}‖ / (‖v_{i+1}‖ + ε)` with `v` the measured next velocities and `v̂`
/// the prediction.
pub fn l_rel(predicted: &[f64], measured: &[f64], eps: f64, n: LossNorm) -> f64 {
    let num = norm(predicted.iter().zip(measured).map(|(p, m)| m - p), n);
    let den = norm(measured.iter().copied(), n) + eps;
    num / den
}

/// Mean of [`l_rel`] over a batch of rows of width `dim`.
pub fn l_rel_mean(predicted: &[f64], measured: &[f64], dim: usize, eps: f64, n: LossNorm) -> f64 {
    let rows = predicted.len() / dim.max(1);
    if rows == 0 {
        return 0.0;
    }
    let s: f64 = predicted
        .chunks_exact(dim)
        .zip(measured.chunks_exact(dim))
        .map(|(p, m)| l_rel(p, m, eps, n))
        .sum();
    s / rows as f64
}

/// Trajectory validation error of Kohler et al. (eq. 10): the mean over validation trajectories
/// of the L1 norm of the final pose error `(x, y, ψ)` (angle wrapped). Each item is
/// `(predicted final pose, measured final pose)`. Returns 0 for no trajectories.
pub fn tve(finals: &[([f64; 3], [f64; 3])]) -> f64 {
    if finals.is_empty() {
        return 0.0;
    }
    let s: f64 = finals
        .iter()
        .map(|(p, m)| {
            let mut e = [0.0; 3];
            pose_error(p, m, &[2], &mut e);
            e.iter().map(|x| x.abs()).sum::<f64>()
        })
        .sum();
    s / finals.len() as f64
}

/// Discounted multi-step pose loss of Tu & Lin (eq. 11) for one window:
/// `Σ_{i=1..k} γ^{i−1} Σ_d w_d · e_{i,d}²` with `e` the pose error (angles wrapped) and `w` the
/// per-dimension weights (their evaluation: `w = (1, 1, 0.0408)`, MSE per dimension).
/// `predicted` and `measured` hold `k` rows of width `w.len()`.
pub fn discounted_pose_loss(
    predicted: &[f64],
    measured: &[f64],
    weights: &[f64],
    angle_dims: &[usize],
    gamma: f64,
) -> f64 {
    let dim = weights.len();
    let mut e = vec![0.0; dim];
    let mut g = 1.0;
    let mut total = 0.0;
    for (p, m) in predicted.chunks_exact(dim).zip(measured.chunks_exact(dim)) {
        pose_error(p, m, angle_dims, &mut e);
        total += g * e.iter().zip(weights).map(|(x, w)| w * x * x).sum::<f64>();
        g *= gamma;
    }
    total
}
