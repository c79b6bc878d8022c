//! Model predictive path integral control of the pushed block (Tu & Lin, after Williams et al.).
//!
//! Each [`Mppi::step`] draws `K` perturbations of the warm-started action sequence (length `T`,
//! clamped into the action bounds), rolls all `K` sequences through the model in one batch
//! ([`dynlab_learn::Model::rollout_f32`]: allocation-free and multi-threaded for residual and
//! NeuralODE Euler/RK4 models; a chunked, threaded [`dynlab_learn::Model::step`] loop for the
//! other kinds), scores each with its own quadratic goal cost (wrapped angle error, weights `Q`),
//! a terminal cost `Q_f` and a collision cost from a separating-axis test against the obstacles,
//! and averages the sequences with weights `exp(−(S_k − S_min)/λ)`. The first action is returned
//! and the sequence is shifted by one for the next call (warm start).
//!
//! Tu & Lin's code summed a `K × K` product in the goal cost, which made every sample's cost
//! linear in the batch-mean error; here every sample is scored on its own trajectory.
//!
//! Deterministic: the noise comes from [`MppiConfig::seed`], and results do not depend on
//! [`MppiConfig::threads`] (tested).

mod config;
mod cost;
mod episode;

pub use config::{ACTION_MAX, ACTION_MIN, MppiConfig};
pub use cost::{CostWeights, PushTask, Rect, goal_error, quadratic, trajectory_cost};
pub use episode::{EpisodeError, EpisodeResult, EpisodeSettings, run_episode};

use dynlab_learn::{LearnError, Model, RolloutWorkspace, World};
use dynlab_nn::parallel::row_blocks;
use dynlab_sim::{SimRng, derive_seed};

/// Samples per chunk of the fallback rollout: fixed, so that batch-adaptive solvers (Dopri5) see
/// the same batches on any number of threads.
const FALLBACK_CHUNK: usize = 64;

/// Errors of the MPPI controller.
#[derive(Debug, thiserror::Error)]
pub enum MppiError {
    /// A setting is out of range.
    #[error("MPPI setting `{key}` = {value}: {fix}")]
    Setting {
        /// The key.
        key: &'static str,
        /// Its value.
        value: String,
        /// What to set.
        fix: &'static str,
    },
    /// The model is not a pushing model.
    #[error(
        "MPPI pushes a block, but the model is a {0} model; train one on pushing data (/push/block_pose, /push/action)"
    )]
    WrongWorld(&'static str),
    /// The state is not finite.
    #[error("MPPI state must be finite, got {0:?}; check the pose input")]
    State([f64; 3]),
    /// The goal is not finite.
    #[error("MPPI goal must be finite, got {0:?}")]
    Goal([f64; 3]),
    /// The model failed on the batch.
    #[error("model rollout failed: {0}")]
    Model(#[from] LearnError),
}

/// What one MPPI step decided, with diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct MppiStep {
    /// The action to execute now `[p, φ, ℓ]`, inside the bounds.
    pub action: [f64; 3],
    /// Lowest sample cost.
    pub cost_min: f64,
    /// Importance-weighted mean sample cost.
    pub cost_mean: f64,
    /// Effective sample size `1 / Σ w²`.
    pub effective_samples: f64,
    /// Samples whose rollout went non-finite (scored as infinitely costly).
    pub diverged: usize,
}

/// The MPPI controller with its warm-start sequence, noise stream and buffers.
#[derive(Debug)]
pub struct Mppi {
    cfg: MppiConfig,
    task: PushTask,
    weights: CostWeights,
    /// Warm-start sequence, `T × 3`.
    nominal: Vec<f64>,
    rng: SimRng,
    ws: RolloutWorkspace,
    s0: Vec<f32>,
    /// Sampled actions, `K × T × 3` (clamped).
    actions: Vec<f32>,
    /// One noise stream position and `T × 3` noise buffer per block of samples.
    sample_blocks: Vec<SampleBlock>,
    traj: Vec<f32>,
    costs: Vec<f64>,
    w: Vec<f64>,
    /// The weighted mean sequence, `T × 3` (reused between steps).
    mean: Vec<f64>,
}

