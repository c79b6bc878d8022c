//! ODE solvers for models written as vector fields `ṡ = f(s, u)` with the input `u` held over the
//! model step, and their exact derivatives.
//!
//! * [`VectorField`] is the one trait a model implements (the physics models here, the MLP in
//!   `dynlab-nn`). It is batched: every call takes `n` samples as contiguous row-major blocks
//!   (`s` is `n × dim_s`, `u` is `n × dim_u`), so a network evaluates a whole batch with one GEMM.
//! * [`Solver`]: explicit Euler and classic RK4 with a fixed number of substeps per model step, and
//!   Dormand–Prince 5(4) with adaptive steps (`rtol`/`atol`, Hairer's step-size control and
//!   starting step, a step limit). Dopri5 lands exactly on `dt`: the last step is shortened, so
//!   one call integrates exactly one model step with the input held. A batch shares one step-size
//!   sequence (the error norm is taken over all samples, as torchdiffeq does), so the result for a
//!   sample can depend slightly on the other samples in its batch (within the tolerance).
//! * Outcomes are data: every integration returns an [`OdeReport`] with an [`OdeStatus`]. A
//!   diverging or non-finite integration stops at the last finite state and says so.
//! * Reverse mode ([`integrate_taped`] + [`integrate_vjp`]) is *discretise-then-differentiate*: the
//!   gradient of exactly the computed result, backpropagated through the accepted steps, with the
//!   accepted step sizes treated as constants (rejected trial steps do not enter). For fixed-step
//!   methods this is the exact gradient of the computed map; for Dopri5 it ignores the (tiny,
//!   non-smooth) dependence of the chosen step sizes on the inputs.
//! * The continuous adjoint method ([`adjoint_vjp`]) integrates the adjoint ODE backwards from the
//!   end state without a tape (memory independent of the number of steps); it re-integrates the
//!   state backwards, so its gradient matches the discrete one only to the solver tolerance.
//! * Forward mode ([`integrate_jvp`], [`tape_jvp`], [`step_jacobians`]) gives directional
//!   derivatives and the input Jacobians `∂s_{k+1}/∂s_k`, `∂s_{k+1}/∂u_k` for the optimisers.

use crate::real::Scalar;

/// A batched vector field `ṡ = f(s, u; θ)` with exact derivatives.
///
/// Layout: `n` samples, row-major: `s[i·dim_s .. (i+1)·dim_s]` is sample `i`. `θ` are the field's own
/// parameters (network weights, physical parameters), `n_params` of them.
pub trait VectorField<T: Scalar = f64> {
    /// What [`VectorField::eval_taped`] keeps for [`VectorField::vjp`] (inputs, activations).
    type Tape: Default + Send;
    /// State dimension.
    fn dim_s(&self) -> usize;
    /// Input dimension.
    fn dim_u(&self) -> usize;
    /// Number of parameters `θ`.
    fn n_params(&self) -> usize;
    /// `out = f(s, u)` for `n` samples.
    fn eval(&self, n: usize, s: &[T], u: &[T], out: &mut [T]);
    /// Like [`VectorField::eval`], recording what the reverse pass needs into `tape` (which may
    /// hold buffers from an earlier use and must be overwritten).
    fn eval_taped(&self, n: usize, s: &[T], u: &[T], out: &mut [T], tape: &mut Self::Tape);
    /// Reverse mode at the point recorded in `tape`: per sample `s̄ = (∂f/∂s)ᵀ ȳ` and
    /// `ū = (∂f/∂u)ᵀ ȳ` (overwritten), and `θ̄ += Σ_samples (∂f/∂θ)ᵀ ȳ` (accumulated).
    /// `pbar` is either empty (no parameter gradient wanted) or `n_params` long.
    fn vjp(&self, tape: &Self::Tape, ybar: &[T], sbar: &mut [T], ubar: &mut [T], pbar: &mut [T]);
    /// Forward mode: `out = f(s, u)` and `out_dot = ∂f/∂s·ṡ + ∂f/∂u·u̇` per sample.
    #[allow(clippy::too_many_arguments)]
    fn jvp(
        &self,
        n: usize,
        s: &[T],
        u: &[T],
        sdot: &[T],
        udot: &[T],
        out: &mut [T],
        out_dot: &mut [T],
    );
    /// Input Jacobians of one sample: `js = ∂f/∂s` (`dim_s × dim_s`, row-major) and
    /// `ju = ∂f/∂u` (`dim_s × dim_u`). The default takes one JVP per input direction.
    fn jacobian(&self, s: &[T], u: &[T], js: &mut [T], ju: &mut [T]) {
        let (ds, du) = (self.dim_s(), self.dim_u());
        let mut sd = vec![T::zero(); ds];
        let mut ud = vec![T::zero(); du];
        let mut out = vec![T::zero(); ds];
        let mut od = vec![T::zero(); ds];
        for j in 0..ds + du {
            sd.iter_mut().for_each(|x| *x = T::zero());
            ud.iter_mut().for_each(|x| *x = T::zero());
            if j < ds {
                sd[j] = T::from_f64(1.0);
            } else {
                ud[j - ds] = T::from_f64(1.0);
            }
            self.jvp(1, s, u, &sd, &ud, &mut out, &mut od);
            for i in 0..ds {
                if j < ds {
                    js[i * ds + j] = od[i];
                } else {
                    ju[i * du + (j - ds)] = od[i];
                }
            }
        }
    }
}

