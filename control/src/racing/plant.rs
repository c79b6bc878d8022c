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
    /// Number of effect states the model carries beside the 6 car states (`d_f` of
    /// `motor_lag`, `delta_w` of `steering_lag`; default 0), see [`Model::dim_extra`].
    fn dim_extra(&self) -> usize {
        0
    }
    /// The effect states settled under a held input (default: none).
    fn settled_extra(&self, _u: &[f64]) -> Vec<f64> {
        Vec::new()
    }
    /// Advances effect states by one model step under `u` (default: nothing to advance).
    fn advance_extra(&self, _e: &mut [f64], _u: &[f64]) {}
    /// Rollout from states `s0` (`m × 6`) and effect states `e0` (`m × dim_extra`); `out`
    /// receives the car states and, if given, `extra_out` the effect states after each step
    /// (`k × m × dim_extra`), as [`Model::rollout_with_extra`]. The default (no effect states)
    /// is [`CarDynamics::rollout`].
    fn rollout_with_extra(
        &self,
        s0: &[f64],
        _e0: &[f64],
        actions: &[f64],
        out: &mut [f64],
        _extra_out: Option<&mut [f64]>,
    ) -> Result<(), RacingError> {
        self.rollout(s0, actions, out)
    }
    /// Step Jacobians over the augmented state `[s, e]` (`nx = 6 + dim_extra`), as
    /// [`Model::jacobians_with_extra`]. The default (no effect states) is
    /// [`CarDynamics::jacobians`].
    fn jacobians_with_extra(
        &self,
        s: &[f64],
        _e: &[f64],
        u: &[f64],
    ) -> Result<StepJacobians, RacingError> {
        self.jacobians(s, u)
    }
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
    fn dim_extra(&self) -> usize {
        Model::dim_extra(self)
    }
    fn settled_extra(&self, u: &[f64]) -> Vec<f64> {
        Model::settled_extra(self, u)
    }
    fn advance_extra(&self, e: &mut [f64], u: &[f64]) {
        Model::advance_extra(self, e, u);
    }
    fn rollout_with_extra(
        &self,
        s0: &[f64],
        e0: &[f64],
        actions: &[f64],
        out: &mut [f64],
        extra_out: Option<&mut [f64]>,
    ) -> Result<(), RacingError> {
        if Model::dim_extra(self) == 0 {
            return CarDynamics::rollout(self, s0, actions, out);
        }
        Model::rollout_with_extra(self, s0, e0, actions, out, extra_out)?;
        Ok(())
    }
    fn jacobians_with_extra(
        &self,
        s: &[f64],
        e: &[f64],
        u: &[f64],
    ) -> Result<StepJacobians, RacingError> {
        if Model::dim_extra(self) == 0 {
            return CarDynamics::jacobians(self, s, u);
        }
        Ok(Model::jacobians_with_extra(self, s, e, u)?)
    }
}

/// Most effect states a [`Plant`] carries: the library's car effects add at most 6 (the servo, the
/// motor and the command delay's two filters), a custom
/// term on a lagged command the 6 lagged commands
/// ([`INPUT_LAG_STATES`](dynlab_learn::dynamics::physics::features::INPUT_LAG_STATES)).
pub const MAX_EXTRA: usize = 12;

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
///
/// A model with effect states (`motor_lag`'s filtered throttle, `steering_lag`'s wheel angle)
/// carries them through every rollout from the plant's initial effect states
/// ([`Plant::with_extra`]; default 0: every lag at rest), and its linearisation is over the
/// augmented state `[x, e]`, so gradients see how an input moves the later effect states.
#[derive(Debug, Clone, Copy)]
pub struct Plant<'a> {
    model: &'a dyn CarDynamics,
    hold: usize,
    ne: usize,
    extra0: [f64; MAX_EXTRA],
}

