//! Evaluation of a model on a data set: one-step and k-step open-loop errors per state dimension
//! (RMSE and MAE, angles wrapped), the training-loss metric at k steps, and for the car the
//! trajectory validation error TVE (Kohler et al. eq. 10) over segments.

use std::ops::Range;

use dynlab_dynamics::conventions::{l_rel, tve, wrap_angle};
use dynlab_dynamics::data::{StateTrajectory, Window, WindowBatch, gather, windows};
use dynlab_dynamics::ode::OdeStatus;
use serde::{Deserialize, Serialize};

use crate::train::{Loss, segment, segment_origins};
use crate::{Dataset, LearnError, Model, World};

/// Errors of one state dimension.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DimError {
    /// State name.
    pub name: String,
    /// Root mean square error.
    pub rmse: f64,
    /// Mean absolute error.
    pub mae: f64,
}

/// Trajectory validation error over segments.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TveReport {
    /// Mean L1 norm of the final pose error `(x, y, ψ)` \[m, m, rad summed\].
    pub tve: f64,
    /// Segments rolled out.
    pub segments: usize,
    /// Segment length \[s\].
    pub segment_s: f64,
}

/// What [`evaluate`] measures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// World.
    pub world: World,
    /// Model kind.
    pub kind: String,
    /// k of the k-step errors.
    pub steps: usize,
    /// Windows evaluated.
    pub windows: usize,
    /// One-step errors per state dimension.
    pub one_step: Vec<DimError>,
    /// Errors after k open-loop steps per state dimension.
    pub k_step: Vec<DimError>,
    /// The world's default training loss over k steps (pushing: Tu & Lin's discounted weighted
    /// pose MSE; car: discounted `L_rel`), mean over windows.
    pub loss: f64,
    /// TVE (car only).
    pub tve: Option<TveReport>,
    /// Model steps whose solver did not succeed.
    pub failed_rollouts: usize,
}

impl Loss {
    /// One rollout step's loss term: `pred` and `target` are full states, `err` their difference
    /// (angles wrapped), `learned` the dimensions the loss covers.
    pub fn step_term(
        &self,
        pred: &[f64],
        target: &[f64],
        err: &[f64],
        learned: Range<usize>,
    ) -> f64 {
        match self {
            Loss::PoseMse { weights } => weights
                .iter()
                .enumerate()
                .map(|(q, w)| w * err[learned.start + q] * err[learned.start + q])
                .sum::<f64>(),
            Loss::LRel { norm, eps } => {
                l_rel(&pred[learned.clone()], &target[learned], *eps, *norm)
            }
        }
    }
}

/// Per-dimension RMSE and mean absolute error from the sums of squared (`sq`) and absolute (`abs`)
/// errors over `n` samples.
pub fn dim_errors(world: World, sq: &[f64], abs: &[f64], n: usize) -> Vec<DimError> {
    world
        .state_names()
        .iter()
        .enumerate()
        .map(|(d, name)| DimError {
            name: name.to_string(),
            rmse: (sq[d] / n.max(1) as f64).sqrt(),
            mae: abs[d] / n.max(1) as f64,
        })
        .collect()
}

/// The initial effect states of windows (`ws.len() × dim_extra`, row-major), each rebuilt from
/// the commands of its trajectory before its start ([`Model::extra_states_along`]). Empty for
/// a model without effect states.
pub fn window_extra_states(model: &Model, trajs: &[StateTrajectory], ws: &[Window]) -> Vec<f64> {
    let ne = model.dim_extra();
    if ne == 0 {
        return Vec::new();
    }
    let mut last = std::collections::BTreeMap::<usize, usize>::new();
    for w in ws {
        let e = last.entry(w.trajectory).or_insert(0);
        *e = (*e).max(w.start);
    }
    let along: std::collections::BTreeMap<usize, Vec<f64>> = last
        .into_iter()
        .map(|(ti, a)| {
            let t = &trajs[ti];
            (ti, model.extra_states_along(&t.u[..(a + 1) * t.dim_u]))
        })
        .collect();
    ws.iter()
        .flat_map(|w| along[&w.trajectory][w.start * ne..(w.start + 1) * ne].to_vec())
        .collect()
}

/// Rolls every window open loop from its measured first state, the effect states rebuilt from
/// the commands before it ([`window_extra_states`]): the gathered batch (with the targets) and
/// the predictions (`k × n × dim_s`, step-major), with the worst solver status.
pub fn rollout_windows(
    model: &Model,
    trajs: &[StateTrajectory],
    ws: &[Window],
    k: usize,
) -> Result<(WindowBatch, Vec<f64>, OdeStatus), LearnError> {
    let b = gather(trajs, ws, k);
    let e0 = window_extra_states(model, trajs, ws);
    let mut out = vec![0.0; k * b.n * model.dim_s()];
    let status = model.rollout_with_extra(&b.s0, &e0, &b.u, &mut out, None)?;
    Ok((b, out, status))
}