impl Mppi {
    /// A controller for `task` (its obstacles are used as given; build them with
    /// [`PushTask::from_scenario`] to add the configured margin).
    pub fn new(cfg: MppiConfig, task: PushTask) -> Result<Self, MppiError> {
        cfg.validate()?;
        if !task.goal.iter().all(|v| v.is_finite()) {
            return Err(MppiError::Goal(task.goal));
        }
        let (k, t) = (cfg.samples, cfg.horizon);
        let weights = CostWeights {
            q: cfg.q,
            q_terminal: cfg.q_terminal,
            collision: cfg.collision_cost,
            swept: cfg.swept_collision,
        };
        let mut m = Self {
            rng: SimRng::new(derive_seed(cfg.seed, 0x6d707069, 0)),
            ws: RolloutWorkspace::new(cfg.threads),
            s0: vec![0.0; k * 3],
            actions: vec![0.0; k * t * 3],
            sample_blocks: Vec::new(),
            traj: vec![0.0; k * t * 3],
            costs: vec![0.0; k],
            w: vec![0.0; k],
            mean: vec![0.0; t * 3],
            nominal: Vec::new(),
            cfg,
            task,
            weights,
        };
        m.reset();
        Ok(m)
    }

    /// The settings.
    pub fn config(&self) -> &MppiConfig {
        &self.cfg
    }

    /// The task (goal, block, obstacles).
    pub fn task(&self) -> &PushTask {
        &self.task
    }

    /// A new goal; the warm start is kept (call [`Mppi::reset`] to drop it too).
    pub fn set_goal(&mut self, goal: [f64; 3]) -> Result<(), MppiError> {
        if !goal.iter().all(|v| v.is_finite()) {
            return Err(MppiError::Goal(goal));
        }
        self.task.goal = goal;
        Ok(())
    }

    /// The warm-start sequence `T × [p, φ, ℓ]`.
    pub fn nominal(&self) -> &[f64] {
        &self.nominal
    }

    /// Drops the warm start: every action of the sequence becomes the centre of the bounds in
    /// `p` and `φ` and the lower bound in `ℓ` (no push). The noise stream continues.
    pub fn reset(&mut self) {
        let c = &self.cfg;
        let centre = [
            0.5 * (c.action_min[0] + c.action_max[0]),
            0.5 * (c.action_min[1] + c.action_max[1]),
            c.action_min[2],
        ];
        self.nominal = (0..c.horizon).flat_map(|_| centre).collect();
    }

    /// Restarts the noise stream from the seed and drops the warm start: the controller then
    /// behaves exactly as a new one.
    pub fn reseed(&mut self, seed: u64) {
        self.cfg.seed = seed;
        self.rng = SimRng::new(derive_seed(seed, 0x6d707069, 0));
        self.reset();
    }