/// A tape that stores the inputs of one call: enough for fields whose reverse pass recomputes
/// from the inputs (the physics models).
#[derive(Clone, Debug, Default)]
pub struct InputTape<T> {
    /// Number of samples.
    pub n: usize,
    /// States, `n × dim_s`.
    pub s: Vec<T>,
    /// Inputs, `n × dim_u`.
    pub u: Vec<T>,
}

impl<T: Copy> InputTape<T> {
    /// Records a call's inputs, reusing the buffers.
    pub fn record(&mut self, n: usize, s: &[T], u: &[T]) {
        self.n = n;
        self.s.clear();
        self.s.extend_from_slice(s);
        self.u.clear();
        self.u.extend_from_slice(u);
    }
}

/// Options of the Dormand–Prince 5(4) solver. Defaults follow torchdiffeq / Hairer.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Dopri5Options {
    /// Relative tolerance (default 1e-7, torchdiffeq's).
    pub rtol: f64,
    /// Absolute tolerance (default 1e-9, torchdiffeq's).
    pub atol: f64,
    /// Maximum number of step attempts (accepted + rejected) per model step (default 10 000);
    /// beyond it the integration stops with [`OdeStatus::MaxStepsExceeded`].
    pub max_steps: usize,
    /// First trial step [same unit as `dt`]; `None` selects it by Hairer's rule (one extra
    /// evaluation).
    pub first_step: Option<f64>,
    /// Safety factor on the optimal step (default 0.9).
    pub safety: f64,
    /// Smallest step-size factor per step (default 0.2).
    pub min_factor: f64,
    /// Largest step-size factor per step (default 10).
    pub max_factor: f64,
}

impl Default for Dopri5Options {
    fn default() -> Self {
        Self {
            rtol: 1e-7,
            atol: 1e-9,
            max_steps: 10_000,
            first_step: None,
            safety: 0.9,
            min_factor: 0.2,
            max_factor: 10.0,
        }
    }
}

/// An integration method for one model step with the input held.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "method", rename_all = "lowercase")]
pub enum Solver {
    /// Explicit Euler with `substeps` equal steps per model step (Tu & Lin: 1).
    Euler {
        /// Steps per model step (≥ 1).
        substeps: u32,
    },
    /// Classic fourth-order Runge–Kutta with `substeps` equal steps per model step.
    Rk4 {
        /// Steps per model step (≥ 1).
        substeps: u32,
    },
    /// Dormand–Prince 5(4), adaptive.
    Dopri5(Dopri5Options),
}

impl Solver {
    /// One explicit Euler step per model step.
    pub fn euler() -> Self {
        Solver::Euler { substeps: 1 }
    }
    /// One RK4 step per model step.
    pub fn rk4() -> Self {
        Solver::Rk4 { substeps: 1 }
    }
    /// Dopri5 with the given tolerances and the other options at their defaults.
    pub fn dopri5(rtol: f64, atol: f64) -> Self {
        Solver::Dopri5(Dopri5Options {
            rtol,
            atol,
            ..Default::default()
        })
    }
    /// The solver's name as in model files (`euler`, `rk4`, `dopri5`).
    pub fn name(&self) -> &'static str {
        match self {
            Solver::Euler { .. } => "euler",
            Solver::Rk4 { .. } => "rk4",
            Solver::Dopri5(_) => "dopri5",
        }
    }
    fn tableau(&self) -> &'static Tableau {
        match self {
            Solver::Euler { .. } => &EULER,
            Solver::Rk4 { .. } => &RK4,
            Solver::Dopri5(_) => &DOPRI5,
        }
    }
}

/// How an integration ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OdeStatus {
    /// Reached the end of the model step.
    Success,
    /// Dopri5 used `max_steps` attempts before the end; the state is the last accepted one.
    MaxStepsExceeded,
    /// The state or its derivative became infinite or NaN; the state is the last finite one.
    NonFinite,
    /// Dopri5's step size fell below the resolution of the time axis (a singularity or a very
    /// stiff field); the state is the last accepted one.
    StepSizeTooSmall,
}

