//! A model held against measurements: where it fails, and against what.
//!
//! [`compare`] rolls a [`Model`] open loop over every k-step window of a [`TimedDataset`] (bags
//! loaded with their stamps) and measures, per state dimension:
//!
//! - one-step and k-step errors (RMSE, MAE; angles wrapped), the training loss and, for the car,
//!   the trajectory validation error TVE, as an [`EvalReport`] with the numbers
//!   `dynlab eval-model` prints (the same windows, learn's segmenting and `conventions::tve`),
//!   computed from one threaded pass over the windows that also feeds everything below;
//! - the k-step error over time, per trajectory, against bag time;
//! - the k-step error binned against the quantities that cause it (car: speed, yaw rate,
//!   sideslip, steering, throttle, x, y; pushing: x, y, push location, angle and length), with
//!   counts per bin;
//! - a map of the k-step position error over the floor or table;
//! - the one-step residual's autocorrelation and its cross-correlation with every input at lags
//!   `−L…L`, with the 95 % band ±1.96/√N; an input peak at a positive lag (the input leads the
//!   residual) outside the band is flagged as an unmodelled delay or lag, in seconds;
//! - the worst segments: the top windows by k-step error (not overlapping), with their bag
//!   stamps.
//!
//! [`compare_with_baseline`] does the same for two models and adds the error change. The result
//! is a serde [`CompareReport`] (the schema of `report.json`, documented field by field);
//! [`html::report`] turns it into the HTML page and [`CompareReport::summary`] into the terminal
//! summary.

#![allow(clippy::needless_range_loop)] // index loops over state dimensions read as the math

pub mod html;
pub mod online;
pub mod stats;

use dynlab_learn::dynamics::conventions::{tve, wrap_angle};
use dynlab_learn::dynamics::data::windows;
use dynlab_learn::dynamics::ode::OdeStatus;
use dynlab_learn::eval::{DimError, EvalReport, TveReport};
use dynlab_learn::train::Loss;
use dynlab_learn::{LearnError, Model, TimedDataset, World};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use stats::{bin_of, cross_correlation, robust_edges};

/// The `schema` value of `report.json` written by this version.
pub const SCHEMA: &str = "dynlab.compare/1";

/// Errors of a comparison. Each names the problem and what to do.
#[derive(Debug, Error)]
pub enum CompareError {
    /// From the model or the data (world mismatch, too little data, NaN, …).
    #[error(transparent)]
    Learn(#[from] LearnError),
    /// A setting out of range.
    #[error("invalid setting {name} = {value}: {hint}")]
    Setting {
        /// Setting name.
        name: &'static str,
        /// Given value.
        value: String,
        /// What is allowed.
        hint: &'static str,
    },
    /// Writing the report.
    #[error(transparent)]
    Report(#[from] crate::report::ReportError),
}

/// Settings of [`compare`]. Every field has a documented default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CompareConfig {
    /// Open-loop steps of the k-step errors (default 5).
    pub steps: usize,
    /// Car: TVE segment length \[s\] (default 3, as Kohler et al.).
    pub segment_s: f64,
    /// Bins per quantity for the binned errors (default 10).
    pub bins: usize,
    /// Cells per side of the position map (default 12).
    pub grid: usize,
    /// Largest lag of the correlations, in steps (default 20).
    pub max_lag: usize,
    /// Worst segments listed (default 10).
    pub worst: usize,
    /// Most points per trajectory in the error-over-time series (blocks of windows are reduced
    /// to their RMS; default 400).
    pub series_points: usize,
    /// Windows per batched rollout (default 2048, as `evaluate`; with an adaptive solver the
    /// step size is shared by a batch, so keep it for numbers identical to `eval-model`).
    pub batch: usize,
    /// Threads for the rollouts (default 2). Every window's numbers are independent of it.
    pub threads: usize,
}

impl Default for CompareConfig {
    fn default() -> Self {
        Self {
            steps: 5,
            segment_s: 3.0,
            bins: 10,
            grid: 12,
            max_lag: 20,
            worst: 10,
            series_points: 400,
            batch: 2048,
            threads: 2,
        }
    }
}

impl CompareConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), CompareError> {
        let bad = |name, value: usize, hint| {
            Err(CompareError::Setting {
                name,
                value: value.to_string(),
                hint,
            })
        };
        if self.steps == 0 {
            return bad("steps", 0, "compare at least 1 step");
        }
        if self.bins == 0 {
            return bad("bins", 0, "use at least 1 bin");
        }
        if self.grid == 0 {
            return bad("grid", 0, "use at least 1 cell per side");
        }
        if self.series_points == 0 {
            return bad("series_points", 0, "keep at least 1 point per trajectory");
        }
        if self.batch == 0 {
            return bad("batch", 0, "use batches of at least 1 window");
        }
        if !(self.segment_s > 0.0 && self.segment_s.is_finite()) {
            return Err(CompareError::Setting {
                name: "segment_s",
                value: self.segment_s.to_string(),
                hint: "a positive number of seconds",
            });
        }
        Ok(())
    }
}

/// Where the data came from and what the pipeline did to it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataSummary {
    /// Bag paths.
    pub bags: Vec<String>,
    /// Trajectories (uninterrupted runs).
    pub trajectories: usize,
    /// States over all trajectories.
    pub states: usize,
    /// Model step \[s\] (median pose interval; pushing: time between pushes).
    pub dt_s: f64,
    /// Per bag, what the pipeline did (gaps, resampling, command hold), in sentences.
    pub notes: Vec<Vec<String>>,
    /// Too little excitation (constant commands, a car standing still).
    pub warnings: Vec<String>,
}

