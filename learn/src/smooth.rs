//! Car states estimated with a physics model: at every sample, the model's motion from a
//! state a little before it, fitted to the poses around it (a local shooting fit), gives the
//! pose and the body velocities there. Where a Savitzky–Golay fit bends a fast yaw response
//! into a polynomial, the model follows the commands. Each fit also takes a constant
//! acceleration of each velocity, so that what the model misses over the fit's span (an
//! effect it lacks) is taken there rather than by the state.
//!
//! Windows' start states fitted by each model ([`StartFits`]): the state at a window's start
//! from the model's own motion fitted to the poses before it, so that models compared are each
//! started from their own estimate.

use dynlab_dynamics::data::StateTrajectory;
use dynlab_dynamics::ode::Solver;
use dynlab_dynamics::physics::PhysicsModel;
use dynlab_nn::parallel::in_blocks;

use std::collections::HashMap;

use dynlab_dynamics::conventions::wrap_angle;

use crate::fit::{initial_states_after, solve};

/// Gauss–Newton iterations of each local fit.
const ITERATIONS: usize = 4;

/// The car states of `trajs` (`[x, y, ψ, vx, vy, ω]`, as estimated) re-estimated with `p`:
/// for sample `i`, the state at `a = i − half` (clamped into the trajectory) and a constant
/// acceleration of `vx`, `vy` and `ω` are fitted (Gauss–Newton) so that the model's rollout
/// from it under the recorded commands matches the poses at `a … a + 2·half` (weighted by
/// `pose_std`); the rollout's state at `i` replaces sample `i`. The poses fitted are those of
/// the states as given. Effect states (`motor_lag`, `steering_lag`) are rebuilt from the
/// trajectory's commands. A trajectory shorter than `2·half + 1` samples is returned as it is.
pub fn model_states(
    p: &PhysicsModel,
    solver: &Solver,
    trajs: &[StateTrajectory],
    pose_std: [f64; 3],
    half: usize,
) -> Vec<StateTrajectory> {
    trajs
        .iter()
        .map(|t| {
            let n = t.len();
            let span = 2 * half + 1;
            if t.dim_s != 6 || n < span || half == 0 {
                return t.clone();
            }
            let centres: Vec<usize> = (0..n).collect();
            let fitted = in_blocks(&centres, |block| {
                fit_block(p, solver, t, block, pose_std, half)
            });
            let mut out = t.clone();
            out.s = fitted.concat();
            out
        })
        .collect()
}

