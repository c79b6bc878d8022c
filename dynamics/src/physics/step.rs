//! One model step of a physics model: [`PhysicsModel::integrate_step`] and its derivatives.
//!
//! The car integrates its vector field directly. A push integrates an augmented field: the
//! state `(x, y, θ)` plus the push's step constants `(ψ, q_x, q_y)` (world push direction and
//! pusher start point, see the [pushing model](super::push)) with zero rate, started from
//! `(s₀, h(s₀, u; θ))`. The constants are internal to the step; the model state and every
//! public dimension stay `(x, y, θ)`. Derivatives chain through `h` exactly (forward-mode
//! dual numbers), so fits, reverse mode and the input Jacobians see the world-line pusher.

use super::JacobianTape;
use super::model::PhysicsModel;
use super::{Robot, push};
use crate::ode::{self, OdeReport, Solver, SolverTape, VectorField};
use crate::real::{Dual, Real};

/// Number of step constants of a push.
const NC: usize = 3;
/// Pushing state dimension.
const DS: usize = 3;
/// Pushing input dimension.
const DU: usize = 3;
const DIRS: usize = 8;

/// The augmented push field `(s, c) ↦ (f_line(s; c, ℓ), 0)`.
struct PushLine<'a> {
    model: &'a PhysicsModel,
}

impl PushLine<'_> {
    fn eval_generic<R: Real>(&self, p: &[R], z: &[R], u: &[R], out: &mut [R]) {
        let act = vec![true; self.model.slots().len()];
        push::rhs_line(
            p,
            self.model,
            &act,
            &z[..DS],
            [z[DS], z[DS + 1], z[DS + 2]],
            u[2],
            &mut out[..DS],
        );
        self.model.add_custom_terms(p, &z[..DS], u, &mut out[..DS]);
        for o in &mut out[DS..] {
            *o = R::cst(0.0);
        }
    }

    /// `f` and `∂f/∂[z, u, θ]` (`6 × nz`) of one sample.
    fn jac(&self, z: &[f64], u: &[f64], with_p: bool, f: &mut [f64], j: &mut [f64]) {
        let params = self.model.params();
        let np = if with_p { params.len() } else { 0 };
        let dz = DS + NC;
        let nz = dz + DU + np;
        let mut zd = [Dual::<DIRS>::cst(0.0); DS + NC];
        let mut ud = [Dual::<DIRS>::cst(0.0); DU];
        let mut pd = vec![Dual::<DIRS>::cst(0.0); params.len()];
        let mut out = [Dual::<DIRS>::cst(0.0); DS + NC];
        let mut base = 0;
        while base < nz {
            let seed = |k: usize| k.wrapping_sub(base);
            for (i, x) in zd.iter_mut().enumerate() {
                *x = Dual::var(z[i], seed(i));
            }
            for (i, x) in ud.iter_mut().enumerate() {
                *x = Dual::var(u[i], seed(dz + i));
            }
            for (i, x) in pd.iter_mut().enumerate() {
                *x = if with_p {
                    Dual::var(params[i], seed(dz + DU + i))
                } else {
                    Dual::cst(params[i])
                };
            }
            self.eval_generic(&pd, &zd, &ud, &mut out);
            super::scatter_duals(&out, base, nz, f, j);
            base += DIRS;
        }
    }
}

impl VectorField<f64> for PushLine<'_> {
    type Tape = JacobianTape;
    fn dim_s(&self) -> usize {
        DS + NC
    }
    fn dim_u(&self) -> usize {
        DU
    }
    fn n_params(&self) -> usize {
        self.model.params().len()
    }
    fn eval(&self, n: usize, s: &[f64], u: &[f64], out: &mut [f64]) {
        let dz = DS + NC;
        for i in 0..n {
            self.eval_generic(
                self.model.params(),
                &s[i * dz..(i + 1) * dz],
                &u[i * DU..(i + 1) * DU],
                &mut out[i * dz..(i + 1) * dz],
            );
        }
    }
    fn eval_taped(&self, n: usize, s: &[f64], u: &[f64], out: &mut [f64], tape: &mut Self::Tape) {
        tape.record(n, s, u);
        self.eval(n, s, u, out);
    }
    fn vjp(
        &self,
        tape: &Self::Tape,
        ybar: &[f64],
        sbar: &mut [f64],
        ubar: &mut [f64],
        pbar: &mut [f64],
    ) {
        tape.vjp(
            (DS + NC, DU, self.n_params()),
            |z, u, with_p, f, j| self.jac(z, u, with_p, f, j),
            ybar,
            sbar,
            ubar,
            pbar,
        );
    }
    fn jvp(
        &self,
        n: usize,
        s: &[f64],
        u: &[f64],
        sdot: &[f64],
        udot: &[f64],
        out: &mut [f64],
        out_dot: &mut [f64],
    ) {
        let dz = DS + NC;
        let pd: Vec<Dual<1>> = self.model.params().iter().map(|&p| Dual::cst(p)).collect();
        let mut zd = [Dual::<1>::cst(0.0); DS + NC];
        let mut ud = [Dual::<1>::cst(0.0); DU];
        let mut od = [Dual::<1>::cst(0.0); DS + NC];
        for i in 0..n {
            for k in 0..dz {
                zd[k] = Dual {
                    v: s[i * dz + k],
                    d: [sdot[i * dz + k]],
                };
            }
            for k in 0..DU {
                ud[k] = Dual {
                    v: u[i * DU + k],
                    d: [udot[i * DU + k]],
                };
            }
            self.eval_generic(&pd, &zd, &ud, &mut od);
            for k in 0..dz {
                out[i * dz + k] = od[k].v;
                out_dot[i * dz + k] = od[k].d[0];
            }
        }
    }
}