/// The outcome of one integration.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OdeReport {
    /// How it ended.
    pub status: OdeStatus,
    /// Time reached (equals `dt` on success).
    pub t_reached: f64,
    /// Accepted steps.
    pub accepted: usize,
    /// Rejected trial steps (Dopri5 only).
    pub rejected: usize,
    /// Evaluations of the vector field (batched calls).
    pub evaluations: usize,
}

impl OdeReport {
    /// Whether the integration reached the end.
    pub fn is_success(&self) -> bool {
        self.status == OdeStatus::Success
    }
}

/// An explicit Runge–Kutta tableau.
struct Tableau {
    /// `a[i]` are the coefficients of stage `i` on stages `0..i`.
    a: &'static [&'static [f64]],
    /// Weights of the propagated solution.
    b: &'static [f64],
    /// Error weights `b − b̂` (embedded pairs only).
    e: &'static [f64],
    /// Stages that enter the propagated solution (recorded for the reverse pass).
    recorded: usize,
}

static EULER: Tableau = Tableau {
    a: &[&[]],
    b: &[1.0],
    e: &[],
    recorded: 1,
};

static RK4: Tableau = Tableau {
    a: &[&[], &[0.5], &[0.0, 0.5], &[0.0, 0.0, 1.0]],
    b: &[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
    e: &[],
    recorded: 4,
};

static DOPRI5: Tableau = Tableau {
    a: &[
        &[],
        &[1.0 / 5.0],
        &[3.0 / 40.0, 9.0 / 40.0],
        &[44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0],
        &[
            19372.0 / 6561.0,
            -25360.0 / 2187.0,
            64448.0 / 6561.0,
            -212.0 / 729.0,
        ],
        &[
            9017.0 / 3168.0,
            -355.0 / 33.0,
            46732.0 / 5247.0,
            49.0 / 176.0,
            -5103.0 / 18656.0,
        ],
        &[
            35.0 / 384.0,
            0.0,
            500.0 / 1113.0,
            125.0 / 192.0,
            -2187.0 / 6784.0,
            11.0 / 84.0,
        ],
    ],
    b: &[
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
        0.0,
    ],
    e: &[
        71.0 / 57600.0,
        0.0,
        -71.0 / 16695.0,
        71.0 / 1920.0,
        -17253.0 / 339200.0,
        22.0 / 525.0,
        -1.0 / 40.0,
    ],
    recorded: 6,
};

/// The system a Runge–Kutta core integrates (the field at fixed `u`, its forward-mode or adjoint
/// augmentation, or a recording wrapper).
trait System<T> {
    fn dim(&self) -> usize;
    /// Leading components used in the Dopri5 error norm.
    fn err_dim(&self) -> usize {
        self.dim()
    }
    fn rhs(&mut self, stage: usize, y: &[T], k: &mut [T]);
    fn accept(&mut self, _h: f64) {}
    /// For FSAL tableaux: the last stage becomes stage 0 of the next step.
    fn fsal_swap(&mut self, _last: usize) {}
}

fn all_finite<T: Scalar>(v: &[T]) -> bool {
    v.iter().all(|x| x.is_finite_value())
}

/// `out = y + h Σ_j a_j k_j`.
fn combine<T: Scalar>(y: &[T], h: f64, a: &[f64], ks: &[Vec<T>], out: &mut [T]) {
    out.copy_from_slice(y);
    for (j, &aj) in a.iter().enumerate() {
        if aj != 0.0 {
            let c = T::from_f64(h * aj);
            for (o, k) in out.iter_mut().zip(ks[j].iter()) {
                *o += c * *k;
            }
        }
    }
}

fn run_fixed<T: Scalar, S: System<T>>(
    sys: &mut S,
    tab: &Tableau,
    y: &mut [T],
    t_end: f64,
    substeps: u32,
) -> OdeReport {
    let dim = sys.dim();
    let steps = substeps.max(1);
    let h = t_end / steps as f64;
    let stages = tab.b.len();
    let mut ks = vec![vec![T::zero(); dim]; stages];
    let mut ytmp = vec![T::zero(); dim];
    let mut ynew = vec![T::zero(); dim];
    let mut rep = OdeReport {
        status: OdeStatus::Success,
        t_reached: 0.0,
        accepted: 0,
        rejected: 0,
        evaluations: 0,
    };
    for step in 0..steps {
        for i in 0..stages {
            combine(y, h, tab.a[i], &ks, &mut ytmp);
            sys.rhs(i, &ytmp, &mut ks[i]);
            rep.evaluations += 1;
        }
        combine(y, h, tab.b, &ks, &mut ynew);
        if !all_finite(&ynew) {
            rep.status = OdeStatus::NonFinite;
            return rep;
        }
        y.copy_from_slice(&ynew);
        sys.accept(h);
        rep.accepted += 1;
        rep.t_reached = if step + 1 == steps {
            t_end
        } else {
            h * (step + 1) as f64
        };
    }
    rep
}

fn rms_norm<T: Scalar>(v: &[T]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    (v.iter().map(|x| x.to_f64().powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

fn run_dopri5<T: Scalar, S: System<T>>(
    sys: &mut S,
    y: &mut [T],
    t_end: f64,
    o: &Dopri5Options,
) -> OdeReport {
    let tab = &DOPRI5;
    let dim = sys.dim();
    let ed = sys.err_dim().min(dim);
    let stages = tab.b.len();
    let mut ks = vec![vec![T::zero(); dim]; stages];
    let mut ytmp = vec![T::zero(); dim];
    let mut ynew = vec![T::zero(); dim];
    let mut rep = OdeReport {
        status: OdeStatus::Success,
        t_reached: 0.0,
        accepted: 0,
        rejected: 0,
        evaluations: 0,
    };
    if t_end <= 0.0 {
        return rep;
    }
    sys.rhs(0, y, &mut ks[0]);
    rep.evaluations += 1;
    if !all_finite(&ks[0]) {
        rep.status = OdeStatus::NonFinite;
        return rep;
    }
    let scale = |i: usize, a: &[T], b: &[T]| -> f64 {
        o.atol + o.rtol * a[i].to_f64().abs().max(b[i].to_f64().abs())
    };
    // Starting step (Hairer, Nørsett & Wanner, Solving ODEs I, II.4).
    let mut h = match o.first_step {
        Some(h0) if h0 > 0.0 => h0,
        _ => {
            let sc: Vec<f64> = (0..ed).map(|i| scale(i, y, y)).collect();
            let d0 = rms_norm(&(0..ed).map(|i| y[i].to_f64() / sc[i]).collect::<Vec<_>>());
            let d1 = rms_norm(
                &(0..ed)
                    .map(|i| ks[0][i].to_f64() / sc[i])
                    .collect::<Vec<_>>(),
            );
            let h0 = if d0 < 1e-5 || d1 < 1e-5 {
                1e-6
            } else {
                0.01 * d0 / d1
            };
            let h0 = h0.min(t_end);
            combine(y, h0, &[1.0], &ks[..1], &mut ytmp);
            sys.rhs(1, &ytmp, &mut ks[1]);
            rep.evaluations += 1;
            let d2 = rms_norm(
                &(0..ed)
                    .map(|i| (ks[1][i].to_f64() - ks[0][i].to_f64()) / sc[i])
                    .collect::<Vec<_>>(),
            ) / h0;
            let h1 = if d1.max(d2) <= 1e-15 {
                (h0 * 1e-3).max(1e-6)
            } else {
                (0.01 / d1.max(d2)).powf(1.0 / 5.0)
            };
            let h = (100.0 * h0).min(h1);
            if h.is_finite() && h > 0.0 { h } else { h0 }
        }
    };
    let mut t = 0.0;
    let mut facmax = o.max_factor;
    let mut attempts = 0usize;
    let hmin = 16.0 * f64::EPSILON * t_end;
    loop {
        let remaining = t_end - t;
        if remaining <= 4.0 * f64::EPSILON * t_end {
            rep.t_reached = t_end;
            return rep;
        }
        if attempts >= o.max_steps {
            rep.status = OdeStatus::MaxStepsExceeded;
            rep.t_reached = t;
            return rep;
        }
        if h < hmin {
            rep.status = OdeStatus::StepSizeTooSmall;
            rep.t_reached = t;
            return rep;
        }
        let last = h >= remaining;
        if last {
            h = remaining;
        }
        attempts += 1;
        for i in 1..stages {
            combine(y, h, tab.a[i], &ks, &mut ytmp);
            sys.rhs(i, &ytmp, &mut ks[i]);
            rep.evaluations += 1;
        }
        // the last Dopri5 stage is evaluated at y_{n+1}: reuse its input
        ynew.copy_from_slice(&ytmp);
        let mut err = 0.0;
        for i in 0..ed {
            let mut e = 0.0;
            for (j, &ej) in tab.e.iter().enumerate() {
                e += ej * ks[j][i].to_f64();
            }
            let r = h * e / scale(i, y, &ynew);
            err += r * r;
        }
        let err = if ed > 0 {
            (err / ed as f64).sqrt()
        } else {
            0.0
        };
        if !err.is_finite() || !all_finite(&ynew) || !all_finite(&ks[stages - 1]) {
            rep.rejected += 1;
            h *= o.min_factor;
            facmax = 1.0;
            continue;
        }
        let fac = if err == 0.0 {
            facmax
        } else {
            o.safety * err.powf(-0.2)
        };
        if err <= 1.0 {
            t = if last { t_end } else { t + h };
            y.copy_from_slice(&ynew);
            sys.accept(h);
            rep.accepted += 1;
            rep.t_reached = t;
            ks.swap(0, stages - 1);
            sys.fsal_swap(stages - 1);
            h *= fac.clamp(o.min_factor, facmax);
            facmax = o.max_factor;
        } else {
            rep.rejected += 1;
            h *= fac.clamp(o.min_factor, 1.0);
            facmax = 1.0;
        }
    }
}

fn run<T: Scalar, S: System<T>>(sys: &mut S, solver: &Solver, y: &mut [T], dt: f64) -> OdeReport {
    match solver {
        Solver::Euler { substeps } => run_fixed(sys, &EULER, y, dt, *substeps),
        Solver::Rk4 { substeps } => run_fixed(sys, &RK4, y, dt, *substeps),
        Solver::Dopri5(o) => run_dopri5(sys, y, dt, o),
    }
}

struct Plain<'a, T, F: ?Sized> {
    field: &'a F,
    n: usize,
    u: &'a [T],
}

impl<T: Scalar, F: VectorField<T> + ?Sized> System<T> for Plain<'_, T, F> {
    fn dim(&self) -> usize {
        self.n * self.field.dim_s()
    }
    fn rhs(&mut self, _stage: usize, y: &[T], k: &mut [T]) {
        self.field.eval(self.n, y, self.u, k);
    }
}

/// Integrates `n` samples over one model step `dt` with the inputs held: `out = s(dt)` from
/// `s(0) = s0`. On failure `out` is the last finite state and the report says why.
pub fn integrate<T: Scalar, F: VectorField<T> + ?Sized>(
    field: &F,
    solver: &Solver,
    n: usize,
    s0: &[T],
    u: &[T],
    dt: f64,
    out: &mut [T],
) -> OdeReport {
    check_batch_shapes("integrate", field, n, s0, u, out);
    out.copy_from_slice(s0);
    let mut sys = Plain { field, n, u };
    run(&mut sys, solver, out, dt)
}

/// The shape contract of the integrators: `s0` and `out` are `n × dim_s`, `u` is `n × dim_u`.
/// A violation is a bug in the caller (for instance the state of a physics model with effect
/// states given without them), reported with the shapes instead of a slice-length panic deep
/// inside a solver stage.
fn check_batch_shapes<T: Scalar, F: VectorField<T> + ?Sized>(
    what: &str,
    field: &F,
    n: usize,
    s0: &[T],
    u: &[T],
    out: &[T],
) {
    let (ds, du) = (field.dim_s(), field.dim_u());
    assert!(
        s0.len() == n * ds && out.len() == n * ds && u.len() == n * du,
        "{what}: a batch of {n} needs states and out of n × dim_s = {n} × {ds} and inputs of          n × dim_u = {n} × {du}; got {} states, {} out, {} inputs (a physics model with effect          states takes them appended to each state: PhysicsModel::dim_state)",
        s0.len(),
        out.len(),
        u.len()
    );
}

/// One accepted step kept on a [`SolverTape`].
#[derive(Debug, Default)]
struct TapedStep<T, P> {
    h: f64,
    inputs: Vec<Vec<T>>,
    tapes: Vec<P>,
}

/// Everything the reverse and forward passes need from a taped integration: the inputs, and for
/// every accepted step its size, the stage states and the field's stage tapes. Reuse one tape
/// across calls to avoid allocations.
#[derive(Debug)]
pub struct SolverTape<T, P> {
    n: usize,
    u: Vec<T>,
    solver: Option<Solver>,
    steps: Vec<TapedStep<T, P>>,
    len: usize,
}

impl<T, P> Default for SolverTape<T, P> {
    fn default() -> Self {
        Self {
            n: 0,
            u: Vec::new(),
            solver: None,
            steps: Vec::new(),
            len: 0,
        }
    }
}

impl<T, P> SolverTape<T, P> {
    /// Number of accepted steps recorded.
    pub fn steps(&self) -> usize {
        self.len
    }
    /// Sizes of the recorded steps.
    pub fn step_sizes(&self) -> Vec<f64> {
        self.steps[..self.len].iter().map(|s| s.h).collect()
    }
}

struct Taped<'a, T, F: VectorField<T> + ?Sized>
where
    T: Scalar,
{
    field: &'a F,
    n: usize,
    u: &'a [T],
    recorded: usize,
    inputs: Vec<Vec<T>>,
    tapes: Vec<F::Tape>,
    tape: &'a mut SolverTape<T, F::Tape>,
}

impl<T: Scalar, F: VectorField<T> + ?Sized> System<T> for Taped<'_, T, F> {
    fn dim(&self) -> usize {
        self.n * self.field.dim_s()
    }
    fn rhs(&mut self, stage: usize, y: &[T], k: &mut [T]) {
        let inp = &mut self.inputs[stage];
        inp.clear();
        inp.extend_from_slice(y);
        self.field
            .eval_taped(self.n, y, self.u, k, &mut self.tapes[stage]);
    }
    fn accept(&mut self, h: f64) {
        let tape = &mut *self.tape;
        if tape.len == tape.steps.len() {
            tape.steps.push(TapedStep {
                h: 0.0,
                inputs: Vec::new(),
                tapes: Vec::new(),
            });
        }
        let st = &mut tape.steps[tape.len];
        st.h = h;
        st.inputs.resize_with(self.recorded, Vec::new);
        st.tapes.resize_with(self.recorded, Default::default);
        for i in 0..self.recorded {
            std::mem::swap(&mut st.inputs[i], &mut self.inputs[i]);
            std::mem::swap(&mut st.tapes[i], &mut self.tapes[i]);
        }
        tape.len += 1;
    }
    fn fsal_swap(&mut self, last: usize) {
        // the last stage's input/tape (at y_{n+1}) is the first stage of the next step
        self.inputs.swap(0, last);
        self.tapes.swap(0, last);
    }
}

/// Like [`integrate`], recording the accepted steps on `tape` for [`integrate_vjp`] and
/// [`tape_jvp`].
#[allow(clippy::too_many_arguments)]
pub fn integrate_taped<T: Scalar, F: VectorField<T> + ?Sized>(
    field: &F,
    solver: &Solver,
    n: usize,
    s0: &[T],
    u: &[T],
    dt: f64,
    out: &mut [T],
    tape: &mut SolverTape<T, F::Tape>,
) -> OdeReport {
    check_batch_shapes("integrate_taped", field, n, s0, u, out);
    let tab = solver.tableau();
    let stages = tab.b.len();
    tape.n = n;
    tape.u.clear();
    tape.u.extend_from_slice(u);
    tape.solver = Some(*solver);
    tape.len = 0;
    out.copy_from_slice(s0);
    let mut sys = Taped {
        field,
        n,
        u,
        recorded: tab.recorded,
        inputs: vec![Vec::new(); stages],
        tapes: (0..stages).map(|_| F::Tape::default()).collect(),
        tape,
    };
    run(&mut sys, solver, out, dt)
}

/// Reverse mode through a taped integration: given `sbar_end = ∂L/∂s(dt)` (`n × dim_s`), writes
/// `sbar0 = ∂L/∂s(0)` and `ubar = ∂L/∂u` (`n × dim_u`) and accumulates `pbar += ∂L/∂θ` (`pbar`
/// empty to skip). Step sizes are constants (discretise-then-differentiate).
pub fn integrate_vjp<T: Scalar, F: VectorField<T> + ?Sized>(
    field: &F,
    tape: &SolverTape<T, F::Tape>,
    sbar_end: &[T],
    sbar0: &mut [T],
    ubar: &mut [T],
    pbar: &mut [T],
) {
    let (n, ds, du) = (tape.n, field.dim_s(), field.dim_u());
    sbar0.copy_from_slice(sbar_end);
    ubar.iter_mut().for_each(|x| *x = T::zero());
    let Some(solver) = tape.solver else { return };
    let tab = solver.tableau();
    let r = tab.recorded;
    let mut ybars = vec![vec![T::zero(); n * ds]; r];
    let mut kbar = vec![T::zero(); n * ds];
    let mut ub = vec![T::zero(); n * du];
    for st in tape.steps[..tape.len].iter().rev() {
        let h = st.h;
        for i in (0..r).rev() {
            let cb = T::from_f64(h * tab.b[i]);
            for (kb, sb) in kbar.iter_mut().zip(sbar0.iter()) {
                *kb = cb * *sb;
            }
            for (l, yl) in ybars.iter().enumerate().take(r).skip(i + 1) {
                let a = tab.a[l][i];
                if a != 0.0 {
                    let c = T::from_f64(h * a);
                    for (kb, y) in kbar.iter_mut().zip(yl.iter()) {
                        *kb += c * *y;
                    }
                }
            }
            field.vjp(&st.tapes[i], &kbar, &mut ybars[i], &mut ub, pbar);
            for (a, b) in ubar.iter_mut().zip(ub.iter()) {
                *a += *b;
            }
        }
        for yb in ybars.iter() {
            for (a, b) in sbar0.iter_mut().zip(yb.iter()) {
                *a += *b;
            }
        }
    }
}

/// Forward mode along a taped integration (same steps, same stage points): the tangent
/// `out_dot = ∂s(dt)/∂s(0)·sdot0 + ∂s(dt)/∂u·udot` for each of the tape's `n` samples.
pub fn tape_jvp<T: Scalar, F: VectorField<T> + ?Sized>(
    field: &F,
    tape: &SolverTape<T, F::Tape>,
    sdot0: &[T],
    udot: &[T],
    out_dot: &mut [T],
) {
    let (n, ds) = (tape.n, field.dim_s());
    out_dot.copy_from_slice(sdot0);
    let Some(solver) = tape.solver else { return };
    let tab = solver.tableau();
    let r = tab.recorded;
    let mut kd = vec![vec![T::zero(); n * ds]; r];
    let mut yd = vec![T::zero(); n * ds];
    let mut scratch = vec![T::zero(); n * ds];
    for st in tape.steps[..tape.len].iter() {
        for i in 0..r {
            combine(out_dot, st.h, tab.a[i], &kd, &mut yd);
            field.jvp(
                n,
                &st.inputs[i],
                &tape.u,
                &yd,
                udot,
                &mut scratch,
                &mut kd[i],
            );
        }
        let base = out_dot.to_vec();
        combine(&base, st.h, &tab.b[..r], &kd, out_dot);
    }
}

struct Jvp<'a, T, F: ?Sized> {
    field: &'a F,
    n: usize,
    u: &'a [T],
    udot: &'a [T],
}

