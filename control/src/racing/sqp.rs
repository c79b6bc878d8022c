//! Trust-region SQP on Clarabel with the exact Jacobians of the learned model.

use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
};

use super::gd::gradient_from;
use super::plant::{Input, Linearization};
use super::{Deadline, Problem, RacingError, Solution, SolveStatus};

/// Settings of the SQP.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SqpSettings {
    /// Largest number of SQP iterations (QPs solved). Default 50.
    pub iterations: usize,
    /// Initial trust radius on the steering step \[rad\]. Default 0.1.
    pub trust_steering: f64,
    /// Initial trust radius on the throttle step. Default 0.3.
    pub trust_throttle: f64,
    /// Smallest trust radius as a fraction of the initial one; below it the solve stops as
    /// converged. Default 1e-4.
    pub min_trust_fraction: f64,
    /// Converged when the QP predicts a decrease below `tolerance · (1 + |ℓ|)`. Default 1e-9.
    pub tolerance: f64,
    /// Impose the track borders (`half_width − margin`) as hard linearised constraints.
    /// Default true.
    pub track_constraints: bool,
    /// When the hard-border QP is infeasible, re-solve it with slacks at this linear penalty
    /// per metre (an exact penalty: equal to the hard QP whenever that one is feasible);
    /// `None` reports [`SolveStatus::Infeasible`] instead. Default `Some(1000)`.
    pub elastic_penalty: Option<f64>,
    /// Once a QP of a solve needed the elastic fallback, solve the following QPs of the same
    /// solve as elastic QPs directly instead of first finding the hard one infeasible again (the
    /// exact penalty gives the hard QP's step whenever that one is feasible). Default false
    /// (the racer's default: true, see [`SqpSettings::fast_qp`]).
    pub sticky_elastic: bool,
    /// Clarabel's gap and feasibility tolerances (`tol_gap_abs`, `tol_gap_rel`, `tol_feas`)
    /// for the QPs. Default 1e-8, Clarabel's own (the racer's default: 1e-6, two fewer
    /// interior-point iterations for a step the trust region and the ratio test check anyway).
    pub qp_tolerance: f64,
    /// Clarabel's iterative refinement of each KKT solve. Default true, Clarabel's own (the
    /// racer's default: false; the refinement was ≈ 20 % of the racing QP's time).
    pub qp_refinement: bool,
    /// Clarabel's equilibration (Ruiz scaling) of the QP data. Default true, Clarabel's own (so
    /// is the racer's: without it the racing QPs took fewer interior-point iterations, but one
    /// ORCA lap run stalled in elastic QPs).
    pub qp_equilibrate: bool,
}

impl SqpSettings {
    /// These settings with the racer's fast QPs: `sticky_elastic`, `qp_tolerance` 1e-6, no
    /// iterative refinement (equilibration kept). [`RacerSettings`](super::RacerSettings)'
    /// default SQP uses them; offline solves to convergence keep Clarabel's defaults.
    pub fn fast_qp(self) -> Self {
        Self {
            sticky_elastic: true,
            qp_tolerance: 1e-6,
            qp_refinement: false,
            ..self
        }
    }
}

impl Default for SqpSettings {
    fn default() -> Self {
        Self {
            iterations: 50,
            trust_steering: 0.1,
            trust_throttle: 0.3,
            min_trust_fraction: 1e-4,
            tolerance: 1e-9,
            track_constraints: true,
            elastic_penalty: Some(1000.0),
            sticky_elastic: false,
            qp_tolerance: 1e-8,
            qp_refinement: true,
            qp_equilibrate: true,
        }
    }
}

enum QpOutcome {
    Step {
        du: Vec<f64>,
        predicted: f64,
        elastic: bool,
        /// Largest border slack of an elastic QP \[m\] (0 for a hard one).
        max_slack: f64,
    },
    Infeasible,
    Failed,
}