/// The re-estimated states (`len × 6`, flat) of the samples `centres` of `t`.
fn fit_block(
    p: &PhysicsModel,
    solver: &Solver,
    t: &StateTrajectory,
    centres: &[usize],
    pose_std: [f64; 3],
    half: usize,
) -> Vec<f64> {
    const DS: usize = 6;
    // the unknowns: the state at the fit's first sample and a constant acceleration of each
    // velocity over the fit (what the model misses there, so that the state does not take it)
    const NZ: usize = DS + 3;
    let n = t.len();
    let span = 2 * half + 1;
    let du = t.dim_u;
    let ne = p.dim_effect_states();
    let dw = DS + ne;
    let effect = if ne > 0 {
        p.effect_states_along(&t.u, t.dt)
    } else {
        Vec::new()
    };
    let m = centres.len();
    let start: Vec<usize> = centres
        .iter()
        .map(|&i| i.saturating_sub(half).min(n - span))
        .collect();
    let mut z: Vec<[f64; NZ]> = start
        .iter()
        .map(|&a| {
            let mut s = [0.0; NZ];
            s[..DS].copy_from_slice(&t.s[a * DS..(a + 1) * DS]);
            s
        })
        .collect();
    let eps = [1e-6, 1e-6, 1e-7, 1e-6, 1e-6, 1e-6, 1e-5, 1e-5, 1e-5];
    let w = [1.0 / pose_std[0], 1.0 / pose_std[1], 1.0 / pose_std[2]];
    // rolls out `copies` perturbations of every fit (copy 0: none; copy c: dimension c − 1)
    // and returns the weighted pose residuals (`copies × m × span × 3`) and, for copy 0, every
    // state along (`m × span × 6`)
    let rollout = |z: &[[f64; NZ]], copies: usize| -> (Vec<f64>, Vec<f64>) {
        let rows = copies * m;
        let mut s = vec![0.0; rows * dw];
        let mut u = vec![0.0; rows * du];
        for c in 0..copies {
            for (k, &a) in start.iter().enumerate() {
                let r = c * m + k;
                s[r * dw..r * dw + DS].copy_from_slice(&z[k][..DS]);
                if c > 0 && c <= DS {
                    s[r * dw + c - 1] += eps[c - 1];
                }
                s[r * dw + DS..(r + 1) * dw].copy_from_slice(&effect[a * ne..(a + 1) * ne]);
            }
        }
        let mut res = vec![0.0; rows * span * 3];
        let mut along = vec![0.0; m * span * DS];
        let mut next = vec![0.0; rows * dw];
        let mut bias = vec![0.0; rows * 3];
        for c in 0..copies {
            for k in 0..m {
                let r = c * m + k;
                bias[r * 3..(r + 1) * 3].copy_from_slice(&z[k][DS..]);
                if c > DS {
                    bias[r * 3 + c - 1 - DS] += eps[c - 1];
                }
            }
        }
        for j in 0..span {
            for r in 0..rows {
                let a = start[r % m] + j;
                for c in 0..3 {
                    res[(r * span + j) * 3 + c] = (s[r * dw + c] - t.s[a * DS + c]) * w[c];
                }
                if r < m {
                    along[(r * span + j) * DS..(r * span + j + 1) * DS]
                        .copy_from_slice(&s[r * dw..r * dw + DS]);
                }
            }
            if j + 1 == span {
                break;
            }
            for r in 0..rows {
                let a = start[r % m] + j;
                u[r * du..(r + 1) * du].copy_from_slice(&t.u[a * du..(a + 1) * du]);
            }
            p.integrate_step(solver, rows, &s, &u, t.dt, &mut next);
            for r in 0..rows {
                for c in 0..3 {
                    next[r * dw + 3 + c] += bias[r * 3 + c] * t.dt;
                }
            }
            std::mem::swap(&mut s, &mut next);
        }
        (res, along)
    };
    let cost = |res: &[f64], k: usize| -> f64 {
        res[k * span * 3..(k + 1) * span * 3]
            .iter()
            .map(|r| if r.is_finite() { r * r } else { 1e30 })
            .sum()
    };
    let nr = span * 3;
    for _ in 0..ITERATIONS {
        let (res, _) = rollout(&z, NZ + 1);
        let mut trial = z.clone();
        for k in 0..m {
            let r0 = &res[k * nr..(k + 1) * nr];
            let mut jtj = [0.0; NZ * NZ];
            let mut jtr = [0.0; NZ];
            for a in 0..NZ {
                let ra = &res[((a + 1) * m + k) * nr..((a + 1) * m + k + 1) * nr];
                for q in 0..nr {
                    let ja = (ra[q] - r0[q]) / eps[a];
                    jtr[a] -= ja * r0[q];
                    for b in 0..=a {
                        let rb = &res[((b + 1) * m + k) * nr..((b + 1) * m + k + 1) * nr];
                        jtj[a * NZ + b] += ja * (rb[q] - r0[q]) / eps[b];
                    }
                }
            }
            for a in 0..NZ {
                for b in 0..a {
                    jtj[b * NZ + a] = jtj[a * NZ + b];
                }
                jtj[a * NZ + a] *= 1.0 + 1e-6;
                jtj[a * NZ + a] += 1e-12;
            }
            if let Some(d) = solve(&jtj, &jtr, NZ) {
                for a in 0..NZ {
                    trial[k][a] += d[a];
                }
            }
        }
        // keep a step only where it lowers the fit's cost
        let (after, _) = rollout(&trial, 1);
        for k in 0..m {
            if cost(&after, k) < cost(&res, k) {
                z[k] = trial[k];
            }
        }
    }
    let (_, along) = rollout(&z, 1);
    centres
        .iter()
        .zip(&start)
        .enumerate()
        .flat_map(|(k, (&i, &a))| {
            let j = i - a;
            along[(k * span + j) * DS..(k * span + j + 1) * DS].to_vec()
        })
        .collect()
}

/// Windows' start states fitted by the model that rolls them out: for a window starting at
/// sample `s`, the car state at `a = s − half` (clamped into the trajectory) is fitted to the
/// poses at `a … a + half` (weighted by the pose noise) and the model's rollout from it gives
/// the state at `s`, effect states included. Every model is started from its own fit to the
/// same poses, so none is scored from states that another model estimated (a Savitzky–Golay
/// fit, or the model diagnosed). The fit is Gauss–Newton with the gain of the model the fits
/// were built with, which moves little between the candidates: a model's fits cost three
/// rollouts of `half` steps (from the states as estimated, then after each of two steps).
#[derive(Clone, Debug)]
pub struct StartFits {
    half: usize,
    weight: [f64; 3],
    /// Per window `(trajectory, start)`: its `(JᵀJ)⁻¹Jᵀ` of the weighted pose residuals
    /// (`6 × 3·(half + 1)`, row-major).
    gain: HashMap<(usize, usize), Vec<f64>>,
}