impl<T: Scalar, F: VectorField<T> + ?Sized> System<T> for Jvp<'_, T, F> {
    fn dim(&self) -> usize {
        2 * self.n * self.field.dim_s()
    }
    fn err_dim(&self) -> usize {
        self.n * self.field.dim_s()
    }
    fn rhs(&mut self, _stage: usize, y: &[T], k: &mut [T]) {
        let m = self.n * self.field.dim_s();
        let (ys, yd) = y.split_at(m);
        let (ks, kd) = k.split_at_mut(m);
        self.field.jvp(self.n, ys, self.u, yd, self.udot, ks, kd);
    }
}

/// Integrates the state and a tangent together: `out = s(dt)` and
/// `out_dot = ∂s(dt)/∂s(0)·sdot0 + ∂s(dt)/∂u·udot`. Dopri5's step control looks at the state only,
/// so the tangent follows exactly the steps an untangented integration takes.
#[allow(clippy::too_many_arguments)]
pub fn integrate_jvp<T: Scalar, F: VectorField<T> + ?Sized>(
    field: &F,
    solver: &Solver,
    n: usize,
    s0: &[T],
    u: &[T],
    dt: f64,
    sdot0: &[T],
    udot: &[T],
    out: &mut [T],
    out_dot: &mut [T],
) -> OdeReport {
    let m = n * field.dim_s();
    let mut y = Vec::with_capacity(2 * m);
    y.extend_from_slice(s0);
    y.extend_from_slice(sdot0);
    let mut sys = Jvp { field, n, u, udot };
    let rep = run(&mut sys, solver, &mut y, dt);
    out.copy_from_slice(&y[..m]);
    out_dot.copy_from_slice(&y[m..]);
    rep
}