/// The k-step error of one trajectory over time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorSeries {
    /// Trajectory index.
    pub trajectory: usize,
    /// Bag index (into `data.bags`).
    pub bag: usize,
    /// Seconds from the bag's first pose of each point (window start; the start of a block
    /// when windows were reduced).
    pub t_s: Vec<f64>,
    /// Per state dimension, the k-step error (RMS over the block) at each point.
    pub rmse: Vec<Vec<f64>>,
}

/// The k-step error binned against one quantity.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BinnedError {
    /// Quantity (`speed`, `yaw_rate`, `sideslip`, `steering`, `throttle`, `x`, `y`,
    /// `push_location`, `push_angle`, `push_length`).
    pub quantity: String,
    /// Unit.
    pub unit: String,
    /// Bin edges (`bins + 1`); the end bins also hold values beyond them.
    pub edges: Vec<f64>,
    /// Windows per bin.
    pub counts: Vec<usize>,
    /// Per state dimension, the k-step RMSE in each bin (0 for an empty bin).
    pub rmse: Vec<Vec<f64>>,
    /// Windows left out (the quantity undefined there, e.g. sideslip below 0.2 m/s).
    pub excluded: usize,
}

/// The k-step position error over a grid of positions (of the window start).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PositionMap {
    /// Cell edges along x \[m\].
    pub x_edges: Vec<f64>,
    /// Cell edges along y \[m\].
    pub y_edges: Vec<f64>,
    /// Windows per cell, `[iy][ix]`.
    pub counts: Vec<Vec<usize>>,
    /// RMS of the k-step position error `√(e_x² + e_y²)` per cell \[m\], `[iy][ix]` (0 when
    /// empty).
    pub rmse: Vec<Vec<f64>>,
}

/// Correlation of the one-step residual of one dimension with itself or an input, at lags.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LagCorrelation {
    /// State dimension of the residual.
    pub state: String,
    /// The other sequence: the same residual (`autocorrelation`) or an input name.
    pub with: String,
    /// Correlation at each lag of `CorrelationReport::lags` (positive lag: the input leads).
    pub r: Vec<f64>,
    /// Lag (steps) of the largest |r| (excluding lag 0 for the autocorrelation).
    pub peak_lag: i64,
    /// r at that lag.
    pub peak_r: f64,
    /// Fraction of lags ≠ 0 outside the 95 % band.
    pub outside_band: f64,
}

/// Residual whiteness and residual–input cross-correlation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CorrelationReport {
    /// Lags in steps, `−max_lag…=max_lag`.
    pub lags: Vec<i64>,
    /// Step length \[s\] (to read lags as times).
    pub dt_s: f64,
    /// Samples `N` pooled over trajectories.
    pub n: usize,
    /// The 95 % band for white noise, ±1.96/√N.
    pub band: f64,
    /// Autocorrelation of each dimension's residual.
    pub autocorrelation: Vec<LagCorrelation>,
    /// Cross-correlation of each dimension's residual with each input.
    pub cross: Vec<LagCorrelation>,
    /// Flagged lagged input peaks: "unmodelled delay or lag".
    pub findings: Vec<LagFinding>,
}

/// A residual–input peak at a positive lag (the input leads) that stands out: larger than twice
/// the band widened for autocorrelation (Bartlett's formula, `b = 1.96·√(Σ_l ρ_e(l)·ρ_u(l) / N)`
/// over the lags computed, never narrower than ±1.96/√N) and larger than the lag-0 value by
/// `2b` — smooth inputs and coloured residuals otherwise cross the white-noise band by chance.
/// Car only: a push is an event held over many pose steps, so a lagged push correlation is the
/// push's own time course, not a delay (its correlations are still reported).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LagFinding {
    /// State dimension.
    pub state: String,
    /// Input.
    pub input: String,
    /// Lag \[steps\].
    pub lag_steps: i64,
    /// Lag \[s\].
    pub lag_s: f64,
    /// Correlation at the peak.
    pub r: f64,
    /// The sentence for people.
    pub message: String,
}

/// One of the worst k-step windows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// Rank (1 = worst).
    pub rank: usize,
    /// Bag index (into `data.bags`).
    pub bag: usize,
    /// Trajectory index.
    pub trajectory: usize,
    /// First state index in the trajectory.
    pub start_index: usize,
    /// Stamp of the window's first state \[ns\].
    pub start_ns: i64,
    /// Stamp of its last state \[ns\].
    pub end_ns: i64,
    /// Seconds from the bag's first pose to the start.
    pub start_s: f64,
    /// Seconds from the bag's first pose to the end.
    pub end_s: f64,
    /// The ranking score (windows within 4k steps of a worse one are not listed): mean over
    /// dimensions of (k-step error / that dimension's k-step
    /// RMSE)²; 1 is a typical window.
    pub score: f64,
    /// k-step error per dimension (signed, angles wrapped).
    pub error: Vec<f64>,
}

/// Everything measured for one model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelComparison {
    /// Model label (its path, as given).
    pub label: String,
    /// Errors, loss and TVE, as `dynlab eval-model` reports them.
    pub eval: EvalReport,
    /// Error over time, per trajectory.
    pub over_time: Vec<ErrorSeries>,
    /// Error binned against its causes.
    pub binned: Vec<BinnedError>,
    /// Position error over the floor / table.
    pub position_map: PositionMap,
    /// Residual correlations.
    pub correlation: CorrelationReport,
    /// Worst segments, worst first.
    pub worst: Vec<Segment>,
}

