//! Bounded nonlinear least squares for physical parameters, and the physics fit of
//! [`train`](crate::train::train).
//!
//! [`bounded_least_squares`] is Levenberg–Marquardt whose step is the box-constrained quadratic
//! program `min ½δᵀ(JᵀJ + λ diag(JᵀJ))δ + (Jᵀr)ᵀδ  s.t.  lower ≤ θ + δ ≤ upper`, solved by
//! `clarabel` (an interior-point QP solver), so bounds are honoured exactly instead of by clamping.
//! For a residual that is linear in the parameters the first step with `λ → 0` is the constrained
//! linear least-squares solution. Standard errors: [`bounded_least_squares`] reports `σ²(JᵀJ)⁻¹`
//! (`σ² = ‖r‖²/(m − n)`, independent residuals); the physics fit replaces them by
//! [`cluster_std`], clustered by trajectory, since overlapping k-step windows are correlated.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
};
use dynlab_dynamics::conventions::wrap_angle;
use dynlab_dynamics::data::{SplitMix64, StateTrajectory, Window};
use dynlab_dynamics::ode::{OdeStatus, Solver};
use dynlab_dynamics::physics::{PhysicsModel, StepTape};
use dynlab_dynamics::real::Dual;
use dynlab_nn::parallel::in_blocks;

use crate::train::{CommandHistory, Loss, PhysicsFit, TrainConfig};
use crate::{LearnError, World};

/// Residuals and Jacobian of a least-squares problem at `θ`: `eval(θ, with_jacobian)` returns
/// `(r, J)` with `J` empty when not asked for.
pub type ResidualFn<'a> = dyn FnMut(&[f64], bool) -> (Vec<f64>, Vec<f64>) + 'a;

/// The result of [`bounded_least_squares`].
#[derive(Clone, Debug, PartialEq)]
pub struct LsqResult {
    /// Fitted parameters (all of them; fixed ones unchanged).
    pub theta: Vec<f64>,
    /// Standard errors (0 for fixed parameters, NaN where `JᵀJ` is singular).
    pub std: Vec<f64>,
    /// `‖r‖²` at the start.
    pub initial_cost: f64,
    /// `‖r‖²` at the end.
    pub cost: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Number of residuals.
    pub residuals: usize,
}