/// The step constants of one sample and their Jacobians wrt `s₀` (`3 × 3`), `u` (`3 × 3`) and
/// the parameters (`3 × n_params`), row-major.
fn constants_jac(model: &PhysicsModel, s: &[f64], u: &[f64]) -> ([f64; NC], Vec<f64>) {
    let params = model.params();
    let np = params.len();
    let nz = DS + DU + np;
    let mut j = vec![0.0; NC * nz];
    let mut c = [0.0; NC];
    let mut base = 0;
    while base < nz {
        let seed = |k: usize| k.wrapping_sub(base);
        let sd: Vec<Dual<DIRS>> = (0..DS).map(|i| Dual::var(s[i], seed(i))).collect();
        let ud: Vec<Dual<DIRS>> = (0..DU).map(|i| Dual::var(u[i], seed(DS + i))).collect();
        let pd: Vec<Dual<DIRS>> = (0..np)
            .map(|i| Dual::var(params[i], seed(DS + DU + i)))
            .collect();
        let out = push::start_constants(&pd, push::flat_pusher(&pd, model, None), &sd, &ud);
        super::scatter_duals(&out, base, nz, &mut c, &mut j);
        base += DIRS;
    }
    (c, j)
}

fn augment(model: &PhysicsModel, n: usize, s0: &[f64], u: &[f64]) -> Vec<f64> {
    let p = model.params();
    let flat = push::flat_pusher(p, model, None);
    let dz = DS + NC;
    let mut z = vec![0.0; n * dz];
    for i in 0..n {
        let s = &s0[i * DS..(i + 1) * DS];
        let c = push::start_constants(p, flat, s, &u[i * DU..(i + 1) * DU]);
        z[i * dz..i * dz + DS].copy_from_slice(s);
        z[i * dz + DS..(i + 1) * dz].copy_from_slice(&c);
    }
    z
}

fn project(n: usize, z: &[f64], out: &mut [f64]) {
    let dz = DS + NC;
    for i in 0..n {
        out[i * DS..(i + 1) * DS].copy_from_slice(&z[i * dz..i * dz + DS]);
    }
}

/// What [`PhysicsModel::integrate_step_taped`] keeps for [`PhysicsModel::integrate_step_vjp`].
/// Reuse one tape across calls to avoid allocations.
#[derive(Debug, Default)]
pub struct StepTape {
    inner: SolverTape<f64, JacobianTape>,
    n: usize,
    s0: Vec<f64>,
    u: Vec<f64>,
}

impl PhysicsModel {
    /// Integrates `n` samples over one model step `dt` with the inputs held (`s0`, `u`, `out`
    /// row-major, `dim_state` / `dim_input` per sample). The car integrates its vector field;
    /// a push integrates `(x, y, θ)` together with its step constants `(ψ, q_x, q_y)` (world
    /// push direction, pusher start point) held fixed, so the pusher moves on a straight world
    /// line while the block turns under it; derivatives chain exactly through the constants.
    /// This is the model's step: use it rather than integrating the [`VectorField`] directly.
    #[allow(clippy::too_many_arguments)]
    pub fn integrate_step(
        &self,
        solver: &Solver,
        n: usize,
        s0: &[f64],
        u: &[f64],
        dt: f64,
        out: &mut [f64],
    ) -> OdeReport {
        match self.robot() {
            Robot::Car => ode::integrate(self, solver, n, s0, u, dt, out),
            Robot::Pushing => {
                let z0 = augment(self, n, s0, u);
                let mut z = vec![0.0; z0.len()];
                let rep = ode::integrate(&PushLine { model: self }, solver, n, &z0, u, dt, &mut z);
                project(n, &z, out);
                rep
            }
        }
    }

    /// Like [`PhysicsModel::integrate_step`], recording what
    /// [`PhysicsModel::integrate_step_vjp`] needs on `tape`.
    #[allow(clippy::too_many_arguments)]
    pub fn integrate_step_taped(
        &self,
        solver: &Solver,
        n: usize,
        s0: &[f64],
        u: &[f64],
        dt: f64,
        out: &mut [f64],
        tape: &mut StepTape,
    ) -> OdeReport {
        tape.n = n;
        tape.s0.clear();
        tape.s0.extend_from_slice(s0);
        tape.u.clear();
        tape.u.extend_from_slice(u);
        match self.robot() {
            Robot::Car => ode::integrate_taped(self, solver, n, s0, u, dt, out, &mut tape.inner),
            Robot::Pushing => {
                let z0 = augment(self, n, s0, u);
                let mut z = vec![0.0; z0.len()];
                let rep = ode::integrate_taped(
                    &PushLine { model: self },
                    solver,
                    n,
                    &z0,
                    u,
                    dt,
                    &mut z,
                    &mut tape.inner,
                );
                project(n, &z, out);
                rep
            }
        }
    }