/// The change of one error from baseline to model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorChange {
    /// State dimension (or `TVE`, `loss`).
    pub state: String,
    /// Steps (1 or k; 0 for TVE).
    pub steps: usize,
    /// Metric (`rmse`, `mae`, `tve`, `loss`).
    pub metric: String,
    /// Baseline value.
    pub baseline: f64,
    /// Model value.
    pub model: f64,
    /// `model − baseline`.
    pub change: f64,
    /// `100 · (model − baseline) / baseline` (negative: the model is better); `null` when the
    /// baseline is 0.
    pub change_pct: Option<f64>,
}

/// The whole comparison: the schema of `report.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompareReport {
    /// Always [`SCHEMA`].
    pub schema: String,
    /// World.
    pub world: World,
    /// State names, the order of every per-dimension vector.
    pub states: Vec<String>,
    /// Input names.
    pub inputs: Vec<String>,
    /// Settings used.
    pub config: CompareConfig,
    /// The data.
    pub data: DataSummary,
    /// The model.
    pub model: ModelComparison,
    /// The baseline (`--baseline`), measured the same way.
    pub baseline: Option<ModelComparison>,
    /// Error changes baseline → model, per dimension and k (with a baseline).
    pub change: Vec<ErrorChange>,
}

/// Per-window errors of one model (internal).
struct WindowErrors {
    /// Windows in order (trajectory-major, consecutive starts).
    trajectory: Vec<usize>,
    start: Vec<usize>,
    /// `n × ds` one-step errors and k-step errors.
    e1: Vec<f64>,
    ek: Vec<f64>,
    /// Per window, the discounted k-step training loss.
    loss: Vec<f64>,
    /// Batches whose solver did not succeed.
    failed: usize,
}

/// One batch of windows: errors after the first and the last step, the loss.
fn batch_errors(
    model: &Model,
    data: &TimedDataset,
    ws: &[dynlab_learn::dynamics::data::Window],
    k: usize,
    e1: &mut [f64],
    ek: &mut [f64],
    loss_w: &mut [f64],
) -> Result<bool, LearnError> {
    let world = model.world();
    let ds = world.state_dim();
    let lr = world.learned_dims();
    let loss = Loss::default_for(world);
    // effect states (motor_lag's d_f) rebuilt from the commands before each window
    let (b, out, status) =
        dynlab_learn::eval::rollout_windows(model, &data.data.trajectories, ws, k)?;
    let m = b.n;
    let ok = status == OdeStatus::Success;
    let mut e = vec![0.0; ds];
    for i in 0..m {
        let mut g = 1.0;
        let mut l = 0.0;
        for j in 0..k {
            let p = &out[(j * m + i) * ds..(j * m + i + 1) * ds];
            let t = &b.target[(j * m + i) * ds..(j * m + i + 1) * ds];
            for d in 0..ds {
                let x = p[d] - t[d];
                e[d] = if d == world.angle_dim() {
                    wrap_angle(x)
                } else {
                    x
                };
            }
            if j == 0 {
                e1[i * ds..(i + 1) * ds].copy_from_slice(&e);
            }
            if j + 1 == k {
                ek[i * ds..(i + 1) * ds].copy_from_slice(&e);
            }
            l += g * loss.step_term(p, t, &e, lr.clone());
            g *= 0.9;
        }
        loss_w[i] = l;
    }
    Ok(ok)
}

fn window_errors(
    model: &Model,
    data: &TimedDataset,
    cfg: &CompareConfig,
) -> Result<WindowErrors, CompareError> {
    let ds = model.world().state_dim();
    let k = cfg.steps;
    let all = windows(&data.data.lengths(), k).map_err(LearnError::from)?;
    let n = all.len();
    let mut e1 = vec![0.0; n * ds];
    let mut ek = vec![0.0; n * ds];
    let mut loss = vec![0.0; n];
    let batches: Vec<_> = all
        .chunks(cfg.batch)
        .zip(e1.chunks_mut(cfg.batch * ds))
        .zip(ek.chunks_mut(cfg.batch * ds))
        .zip(loss.chunks_mut(cfg.batch))
        .map(|(((w, a), b), c)| (w, a, b, c))
        .collect();
    // contiguous runs of batches per thread: each window's numbers do not depend on the split
    let threads = cfg.threads.max(1).min(batches.len().max(1));
    let per = batches.len().div_ceil(threads);
    let mut groups: Vec<Vec<_>> = Vec::new();
    let mut it = batches.into_iter();
    loop {
        let g: Vec<_> = it.by_ref().take(per).collect();
        if g.is_empty() {
            break;
        }
        groups.push(g);
    }
    let results: Vec<Result<usize, LearnError>> = std::thread::scope(|sc| {
        let handles: Vec<_> = groups
            .into_iter()
            .map(|g| {
                sc.spawn(move || {
                    let mut failed = 0;
                    for (w, a, b, c) in g {
                        if !batch_errors(model, data, w, k, a, b, c)? {
                            failed += 1;
                        }
                    }
                    Ok(failed)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(LearnError::InvalidSetting {
                        name: "threads",
                        value: "worker".into(),
                        hint:
                            "a rollout worker panicked; rerun with threads = 1 and report the bug"
                                .into(),
                    })
                })
            })
            .collect()
    });
    let mut failed = 0;
    for r in results {
        failed += r?;
    }
    Ok(WindowErrors {
        trajectory: all.iter().map(|w| w.trajectory).collect(),
        start: all.iter().map(|w| w.start).collect(),
        e1,
        ek,
        loss,
        failed,
    })
}