    /// Samples, rolls out and scores `K` action sequences from `state = [x, y, θ]` and returns
    /// the action to execute now; the warm start is shifted for the next call.
    pub fn step(&mut self, model: &Model, state: [f64; 3]) -> Result<MppiStep, MppiError> {
        if model.world() != World::Push {
            return Err(MppiError::WrongWorld(model.world().name()));
        }
        if !state.iter().all(|v| v.is_finite()) {
            return Err(MppiError::State(state));
        }
        let t = self.cfg.horizon;
        self.sample()?;
        for row in self.s0.chunks_exact_mut(3) {
            for (x, s) in row.iter_mut().zip(state) {
                *x = s as f32;
            }
        }
        self.rollout(model)?;
        let row = t * 3;
        let (task, weights, traj) = (&self.task, &self.weights, &self.traj);
        let mut blocks = vec![(); self.cfg.threads];
        self.ws
            .workers()
            .for_each_row_block(&mut self.costs, 1, &mut blocks, |rows, costs, _| {
                for (i, c) in rows.zip(costs) {
                    *c = trajectory_cost(task, weights, state, &traj[i * row..(i + 1) * row]);
                }
                Ok(())
            })
            .map_err(LearnError::from)?;
        let diverged = self.costs.iter().filter(|c| !c.is_finite()).count();
        let cost_min = self.costs.iter().copied().fold(f64::INFINITY, f64::min);
        let mut sum = 0.0;
        for (w, c) in self.w.iter_mut().zip(&self.costs) {
            *w = if cost_min.is_finite() && c.is_finite() {
                (-(c - cost_min) / self.cfg.lambda).exp()
            } else {
                0.0
            };
            sum += *w;
        }
        if sum > 0.0 {
            let new = &mut self.mean;
            new.clear();
            new.resize(row, 0.0);
            for (i, w) in self.w.iter_mut().enumerate() {
                *w /= sum;
                if *w == 0.0 {
                    continue;
                }
                for (n, a) in new.iter_mut().zip(&self.actions[i * row..(i + 1) * row]) {
                    *n += *w * f64::from(*a);
                }
            }
            for (j, n) in new.iter().enumerate() {
                let d = j % 3;
                self.nominal[j] = n.clamp(self.cfg.action_min[d], self.cfg.action_max[d]);
            }
        }
        let mut cost_mean = 0.0;
        let mut sq = 0.0;
        for (w, c) in self.w.iter().zip(&self.costs) {
            if *w > 0.0 {
                cost_mean += w * c;
                sq += w * w;
            }
        }
        let action = [self.nominal[0], self.nominal[1], self.nominal[2]];
        // warm start: shift by one; the last action stays in place, so it repeats
        self.nominal.copy_within(3.., 0);
        Ok(MppiStep {
            action,
            cost_min,
            cost_mean: if sum > 0.0 { cost_mean } else { f64::INFINITY },
            effective_samples: if sq > 0.0 { 1.0 / sq } else { 0.0 },
            diverged,
        })
    }

    /// Draws the noise and the clamped sampled sequences, in blocks of samples on the workers.
    /// Sample `i`'s normals are numbers `i·T·3 …` of the one seeded stream (each block seeks to
    /// its first), so the thread count cannot change them.
    fn sample(&mut self) -> Result<(), MppiError> {
        let c = &self.cfg;
        let (k, t) = (c.samples, c.horizon);
        let per_sample = t * 3;
        let ranges = row_blocks(k, c.threads);
        self.sample_blocks
            .resize_with(ranges.len(), SampleBlock::default);
        for (b, r) in self.sample_blocks.iter_mut().zip(&ranges) {
            b.rng = self.rng.after_normals(r.start * per_sample);
            b.noise.resize(per_sample, 0.0);
        }
        self.rng = self.rng.after_normals(k * per_sample);
        let nominal = &self.nominal;
        self.ws
            .workers()
            .for_each_row_block(
                &mut self.actions,
                per_sample,
                &mut self.sample_blocks,
                |rows, actions, b| {
                    for (i, acts) in rows.zip(actions.chunks_exact_mut(per_sample)) {
                        b.draw(c, i, nominal, acts);
                    }
                    Ok(())
                },
            )
            .map_err(LearnError::from)?;
        Ok(())
    }

    fn rollout(&mut self, model: &Model) -> Result<(), MppiError> {
        if model.has_fast_rollout() {
            model.rollout_f32(&self.s0, &self.actions, &mut self.traj, &mut self.ws)?;
            return Ok(());
        }
        fallback_rollout(
            model,
            self.cfg.threads,
            self.cfg.horizon,
            &self.s0,
            &self.actions,
            &mut self.traj,
        );
        Ok(())
    }
}

