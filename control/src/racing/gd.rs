//! The exact gradient `dℓ/du` by reverse mode and the paper's batch gradient descent.

use super::plant::{Input, Linearization};
use super::{Deadline, Problem, RacingError, Solution, SolveStatus};

/// Settings of the batch gradient descent (Kohler et al., Sec. III-C).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct GdSettings {
    /// Largest number of iterations. Default 300.
    pub iterations: usize,
    /// Step sizes tried per iteration, log-spaced in `[smallest_step, largest_step]`.
    /// Default 512.
    pub step_sizes: usize,
    /// Largest step size. Default 1.
    pub largest_step: f64,
    /// Smallest step size. Default 1e-6.
    pub smallest_step: f64,
    /// Converged when the best candidate lowers the cost by less than `tolerance · (1 + |ℓ|)`.
    /// Default 1e-9.
    pub tolerance: f64,
}

impl Default for GdSettings {
    fn default() -> Self {
        Self {
            iterations: 300,
            step_sizes: 512,
            largest_step: 1.0,
            smallest_step: 1e-6,
            tolerance: 1e-9,
        }
    }
}

/// Cost, exact gradient `dℓ/du` (one `[∂δ, ∂d]` per step) and the linearisation, by the
/// adjoint recursion `λ_n = ∇ℓ_n`, `λ_k = ∇ℓ_k + A_kᵀ λ_{k+1}`, `dℓ/du_k = ∇_u ℓ + B_kᵀ λ_{k+1}`
/// (the implicit-function view of eqs. 7–9, solved backwards through the block-bidiagonal
/// system instead of forming its inverse).
pub fn gradient(
    problem: &Problem<'_>,
    inputs: &[Input],
) -> Result<(f64, Vec<Input>, Linearization), RacingError> {
    let lin = problem.plant.linearize(&problem.s0, inputs)?;
    let (cost, grad) = gradient_from(problem, inputs, &lin);
    Ok((cost, grad, lin))
}

#[allow(clippy::needless_range_loop)] // index loops mirror the equations
pub(crate) fn gradient_from(
    problem: &Problem<'_>,
    inputs: &[Input],
    lin: &Linearization,
) -> (f64, Vec<Input>) {
    let n = inputs.len();
    let obj = &problem.objective;
    if lin.states.iter().flatten().any(|v| !v.is_finite()) {
        return (f64::INFINITY, vec![[0.0; 2]; n]);
    }
    let locs = obj.locate(&lin.states);
    let (vu, gu, _) = obj.input_terms(inputs);
    let mut cost = vu;
    let mut grad = vec![[0.0; 2]; n];
    for k in 0..n {
        grad[k] = [gu[2 * k], gu[2 * k + 1]];
    }
    // λ over the augmented state [s, e]: the cost reads the car states only, but the effect
    // states carry how earlier inputs act later
    let nx = lin.nx;
    let mut lambda = vec![0.0; nx];
    let mut next = vec![0.0; nx];
    for k in (1..=n).rev() {
        let loc = if locs.is_empty() {
            None
        } else {
            Some((&locs[0], &locs[k]))
        };
        let st = obj.state_term(k, n, &lin.states[k], loc);
        cost += st.value;
        for i in 0..6 {
            lambda[i] += st.grad[i];
        }
        // λ now is dℓ/dx_k; pass it through B_{k-1} and A_{k-1}
        let (a, b) = (&lin.a[k - 1], &lin.b[k - 1]);
        for c in 0..2 {
            grad[k - 1][c] += (0..nx).map(|r| b[r * 2 + c] * lambda[r]).sum::<f64>();
        }
        for (c, v) in next.iter_mut().enumerate() {
            *v = (0..nx).map(|r| a[r * nx + c] * lambda[r]).sum();
        }
        std::mem::swap(&mut lambda, &mut next);
    }
    (cost, grad)
}

/// Candidates per batched rollout in the line search: a fixed split, so the batches a model
/// sees (and so the results) do not depend on the number of threads.
const LINE_SEARCH_CHUNK: usize = 64;