/// The errors, loss and TVE in the form `dynlab_learn::evaluate` reports them, from the
/// per-window pass (no second rollout of the windows); TVE with learn's own segmenting and
/// `conventions::tve`, all segments rolled out in one batch.
fn eval_report(
    model: &Model,
    data: &TimedDataset,
    we: &WindowErrors,
    cfg: &CompareConfig,
) -> Result<EvalReport, CompareError> {
    let world = model.world();
    let ds = world.state_dim();
    let n = we.start.len();
    let dims = |e: &[f64]| -> Vec<DimError> {
        let mut sq = vec![0.0; ds];
        let mut ab = vec![0.0; ds];
        for row in e.chunks_exact(ds) {
            for d in 0..ds {
                sq[d] += row[d] * row[d];
                ab[d] += row[d].abs();
            }
        }
        dynlab_learn::eval::dim_errors(world, &sq, &ab, n)
    };
    let tve_report = if world == World::Car {
        let seg_len = (cfg.segment_s / data.data.pose_dt_s).round().max(1.0) as usize + 1;
        let (segs, e0): (Vec<_>, Vec<_>) =
            dynlab_learn::eval::segments_with_extra(model, &data.data.trajectories, seg_len)
                .into_iter()
                .filter(|(s, _)| s.len() == seg_len)
                .unzip();
        let e0: Vec<f64> = e0.concat();
        let steps = seg_len - 1;
        let m = segs.len();
        let mut finals = Vec::with_capacity(m);
        if m > 0 {
            let du = world.action_dim();
            let s0: Vec<f64> = segs.iter().flat_map(|s| s.s[..ds].to_vec()).collect();
            let mut u = vec![0.0; steps * m * du];
            for j in 0..steps {
                for (i, sg) in segs.iter().enumerate() {
                    u[(j * m + i) * du..(j * m + i + 1) * du]
                        .copy_from_slice(&sg.u[j * du..(j + 1) * du]);
                }
            }
            let mut out = vec![0.0; steps * m * ds];
            model.rollout_with_extra(&s0, &e0, &u, &mut out, None)?;
            for (i, sg) in segs.iter().enumerate() {
                let p = &out[((steps - 1) * m + i) * ds..((steps - 1) * m + i + 1) * ds];
                let q = &sg.s[steps * ds..(steps + 1) * ds];
                finals.push(([p[0], p[1], p[2]], [q[0], q[1], q[2]]));
            }
        }
        Some(TveReport {
            tve: tve(&finals),
            segments: finals.len(),
            segment_s: cfg.segment_s,
        })
    } else {
        None
    };
    Ok(EvalReport {
        world,
        kind: model.kind().name().to_string(),
        steps: cfg.steps,
        windows: n,
        one_step: dims(&we.e1),
        k_step: dims(&we.ek),
        loss: we.loss.iter().sum::<f64>() / n.max(1) as f64,
        tve: tve_report,
        failed_rollouts: we.failed,
    })
}

struct Quantity {
    name: &'static str,
    unit: &'static str,
    values: Vec<f64>,
}

/// The quantities errors are binned against, at each window's start (measured state and the
/// command held over the first step).
fn quantities(world: World, data: &TimedDataset, we: &WindowErrors) -> Vec<Quantity> {
    let trajs = &data.data.trajectories;
    let state = |w: usize, d: usize| {
        let t = &trajs[we.trajectory[w]];
        t.s[we.start[w] * t.dim_s + d]
    };
    let input = |w: usize, d: usize| {
        let t = &trajs[we.trajectory[w]];
        t.u[we.start[w] * t.dim_u + d]
    };
    let n = we.start.len();
    let q = |name, unit, f: &dyn Fn(usize) -> f64| Quantity {
        name,
        unit,
        values: (0..n).map(f).collect(),
    };
    match world {
        World::Car => vec![
            q("speed", "m/s", &|w| state(w, 3).hypot(state(w, 4))),
            q("yaw_rate", "rad/s", &|w| state(w, 5)),
            q("sideslip", "rad", &|w| {
                if state(w, 3).hypot(state(w, 4)) > 0.2 {
                    state(w, 4).atan2(state(w, 3))
                } else {
                    f64::NAN
                }
            }),
            q("steering", "rad", &|w| input(w, 0)),
            q("throttle", "1", &|w| input(w, 1)),
            q("x", "m", &|w| state(w, 0)),
            q("y", "m", &|w| state(w, 1)),
        ],
        World::Push => vec![
            q("x", "m", &|w| state(w, 0)),
            q("y", "m", &|w| state(w, 1)),
            q("push_location", "1", &|w| input(w, 0)),
            q("push_angle", "rad", &|w| input(w, 1)),
            q("push_length", "0.1 m", &|w| input(w, 2)),
        ],
    }
}