/// Sparse upper triangle (or full matrix) of a dense row-major `rows × cols` matrix.
fn csc(rows: usize, cols: usize, dense: &[f64], upper: bool) -> CscMatrix<f64> {
    let mut colptr = Vec::with_capacity(cols + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for c in 0..cols {
        let last = if upper { (c + 1).min(rows) } else { rows };
        for r in 0..last {
            let v = dense[r * cols + c];
            if v != 0.0 {
                rowval.push(r);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows, cols, colptr, rowval, nzval)
}

/// Builds and solves the QP of one SQP iteration.
// index loops mirror the block equations of the QP
#[allow(non_snake_case, clippy::needless_range_loop)]
fn solve_qp(
    problem: &Problem<'_>,
    u: &[Input],
    lin: &Linearization,
    radius: [f64; 2],
    settings: &SqpSettings,
    elastic: bool,
) -> QpOutcome {
    let n = u.len();
    let m = 2 * n;
    let obj = &problem.objective;
    let locs = obj.locate(&lin.states);
    // sensitivities G_k = ∂x_k/∂u (nx × m, the augmented state [s, e]) for k = 1..n; the cost
    // terms below read the car states' rows
    let nx = lin.nx;
    let mut G = vec![vec![0.0; nx * m]; n + 1];
    for k in 0..n {
        let (a, b) = (&lin.a[k], &lin.b[k]);
        let mut next = vec![0.0; nx * m];
        for r in 0..nx {
            for c in 0..2 * k {
                next[r * m + c] = (0..nx).map(|q| a[r * nx + q] * G[k][q * m + c]).sum();
            }
            next[r * m + 2 * k] = b[r * 2];
            next[r * m + 2 * k + 1] = b[r * 2 + 1];
        }
        G[k + 1] = next;
    }
    let (_, gu, hu) = obj.input_terms(u);
    let mut P = hu;
    let mut q = gu;
    let mut borders: Vec<(Vec<f64>, f64, f64)> = Vec::new();
    for k in 1..=n {
        let loc = if locs.is_empty() {
            None
        } else {
            Some((&locs[0], &locs[k]))
        };
        let st = obj.state_term(k, n, &lin.states[k], loc);
        let g = &G[k];
        // q += Gᵀ ∇ℓ_k,  P += Gᵀ H_k G
        let active: Vec<usize> = (0..6)
            .filter(|&i| st.grad[i] != 0.0 || (0..6).any(|j| st.hess[i * 6 + j] != 0.0))
            .collect();
        for &i in &active {
            for c in 0..m {
                q[c] += g[i * m + c] * st.grad[i];
            }
        }
        for &i in &active {
            for &j in &active {
                let h = st.hess[i * 6 + j];
                if h == 0.0 {
                    continue;
                }
                for r in 0..m {
                    let gr = g[i * m + r] * h;
                    if gr == 0.0 {
                        continue;
                    }
                    for c in 0..m {
                        P[r * m + c] += gr * g[j * m + c];
                    }
                }
            }
        }
        if settings.track_constraints
            && let (Some(tt), Some((_, l))) = (&obj.track, loc)
        {
            let row: Vec<f64> = (0..m)
                .map(|c| l.normal[0] * g[c] + l.normal[1] * g[m + c])
                .collect();
            let w = l.half_width - tt.margin_at(k);
            borders.push((row, w - l.lateral, w + l.lateral));
        }
    }
    let ns = if elastic { borders.len() } else { 0 };
    let nv = m + ns;
    let penalty = settings.elastic_penalty.unwrap_or(1000.0);
    // P over [δu, σ]
    let mut Pf = vec![0.0; nv * nv];
    for r in 0..m {
        for c in 0..m {
            Pf[r * nv + c] = 0.5 * (P[r * m + c] + P[c * m + r]);
        }
    }
    for s in 0..ns {
        Pf[(m + s) * nv + m + s] = 1e-6;
    }
    let mut qf = q.clone();
    qf.extend(std::iter::repeat_n(penalty, ns));
    // constraints A x ≤ b
    let (lo, hi) = (obj.limits.lower(), obj.limits.upper());
    let rows = 2 * m + 2 * borders.len() + ns;
    let mut A = vec![0.0; rows * nv];
    let mut bvec = vec![0.0; rows];
    let mut r = 0;
    for k in 0..n {
        for i in 0..2 {
            let c = 2 * k + i;
            let upper = (hi[i] - u[k][i]).min(radius[i]).max(0.0);
            let lower = (lo[i] - u[k][i]).max(-radius[i]).min(0.0);
            A[r * nv + c] = 1.0;
            bvec[r] = upper;
            r += 1;
            A[r * nv + c] = -1.0;
            bvec[r] = -lower;
            r += 1;
        }
    }
    for (s, (row, up, down)) in borders.iter().enumerate() {
        for c in 0..m {
            A[r * nv + c] = row[c];
            A[(r + 1) * nv + c] = -row[c];
        }
        bvec[r] = *up;
        bvec[r + 1] = *down;
        if elastic {
            A[r * nv + m + s] = -1.0;
            A[(r + 1) * nv + m + s] = -1.0;
        }
        r += 2;
    }
    for s in 0..ns {
        A[r * nv + m + s] = -1.0;
        r += 1;
    }
    let Pc = csc(nv, nv, &Pf, true);
    let Ac = csc(rows, nv, &A, false);
    let cones = [NonnegativeConeT(rows)];
    let tol = settings.qp_tolerance;
    let Ok(cfg) = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(100)
        .tol_gap_abs(tol)
        .tol_gap_rel(tol)
        .tol_feas(tol)
        .iterative_refinement_enable(settings.qp_refinement)
        .equilibrate_enable(settings.qp_equilibrate)
        .build()
    else {
        return QpOutcome::Failed;
    };
    let Ok(mut solver) = DefaultSolver::new(&Pc, &qf, &Ac, &bvec, &cones, cfg) else {
        return QpOutcome::Failed;
    };
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {
            let du = solver.solution.x[..m].to_vec();
            let max_slack = solver.solution.x[m..].iter().fold(0.0f64, |a, &b| a.max(b));
            let mut quad = 0.0;
            for a in 0..m {
                for b in 0..m {
                    quad += du[a] * Pf[a * nv + b] * du[b];
                }
            }
            let lin_term: f64 = (0..m).map(|a| q[a] * du[a]).sum();
            QpOutcome::Step {
                predicted: -(lin_term + 0.5 * quad),
                du,
                elastic,
                max_slack,
            }
        }
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            QpOutcome::Infeasible
        }
        _ => QpOutcome::Failed,
    }
}

/// Trust-region SQP: linearise the model about the current inputs (exact Jacobians), solve the
/// Gauss–Newton QP in the input step with input limits, trust region and (optionally) the track
/// borders as hard constraints, accept the step if the true cost falls by at least 10 % of the
/// predicted decrease, otherwise shrink the trust region.
pub fn solve_sqp(
    problem: &Problem<'_>,
    initial: &[Input],
    settings: &SqpSettings,
) -> Result<Solution, RacingError> {
    solve_sqp_until(problem, initial, settings, None)
}

/// [`solve_sqp`] that stops at a wall-clock `deadline` (`None`: no deadline, exactly
/// [`solve_sqp`]).
///
/// An iteration (the first one including the initial linearisation) is only started while
/// [`Deadline::allows_iteration`]: more time is left than the longest iteration recorded on
/// the deadline so far. A solve stopped this way returns the best iterate found (every accepted
/// step lowers the true cost, so that is the last accepted one) with [`SolveStatus::Deadline`].
/// When not even the first iteration fits, the initial guess (clamped to the input limits) is
/// rolled out and returned with 0 iterations: a plan is always returned. Without a deadline, or
/// when it is not reached, the result is bitwise that of [`solve_sqp`].
pub fn solve_sqp_until(
    problem: &Problem<'_>,
    initial: &[Input],
    settings: &SqpSettings,
    deadline: Option<&Deadline>,
) -> Result<Solution, RacingError> {
    if !(settings.qp_tolerance > 0.0 && settings.qp_tolerance < 1.0) {
        return Err(RacingError::setting(
            "sqp.qp_tolerance",
            settings.qp_tolerance,
            "a QP tolerance in (0, 1), e.g. 1e-6 (Clarabel's default 1e-8)",
        ));
    }
    if !(settings.trust_steering > 0.0 && settings.trust_throttle > 0.0) {
        return Err(RacingError::setting(
            "sqp.trust_steering/trust_throttle",
            format!("{} / {}", settings.trust_steering, settings.trust_throttle),
            "trust radii must be > 0",
        ));
    }
    let limits = problem.objective.limits;
    let mut u: Vec<Input> = initial.iter().map(|x| limits.clamp(*x)).collect();
    let entry = Instant::now();
    if deadline.is_some_and(|d| !d.allows_iteration()) {
        // no time for an iteration: the initial guess's plan, without its Jacobians
        let states = problem.plant.rollout(&problem.s0, &u)?;
        let cost = problem.objective.cost(&states, &u);
        return Ok(Solution {
            inputs: u,
            states,
            cost,
            status: if cost.is_finite() {
                SolveStatus::Deadline
            } else {
                SolveStatus::ModelFailure
            },
            iterations: 0,
            history: vec![cost],
            elastic_qps: 0,
        });
    }
    let mut lin = problem.plant.linearize(&problem.s0, &u)?;
    let (mut cost, _) = gradient_from(problem, &u, &lin);
    let mut history = vec![cost];
    let mut elastic_qps = 0;
    if !cost.is_finite() {
        return Ok(Solution {
            inputs: u,
            states: lin.states,
            cost,
            status: SolveStatus::ModelFailure,
            iterations: 0,
            history,
            elastic_qps,
        });
    }
    let r0 = [settings.trust_steering, settings.trust_throttle];
    let mut scale = 1.0f64;
    let mut status = SolveStatus::MaxIterations;
    let mut iterations = 0;
    // the fine trajectory of the last accepted step, linearised lazily
    let mut stale: Option<Vec<f64>> = None;
    while iterations < settings.iterations {
        // the first iteration started with the initial linearisation (on entry)
        let started = if iterations == 0 {
            entry
        } else {
            Instant::now()
        };
        if iterations > 0 && deadline.is_some_and(|d| !d.allows_iteration()) {
            status = SolveStatus::Deadline;
            break;
        }
        iterations += 1;
        let radius = [r0[0] * scale, r0[1] * scale];
        if let Some(fine) = stale.take() {
            lin = problem.plant.linearize_fine(&fine, &u)?;
        }
        let go_elastic = settings.sticky_elastic && elastic_qps > 0;
        // a direct elastic QP counts as elastic only when its slacks are used (the hard QP
        // would have been infeasible)
        let mut out = solve_qp(problem, &u, &lin, radius, settings, go_elastic);
        if !go_elastic && matches!(out, QpOutcome::Infeasible) && settings.elastic_penalty.is_some()
        {
            out = solve_qp(problem, &u, &lin, radius, settings, true);
        }
        let (du, predicted, elastic) = match out {
            QpOutcome::Step {
                du,
                predicted,
                elastic,
                max_slack,
            } => (du, predicted, elastic && (!go_elastic || max_slack > 1e-6)),
            QpOutcome::Infeasible => {
                status = SolveStatus::Infeasible;
                break;
            }
            QpOutcome::Failed => {
                status = SolveStatus::NumericalError;
                break;
            }
        };
        if elastic {
            elastic_qps += 1;
        }
        if predicted <= settings.tolerance * (1.0 + cost.abs()) {
            status = SolveStatus::Solved;
            break;
        }
        let cand: Vec<Input> = u
            .iter()
            .enumerate()
            .map(|(k, x)| limits.clamp([x[0] + du[2 * k], x[1] + du[2 * k + 1]]))
            .collect();
        let fine = problem.plant.rollout_fine(&problem.s0, &cand)?;
        let states = problem.plant.coarse(&fine);
        let new_cost = problem.objective.cost(&states, &cand);
        let actual = cost - new_cost;
        let rho = actual / predicted;
        if new_cost.is_finite() && rho >= 0.1 {
            u = cand;
            // linearise lazily: the last accepted step needs only its states
            lin.states = states;
            stale = Some(fine);
            cost = new_cost;
            history.push(cost);
            let at_edge = du
                .chunks(2)
                .any(|d| d[0].abs() >= 0.99 * radius[0] || d[1].abs() >= 0.99 * radius[1]);
            if rho > 0.75 && at_edge {
                scale = (scale * 2.0).min(10.0);
            }
        } else {
            scale *= 0.25;
            if scale < settings.min_trust_fraction {
                status = SolveStatus::Solved;
                break;
            }
        }
        if let Some(d) = deadline {
            d.record(started.elapsed());
        }
    }
    Ok(Solution {
        inputs: u,
        states: lin.states,
        cost,
        status,
        iterations,
        history,
        elastic_qps,
    })
}