/// The segments of [`segment`]`(trajs, seg_len)`, each with its initial effect states rebuilt
/// from the commands of its trajectory before it (empty without effect states).
pub fn segments_with_extra(
    model: &Model,
    trajs: &[StateTrajectory],
    seg_len: usize,
) -> Vec<(StateTrajectory, Vec<f64>)> {
    let ne = model.dim_extra();
    let along: Vec<Vec<f64>> = if ne == 0 {
        vec![Vec::new(); trajs.len()]
    } else {
        trajs
            .iter()
            .map(|t| model.extra_states_along(&t.u))
            .collect()
    };
    segment(trajs, seg_len)
        .into_iter()
        .zip(segment_origins(trajs, seg_len))
        .map(|(sg, (ti, a, _))| (sg, along[ti][a * ne..(a + 1) * ne].to_vec()))
        .collect()
}

/// Evaluates `model` on every k-step window of `data` (and, for the car, TVE over segments of
/// `segment_s` seconds).
pub fn evaluate(
    model: &Model,
    data: &Dataset,
    k: usize,
    segment_s: f64,
) -> Result<EvalReport, LearnError> {
    let world = model.world();
    if data.world != world {
        return Err(LearnError::WorldMismatch {
            what: "the data".into(),
            found: data.world.name().into(),
            expected: world.name().into(),
            hint: "evaluate on a bag of the robot the model was trained for".into(),
        });
    }
    if k == 0 {
        return Err(LearnError::setting("steps", 0, "evaluate at least 1 step"));
    }
    let ds = world.state_dim();
    let all: Vec<Window> = windows(&data.lengths(), k)?;
    let loss = Loss::default_for(world);
    let mut sq1 = vec![0.0; ds];
    let mut ab1 = vec![0.0; ds];
    let mut sqk = vec![0.0; ds];
    let mut abk = vec![0.0; ds];
    let mut total_loss = 0.0;
    let mut failed = 0;
    let lr = world.learned_dims();
    for ws in all.chunks(2048) {
        let (b, out, status) = rollout_windows(model, &data.trajectories, ws, k)?;
        let n = b.n;
        if status != OdeStatus::Success {
            failed += 1;
        }
        for i in 0..n {
            let mut g = 1.0;
            for j in 0..k {
                let p = &out[(j * n + i) * ds..(j * n + i + 1) * ds];
                let t = &b.target[(j * n + i) * ds..(j * n + i + 1) * ds];
                let e: Vec<f64> = (0..ds)
                    .map(|d| {
                        let x = p[d] - t[d];
                        if d == world.angle_dim() {
                            wrap_angle(x)
                        } else {
                            x
                        }
                    })
                    .collect();
                if j == 0 {
                    for d in 0..ds {
                        sq1[d] += e[d] * e[d];
                        ab1[d] += e[d].abs();
                    }
                }
                if j + 1 == k {
                    for d in 0..ds {
                        sqk[d] += e[d] * e[d];
                        abk[d] += e[d].abs();
                    }
                }
                total_loss += g * loss.step_term(p, t, &e, lr.clone());
                g *= 0.9;
            }
        }
    }
    let n = all.len();
    let tve_report = if world == World::Car {
        let seg_len = (segment_s / data.pose_dt_s).round().max(1.0) as usize + 1;
        let segs = segments_with_extra(model, &data.trajectories, seg_len);
        let mut finals = Vec::new();
        for (sgm, e0) in segs.iter().filter(|(s, _)| s.len() == seg_len) {
            let steps = sgm.len() - 1;
            let mut out = vec![0.0; steps * ds];
            model.rollout_with_extra(
                &sgm.s[..ds],
                e0,
                &sgm.u[..steps * sgm.dim_u],
                &mut out,
                None,
            )?;
            let p = &out[(steps - 1) * ds..steps * ds];
            let m = &sgm.s[steps * ds..(steps + 1) * ds];
            finals.push(([p[0], p[1], p[2]], [m[0], m[1], m[2]]));
        }
        Some(TveReport {
            tve: tve(&finals),
            segments: finals.len(),
            segment_s,
        })
    } else {
        None
    };
    Ok(EvalReport {
        world,
        kind: model.kind().name().to_string(),
        steps: k,
        windows: n,
        one_step: dim_errors(world, &sq1, &ab1, n),
        k_step: dim_errors(world, &sqk, &abk, n),
        loss: total_loss / n.max(1) as f64,
        tve: tve_report,
        failed_rollouts: failed,
    })
}

impl EvalReport {
    /// The report as a text table.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{} model, {} world, {} windows of {} steps\n",
            self.kind, self.world, self.windows, self.steps
        );
        s += &format!(
            "{:<8} {:>12} {:>12} {:>12} {:>12}\n",
            "state",
            "RMSE 1-step",
            "MAE 1-step",
            format!("RMSE {}-step", self.steps),
            format!("MAE {}-step", self.steps)
        );
        for (a, b) in self.one_step.iter().zip(&self.k_step) {
            s += &format!(
                "{:<8} {:>12.4e} {:>12.4e} {:>12.4e} {:>12.4e}\n",
                a.name, a.rmse, a.mae, b.rmse, b.mae
            );
        }
        s += &format!("loss ({} steps, γ = 0.9): {:.4e}\n", self.steps, self.loss);
        if let Some(t) = &self.tve {
            s += &format!(
                "TVE over {} segments of {:.1} s: {:.4}\n",
                t.segments, t.segment_s, t.tve
            );
        }
        if self.failed_rollouts > 0 {
            s += &format!(
                "warning: {} rollout batches had a solver failure\n",
                self.failed_rollouts
            );
        }
        s
    }
}