fn bin_errors(q: &Quantity, ek: &[f64], ds: usize, bins: usize) -> BinnedError {
    let edges = robust_edges(&q.values, bins).unwrap_or_else(|| vec![0.0, 1.0]);
    let nb = edges.len() - 1;
    let mut counts = vec![0usize; nb];
    let mut sq = vec![vec![0.0; nb]; ds];
    let mut excluded = 0;
    for (w, &v) in q.values.iter().enumerate() {
        match bin_of(&edges, v) {
            Some(b) => {
                counts[b] += 1;
                for d in 0..ds {
                    sq[d][b] += ek[w * ds + d] * ek[w * ds + d];
                }
            }
            None => excluded += 1,
        }
    }
    let rmse = sq
        .iter()
        .map(|row| {
            row.iter()
                .zip(&counts)
                .map(|(s, &c)| if c > 0 { (s / c as f64).sqrt() } else { 0.0 })
                .collect()
        })
        .collect();
    BinnedError {
        quantity: q.name.into(),
        unit: q.unit.into(),
        edges,
        counts,
        rmse,
        excluded,
    }
}

fn position_map(x: &[f64], y: &[f64], ek: &[f64], ds: usize, grid: usize) -> PositionMap {
    let xe = robust_edges(x, grid).unwrap_or_else(|| vec![0.0, 1.0]);
    let ye = robust_edges(y, grid).unwrap_or_else(|| vec![0.0, 1.0]);
    let (nx, ny) = (xe.len() - 1, ye.len() - 1);
    let mut counts = vec![vec![0usize; nx]; ny];
    let mut sq = vec![vec![0.0; nx]; ny];
    for w in 0..x.len() {
        if let (Some(ix), Some(iy)) = (bin_of(&xe, x[w]), bin_of(&ye, y[w])) {
            counts[iy][ix] += 1;
            sq[iy][ix] += ek[w * ds] * ek[w * ds] + ek[w * ds + 1] * ek[w * ds + 1];
        }
    }
    let rmse = sq
        .iter()
        .zip(&counts)
        .map(|(r, c)| {
            r.iter()
                .zip(c)
                .map(|(s, &c)| if c > 0 { (s / c as f64).sqrt() } else { 0.0 })
                .collect()
        })
        .collect();
    PositionMap {
        x_edges: xe,
        y_edges: ye,
        counts,
        rmse,
    }
}

/// Splits per-window values into per-trajectory runs (windows are trajectory-major).
fn runs(trajectory: &[usize]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut s = 0;
    for i in 1..=trajectory.len() {
        if i == trajectory.len() || trajectory[i] != trajectory[s] {
            out.push(s..i);
            s = i;
        }
    }
    out
}

fn lag_correlation(
    state: &str,
    with: &str,
    r: Vec<f64>,
    max_lag: usize,
    band: f64,
    skip_zero: bool,
) -> LagCorrelation {
    let l = max_lag as i64;
    let (mut peak_lag, mut peak_r) = (0i64, 0.0f64);
    let mut outside = 0usize;
    for (i, &v) in r.iter().enumerate() {
        let lag = i as i64 - l;
        if lag != 0 && v.abs() > band {
            outside += 1;
        }
        if (skip_zero && lag == 0) || v.abs() <= peak_r.abs() {
            continue;
        }
        peak_lag = lag;
        peak_r = v;
    }
    LagCorrelation {
        state: state.into(),
        with: with.into(),
        r,
        peak_lag,
        peak_r,
        outside_band: outside as f64 / (2 * max_lag).max(1) as f64,
    }
}

fn correlations(
    world: World,
    data: &TimedDataset,
    we: &WindowErrors,
    max_lag: usize,
) -> CorrelationReport {
    let ds = world.state_dim();
    let du = world.action_dim();
    let rs = runs(&we.trajectory);
    let trajs = &data.data.trajectories;
    // per run: residual per dim and input per dim (the command held over the step)
    let mut res: Vec<Vec<Vec<f64>>> = vec![Vec::new(); ds];
    let mut inp: Vec<Vec<Vec<f64>>> = vec![Vec::new(); du];
    for r in &rs {
        for d in 0..ds {
            res[d].push(r.clone().map(|w| we.e1[w * ds + d]).collect());
        }
        for j in 0..du {
            inp[j].push(
                r.clone()
                    .map(|w| {
                        let t = &trajs[we.trajectory[w]];
                        t.u[we.start[w] * t.dim_u + j]
                    })
                    .collect(),
            );
        }
    }
    let names = world.state_names();
    let inames = world.action_names();
    let dt = data.data.pose_dt_s;
    let mut n_all = 0;
    let mut auto = Vec::new();
    let mut cross = Vec::new();
    let mut findings = Vec::new();
    let n_total: usize = rs.iter().map(|r| r.len()).sum();
    let band = 1.96 / (n_total.max(1) as f64).sqrt();
    // autocorrelation of each input, for Bartlett's band of the cross-correlation
    let inp_auto: Vec<Vec<f64>> = (0..du)
        .map(|j| {
            let pairs: Vec<(&[f64], &[f64])> = inp[j]
                .iter()
                .map(|a| (a.as_slice(), a.as_slice()))
                .collect();
            cross_correlation(&pairs, max_lag).0
        })
        .collect();
    for d in 0..ds {
        let pairs: Vec<(&[f64], &[f64])> = res[d]
            .iter()
            .map(|a| (a.as_slice(), a.as_slice()))
            .collect();
        let (r_auto, n) = cross_correlation(&pairs, max_lag);
        n_all = n;
        for j in 0..du {
            let pairs: Vec<(&[f64], &[f64])> = res[d]
                .iter()
                .zip(&inp[j])
                .map(|(a, b)| (a.as_slice(), b.as_slice()))
                .collect();
            let (r, _) = cross_correlation(&pairs, max_lag);
            let r0 = r[max_lag];
            // Bartlett: var r_xy ≈ (1/N) Σ_l ρ_xx(l) ρ_yy(l) when x and y are uncorrelated
            // but each autocorrelated; never narrower than the white-noise band
            let sum: f64 = r_auto.iter().zip(&inp_auto[j]).map(|(a, b)| a * b).sum();
            let band_j = 1.96 * (sum.max(1.0) / n_total.max(1) as f64).sqrt();
            let lc = lag_correlation(names[d], inames[j], r, max_lag, band, false);
            if world == World::Car
                && lc.peak_lag > 0
                && lc.peak_r.abs() > 2.0 * band_j
                && lc.peak_r.abs() > r0.abs() + 2.0 * band_j
            {
                let lag_s = lc.peak_lag as f64 * dt;
                findings.push(LagFinding {
                    state: names[d].into(),
                    input: inames[j].into(),
                    lag_steps: lc.peak_lag,
                    lag_s,
                    r: lc.peak_r,
                    message: format!(
                        "unmodelled delay or lag: the {} residual follows input {} by {} steps ({:.3} s), r = {:.2} (r at lag 0: {:.2}; band ±{:.3}, ±{:.3} allowing for autocorrelation)",
                        names[d], inames[j], lc.peak_lag, lag_s, lc.peak_r, r0, band, band_j
                    ),
                });
            }
            cross.push(lc);
        }
        auto.push(lag_correlation(
            names[d],
            "autocorrelation",
            r_auto,
            max_lag,
            band,
            true,
        ));
    }
    CorrelationReport {
        lags: (-(max_lag as i64)..=max_lag as i64).collect(),
        dt_s: dt,
        n: n_all,
        band,
        autocorrelation: auto,
        cross,
        findings,
    }
}

