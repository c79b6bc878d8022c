//! The learned model with a zero-order input hold: rollouts and exact linearisations.

use dynlab_learn::dynamics::ode::{Solver, VectorField, integrate};
use dynlab_learn::model::car_pose_update;
use dynlab_learn::net::NetField;
use dynlab_learn::{Model, ModelKind, StepJacobians, World};

use super::RacingError;

/// Car state `[x, y, ψ, vx, vy, ω]` (m, m, rad, m/s, m/s, rad/s; velocities in the body frame).
pub type State = [f64; 6];
/// Car input `[δ, d]`: steering \[rad\] and throttle.
pub type Input = [f64; 2];

/// A discrete-time car model `x⁺ = f(x, u)` over one model step `dt`: what the optimiser
/// needs from a model. Implemented by every learned [`Model`] (exact Jacobians) and by
/// [`SimCar`](super::SimCar), the simulator itself (the "true model").
pub trait CarDynamics: std::fmt::Debug + Sync {
    /// Model step \[s\].
    fn dt(&self) -> f64;
    /// Checks that this is a car model.
    fn check(&self) -> Result<(), RacingError> {
        Ok(())
    }
    /// Rollout as [`Model::rollout`]: `s0` is `m × 6`, `actions` step-major `k × m × 2`, `out`
    /// receives `k × m × 6`. Non-finite states propagate (no error).
    fn rollout(&self, s0: &[f64], actions: &[f64], out: &mut [f64]) -> Result<(), RacingError>;
    /// Next states and step Jacobians for a batch, as [`Model::jacobians`].
    fn jacobians(&self, s: &[f64], u: &[f64]) -> Result<StepJacobians, RacingError>;
}

impl CarDynamics for Model {
    fn dt(&self) -> f64 {
        Model::dt(self)
    }
    fn check(&self) -> Result<(), RacingError> {
        if self.world() != World::Car {
            return Err(RacingError::NotACarModel {
                found: self.world().name().into(),
            });
        }
        Ok(())
    }
    fn rollout(&self, s0: &[f64], actions: &[f64], out: &mut [f64]) -> Result<(), RacingError> {
        if !rollout_one_field(self, s0, actions, out) {
            Model::rollout(self, s0, actions, out)?;
        }
        Ok(())
    }
    fn jacobians(&self, s: &[f64], u: &[f64]) -> Result<StepJacobians, RacingError> {
        Ok(Model::jacobians_stagewise(self, s, u)?)
    }
}

/// [`Model::rollout`] for car models whose step is the network alone (residual, NeuralODE
/// Euler/RK4): the same arithmetic (bit for bit: tested), but one network field — and so one
/// network workspace — for all steps instead of a fresh one per step. Returns false (nothing
/// done) for other models and malformed shapes, which [`Model::rollout`] then handles.
fn rollout_one_field(model: &Model, s0: &[f64], actions: &[f64], out: &mut [f64]) -> bool {
    let Some(net) = model.network() else {
        return false;
    };
    let kind = model.kind();
    let node = matches!(kind, ModelKind::NodeEuler | ModelKind::NodeRk4);
    if model.world() != World::Car
        || model.physics().is_some()
        || !(node || kind == ModelKind::Residual)
        || s0.is_empty()
        || !s0.len().is_multiple_of(6)
    {
        return false;
    }
    let n = s0.len() / 6;
    if !actions.len().is_multiple_of(n * 2) || out.len() != actions.len() / 2 * 6 {
        return false;
    }
    if s0.iter().chain(actions).any(|v| !v.is_finite()) {
        return false;
    }
    // as Model::step
    let solver = model.solver().unwrap_or(Solver::rk4());
    let field = NetField::new(net);
    let dt = model.dt();
    let mut cur = s0.to_vec();
    let mut z = vec![0.0f32; n * 3];
    let mut uf = vec![0.0f32; n * 2];
    let mut zn = vec![0.0f32; n * 3];
    for (j, u) in actions.chunks_exact(n * 2).enumerate() {
        for i in 0..n {
            for d in 0..3 {
                z[i * 3 + d] = cur[i * 6 + 3 + d] as f32;
            }
        }
        for (a, b) in uf.iter_mut().zip(u) {
            *a = *b as f32;
        }
        if node {
            integrate(&field, &solver, n, &z, &uf, 1.0, &mut zn);
        } else {
            field.eval(n, &z, &uf, &mut zn);
            for (a, b) in zn.iter_mut().zip(&z) {
                *a += b;
            }
        }
        let dst = &mut out[j * n * 6..(j + 1) * n * 6];
        for i in 0..n {
            let si = &cur[i * 6..i * 6 + 6];
            let vn = [
                f64::from(zn[i * 3]),
                f64::from(zn[i * 3 + 1]),
                f64::from(zn[i * 3 + 2]),
            ];
            let p = car_pose_update(dt, [si[0], si[1], si[2]], [si[3], si[4], si[5]], vn);
            dst[i * 6..i * 6 + 3].copy_from_slice(&p);
            dst[i * 6 + 3..i * 6 + 6].copy_from_slice(&vn);
        }
        cur.copy_from_slice(dst);
    }
    true
}