/// Minimises `‖r(θ)‖²` over the parameters with `free[i]` set, within `[lower, upper]`.
/// `eval(θ, with_jacobian)` returns the residuals and, when asked, the Jacobian (`m × n`
/// row-major over all `n` parameters; fixed columns are ignored). A trial whose residuals are not
/// finite is rejected like a worse one.
pub fn bounded_least_squares(
    theta0: &[f64],
    lower: &[f64],
    upper: &[f64],
    free: &[bool],
    iterations: usize,
    eval: &mut ResidualFn<'_>,
) -> LsqResult {
    let n = theta0.len();
    let idx: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
    let nf = idx.len();
    let cost = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>();
    let mut theta: Vec<f64> = theta0
        .iter()
        .zip(lower.iter().zip(upper))
        .map(|(t, (l, u))| t.clamp(*l, *u))
        .collect();
    let (mut r, mut jac) = eval(&theta, nf > 0);
    let initial_cost = cost(&r);
    let mut c = initial_cost;
    let mut lambda = 1e-3;
    let mut its = 0;
    while nf > 0 && its < iterations {
        its += 1;
        let (jtj, jtr) = reduced_normal_equations(&jac, &r, n, &idx);
        let mut improved = false;
        for _ in 0..12 {
            let mut a = jtj.clone();
            for i in 0..nf {
                a[i * nf + i] += lambda * jtj[i * nf + i].max(1e-12) + 1e-15;
            }
            let lo: Vec<f64> = idx.iter().map(|&i| lower[i] - theta[i]).collect();
            let hi: Vec<f64> = idx.iter().map(|&i| upper[i] - theta[i]).collect();
            let Some(delta) = box_qp(&a, &jtr, &lo, &hi) else {
                lambda *= 10.0;
                continue;
            };
            let mut cand = theta.clone();
            for (k, &i) in idx.iter().enumerate() {
                cand[i] = (theta[i] + delta[k]).clamp(lower[i], upper[i]);
            }
            let (rt, _) = eval(&cand, false);
            let ct = cost(&rt);
            if ct.is_finite() && ct < c {
                let rel = (c - ct) / c.max(f64::MIN_POSITIVE);
                theta = cand;
                c = ct;
                lambda = (lambda / 3.0).max(1e-12);
                improved = rel > 1e-10;
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
        let (r2, j2) = eval(&theta, true);
        r = r2;
        jac = j2;
    }
    let m = r.len();
    let mut std = vec![0.0; n];
    if nf > 0 && jac.len() == m * n {
        let (jtj, _) = reduced_normal_equations(&jac, &r, n, &idx);
        let dof = (m as f64 - nf as f64).max(1.0);
        let sigma2 = cost(&r) / dof;
        let trace: f64 = (0..nf).map(|i| jtj[i * nf + i]).sum::<f64>().max(1e-300);
        let mut a = jtj.clone();
        for i in 0..nf {
            a[i * nf + i] += 1e-12 * trace / nf as f64;
        }
        for (k, &i) in idx.iter().enumerate() {
            let mut e = vec![0.0; nf];
            e[k] = 1.0;
            std[i] = match solve(&a, &e, nf) {
                Some(col) => (sigma2 * col[k]).max(0.0).sqrt(),
                None => f64::NAN,
            };
        }
    }
    LsqResult {
        theta,
        std,
        initial_cost,
        cost: c,
        iterations: its,
        residuals: m,
    }
}

/// The forward-difference Jacobian of `resid` at `theta`, whose residuals `r0` the caller has:
/// `m × n` row-major, column `c` from the step `step(c)`. A column whose step is 0 or not finite
/// (a fixed parameter), or whose trial returns another number of residuals than `r0` (a model
/// the trial made invalid), is left 0.
pub fn forward_jacobian(
    theta: &[f64],
    r0: &[f64],
    step: &dyn Fn(usize) -> f64,
    resid: &dyn Fn(&[f64]) -> Vec<f64>,
) -> Vec<f64> {
    let n = theta.len();
    let mut jac = vec![0.0; r0.len() * n];
    for c in 0..n {
        let h = step(c);
        if !(h.is_finite() && h != 0.0) {
            continue;
        }
        let mut t = theta.to_vec();
        t[c] += h;
        let r = resid(&t);
        if r.len() != r0.len() {
            continue;
        }
        for (i, (a, b)) in r.iter().zip(r0).enumerate() {
            jac[i * n + c] = (a - b) / h;
        }
    }
    jac
}

/// [`bounded_least_squares`]'s `eval` by forward differences ([`forward_jacobian`]) of a
/// residual function that is pure in `θ`, remembering its last evaluation with a Jacobian and its
/// last without: Levenberg–Marquardt asks for the Jacobian at the point whose residuals its
/// accepted trial has just evaluated, and a caller for the Jacobian at the result, which the fit
/// has just evaluated; neither is integrated again. The values are those a fresh evaluation gives
/// (a point is the same only bit for bit).
pub struct ForwardDifferences<'a> {
    resid: &'a dyn Fn(&[f64]) -> Vec<f64>,
    step: &'a dyn Fn(&[f64], usize) -> f64,
    /// `(θ, r)` of the last evaluation without a Jacobian.
    last: Option<(Vec<f64>, Vec<f64>)>,
    /// `(θ, r, J)` of the last evaluation with one.
    last_jacobian: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
}

impl<'a> ForwardDifferences<'a> {
    /// Residuals `resid(θ)`, and column `c` of the Jacobian at `θ` from the step `step(θ, c)`
    /// (0 for a fixed parameter).
    pub fn new(
        resid: &'a dyn Fn(&[f64]) -> Vec<f64>,
        step: &'a dyn Fn(&[f64], usize) -> f64,
    ) -> Self {
        Self {
            resid,
            step,
            last: None,
            last_jacobian: None,
        }
    }

    /// `(r, J)` at `theta` as [`ResidualFn`] gives them: `J` empty unless `with_jacobian`.
    pub fn eval(&mut self, theta: &[f64], with_jacobian: bool) -> (Vec<f64>, Vec<f64>) {
        let same = |t: &[f64]| {
            t.len() == theta.len() && t.iter().zip(theta).all(|(a, b)| a.to_bits() == b.to_bits())
        };
        if let Some((t, r, jac)) = &self.last_jacobian
            && same(t)
        {
            let jac = match with_jacobian {
                true => jac.clone(),
                false => Vec::new(),
            };
            return (r.clone(), jac);
        }
        let r = match &self.last {
            Some((t, r)) if same(t) => r.clone(),
            _ => (self.resid)(theta),
        };
        if !with_jacobian {
            self.last = Some((theta.to_vec(), r.clone()));
            return (r, Vec::new());
        }
        let jac = forward_jacobian(theta, &r, &|c| (self.step)(theta, c), self.resid);
        self.last_jacobian = Some((theta.to_vec(), r.clone(), jac.clone()));
        (r, jac)
    }
}

/// How many times the median window's sensitivity a fit window may have by default (see
/// [`calm_windows`]).
pub const SENSITIVITY_LIMIT: f64 = 100.0;

/// Which fit windows a k-step fit keeps, from each window's sensitivity `Σ (∂r/∂θ)²` to the
/// fitted parameters: those at most `limit` times the median's (e.g. [`SENSITIVITY_LIMIT`]).
/// A rollout near a spin or a tire-saturation bifurcation, where a tiny change of a parameter
/// changes the whole trajectory, would dominate both the fit and `JᵀJ`: Levenberg–Marquardt
/// then takes steps too small to leave its start and the standard errors shrink to nothing.
/// Every window is kept when fewer than half would stay; non-finite sensitivities are left out.
pub fn calm_windows(sensitivity: &[f64], limit: f64) -> Vec<bool> {
    let mut sorted: Vec<f64> = sensitivity
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if sorted.is_empty() {
        return vec![true; sensitivity.len()];
    }
    sorted.sort_by(|a, b| a.total_cmp(b));
    let limit = limit * sorted[sorted.len() / 2].max(1e-300);
    let keep: Vec<bool> = sensitivity
        .iter()
        .map(|s| s.is_finite() && *s <= limit)
        .collect();
    if 2 * keep.iter().filter(|&&k| k).count() < sensitivity.len() {
        vec![true; sensitivity.len()]
    } else {
        keep
    }
}

/// Cluster-robust ("sandwich") standard errors of a least-squares fit: residuals `r` and
/// Jacobian `jac` (`m × n` row-major) at the solution, and a cluster id per residual (the
/// trajectory it comes from). `Cov = A⁻¹ B A⁻¹ · G/(G − 1)` with `A = JᵀJ` and
/// `B = Σ_g (J_gᵀ r_g)(J_gᵀ r_g)ᵀ` over the `G` clusters, over the free parameters. Residuals
/// of overlapping k-step windows of one trajectory are strongly correlated, so `σ²(JᵀJ)⁻¹`
/// (which treats every residual as independent) is far too small; clustering by whole
/// trajectories keeps that correlation. Fixed parameters get 0, and every free one NaN when
/// there are fewer than 2 clusters or `JᵀJ` is singular.
pub fn cluster_std(jac: &[f64], r: &[f64], n: usize, free: &[bool], cluster: &[usize]) -> Vec<f64> {
    let idx = match free_columns(jac, r, n, free, cluster) {
        Ok(idx) => idx,
        Err(std) => return std,
    };
    let nf = idx.len();
    let mut std = vec![0.0; n];
    let (jtj, _) = reduced_normal_equations(jac, r, n, &idx);
    let mut scores: std::collections::BTreeMap<usize, Vec<f64>> = Default::default();
    for ((row, ri), &g) in jac.chunks_exact(n).zip(r).zip(cluster) {
        let sc = scores.entry(g).or_insert_with(|| vec![0.0; nf]);
        for (a, &ia) in idx.iter().enumerate() {
            sc[a] += row[ia] * ri;
        }
    }
    let g = scores.len();
    if g < 2 {
        idx.iter().for_each(|&i| std[i] = f64::NAN);
        return std;
    }
    let mut b = vec![0.0; nf * nf];
    for sc in scores.values() {
        for i in 0..nf {
            for j in 0..nf {
                b[i * nf + j] += sc[i] * sc[j];
            }
        }
    }
    let trace: f64 = (0..nf).map(|i| jtj[i * nf + i]).sum::<f64>().max(1e-300);
    let mut a = jtj;
    for i in 0..nf {
        a[i * nf + i] += 1e-12 * trace / nf as f64;
    }
    // columns of A⁻¹
    let mut inv = vec![0.0; nf * nf];
    for k in 0..nf {
        let mut e = vec![0.0; nf];
        e[k] = 1.0;
        match solve(&a, &e, nf) {
            Some(col) => (0..nf).for_each(|i| inv[i * nf + k] = col[i]),
            None => {
                idx.iter().for_each(|&i| std[i] = f64::NAN);
                return std;
            }
        }
    }
    let corr = g as f64 / (g as f64 - 1.0);
    for (k, &i) in idx.iter().enumerate() {
        // (A⁻¹ B A⁻¹)_kk
        let mut v = 0.0;
        for p in 0..nf {
            for q in 0..nf {
                v += inv[k * nf + p] * b[p * nf + q] * inv[q * nf + k];
            }
        }
        std[i] = (corr * v).max(0.0).sqrt();
    }
    std
}

/// The free columns of a cluster-robust σ's arguments ([`cluster_std`]), or the σ to return
/// at once: all 0 without a free parameter, NaN for the free ones when the Jacobian or the
/// cluster ids do not match the residuals.
fn free_columns(
    jac: &[f64],
    r: &[f64],
    n: usize,
    free: &[bool],
    cluster: &[usize],
) -> Result<Vec<usize>, Vec<f64>> {
    let idx: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
    let mut std = vec![0.0; n];
    if idx.is_empty() {
        return Err(std);
    }
    let m = r.len();
    if jac.len() != m * n || cluster.len() != m {
        idx.iter().for_each(|&i| std[i] = f64::NAN);
        return Err(std);
    }
    Ok(idx)
}

/// Standard errors of a least-squares fit by the delete-one-cluster jackknife (the "CR3"
/// cluster-robust form), each cluster's removal taken as one Gauss–Newton step from the
/// solution: `Δθ_g = (JᵀJ − J_gᵀJ_g)⁻¹ J_gᵀ r_g`, `Var = (G − 1)/G · Σ_g (Δθ_g − Δ̄)²`. Arguments
/// as [`cluster_std`]. Where one cluster carries most of what determines a parameter (the one
/// segment over a grip patch, a segment through a spin, whose Jacobian dwarfs the rest) the
/// sandwich of [`cluster_std`] is far too small, since the fit follows that cluster's residuals
/// and its score is near zero; without the cluster the parameter moves, and the jackknife
/// shows it. Fixed parameters get 0, every free one NaN with fewer than 2 clusters or when
/// `JᵀJ` without some cluster cannot be solved.
pub fn cluster_jackknife_std(
    jac: &[f64],
    r: &[f64],
    n: usize,
    free: &[bool],
    cluster: &[usize],
) -> Vec<f64> {
    let idx = match free_columns(jac, r, n, free, cluster) {
        Ok(idx) => idx,
        Err(std) => return std,
    };
    let nf = idx.len();
    let mut std = vec![0.0; n];
    let undetermined = |mut std: Vec<f64>| {
        idx.iter().for_each(|&i| std[i] = f64::NAN);
        std
    };
    // per cluster: J_gᵀJ_g and J_gᵀr_g
    let mut parts: std::collections::BTreeMap<usize, (Vec<f64>, Vec<f64>)> = Default::default();
    for ((row, ri), &g) in jac.chunks_exact(n).zip(r).zip(cluster) {
        let (a, s) = parts
            .entry(g)
            .or_insert_with(|| (vec![0.0; nf * nf], vec![0.0; nf]));
        add_row(row, *ri, idx.as_slice(), a, s);
    }
    let g = parts.len();
    if g < 2 {
        return undetermined(std);
    }
    let mut total = vec![0.0; nf * nf];
    for (a, _) in parts.values() {
        total.iter_mut().zip(a).for_each(|(t, v)| *t += v);
    }
    let trace: f64 = (0..nf).map(|i| total[i * nf + i]).sum::<f64>().max(1e-300);
    let mut steps: Vec<Vec<f64>> = Vec::with_capacity(g);
    for (a, s) in parts.values() {
        let mut rest: Vec<f64> = total.iter().zip(a).map(|(t, v)| t - v).collect();
        for i in 0..nf {
            rest[i * nf + i] += 1e-12 * trace / nf as f64;
        }
        match solve(&rest, s, nf) {
            Some(d) => steps.push(d),
            None => return undetermined(std),
        }
    }
    let gf = g as f64;
    for (k, &i) in idx.iter().enumerate() {
        let mean = steps.iter().map(|d| d[k]).sum::<f64>() / gf;
        let var = steps.iter().map(|d| (d[k] - mean).powi(2)).sum::<f64>() * (gf - 1.0) / gf;
        std[i] = var.sqrt();
    }
    std
}

/// Adds one residual's Jacobian row `row` and value `ri` to `JᵀJ` (`jtj`) and `Jᵀr` (`jtr`)
/// over the columns `idx`.
fn add_row(row: &[f64], ri: f64, idx: &[usize], jtj: &mut [f64], jtr: &mut [f64]) {
    let nf = idx.len();
    for (a, &ia) in idx.iter().enumerate() {
        let va = row[ia];
        if va == 0.0 {
            continue;
        }
        jtr[a] += va * ri;
        for (b, &ib) in idx.iter().enumerate() {
            jtj[a * nf + b] += va * row[ib];
        }
    }
}

/// `JᵀJ` and `Jᵀr` over the columns `idx`.
fn reduced_normal_equations(
    jac: &[f64],
    r: &[f64],
    n: usize,
    idx: &[usize],
) -> (Vec<f64>, Vec<f64>) {
    let nf = idx.len();
    let mut jtj = vec![0.0; nf * nf];
    let mut jtr = vec![0.0; nf];
    for (row, ri) in jac.chunks_exact(n).zip(r) {
        add_row(row, *ri, idx, &mut jtj, &mut jtr);
    }
    (jtj, jtr)
}

/// `min ½δᵀAδ + gᵀδ  s.t.  lo ≤ δ ≤ hi` by clarabel; falls back to the clamped unconstrained
/// solution when the solver does not converge.
#[allow(non_snake_case)] // P, A, q as in Clarabel's paper
fn box_qp(a: &[f64], g: &[f64], lo: &[f64], hi: &[f64]) -> Option<Vec<f64>> {
    let n = g.len();
    let neg: Vec<f64> = g.iter().map(|x| -x).collect();
    let raw = solve(a, &neg, n);
    let clamp = |d: &[f64]| -> Vec<f64> {
        d.iter()
            .zip(lo.iter().zip(hi))
            .map(|(x, (l, h))| x.clamp(*l, *h))
            .collect()
    };
    if let Some(d) = &raw
        && d.iter()
            .zip(lo.iter().zip(hi))
            .all(|(x, (l, h))| x >= l && x <= h)
    {
        return raw; // inside the box: the QP's solution is the Newton step
    }
    // P upper triangular
    let mut colptr = vec![0usize];
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    for c in 0..n {
        for r in 0..=c {
            rowval.push(r);
            nzval.push(a[r * n + c]);
        }
        colptr.push(rowval.len());
    }
    let P = CscMatrix::new(n, n, colptr, rowval, nzval);
    // [I; −I] δ ≤ [hi; −lo]
    let mut colptr = vec![0usize];
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    for c in 0..n {
        rowval.extend([c, n + c]);
        nzval.extend([1.0, -1.0]);
        colptr.push(rowval.len());
    }
    let A = CscMatrix::new(2 * n, n, colptr, rowval, nzval);
    let b: Vec<f64> = hi.iter().copied().chain(lo.iter().map(|l| -l)).collect();
    let cones = [NonnegativeConeT(2 * n)];
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .build()
        .ok()?;
    let mut solver = DefaultSolver::new(&P, g, &A, &b, &cones, settings).ok()?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => Some(clamp(&solver.solution.x)),
        _ => raw.map(|d| clamp(&d)),
    }
}