/// The trajectory and its exact linearisation about it: `δx_{k+1} = A_k δx_k + B_k δu_k` over
/// the augmented state `x = [s, e]` (`nx = 6 + dim_extra`; the cost reads the first 6).
#[derive(Debug, Clone, PartialEq)]
pub struct Linearization {
    /// Car states `s₀ … s_n`.
    pub states: Vec<State>,
    /// Augmented state dimension `nx` (6 without effect states).
    pub nx: usize,
    /// `A_k = ∂x_{k+1}/∂x_k` (`nx × nx` row-major), `n` of them.
    pub a: Vec<Vec<f64>>,
    /// `B_k = ∂x_{k+1}/∂u_k` (`nx × 2` row-major), `n` of them.
    pub b: Vec<Vec<f64>>,
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
        let ne = model.dim_extra();
        if ne > MAX_EXTRA {
            return Err(RacingError::setting(
                "effects",
                format!("{ne} effect states"),
                format!("the racing plant carries at most {MAX_EXTRA}; use fewer stateful effects"),
            ));
        }
        Ok(Self {
            model,
            hold,
            ne,
            extra0: [0.0; MAX_EXTRA],
        })
    }

    /// The plant with initial effect states `e0` (`dim_extra` values, from the command history:
    /// [`Model::extra_states_along`], or [`CarDynamics::advance_extra`] over the inputs applied).
    pub fn with_extra(mut self, e0: &[f64]) -> Result<Self, RacingError> {
        if e0.len() != self.ne || e0.iter().any(|v| !v.is_finite()) {
            return Err(RacingError::setting(
                "effect states",
                format!("{e0:?}"),
                format!(
                    "give the model's {} effect states, finite (Model::extra_state_names)",
                    self.ne
                ),
            ));
        }
        self.extra0 = [0.0; MAX_EXTRA];
        self.extra0[..self.ne].copy_from_slice(e0);
        Ok(self)
    }

    /// The initial effect states (empty without them).
    pub fn extra(&self) -> &[f64] {
        &self.extra0[..self.ne]
    }

    /// Augmented state dimension `6 + dim_extra`.
    pub fn nx(&self) -> usize {
        6 + self.ne
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
        let e0s: Vec<f64> = (0..m).flat_map(|_| self.extra().iter().copied()).collect();
        let mut out = vec![0.0; steps * m * 6];
        self.model
            .rollout_with_extra(&s0s, &e0s, &actions, &mut out, None)?;
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

    /// Every model step's augmented state `[s, e]` (car and effect states), `x₀, x_{0,1}, …`,
    /// under `inputs` held for `hold` steps (`(n · hold + 1) × nx`, flat): what
    /// [`Plant::linearize_fine`] needs.
    pub fn rollout_fine(&self, s0: &State, inputs: &[Input]) -> Result<Vec<f64>, RacingError> {
        let h = self.hold;
        let (ne, nx) = (self.ne, self.nx());
        let steps = inputs.len() * h;
        let mut fine = vec![0.0; (steps + 1) * nx];
        fine[..6].copy_from_slice(s0);
        fine[6..nx].copy_from_slice(self.extra());
        if steps > 0 {
            let u_fine = self.fine_inputs(inputs);
            let mut out = vec![0.0; steps * 6];
            let mut eo = vec![0.0; steps * ne];
            self.model
                .rollout_with_extra(s0, self.extra(), &u_fine, &mut out, Some(&mut eo))?;
            for j in 0..steps {
                let row = &mut fine[(j + 1) * nx..(j + 2) * nx];
                row[..6].copy_from_slice(&out[j * 6..(j + 1) * 6]);
                row[6..].copy_from_slice(&eo[j * ne..(j + 1) * ne]);
            }
        }
        Ok(fine)
    }

    /// The control-step car states `s₀ … s_n` of a fine trajectory from
    /// [`Plant::rollout_fine`].
    pub fn coarse(&self, fine: &[f64]) -> Vec<State> {
        fine.chunks_exact(self.nx())
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
        let (ne, nx) = (self.ne, self.nx());
        let steps = n * h;
        if fine.len() != (steps + 1) * nx {
            return Err(RacingError::setting(
                "fine trajectory",
                fine.len(),
                "pass the output of Plant::rollout_fine for the same inputs",
            ));
        }
        let u_fine = self.fine_inputs(inputs);
        let mut s_fine = Vec::with_capacity(steps * 6);
        let mut e_fine = Vec::with_capacity(steps * ne);
        for row in fine[..steps * nx].chunks_exact(nx) {
            s_fine.extend_from_slice(&row[..6]);
            e_fine.extend_from_slice(&row[6..]);
        }
        let jac = self.model.jacobians_with_extra(&s_fine, &e_fine, &u_fine)?;
        let states = self.coarse(fine);
        let mut a = Vec::with_capacity(n);
        let mut b = Vec::with_capacity(n);
        let (nn, nu) = (nx * nx, nx * 2);
        for k in 0..n {
            let mut ak = vec![0.0; nn];
            for i in 0..nx {
                ak[i * nx + i] = 1.0;
            }
            let mut bk = vec![0.0; nu];
            let mut na = vec![0.0; nn];
            let mut nb = vec![0.0; nu];
            for j in 0..h {
                let idx = k * h + j;
                let js = &jac.ds[idx * nn..(idx + 1) * nn];
                let ju = &jac.du[idx * nu..(idx + 1) * nu];
                for r in 0..nx {
                    for c in 0..nx {
                        let mut acc = 0.0;
                        for m in 0..nx {
                            acc += js[r * nx + m] * ak[m * nx + c];
                        }
                        na[r * nx + c] = acc;
                    }
                    for c in 0..2 {
                        let mut acc = ju[r * 2 + c];
                        for m in 0..nx {
                            acc += js[r * nx + m] * bk[m * 2 + c];
                        }
                        nb[r * 2 + c] = acc;
                    }
                }
                std::mem::swap(&mut ak, &mut na);
                std::mem::swap(&mut bk, &mut nb);
            }
            a.push(ak);
            b.push(bk);
        }
        Ok(Linearization { states, nx, a, b })
    }
}