fn over_time(data: &TimedDataset, we: &WindowErrors, ds: usize, points: usize) -> Vec<ErrorSeries> {
    let st = &data.stamps;
    runs(&we.trajectory)
        .into_iter()
        .map(|r| {
            let traj = we.trajectory[r.start];
            let len = r.len();
            let block = len.div_ceil(points).max(1);
            let mut t_s = Vec::new();
            let mut rmse = vec![Vec::new(); ds];
            let mut w = r.start;
            while w < r.end {
                let e = (w + block).min(r.end);
                t_s.push(st.seconds_from_bag_start(traj, we.start[w]));
                for d in 0..ds {
                    let s: f64 = (w..e).map(|i| we.ek[i * ds + d].powi(2)).sum();
                    rmse[d].push((s / (e - w) as f64).sqrt());
                }
                w = e;
            }
            ErrorSeries {
                trajectory: traj,
                bag: st.bag.get(traj).copied().unwrap_or(0),
                t_s,
                rmse,
            }
        })
        .collect()
}

fn worst_segments(
    data: &TimedDataset,
    we: &WindowErrors,
    k_rmse: &[DimError],
    ds: usize,
    k: usize,
    count: usize,
) -> Vec<Segment> {
    let n = we.start.len();
    let score: Vec<f64> = (0..n)
        .map(|w| {
            (0..ds)
                .map(|d| {
                    let s = k_rmse[d].rmse;
                    if s > 0.0 {
                        (we.ek[w * ds + d] / s).powi(2)
                    } else {
                        0.0
                    }
                })
                .sum::<f64>()
                / ds as f64
        })
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| score[b].total_cmp(&score[a]).then(a.cmp(&b)));
    let st = &data.stamps;
    let mut out: Vec<Segment> = Vec::new();
    for w in order {
        if out.len() >= count {
            break;
        }
        let (traj, start) = (we.trajectory[w], we.start[w]);
        if out
            .iter()
            .any(|s| s.trajectory == traj && s.start_index.abs_diff(start) <= 4 * k)
        {
            continue;
        }
        let t = |i: usize| {
            st.t_ns
                .get(traj)
                .and_then(|v| v.get(i))
                .copied()
                .unwrap_or(0)
        };
        out.push(Segment {
            rank: out.len() + 1,
            bag: st.bag.get(traj).copied().unwrap_or(0),
            trajectory: traj,
            start_index: start,
            start_ns: t(start),
            end_ns: t(start + k),
            start_s: st.seconds_from_bag_start(traj, start),
            end_s: st.seconds_from_bag_start(traj, start + k),
            score: score[w],
            error: we.ek[w * ds..(w + 1) * ds].to_vec(),
        });
    }
    out
}