/// Solves `A x = b` (n × n) by Gaussian elimination with partial pivoting.
pub(crate) fn solve(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    for col in 0..n {
        let piv =
            (col..n).max_by(|&i, &j| m[i * n + col].abs().total_cmp(&m[j * n + col].abs()))?;
        if m[piv * n + col].abs() < 1e-300 || !m[piv * n + col].is_finite() {
            return None;
        }
        if piv != col {
            for c in 0..n {
                m.swap(piv * n + c, col * n + c);
            }
            x.swap(piv, col);
        }
        for r in col + 1..n {
            let f = m[r * n + col] / m[col * n + col];
            if f != 0.0 {
                for c in col..n {
                    m[r * n + c] -= f * m[col * n + c];
                }
                x[r] -= f * x[col];
            }
        }
    }
    for col in (0..n).rev() {
        let mut s = x[col];
        for c in col + 1..n {
            s -= m[col * n + c] * x[c];
        }
        x[col] = s / m[col * n + col];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The model state at state index `a` of trajectory `t`: the measured state with the effect
/// states (`motor_lag`'s `d_f`, `steering_lag`'s `δ_w`) rebuilt from the trajectory's commands
/// before `a` by [`PhysicsModel::effect_states_along`] (started settled at the first command).
pub fn initial_state(p: &PhysicsModel, t: &StateTrajectory, a: usize) -> Vec<f64> {
    initial_state_after(p, &[], t, a)
}

/// [`initial_state`] at every `(trajectory, index)` of `at`, concatenated: the effect states are
/// rebuilt once per trajectory over all its commands (entry `a` of
/// [`PhysicsModel::effect_states_along`] depends only on the commands before `a`), not once per
/// window over its prefix.
pub fn initial_states(
    p: &PhysicsModel,
    trajs: &[StateTrajectory],
    at: impl IntoIterator<Item = (usize, usize)>,
) -> Vec<f64> {
    initial_states_after(p, &[], trajs, at)
}

/// [`initial_states`] of trajectories that continue recordings ([`initial_state_after`]):
/// `history[i]` holds the recording's commands before trajectory `i` (none past its end).
pub fn initial_states_after(
    p: &PhysicsModel,
    history: &[Vec<f64>],
    trajs: &[StateTrajectory],
    at: impl IntoIterator<Item = (usize, usize)>,
) -> Vec<f64> {
    let ne = p.dim_effect_states();
    // per trajectory: the effect states along its history and its commands, and the index of
    // its first sample among them
    let mut along: std::collections::BTreeMap<usize, (Vec<f64>, usize)> = Default::default();
    let mut out = Vec::new();
    for (ti, a) in at {
        let t = &trajs[ti];
        out.extend_from_slice(&t.s[a * t.dim_s..(a + 1) * t.dim_s]);
        if ne > 0 {
            let (e, first) = along.entry(ti).or_insert_with(|| {
                let before = history.get(ti).map_or(&[][..], Vec::as_slice);
                let mut u = before.to_vec();
                u.extend_from_slice(&t.u);
                let first = before.len() / t.dim_u.max(1);
                (p.effect_states_along(&u, t.dt), first)
            });
            let i = *first + a;
            out.extend_from_slice(&e[i * ne..(i + 1) * ne]);
        }
    }
    out
}

/// [`initial_state`] of a trajectory that continues a recording: the effect states are rebuilt
/// over `before` (the recording's commands before `t`, `n × dim_u`, settled at its first) and
/// `t`'s own commands up to `a`, so that cutting a recording into segments does not restart them.
pub fn initial_state_after(
    p: &PhysicsModel,
    before: &[f64],
    t: &StateTrajectory,
    a: usize,
) -> Vec<f64> {
    let ds = t.dim_s;
    let mut s = t.s[a * ds..(a + 1) * ds].to_vec();
    let ne = p.dim_effect_states();
    if ne > 0 {
        let mut u = Vec::with_capacity(before.len() + (a + 1) * t.dim_u);
        u.extend_from_slice(before);
        u.extend_from_slice(&t.u[..(a + 1) * t.dim_u]);
        let e = p.effect_states_along(&u, t.dt);
        let i = before.len() / t.dim_u.max(1) + a;
        s.extend_from_slice(&e[i * ne..(i + 1) * ne]);
    }
    s
}

/// Effect states at every sample of every trajectory of `history` (as
/// [`CommandHistory::effect_states`]) and their derivatives wrt all parameters of `p`
/// (`len × dim_effect_states × n_params` per trajectory), by dual numbers through the same
/// recursion: the fit's Jacobian includes how the initial effect state of each window moves
/// with `τ`.
fn effect_states_with_sens(
    p: &PhysicsModel,
    history: &CommandHistory,
    dt: f64,
    lens: &[usize],
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    const N: usize = 8;
    let ne = p.dim_effect_states();
    let np = p.params().len();
    let nt = history.origin.len();
    if ne == 0 {
        return (vec![Vec::new(); nt], vec![Vec::new(); nt]);
    }
    let mut vals: Vec<Vec<f64>> = Vec::new();
    let mut sens: Vec<Vec<f64>> = history
        .sources
        .iter()
        .map(|u| vec![0.0; u.len() / p.dim_input().max(1) * ne * np])
        .collect();
    let mut base = 0;
    while base < np {
        let pd: Vec<Dual<N>> = p
            .params()
            .iter()
            .enumerate()
            .map(|(i, &v)| Dual::var(v, i.wrapping_sub(base)))
            .collect();
        for (si, u) in history.sources.iter().enumerate() {
            let e = p.effect_states_along_generic(&pd, u, dt);
            if base == 0 {
                vals.push(e.iter().map(|x| x.v).collect());
            }
            for (r, x) in e.iter().enumerate() {
                for d in 0..N.min(np - base) {
                    sens[si][r * np + base + d] = x.d[d];
                }
            }
        }
        base += N;
    }
    let mut v_out = Vec::with_capacity(nt);
    let mut s_out = Vec::with_capacity(nt);
    for (&(src, off), &len) in history.origin.iter().zip(lens) {
        v_out.push(vals[src][off * ne..(off + len) * ne].to_vec());
        s_out.push(sens[src][off * ne * np..(off + len) * ne * np].to_vec());
    }
    (v_out, s_out)
}

/// The smallest rectangle `(lo, hi)` around the positions (the first two state components) of
/// `trajs`.
pub fn position_extent(trajs: &[StateTrajectory]) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for t in trajs.iter().filter(|t| t.dim_s >= 2) {
        for i in 0..t.len() {
            for c in 0..2 {
                lo[c] = lo[c].min(t.s[i * t.dim_s + c]);
                hi[c] = hi[c].max(t.s[i * t.dim_s + c]);
            }
        }
    }
    (lo, hi)
}

/// Which parameters the fit frees: `cfg.physics_free` names the nominal ones when set (effect
/// parameters are always free except a patch's edge width), else [`PhysicsModel::default_free`].
pub fn free_mask(p: &PhysicsModel, cfg: &TrainConfig) -> Result<Vec<bool>, LearnError> {
    let mut free = p.default_free();
    if let Some(names) = &cfg.physics_free {
        let all = p.param_names();
        let nominal = PhysicsModel::nominal_specs(p.robot()).len();
        for f in free.iter_mut().take(nominal) {
            *f = false;
        }
        for n in names {
            let i = all.iter().position(|a| a == n).ok_or_else(|| {
                LearnError::setting(
                    "physics_free",
                    n,
                    format!("name parameters of the model: {}", all.join(", ")),
                )
            })?;
            free[i] = true;
        }
    }
    Ok(free)
}

/// Fits the free parameters of `p` (see [`free_mask`]; values from `cfg.physics_values` are set
/// first) by [`bounded_least_squares`] on the k-step open-loop residual of the learned
/// dimensions, weighted like the training loss (pushing: `√w_d`, car: `1/σ_d` of the velocities,
/// discount `√γ^(j−1)`), and sets the parameter standard errors.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit_physics(
    p: &mut PhysicsModel,
    solver: &Solver,
    world: World,
    dt: f64,
    trajs: &[StateTrajectory],
    history: &CommandHistory,
    train_w: &[Window],
    k: usize,
    cfg: &TrainConfig,
    loss: &Loss,
) -> Result<PhysicsFit, LearnError> {
    for (name, v) in &cfg.physics_values {
        p.set_param(name, *v)?;
    }
    let free = free_mask(p, cfg)?;
    let lr = world.learned_dims();
    let ds = world.state_dim();
    let dp = p.dim_state();
    let t_phys = if world == World::Push { 1.0 } else { dt };
    let weights: Vec<f64> = match loss {
        Loss::PoseMse { weights } => weights.iter().map(|w| w.sqrt()).collect(),
        Loss::LRel { .. } => {
            let mut rows = Vec::new();
            for t in trajs {
                for i in 0..t.len() {
                    rows.extend_from_slice(&t.s[i * ds + lr.start..i * ds + lr.end]);
                }
            }
            let nz = dynlab_dynamics::data::Normalizer::fit(&rows, lr.len(), 1e-9)?;
            nz.std.iter().map(|s| 1.0 / s).collect()
        }
    };
    let mut ws: Vec<Window> = train_w.to_vec();
    SplitMix64::new(cfg.seed ^ 0x5851_F42D_4C95_7F2D).shuffle(&mut ws);
    ws.truncate(cfg.physics_max_windows.max(1));
    ws.sort_by_key(|w| (w.trajectory, w.start));
    let specs = p.param_specs();
    let np = specs.len();
    let lower: Vec<f64> = specs.iter().map(|(_, s)| s.lower).collect();
    let upper: Vec<f64> = specs.iter().map(|(_, s)| s.upper).collect();
    let base = p.clone();
    let lens: Vec<usize> = trajs.iter().map(StateTrajectory::len).collect();
    // the residuals (and Jacobian rows) of a block of windows, in window order
    let eval_block = |p: &PhysicsModel,
                      ws: &[Window],
                      extra: &[Vec<f64>],
                      extra_sens: &[Vec<f64>],
                      with_j: bool|
     -> (Vec<f64>, Vec<f64>) {
        let mut r = Vec::new();
        let mut jac = Vec::new();
        let mut tape = StepTape::default();
        let mut sn = vec![0.0; dp];
        let mut sens = vec![0.0; dp * np];
        let mut phis = vec![0.0; dp * dp];
        let mut phit = vec![0.0; dp * np];
        let mut ybar = vec![0.0; dp];
        let mut sbar0 = vec![0.0; dp];
        let du = world.action_dim();
        let mut ubar = vec![0.0; du];
        let mut pbar = vec![0.0; np];
        let ne = dp - ds;
        for w in ws {
            let t = &trajs[w.trajectory];
            let a0 = w.start;
            let mut s = t.s[a0 * ds..(a0 + 1) * ds].to_vec();
            s.extend_from_slice(&extra[w.trajectory][a0 * ne..(a0 + 1) * ne]);
            sens.iter_mut().for_each(|x| *x = 0.0);
            if with_j && ne > 0 {
                sens[ds * np..]
                    .copy_from_slice(&extra_sens[w.trajectory][a0 * ne * np..(a0 + 1) * ne * np]);
            }
            let mut g: f64 = 1.0;
            for j in 0..k {
                let a = w.start + j;
                let u = &t.u[a * du..(a + 1) * du];
                let rep = if with_j {
                    p.integrate_step_taped(solver, 1, &s, u, t_phys, &mut sn, &mut tape)
                } else {
                    p.integrate_step(solver, 1, &s, u, t_phys, &mut sn)
                };
                let bad = rep.status != OdeStatus::Success;
                if with_j {
                    for d in 0..dp {
                        ybar.iter_mut().for_each(|x| *x = 0.0);
                        ybar[d] = 1.0;
                        pbar.iter_mut().for_each(|x| *x = 0.0);
                        p.integrate_step_vjp(&tape, &ybar, &mut sbar0, &mut ubar, &mut pbar);
                        phis[d * dp..(d + 1) * dp].copy_from_slice(&sbar0);
                        phit[d * np..(d + 1) * np].copy_from_slice(&pbar);
                    }
                    let mut new = phit.clone();
                    for r_ in 0..dp {
                        for m in 0..dp {
                            let a_ = phis[r_ * dp + m];
                            if a_ != 0.0 {
                                for c in 0..np {
                                    new[r_ * np + c] += a_ * sens[m * np + c];
                                }
                            }
                        }
                    }
                    sens = new;
                }
                let meas = &t.s[(a + 1) * ds..(a + 2) * ds];
                let sg = g.sqrt();
                for (q, d) in lr.clone().enumerate() {
                    let e = sn[d] - meas[d];
                    let e = if d == world.angle_dim() {
                        wrap_angle(e)
                    } else {
                        e
                    };
                    let e = if bad || !e.is_finite() { 1e3 } else { e };
                    r.push(sg * weights[q] * e);
                    if with_j {
                        jac.extend(sens[d * np..(d + 1) * np].iter().map(|x| {
                            let v = sg * weights[q] * x;
                            if v.is_finite() { v } else { 0.0 }
                        }));
                    }
                }
                s.copy_from_slice(&sn);
                g *= cfg.gamma;
            }
        }
        (r, jac)
    };
    let eval_on = |ws: &[Window], theta: &[f64], with_j: bool| -> (Vec<f64>, Vec<f64>) {
        let mut p = base.clone();
        if p.set_params(theta).is_err() {
            return (vec![f64::INFINITY], Vec::new());
        }
        // initial effect states of every window from the commands before it, with ∂/∂θ
        let (extra, extra_sens) = if with_j {
            effect_states_with_sens(&p, history, t_phys, &lens)
        } else {
            let e = history.effect_states(&p, t_phys, &lens);
            (e, vec![Vec::new(); lens.len()])
        };
        let (p, extra, extra_sens) = (&p, &extra[..], &extra_sens[..]);
        let mut r = Vec::new();
        let mut jac = Vec::new();
        for (rb, jb) in in_blocks(ws, |b| eval_block(p, b, extra, extra_sens, with_j)) {
            r.extend(rb);
            jac.extend(jb);
        }
        (r, jac)
    };
    let started = screen_starts(p, cfg, trajs, &|theta: &[f64]| {
        eval_on(&ws, theta, false).0.iter().map(|r| r * r).sum()
    })?;
    let rows = k * lr.len();
    // rollouts through a spin out of the fit (see `calm_windows`): which of the `n` windows
    // behind residuals `r` and Jacobian `jac` at `theta` are calm, from each window's
    // sensitivity to the free parameters, each column scaled by its parameter's size
    let calm = |n: usize, r: &[f64], jac: &[f64], theta: &[f64]| -> Option<Vec<bool>> {
        if r.len() != n * rows || jac.len() != r.len() * np {
            return None;
        }
        let sens: Vec<f64> = (0..n)
            .map(|i| {
                let mut s = 0.0;
                for row in i * rows..(i + 1) * rows {
                    for c in (0..np).filter(|&c| free[c]) {
                        let d = jac[row * np + c] * theta[c].abs().max(1e-12);
                        s += d * d;
                    }
                }
                s
            })
            .collect();
        Some(calm_windows(&sens, SENSITIVITY_LIMIT))
    };
    let screen = free.iter().any(|&f| f) && k > 1;
    if screen {
        let (r, jac) = eval_on(&ws, p.params(), true);
        if let Some(keep) = calm(ws.len(), &r, &jac, p.params()) {
            ws = kept_windows(ws, &keep);
        }
    }
    let mut res = bounded_least_squares(
        p.params(),
        &lower,
        &upper,
        &free,
        cfg.physics_iterations,
        &mut |theta: &[f64], with_j: bool| eval_on(&ws, theta, with_j),
    );
    // honest standard errors: clustered by trajectory (windows overlap), from the windows
    // calm at the result: a window calm at the start can spin at the parameters the fit
    // reaches (and stop it there), and its Jacobian would shrink them to nothing
    if free.iter().any(|&f| f) {
        let (mut r, mut jac) = eval_on(&ws, &res.theta, true);
        let keep = screen
            .then(|| calm(ws.len(), &r, &jac, &res.theta))
            .flatten();
        if let Some(keep) = keep {
            (r, jac) = kept_rows(&r, &jac, np, |row| keep[row / rows]);
            ws = kept_windows(ws, &keep);
        }
        let cluster: Vec<usize> = ws
            .iter()
            .flat_map(|w| std::iter::repeat_n(w.trajectory, rows))
            .collect();
        let cs = cluster_std(&jac, &r, np, &free, &cluster);
        if cs.iter().all(|v| !v.is_nan()) {
            res.std = cs;
        }
    }
    p.canonical(&mut res.theta, &mut res.std);
    p.set_params(&res.theta)?;
    p.set_std_errors(Some(res.std))?;
    Ok(PhysicsFit {
        initial_cost: res.initial_cost,
        final_cost: res.cost,
        iterations: res.iterations,
        residuals: res.residuals,
        started,
    })
}