/// The cost of every candidate input sequence: the candidates are rolled out in fixed chunks of
/// [`LINE_SEARCH_CHUNK`] (one batched model call each), the chunks spread over the available
/// cores. Deterministic: each chunk is the same batch whatever the thread count.
fn candidate_costs(problem: &Problem<'_>, cands: &[Vec<Input>]) -> Result<Vec<f64>, RacingError> {
    let chunks: Vec<&[Vec<Input>]> = cands.chunks(LINE_SEARCH_CHUNK).collect();
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, chunks.len().max(1));
    let eval = |chunk: &[Vec<Input>]| -> Result<Vec<f64>, RacingError> {
        let rolled = problem.plant.rollout_batch(&problem.s0, chunk)?;
        Ok(chunk
            .iter()
            .zip(&rolled)
            .map(|(c, s)| problem.objective.cost(s, c))
            .collect())
    };
    if threads <= 1 {
        let mut out = Vec::with_capacity(cands.len());
        for c in &chunks {
            out.extend(eval(c)?);
        }
        return Ok(out);
    }
    // thread t takes chunks t, t + threads, …; results are put back in chunk order
    type ChunkCosts = Vec<(usize, Vec<f64>)>;
    let per_thread: Vec<Result<ChunkCosts, RacingError>> = std::thread::scope(|sc| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let chunks = &chunks;
                let eval = &eval;
                sc.spawn(move || {
                    let mut got = Vec::new();
                    for i in (t..chunks.len()).step_by(threads) {
                        got.push((i, eval(chunks[i])?));
                    }
                    Ok(got)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(RacingError::setting(
                        "gd",
                        "a line-search thread panicked",
                        "report this as a bug",
                    ))
                })
            })
            .collect()
    });
    let mut by_chunk: Vec<Vec<f64>> = vec![Vec::new(); chunks.len()];
    for r in per_thread {
        for (i, v) in r? {
            by_chunk[i] = v;
        }
    }
    Ok(by_chunk.into_iter().flatten().collect())
}

/// The paper's batch gradient descent: each iteration scales the exact gradient by
/// `step_sizes` constants log-spaced in `[smallest_step, largest_step]`, rolls all candidates
/// out in one batch and keeps the cheapest; stops when no candidate improves the cost.
pub fn solve_gd(
    problem: &Problem<'_>,
    initial: &[Input],
    settings: &GdSettings,
) -> Result<Solution, RacingError> {
    solve_gd_until(problem, initial, settings, None)
}

/// [`solve_gd`] that stops at a wall-clock `deadline` (`None`: exactly [`solve_gd`]): an
/// iteration is only started while [`Deadline::allows_iteration`]; a solve stopped this way
/// returns the cheapest inputs found with [`SolveStatus::Deadline`] (the initial guess, with
/// its gradient evaluated, when no iteration fitted).
pub fn solve_gd_until(
    problem: &Problem<'_>,
    initial: &[Input],
    settings: &GdSettings,
    deadline: Option<&Deadline>,
) -> Result<Solution, RacingError> {
    if settings.step_sizes == 0
        || !(settings.smallest_step > 0.0 && settings.largest_step >= settings.smallest_step)
    {
        return Err(RacingError::setting(
            "gd.step_sizes",
            format!(
                "{} in [{}, {}]",
                settings.step_sizes, settings.smallest_step, settings.largest_step
            ),
            "need ≥ 1 step size and 0 < smallest_step ≤ largest_step",
        ));
    }
    let mut u = initial.to_vec();
    let (mut cost, mut grad, mut lin) = gradient(problem, &u)?;
    let mut history = vec![cost];
    if !cost.is_finite() {
        return Ok(Solution {
            inputs: u,
            states: lin.states,
            cost,
            status: SolveStatus::ModelFailure,
            iterations: 0,
            history,
            elastic_qps: 0,
        });
    }
    let m = settings.step_sizes;
    let ratio = if m > 1 {
        (settings.smallest_step / settings.largest_step).powf(1.0 / (m - 1) as f64)
    } else {
        1.0
    };
    let alphas: Vec<f64> = (0..m)
        .map(|i| settings.largest_step * ratio.powi(i as i32))
        .collect();
    let mut status = SolveStatus::MaxIterations;
    let mut iterations = 0;
    for _ in 0..settings.iterations {
        let started = std::time::Instant::now();
        if deadline.is_some_and(|d| !d.allows_iteration()) {
            status = SolveStatus::Deadline;
            break;
        }
        iterations += 1;
        let cands: Vec<Vec<Input>> = alphas
            .iter()
            .map(|a| {
                u.iter()
                    .zip(&grad)
                    .map(|(x, g)| [x[0] - a * g[0], x[1] - a * g[1]])
                    .collect()
            })
            .collect();
        let costs = candidate_costs(problem, &cands)?;
        let mut best = (cost, usize::MAX);
        for (i, &v) in costs.iter().enumerate() {
            if v < best.0 {
                best = (v, i);
            }
        }
        if best.1 == usize::MAX || cost - best.0 <= settings.tolerance * (1.0 + cost.abs()) {
            if best.1 != usize::MAX {
                u = cands[best.1].clone();
                let (c, _, l) = gradient(problem, &u)?;
                (cost, lin) = (c, l);
                history.push(cost);
            }
            status = SolveStatus::Solved;
            break;
        }
        u = cands[best.1].clone();
        (cost, grad, lin) = gradient(problem, &u)?;
        history.push(cost);
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
        elastic_qps: 0,
    })
}
