//! Closed-loop pushing episodes: MPPI over a model against the simulator, judged as in Tu &
//! Lin's Table I (final xy distance < 0.1 m within 20 pushes) and by a strict criterion
//! (distance < 0.02 m and heading within 0.1 rad); an episode that touched an obstacle is never
//! a success.

use dynlab_learn::Model;
use dynlab_sim::{PushAction, PushScenario, PushWorld, SimRng, derive_seed};
use serde::{Deserialize, Serialize};

use super::{Mppi, MppiConfig, MppiError, PushTask, goal_error};

/// How an episode runs and is judged. Defaults: Tu & Lin's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EpisodeSettings {
    /// Pushes at most. Default 20.
    pub max_steps: usize,
    /// Success: final xy distance below this \[m\]. Default 0.1.
    pub success_distance: f64,
    /// Strict success: distance below this \[m\] ... Default 0.02.
    pub strict_distance: f64,
    /// ... and heading error below this \[rad\]. Default 0.1.
    pub strict_angle: f64,
}

impl Default for EpisodeSettings {
    fn default() -> Self {
        Self {
            max_steps: 20,
            success_distance: 0.1,
            strict_distance: 0.02,
            strict_angle: 0.1,
        }
    }
}

/// What one episode did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeResult {
    /// The episode seed (MPPI noise and measurement noise derive from it).
    pub seed: u64,
    /// Pushes executed.
    pub steps: usize,
    /// Final xy distance below `success_distance` and no collision.
    pub success: bool,
    /// Final pose within the strict tolerances and no collision.
    pub strict: bool,
    /// The block touched an obstacle (simulator contact) during some push.
    pub collision: bool,
    /// First push after which the distance was below `success_distance`.
    pub steps_to_success: Option<usize>,
    /// First push after which the pose was within the strict tolerances.
    pub steps_to_strict: Option<usize>,
    /// Final ground-truth pose `[x, y, θ]`.
    pub final_pose: [f64; 3],
    /// Final xy distance to the goal \[m\].
    pub final_distance: f64,
    /// Final wrapped heading error \[rad\].
    pub final_angle_error: f64,
    /// Ground-truth poses: start, then after every push.
    pub trajectory: Vec<[f64; 3]>,
    /// Actions executed.
    pub actions: Vec<[f64; 3]>,
}

/// Runs one episode: the block starts at the scenario's start; each push, the controller sees a
/// noisy measurement (the scenario's `noise`), MPPI chooses an action over `model`, the
/// simulator executes it. The episode stops when the measured pose is within the strict
/// tolerances (the controller stops at the goal) or after `max_steps` pushes. Deterministic in
/// `seed`.
pub fn run_episode(
    model: &Model,
    scenario: &PushScenario,
    cfg: &MppiConfig,
    settings: &EpisodeSettings,
    seed: u64,
) -> Result<EpisodeResult, EpisodeError> {
    let mut world = PushWorld::new(scenario)?;
    let mut noise = SimRng::new(derive_seed(seed, 2, 0));
    let cfg = MppiConfig {
        seed: derive_seed(seed, 1, 0),
        ..cfg.clone()
    };
    let task = PushTask::from_scenario(scenario, cfg.obstacle_margin);
    let goal = scenario.goal;
    let mut mppi = Mppi::new(cfg, task)?;
    let within = |p: [f64; 3]| {
        let e = goal_error(p, goal);
        let d = e[0].hypot(e[1]);
        (
            d < settings.success_distance,
            d < settings.strict_distance && e[2].abs() < settings.strict_angle,
        )
    };
    let mut trajectory = vec![world.block_pose().to_array()];
    let mut actions = Vec::new();
    let mut collision = false;
    let (mut to_success, mut to_strict) = (None, None);
    for step in 1..=settings.max_steps {
        let measured = world.measure(&mut noise).to_array();
        if within(measured).1 {
            break;
        }
        let out = mppi.step(model, measured)?;
        let a = PushAction::new(out.action[0], out.action[1], out.action[2]).clamped();
        let outcome = world.apply(a)?;
        collision |= outcome.obstacle_collision;
        let p = world.block_pose().to_array();
        collision |= scenario.collides(world.block_pose());
        trajectory.push(p);
        actions.push(out.action);
        let (ok, strict) = within(p);
        if ok && to_success.is_none() {
            to_success = Some(step);
        }
        if strict && to_strict.is_none() {
            to_strict = Some(step);
        }
    }
    let last = *trajectory.last().unwrap_or(&scenario.start);
    let e = goal_error(last, goal);
    let (ok, strict) = within(last);
    Ok(EpisodeResult {
        seed,
        steps: actions.len(),
        success: ok && !collision,
        strict: strict && !collision,
        collision,
        steps_to_success: to_success,
        steps_to_strict: to_strict,
        final_pose: last,
        final_distance: e[0].hypot(e[1]),
        final_angle_error: e[2],
        trajectory,
        actions,
    })
}

/// Errors of an episode.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError {
    /// The controller failed.
    #[error(transparent)]
    Mppi(#[from] MppiError),
    /// The simulator rejected the scenario or an action.
    #[error("simulator: {0}")]
    Sim(#[from] dynlab_sim::SimError),
}