/// The residual rows of `r` for which `keep(row)` holds, with their rows of the Jacobian `jac`
/// (`np` columns, row-major).
pub fn kept_rows(
    r: &[f64],
    jac: &[f64],
    np: usize,
    keep: impl Fn(usize) -> bool,
) -> (Vec<f64>, Vec<f64>) {
    let rows: Vec<usize> = (0..r.len()).filter(|&i| keep(i)).collect();
    let jac = rows
        .iter()
        .flat_map(|&i| jac[i * np..(i + 1) * np].iter().copied())
        .collect();
    (rows.iter().map(|&i| r[i]).collect(), jac)
}

/// The windows whose `keep` is set.
fn kept_windows(ws: Vec<Window>, keep: &[bool]) -> Vec<Window> {
    ws.into_iter()
        .zip(keep)
        .filter_map(|(w, &k)| k.then_some(w))
        .collect()
}

/// Starts every library effect of `p` that `cfg.physics_values` gives no value from the best
/// of its starting points ([`Effect::starts`](dynlab_dynamics::physics::Effect::starts) and
/// [`Effect::fine_starts`](dynlab_dynamics::physics::Effect::fine_starts) over the data's
/// extent) by the fit's cost `cost(θ)`, one effect after the other, and says so for
/// each effect moved off its defaults (why a fit needs them:
/// [`Effect::starts`](dynlab_dynamics::physics::Effect::starts)).
fn screen_starts(
    p: &mut PhysicsModel,
    cfg: &TrainConfig,
    trajs: &[StateTrajectory],
    cost: &dyn Fn(&[f64]) -> f64,
) -> Result<Vec<String>, LearnError> {
    let (lo, hi) = position_extent(trajs);
    let mut started = Vec::new();
    for e in p.effects() {
        let prefix = format!("{}.", e.name());
        if cfg
            .physics_values
            .iter()
            .any(|(n, _)| n.starts_with(&prefix))
        {
            continue;
        }
        let mut starts = e.starts(lo, hi);
        starts.extend(e.fine_starts(lo, hi));
        if starts.len() < 2 {
            continue;
        }
        let mut best = (cost(p.params()), None);
        for st in &starts {
            let mut q = p.clone();
            if st
                .iter()
                .any(|(n, v)| q.set_param(&format!("{prefix}{n}"), *v).is_err())
            {
                continue;
            }
            let c = cost(q.params());
            if c < best.0 {
                best = (c, Some(st));
            }
        }
        if let Some(st) = best.1 {
            for (n, v) in st {
                p.set_param(&format!("{prefix}{n}"), *v)?;
            }
            let values: Vec<String> = st.iter().map(|(n, v)| format!("{n} = {v:.3}")).collect();
            started.push(format!(
                "{} from {} (the best of {} starting points and its defaults)",
                e.name(),
                values.join(", "),
                starts.len()
            ));
        }
    }
    Ok(started)
}