/// A block of samples' position in the noise stream and its noise buffer.
#[derive(Debug, Clone)]
struct SampleBlock {
    rng: SimRng,
    noise: Vec<f64>,
}

impl Default for SampleBlock {
    fn default() -> Self {
        Self {
            rng: SimRng::new(0),
            noise: Vec::new(),
        }
    }
}

impl SampleBlock {
    /// Sample `i`'s noise (AR(1) along the horizon with correlation β and unit variance) and its
    /// clamped actions; the first `keep_nominal` samples are the nominal sequence itself (their
    /// noise is drawn all the same, so the stream does not depend on the setting).
    fn draw(&mut self, c: &MppiConfig, i: usize, nominal: &[f64], actions: &mut [f32]) {
        let beta = c.noise_correlation;
        let gain = (1.0 - beta * beta).sqrt();
        for idx in 0..self.noise.len() {
            let n = self.rng.normal();
            self.noise[idx] = if idx < 3 {
                n
            } else {
                beta * self.noise[idx - 3] + gain * n
            };
        }
        let keep = i < usize::from(c.keep_nominal);
        for (idx, a) in actions.iter_mut().enumerate() {
            let d = idx % 3;
            let eps = if keep {
                0.0
            } else {
                c.sigma[d] * self.noise[idx]
            };
            *a = (nominal[idx] + eps).clamp(c.action_min[d], c.action_max[d]) as f32;
        }
    }
}

/// Rolls `n` samples through [`Model::step`] in fixed chunks of [`FALLBACK_CHUNK`] samples spread
/// over `threads` threads. A chunk whose step fails (a non-finite state) is marked non-finite
/// from that step on instead of failing the whole batch.
fn fallback_rollout(
    model: &Model,
    threads: usize,
    horizon: usize,
    s0: &[f32],
    actions: &[f32],
    out: &mut [f32],
) {
    let row = horizon * 3;
    let chunks: Vec<(usize, &mut [f32])> = out
        .chunks_mut(FALLBACK_CHUNK * row)
        .enumerate()
        .map(|(c, o)| (c * FALLBACK_CHUNK, o))
        .collect();
    let per = chunks.len().div_ceil(threads.max(1)).max(1);
    let mut groups: Vec<Vec<(usize, &mut [f32])>> = Vec::new();
    let mut it = chunks.into_iter().peekable();
    while it.peek().is_some() {
        groups.push(it.by_ref().take(per).collect());
    }
    std::thread::scope(|scope| {
        let mut groups = groups.into_iter();
        let first = groups.next();
        for g in groups {
            scope.spawn(move || {
                for (start, o) in g {
                    fallback_chunk(model, horizon, start, s0, actions, o);
                }
            });
        }
        if let Some(g) = first {
            for (start, o) in g {
                fallback_chunk(model, horizon, start, s0, actions, o);
            }
        }
    });
}

fn fallback_chunk(
    model: &Model,
    horizon: usize,
    start: usize,
    s0: &[f32],
    actions: &[f32],
    out: &mut [f32],
) {
    let n = out.len() / (horizon * 3);
    let mut cur: Vec<f64> = s0[start * 3..(start + n) * 3]
        .iter()
        .map(|&x| f64::from(x))
        .collect();
    let mut next = vec![0.0; n * 3];
    let mut u = vec![0.0; n * 3];
    let mut dead = false;
    for t in 0..horizon {
        if !dead {
            for i in 0..n {
                for d in 0..3 {
                    u[i * 3 + d] = f64::from(actions[((start + i) * horizon + t) * 3 + d]);
                }
            }
            dead = model.step(&cur, &u, &mut next).is_err();
        }
        for i in 0..n {
            for d in 0..3 {
                out[(i * horizon + t) * 3 + d] = if dead {
                    f32::NAN
                } else {
                    next[i * 3 + d] as f32
                };
            }
        }
        std::mem::swap(&mut cur, &mut next);
    }
}