/// State dimensions of the car that the start fits estimate.
const CAR_DS: usize = 6;

/// Finite-difference steps of the car state's dimensions.
const CAR_EPS: [f64; CAR_DS] = [1e-6, 1e-6, 1e-7, 1e-6, 1e-6, 1e-6];

/// Gauss–Newton iterations of each start fit.
const START_ITERATIONS: usize = 2;

impl StartFits {
    /// The gains of the windows `at` (`(trajectory, start)`), linearised with `p` at the
    /// trajectories' states; `history[i]` holds the recording's commands before trajectory
    /// `i`. `half` samples of poses before each start (at least 1) are fitted, weighted by
    /// `pose_std` (`x`, `y`, heading); `dt` is the model's step.
    pub fn new(
        p: &PhysicsModel,
        solver: &Solver,
        data: (&[StateTrajectory], &[Vec<f64>]),
        at: impl IntoIterator<Item = (usize, usize)>,
        half: usize,
        pose_std: [f64; 3],
        dt: f64,
    ) -> Self {
        let (trajs, history) = data;
        let half = half.max(1);
        let weight = pose_std.map(|s| 1.0 / s.max(1e-12));
        let mut fits = Self {
            half,
            weight,
            gain: HashMap::new(),
        };
        let mut keys: Vec<(usize, usize)> = at.into_iter().collect();
        keys.sort_unstable();
        keys.dedup();
        keys.retain(|&(ti, _)| trajs[ti].dim_s == CAR_DS && trajs[ti].len() > half);
        if keys.is_empty() {
            return fits;
        }
        let m = keys.len();
        let origins: Vec<(usize, usize)> = keys.iter().map(|&w| fits.origin(trajs, w)).collect();
        let s0 = initial_states_after(p, history, trajs, origins.iter().copied());
        let dw = p.dim_state();
        // copy 0 as estimated, copy c + 1 with dimension c moved
        let mut s = Vec::with_capacity((CAR_DS + 1) * m * dw);
        let mut rows = Vec::with_capacity((CAR_DS + 1) * m);
        for c in 0..=CAR_DS {
            for (r, &o) in origins.iter().enumerate() {
                let mut x = s0[r * dw..(r + 1) * dw].to_vec();
                if c > 0 {
                    x[c - 1] += CAR_EPS[c - 1];
                }
                s.extend_from_slice(&x);
                rows.push((o, 0));
            }
        }
        let (res, _) = fits.roll(p, solver, trajs, &rows, s, dt);
        let nr = 3 * (half + 1);
        for (r, key) in keys.iter().enumerate() {
            let r0 = &res[r * nr..(r + 1) * nr];
            let jac: Vec<Vec<f64>> = (0..CAR_DS)
                .map(|c| {
                    let rc = &res[((c + 1) * m + r) * nr..((c + 1) * m + r + 1) * nr];
                    (0..nr).map(|q| (rc[q] - r0[q]) / CAR_EPS[c]).collect()
                })
                .collect();
            let mut jtj = [0.0; CAR_DS * CAR_DS];
            for a in 0..CAR_DS {
                for b in 0..CAR_DS {
                    jtj[a * CAR_DS + b] = (0..nr).map(|q| jac[a][q] * jac[b][q]).sum();
                }
                jtj[a * CAR_DS + a] *= 1.0 + 1e-9;
                jtj[a * CAR_DS + a] += 1e-12;
            }
            // (JᵀJ)⁻¹Jᵀ, column by column of Jᵀ
            let mut g = vec![0.0; CAR_DS * nr];
            let mut ok = true;
            for q in 0..nr {
                let col: Vec<f64> = (0..CAR_DS).map(|a| jac[a][q]).collect();
                match solve(&jtj, &col, CAR_DS) {
                    Some(x) if x.iter().all(|v| v.is_finite()) => {
                        for a in 0..CAR_DS {
                            g[a * nr + q] = x[a];
                        }
                    }
                    _ => ok = false,
                }
            }
            if ok {
                fits.gain.insert(*key, g);
            }
        }
        fits
    }