/// Input Jacobians of one model step for `n` samples: `out = s(dt)`,
/// `js[i] = ∂s(dt)/∂s(0)` (`dim_s × dim_s` per sample, row-major) and `ju[i] = ∂s(dt)/∂u`
/// (`dim_s × dim_u`), by forward mode along one taped integration (one batched JVP per input
/// direction).
#[allow(clippy::too_many_arguments)]
pub fn step_jacobians<T: Scalar, F: VectorField<T> + ?Sized>(
    field: &F,
    solver: &Solver,
    n: usize,
    s0: &[T],
    u: &[T],
    dt: f64,
    out: &mut [T],
    js: &mut [T],
    ju: &mut [T],
) -> OdeReport {
    let (ds, du) = (field.dim_s(), field.dim_u());
    let mut tape = SolverTape::default();
    let rep = integrate_taped(field, solver, n, s0, u, dt, out, &mut tape);
    let mut sd = vec![T::zero(); n * ds];
    let mut ud = vec![T::zero(); n * du];
    let mut od = vec![T::zero(); n * ds];
    for j in 0..ds + du {
        sd.iter_mut().for_each(|x| *x = T::zero());
        ud.iter_mut().for_each(|x| *x = T::zero());
        for b in 0..n {
            if j < ds {
                sd[b * ds + j] = T::from_f64(1.0);
            } else {
                ud[b * du + j - ds] = T::from_f64(1.0);
            }
        }
        tape_jvp(field, &tape, &sd, &ud, &mut od);
        for b in 0..n {
            for i in 0..ds {
                let v = od[b * ds + i];
                if j < ds {
                    js[b * ds * ds + i * ds + j] = v;
                } else {
                    ju[b * ds * du + i * du + (j - ds)] = v;
                }
            }
        }
    }
    rep
}