/// A car model whose input is held for `hold` model steps: one control step is `hold · dt`.
#[derive(Debug, Clone, Copy)]
pub struct Plant<'a> {
    model: &'a dyn CarDynamics,
    hold: usize,
}

/// The trajectory and its exact linearisation about it: `δx_{k+1} = A_k δx_k + B_k δu_k`.
#[derive(Debug, Clone, PartialEq)]
pub struct Linearization {
    /// States `x₀ … x_n`.
    pub states: Vec<State>,
    /// `A_k = ∂x_{k+1}/∂x_k` (6 × 6 row-major), `n` of them.
    pub a: Vec<[f64; 36]>,
    /// `B_k = ∂x_{k+1}/∂u_k` (6 × 2 row-major), `n` of them.
    pub b: Vec<[f64; 12]>,
}

impl<'a> Plant<'a> {
    /// A plant over a car `model`, holding each input for `hold ≥ 1` model steps.
    pub fn new(model: &'a dyn CarDynamics, hold: usize) -> Result<Self, RacingError> {
        model.check()?;
        if hold == 0 {
            return Err(RacingError::setting(
                "hold",
                hold,
                "hold each input for at least one model step",
            ));
        }
        Ok(Self { model, hold })
    }

    /// The model.
    pub fn model(&self) -> &'a dyn CarDynamics {
        self.model
    }

    /// Model steps per control step.
    pub fn hold(&self) -> usize {
        self.hold
    }

    /// Control step \[s\] (`hold · dt`).
    pub fn dt(&self) -> f64 {
        self.model.dt() * self.hold as f64
    }

    /// States `x₀ … x_n` under `inputs` (non-finite states are returned as they come: the cost
    /// of such a trajectory is infinite).
    pub fn rollout(&self, s0: &State, inputs: &[Input]) -> Result<Vec<State>, RacingError> {
        Ok(self.rollout_batch(s0, &[inputs.to_vec()])?.remove(0))
    }

    /// Rolls out several input sequences of equal length from the same state in one batched
    /// model call; one state list `x₀ … x_n` per sequence.
    pub fn rollout_batch(
        &self,
        s0: &State,
        candidates: &[Vec<Input>],
    ) -> Result<Vec<Vec<State>>, RacingError> {
        let m = candidates.len();
        let n = candidates.first().map_or(0, Vec::len);
        if m == 0 || n == 0 {
            return Ok(vec![vec![*s0]; m]);
        }
        if candidates.iter().any(|c| c.len() != n) {
            return Err(RacingError::setting(
                "candidates",
                "sequences of different lengths",
                "every candidate needs one input per control step",
            ));
        }
        let h = self.hold;
        let steps = n * h;
        let mut actions = vec![0.0; steps * m * 2];
        for j in 0..steps {
            for (c, cand) in candidates.iter().enumerate() {
                let u = cand[j / h];
                actions[(j * m + c) * 2] = u[0];
                actions[(j * m + c) * 2 + 1] = u[1];
            }
        }
        let s0s: Vec<f64> = (0..m).flat_map(|_| s0.iter().copied()).collect();
        let mut out = vec![0.0; steps * m * 6];
        self.model.rollout(&s0s, &actions, &mut out)?;
        Ok((0..m)
            .map(|c| {
                let mut v = Vec::with_capacity(n + 1);
                v.push(*s0);
                for k in 1..=n {
                    let j = k * h - 1;
                    let mut s = [0.0; 6];
                    s.copy_from_slice(&out[(j * m + c) * 6..(j * m + c) * 6 + 6]);
                    v.push(s);
                }
                v
            })
            .collect())
    }

    /// Every model step's state `x₀, x_{0,1}, …` under `inputs` held for `hold` steps
    /// (`(n · hold + 1) × 6`, flat): what [`Plant::linearize_fine`] needs.
    pub fn rollout_fine(&self, s0: &State, inputs: &[Input]) -> Result<Vec<f64>, RacingError> {
        let h = self.hold;
        let steps = inputs.len() * h;
        let mut fine = vec![0.0; (steps + 1) * 6];
        fine[..6].copy_from_slice(s0);
        if steps > 0 {
            let u_fine = self.fine_inputs(inputs);
            let (head, tail) = fine.split_at_mut(6);
            self.model.rollout(head, &u_fine, tail)?;
        }
        Ok(fine)
    }

    /// The control-step states `x₀ … x_n` of a fine trajectory from [`Plant::rollout_fine`].
    pub fn coarse(&self, fine: &[f64]) -> Vec<State> {
        fine.chunks_exact(6)
            .step_by(self.hold)
            .map(|c| [c[0], c[1], c[2], c[3], c[4], c[5]])
            .collect()
    }

    fn fine_inputs(&self, inputs: &[Input]) -> Vec<f64> {
        let h = self.hold;
        let mut u_fine = vec![0.0; inputs.len() * h * 2];
        for j in 0..inputs.len() * h {
            u_fine[j * 2..j * 2 + 2].copy_from_slice(&inputs[j / h]);
        }
        u_fine
    }

    /// Rolls out `inputs` and linearises about the trajectory: the exact Jacobians of every
    /// model step in one batched call, composed over each hold.
    pub fn linearize(&self, s0: &State, inputs: &[Input]) -> Result<Linearization, RacingError> {
        let fine = self.rollout_fine(s0, inputs)?;
        self.linearize_fine(&fine, inputs)
    }

    /// As [`Plant::linearize`] about an already rolled-out fine trajectory `fine` of `inputs`
    /// (from [`Plant::rollout_fine`]): only the Jacobians are evaluated.
    pub fn linearize_fine(
        &self,
        fine: &[f64],
        inputs: &[Input],
    ) -> Result<Linearization, RacingError> {
        let n = inputs.len();
        let h = self.hold;
        let steps = n * h;
        if fine.len() != (steps + 1) * 6 {
            return Err(RacingError::setting(
                "fine trajectory",
                fine.len(),
                "pass the output of Plant::rollout_fine for the same inputs",
            ));
        }
        let u_fine = self.fine_inputs(inputs);
        let jac = self.model.jacobians(&fine[..steps * 6], &u_fine)?;
        let mut states = Vec::with_capacity(n + 1);
        let mut a = Vec::with_capacity(n);
        let mut b = Vec::with_capacity(n);
        for k in 0..=n {
            let mut s = [0.0; 6];
            s.copy_from_slice(&fine[k * h * 6..k * h * 6 + 6]);
            states.push(s);
        }
        for k in 0..n {
            let mut ak = [0.0; 36];
            for i in 0..6 {
                ak[i * 6 + i] = 1.0;
            }
            let mut bk = [0.0; 12];
            for j in 0..h {
                let idx = k * h + j;
                let js = &jac.ds[idx * 36..idx * 36 + 36];
                let ju = &jac.du[idx * 12..idx * 12 + 12];
                let mut na = [0.0; 36];
                let mut nb = [0.0; 12];
                for r in 0..6 {
                    for c in 0..6 {
                        let mut acc = 0.0;
                        for m in 0..6 {
                            acc += js[r * 6 + m] * ak[m * 6 + c];
                        }
                        na[r * 6 + c] = acc;
                    }
                    for c in 0..2 {
                        let mut acc = ju[r * 2 + c];
                        for m in 0..6 {
                            acc += js[r * 6 + m] * bk[m * 2 + c];
                        }
                        nb[r * 2 + c] = acc;
                    }
                }
                ak = na;
                bk = nb;
            }
            a.push(ak);
            b.push(bk);
        }
        Ok(Linearization { states, a, b })
    }
}