/// Measures one model against the data (see the module docs).
pub fn compare_model(
    label: &str,
    model: &Model,
    data: &TimedDataset,
    cfg: &CompareConfig,
) -> Result<ModelComparison, CompareError> {
    cfg.validate()?;
    let world = model.world();
    if data.data.world != world {
        return Err(LearnError::WorldMismatch {
            what: "the data".into(),
            found: data.data.world.name().into(),
            expected: world.name().into(),
            hint: format!(
                "the model {label} is a {} model: compare it on a bag of that robot",
                world.name()
            ),
        }
        .into());
    }
    if world == World::Car && (data.data.pose_dt_s - model.dt()).abs() > 0.01 * model.dt() {
        return Err(CompareError::Setting {
            name: "data step",
            value: format!(
                "{:.5} s (the model steps {:.5} s)",
                data.data.pose_dt_s,
                model.dt()
            ),
            hint: "resample the poses to the model's step (load_bags_timed_at; dynlab compare does this itself)",
        });
    }
    if data.stamps.t_ns.len() != data.data.trajectories.len() {
        return Err(CompareError::Setting {
            name: "stamps",
            value: format!(
                "{} for {} trajectories",
                data.stamps.t_ns.len(),
                data.data.trajectories.len()
            ),
            hint: "load the data with load_bags_timed so every trajectory has its stamps",
        });
    }
    let ds = world.state_dim();
    let we = window_errors(model, data, cfg)?;
    let eval = eval_report(model, data, &we, cfg)?;
    let qs = quantities(world, data, &we);
    let binned = qs
        .iter()
        .map(|q| bin_errors(q, &we.ek, ds, cfg.bins))
        .collect();
    let xs = &qs.iter().find(|q| q.name == "x").map(|q| q.values.clone());
    let ys = &qs.iter().find(|q| q.name == "y").map(|q| q.values.clone());
    let position_map = position_map(
        xs.as_deref().unwrap_or(&[]),
        ys.as_deref().unwrap_or(&[]),
        &we.ek,
        ds,
        cfg.grid,
    );
    let correlation = correlations(world, data, &we, cfg.max_lag);
    let over_time = over_time(data, &we, ds, cfg.series_points);
    let worst = worst_segments(data, &we, &eval.k_step, ds, cfg.steps, cfg.worst);
    Ok(ModelComparison {
        label: label.into(),
        eval,
        over_time,
        binned,
        position_map,
        correlation,
        worst,
    })
}

fn data_summary(data: &TimedDataset) -> DataSummary {
    DataSummary {
        bags: data.data.sources.iter().map(|s| s.path.clone()).collect(),
        trajectories: data.data.trajectories.len(),
        states: data.data.trajectories.iter().map(|t| t.len()).sum(),
        dt_s: data.data.pose_dt_s,
        notes: data
            .data
            .reports
            .iter()
            .map(dynlab_learn::pipeline_notes)
            .collect(),
        warnings: dynlab_learn::excitation_warnings(&data.data),
    }
}

/// Compares one model with the data: [`compare_model`] plus the data summary.
pub fn compare(
    label: &str,
    model: &Model,
    data: &TimedDataset,
    cfg: &CompareConfig,
) -> Result<CompareReport, CompareError> {
    compare_with_baseline((label, model), None, data, cfg)
}

fn change(state: &str, steps: usize, metric: &str, baseline: f64, model: f64) -> ErrorChange {
    ErrorChange {
        state: state.into(),
        steps,
        metric: metric.into(),
        baseline,
        model,
        change: model - baseline,
        change_pct: (baseline != 0.0).then(|| 100.0 * (model - baseline) / baseline),
    }
}

/// The error changes from `base` to `model`: per dimension RMSE and MAE at 1 and k steps, the
/// loss, and TVE for the car.
pub fn error_changes(base: &EvalReport, model: &EvalReport) -> Vec<ErrorChange> {
    let mut out = Vec::new();
    for (steps, b, m) in [
        (1, &base.one_step, &model.one_step),
        (model.steps, &base.k_step, &model.k_step),
    ] {
        for (bd, md) in b.iter().zip(m) {
            out.push(change(&md.name, steps, "rmse", bd.rmse, md.rmse));
            out.push(change(&md.name, steps, "mae", bd.mae, md.mae));
        }
    }
    out.push(change("all", model.steps, "loss", base.loss, model.loss));
    if let (Some(b), Some(m)) = (&base.tve, &model.tve) {
        out.push(change("pose", 0, "tve", b.tve, m.tve));
    }
    out
}

/// Compares a model and, optionally, a baseline `(label, model)` with the same data and
/// settings, with the error change from baseline to model.
pub fn compare_with_baseline(
    model: (&str, &Model),
    baseline: Option<(&str, &Model)>,
    data: &TimedDataset,
    cfg: &CompareConfig,
) -> Result<CompareReport, CompareError> {
    let world = model.1.world();
    let m = compare_model(model.0, model.1, data, cfg)?;
    let b = match baseline {
        Some((label, b)) => {
            if b.world() != world {
                return Err(LearnError::WorldMismatch {
                    what: format!("the baseline {label}"),
                    found: b.world().name().into(),
                    expected: world.name().into(),
                    hint: "compare two models of the same robot".into(),
                }
                .into());
            }
            Some(compare_model(label, b, data, cfg)?)
        }
        None => None,
    };
    let change = b
        .as_ref()
        .map(|b| error_changes(&b.eval, &m.eval))
        .unwrap_or_default();
    Ok(CompareReport {
        schema: SCHEMA.into(),
        world,
        states: world.state_names().iter().map(|s| s.to_string()).collect(),
        inputs: world.action_names().iter().map(|s| s.to_string()).collect(),
        config: cfg.clone(),
        data: data_summary(data),
        model: m,
        baseline: b,
        change,
    })
}

fn fmt_pct(p: Option<f64>) -> String {
    p.map(|p| format!("{p:+.1} %"))
        .unwrap_or_else(|| "-".into())
}