struct Adjoint<'a, T: Scalar, F: VectorField<T> + ?Sized> {
    field: &'a F,
    n: usize,
    u: &'a [T],
    tape: F::Tape,
    f: Vec<T>,
    sb: Vec<T>,
    ub: Vec<T>,
}

impl<T: Scalar, F: VectorField<T> + ?Sized> System<T> for Adjoint<'_, T, F> {
    fn dim(&self) -> usize {
        let m = self.n * self.field.dim_s();
        2 * m + self.n * self.field.dim_u() + self.field.n_params()
    }
    fn err_dim(&self) -> usize {
        // the state and the adjoint; the accumulated gradients are left out of the norm
        2 * self.n * self.field.dim_s()
    }
    fn rhs(&mut self, _stage: usize, y: &[T], k: &mut [T]) {
        let m = self.n * self.field.dim_s();
        let mu = self.n * self.field.dim_u();
        let (s, rest) = y.split_at(m);
        let a = &rest[..m];
        self.field
            .eval_taped(self.n, s, self.u, &mut self.f, &mut self.tape);
        let (ks, krest) = k.split_at_mut(m);
        for (kk, f) in ks.iter_mut().zip(self.f.iter()) {
            *kk = -*f;
        }
        let (ka, krest) = krest.split_at_mut(m);
        let (ku, kp) = krest.split_at_mut(mu);
        kp.iter_mut().for_each(|x| *x = T::zero());
        self.field
            .vjp(&self.tape, a, &mut self.sb, &mut self.ub, kp);
        ka.copy_from_slice(&self.sb);
        ku.copy_from_slice(&self.ub);
    }
}