    /// Reverse mode through a taped step: from `sbar_end = ∂L/∂s(dt)` (`n × dim_state`) writes
    /// `sbar0 = ∂L/∂s(0)`, `ubar = ∂L/∂u` and accumulates `pbar += ∂L/∂θ` (`pbar` empty to
    /// skip), as [`ode::integrate_vjp`] does.
    pub fn integrate_step_vjp(
        &self,
        tape: &StepTape,
        sbar_end: &[f64],
        sbar0: &mut [f64],
        ubar: &mut [f64],
        pbar: &mut [f64],
    ) {
        match self.robot() {
            Robot::Car => ode::integrate_vjp(self, &tape.inner, sbar_end, sbar0, ubar, pbar),
            Robot::Pushing => {
                let n = tape.n;
                let dz = DS + NC;
                let np = self.params().len();
                let mut zbar_end = vec![0.0; n * dz];
                for i in 0..n {
                    zbar_end[i * dz..i * dz + DS].copy_from_slice(&sbar_end[i * DS..(i + 1) * DS]);
                }
                let mut zbar0 = vec![0.0; n * dz];
                ode::integrate_vjp(
                    &PushLine { model: self },
                    &tape.inner,
                    &zbar_end,
                    &mut zbar0,
                    ubar,
                    pbar,
                );
                let nzc = DS + DU + np;
                for i in 0..n {
                    let s = &tape.s0[i * DS..(i + 1) * DS];
                    let u = &tape.u[i * DU..(i + 1) * DU];
                    let (_, jc) = constants_jac(self, s, u);
                    let cb = &zbar0[i * dz + DS..(i + 1) * dz];
                    for k in 0..DS {
                        let g: f64 = (0..NC).map(|r| cb[r] * jc[r * nzc + k]).sum();
                        sbar0[i * DS + k] = zbar0[i * dz + k] + g;
                    }
                    for k in 0..DU {
                        let g: f64 = (0..NC).map(|r| cb[r] * jc[r * nzc + DS + k]).sum();
                        ubar[i * DU + k] += g;
                    }
                    if !pbar.is_empty() {
                        for k in 0..np {
                            let g: f64 = (0..NC).map(|r| cb[r] * jc[r * nzc + DS + DU + k]).sum();
                            pbar[k] += g;
                        }
                    }
                }
            }
        }
    }

    /// One step and its input Jacobians per sample: `js = ∂s(dt)/∂s(0)` (`n × dim_state²`) and
    /// `ju = ∂s(dt)/∂u` (`n × dim_state × dim_input`), as [`ode::step_jacobians`] does.
    #[allow(clippy::too_many_arguments)]
    pub fn step_jacobians(
        &self,
        solver: &Solver,
        n: usize,
        s0: &[f64],
        u: &[f64],
        dt: f64,
        out: &mut [f64],
        js: &mut [f64],
        ju: &mut [f64],
    ) -> OdeReport {
        match self.robot() {
            Robot::Car => ode::step_jacobians(self, solver, n, s0, u, dt, out, js, ju),
            Robot::Pushing => {
                let dz = DS + NC;
                let np = self.params().len();
                let nzc = DS + DU + np;
                let z0 = augment(self, n, s0, u);
                let mut z = vec![0.0; z0.len()];
                let mut jz = vec![0.0; n * dz * dz];
                let mut juz = vec![0.0; n * dz * DU];
                let rep = ode::step_jacobians(
                    &PushLine { model: self },
                    solver,
                    n,
                    &z0,
                    u,
                    dt,
                    &mut z,
                    &mut jz,
                    &mut juz,
                );
                project(n, &z, out);
                for b in 0..n {
                    let (_, jc) =
                        constants_jac(self, &s0[b * DS..(b + 1) * DS], &u[b * DU..(b + 1) * DU]);
                    let jzb = &jz[b * dz * dz..(b + 1) * dz * dz];
                    let jub = &juz[b * dz * DU..(b + 1) * dz * DU];
                    for r in 0..DS {
                        for k in 0..DS {
                            let chain: f64 = (0..NC)
                                .map(|c| jzb[r * dz + DS + c] * jc[c * nzc + k])
                                .sum();
                            js[b * DS * DS + r * DS + k] = jzb[r * dz + k] + chain;
                        }
                        for k in 0..DU {
                            let chain: f64 = (0..NC)
                                .map(|c| jzb[r * dz + DS + c] * jc[c * nzc + DS + k])
                                .sum();
                            ju[b * DS * DU + r * DU + k] = jub[r * DU + k] + chain;
                        }
                    }
                }
                rep
            }
        }
    }
}