    /// The fitted start states of `p` (`dim_state` each, effect states included) at the
    /// windows `at`; a window without a gain starts from its state as estimated.
    pub fn states(
        &self,
        p: &PhysicsModel,
        solver: &Solver,
        data: (&[StateTrajectory], &[Vec<f64>]),
        at: impl IntoIterator<Item = (usize, usize)>,
        dt: f64,
    ) -> Vec<f64> {
        let (trajs, history) = data;
        let at: Vec<(usize, usize)> = at.into_iter().collect();
        let rows: Vec<((usize, usize), usize)> = at
            .iter()
            .map(|&w| match self.gain.contains_key(&w) {
                true => {
                    let o = self.origin(trajs, w);
                    (o, w.1 - o.1)
                }
                false => (w, 0),
            })
            .collect();
        let mut s = initial_states_after(p, history, trajs, rows.iter().map(|r| r.0));
        let dw = p.dim_state();
        let nr = 3 * (self.half + 1);
        let cost = |res: &[f64], r: usize| -> f64 {
            res[r * nr..(r + 1) * nr]
                .iter()
                .map(|v| if v.is_finite() { v * v } else { f64::INFINITY })
                .sum()
        };
        let (mut res, mut out) = self.roll(p, solver, trajs, &rows, s.clone(), dt);
        for _ in 0..START_ITERATIONS {
            let mut trial = s.clone();
            for (r, w) in at.iter().enumerate() {
                let Some(g) = self.gain.get(w) else {
                    continue;
                };
                let rr = &res[r * nr..(r + 1) * nr];
                if !rr.iter().all(|v| v.is_finite()) {
                    continue;
                }
                for a in 0..CAR_DS {
                    let d: f64 = (0..nr).map(|q| g[a * nr + q] * rr[q]).sum();
                    trial[r * dw + a] -= d;
                }
            }
            let (res_t, out_t) = self.roll(p, solver, trajs, &rows, trial.clone(), dt);
            // a step is kept only where it lowers the fit's cost
            for r in 0..at.len() {
                if cost(&res_t, r) < cost(&res, r) {
                    s[r * dw..(r + 1) * dw].copy_from_slice(&trial[r * dw..(r + 1) * dw]);
                    res[r * nr..(r + 1) * nr].copy_from_slice(&res_t[r * nr..(r + 1) * nr]);
                    out[r * dw..(r + 1) * dw].copy_from_slice(&out_t[r * dw..(r + 1) * dw]);
                }
            }
        }
        out
    }

    /// Where the fit of the window `(trajectory, start)` starts.
    fn origin(&self, trajs: &[StateTrajectory], (ti, start): (usize, usize)) -> (usize, usize) {
        let last = trajs[ti].len() - 1;
        (ti, start.saturating_sub(self.half).min(last - self.half))
    }

    /// Rolls out `p` from the states `s` (`rows.len() × dim_state`) of `rows` (`((trajectory,
    /// origin), out)`) over `half` steps of their commands: the weighted pose residuals
    /// (`rows × (half + 1) × 3`) and each row's state at its step `out`.
    fn roll(
        &self,
        p: &PhysicsModel,
        solver: &Solver,
        trajs: &[StateTrajectory],
        rows: &[((usize, usize), usize)],
        mut s: Vec<f64>,
        dt: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let n = rows.len();
        let dw = p.dim_state();
        let du = trajs.first().map_or(0, |t| t.dim_u);
        let span = self.half + 1;
        let mut res = vec![0.0; n * span * 3];
        let mut out = vec![0.0; n * dw];
        let mut u = vec![0.0; n * du];
        let mut next = vec![0.0; n * dw];
        for j in 0..span {
            for (r, &((ti, a), o)) in rows.iter().enumerate() {
                let t = &trajs[ti];
                // (a window without a fit, started at its own sample, may end its unused
                // rollout past the trajectory)
                let i = (a + j).min(t.len() - 1);
                let meas = &t.s[i * t.dim_s..];
                for c in 0..3 {
                    let mut e = s[r * dw + c] - meas[c];
                    if c == 2 {
                        e = wrap_angle(e);
                    }
                    res[(r * span + j) * 3 + c] = e * self.weight[c];
                }
                if j == o {
                    out[r * dw..(r + 1) * dw].copy_from_slice(&s[r * dw..(r + 1) * dw]);
                }
            }
            if j + 1 == span {
                break;
            }
            for (r, &((ti, a), _)) in rows.iter().enumerate() {
                let t = &trajs[ti];
                let i = (a + j).min(t.len() - 1);
                u[r * du..(r + 1) * du].copy_from_slice(&t.u[i * du..(i + 1) * du]);
            }
            p.integrate_step(solver, n, &s, &u, dt, &mut next);
            std::mem::swap(&mut s, &mut next);
        }
        (res, out)
    }
}