impl CompareReport {
    /// The error table (with the baseline and the change when there is one).
    pub fn error_table(&self) -> crate::report::Table {
        use crate::report::Table;
        let k = self.config.steps;
        match &self.baseline {
            None => {
                let mut t = Table::new([
                    "state".to_string(),
                    "RMSE 1-step".into(),
                    "MAE 1-step".into(),
                    format!("RMSE {k}-step"),
                    format!("MAE {k}-step"),
                ]);
                for (a, b) in self.model.eval.one_step.iter().zip(&self.model.eval.k_step) {
                    t.push([
                        a.name.clone(),
                        format!("{:.4e}", a.rmse),
                        format!("{:.4e}", a.mae),
                        format!("{:.4e}", b.rmse),
                        format!("{:.4e}", b.mae),
                    ]);
                }
                t
            }
            Some(_) => {
                let mut t = Table::new([
                    "state", "steps", "metric", "baseline", "model", "change", "change %",
                ]);
                for c in &self.change {
                    if c.metric == "mae" {
                        continue;
                    }
                    t.push([
                        c.state.clone(),
                        c.steps.to_string(),
                        c.metric.clone(),
                        format!("{:.4e}", c.baseline),
                        format!("{:.4e}", c.model),
                        format!("{:+.3e}", c.change),
                        fmt_pct(c.change_pct),
                    ]);
                }
                t
            }
        }
    }

    /// The short terminal summary: errors (and their change), TVE, data notes and warnings,
    /// flagged lags, the worst segments, where the error is largest.
    pub fn summary(&self) -> String {
        let m = &self.model;
        let mut s = format!(
            "{} model {} on {} ({} trajectories, {} states, step {:.4} s), {} windows of {} steps\n",
            m.eval.kind,
            m.label,
            self.data.bags.join(", "),
            self.data.trajectories,
            self.data.states,
            self.data.dt_s,
            m.eval.windows,
            self.config.steps
        );
        if let Some(b) = &self.baseline {
            s += &format!("baseline: {} model {}\n", b.eval.kind, b.label);
        }
        s += &self.error_table().to_text();
        if self.baseline.is_none()
            && let Some(t) = &m.eval.tve
        {
            s += &format!(
                "TVE over {} segments of {:.1} s: {:.4}\n",
                t.segments, t.segment_s, t.tve
            );
        }
        for notes in &self.data.notes {
            for n in notes
                .iter()
                .filter(|n| n.contains("gap") || n.contains("resampled") || n.contains("dropped"))
            {
                s += &format!("data: {n}\n");
            }
        }
        for w in &self.data.warnings {
            s += &format!("warning: {w}\n");
        }
        // where the error is largest: the bin with the largest mean-normalised error per quantity
        let mut hot = Vec::new();
        for b in &m.binned {
            let ds = b.rmse.len();
            let norm: Vec<f64> = (0..ds).map(|d| m.eval.k_step[d].rmse).collect();
            let mut best = (0usize, 0.0f64);
            for i in 0..b.counts.len() {
                if b.counts[i] < 5 {
                    continue;
                }
                let v = (0..ds)
                    .map(|d| {
                        if norm[d] > 0.0 {
                            b.rmse[d][i] / norm[d]
                        } else {
                            0.0
                        }
                    })
                    .sum::<f64>()
                    / ds as f64;
                if v > best.1 {
                    best = (i, v);
                }
            }
            if best.1 > 1.5 {
                hot.push(format!(
                    "{} in [{:.3}, {:.3}] {} ({:.1}× the mean error, {} windows)",
                    b.quantity,
                    b.edges[best.0],
                    b.edges[best.0 + 1],
                    b.unit,
                    best.1,
                    b.counts[best.0]
                ));
            }
        }
        if !hot.is_empty() {
            s += "largest errors at:\n";
            for h in hot {
                s += &format!("  {h}\n");
            }
        }
        let c = &m.correlation;
        let white: Vec<String> = c
            .autocorrelation
            .iter()
            .map(|a| format!("{} {:.0} %", a.state, 100.0 * a.outside_band))
            .collect();
        s += &format!(
            "residual autocorrelation outside the 95 % band (±{:.3}): {}\n",
            c.band,
            white.join(", ")
        );
        for f in &c.findings {
            s += &format!("finding: {}\n", f.message);
        }
        if c.findings.is_empty() {
            s += "no lagged input peak outside the band\n";
        }
        if !m.worst.is_empty() {
            s += "worst segments (bag, seconds from its start):\n";
            for w in m.worst.iter().take(5) {
                s += &format!(
                    "  #{} {} {:.3}–{:.3} s (stamps {}–{} ns), score {:.1}\n",
                    w.rank,
                    self.data.bags.get(w.bag).map(String::as_str).unwrap_or("?"),
                    w.start_s,
                    w.end_s,
                    w.start_ns,
                    w.end_ns,
                    w.score
                );
            }
        }
        if m.eval.failed_rollouts > 0 {
            s += &format!(
                "warning: {} rollout batches had a solver failure\n",
                m.eval.failed_rollouts
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_split_at_trajectory_changes() {
        assert_eq!(runs(&[0, 0, 1, 1, 1, 3]), vec![0..2, 2..5, 5..6]);
        assert!(runs(&[]).is_empty());
    }

    #[test]
    fn change_in_percent() {
        let c = change("x", 1, "rmse", 2.0, 1.0);
        assert_eq!(c.change, -1.0);
        assert_eq!(c.change_pct, Some(-50.0));
        assert_eq!(change("x", 1, "rmse", 0.0, 1.0).change_pct, None);
    }

    #[test]
    fn config_rejects_zero_steps() {
        let cfg = CompareConfig {
            steps: 0,
            ..Default::default()
        };
        assert!(cfg.validate().unwrap_err().to_string().contains("steps"));
    }
}