/// The continuous adjoint method (Chen et al. 2018): from the end state `s_end = s(dt)` and
/// `sbar_end = ∂L/∂s(dt)`, integrates `[s, a, ū, θ̄]` backwards in time with
/// `ṡ = f`, `ȧ = −aᵀ∂f/∂s`, `dū/dt = −aᵀ∂f/∂u`, `dθ̄/dt = −aᵀ∂f/∂θ`, giving `sbar0 = a(0)`,
/// `ubar` and `pbar += θ̄` without a tape. The step-size control of `solver` sees the state and
/// the adjoint (a semi-norm: the accumulated gradients are left out). The state is
/// re-integrated backwards, so the result matches [`integrate_vjp`] to the solver's accuracy, not
/// exactly.
#[allow(clippy::too_many_arguments)]
pub fn adjoint_vjp<T: Scalar, F: VectorField<T> + ?Sized>(
    field: &F,
    solver: &Solver,
    n: usize,
    s_end: &[T],
    u: &[T],
    dt: f64,
    sbar_end: &[T],
    sbar0: &mut [T],
    ubar: &mut [T],
    pbar: &mut [T],
) -> OdeReport {
    let (ds, du, np) = (field.dim_s(), field.dim_u(), field.n_params());
    let m = n * ds;
    let mu = n * du;
    let np_used = if pbar.is_empty() { 0 } else { np };
    let mut y = vec![T::zero(); 2 * m + mu + np];
    y[..m].copy_from_slice(s_end);
    y[m..2 * m].copy_from_slice(sbar_end);
    let mut sys = Adjoint {
        field,
        n,
        u,
        tape: F::Tape::default(),
        f: vec![T::zero(); m],
        sb: vec![T::zero(); m],
        ub: vec![T::zero(); mu],
    };
    let rep = run(&mut sys, solver, &mut y, dt);
    sbar0.copy_from_slice(&y[m..2 * m]);
    ubar.copy_from_slice(&y[2 * m..2 * m + mu]);
    for (p, g) in pbar.iter_mut().zip(y[2 * m + mu..].iter()).take(np_used) {
        *p += *g;
    }
    rep
}
