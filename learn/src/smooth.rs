//! Car states estimated with a physics model: at every sample, the model's motion from a
//! state a little before it, fitted to the poses around it (a local shooting fit), gives the
//! pose and the body velocities there. Where a Savitzky–Golay fit bends a fast yaw response
//! into a polynomial, the model follows the commands. Each fit also takes a constant
//! acceleration of each velocity, so that what the model misses over the fit's span (an
//! effect it lacks) is taken there rather than by the state.

use dynlab_dynamics::data::StateTrajectory;
use dynlab_dynamics::ode::Solver;
use dynlab_dynamics::physics::PhysicsModel;
use dynlab_nn::parallel::in_blocks;

use crate::fit::solve;

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
