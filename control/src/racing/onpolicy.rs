//! On-policy racing data: the racer drives the simulator on a track with perturbations, and the
//! run is recorded as an episode with the same records (poses, odometry, commands) the
//! exploration episodes of `dynlab collect car` carry.
//!
//! Random exploration rarely drives the line a racer drives (high speed with large slip and
//! steering at the apex of a bend); a model trained only on it is least accurate exactly where
//! the racer needs it. These episodes put the racer's own regime into the training set: each
//! starts at a random centre-line point, draws its reference speed from a range and adds
//! Gaussian noise to every command, so the data also covers the neighbourhood of the racing
//! line rather than one line.

use dynlab_learn::dynamics::data::SavGol;
use dynlab_sim::episode::{Episode, EpisodeEnd, Record, Sample};
use dynlab_sim::{CarInput, CarScenario, CarState, CarWorld, SimRng, Track, derive_seed};

use super::RacingError;
use super::estimate::CarStateEstimator;
use super::plant::CarDynamics;
use super::race::{Racer, RacerSettings};

/// Seed streams of an on-policy episode (distinct from the simulator's exploration streams).
const STREAM_START: u64 = 0x52_41_43_45_01;
const STREAM_NOISE: u64 = 0x52_41_43_45_02;
const STREAM_POSE: u64 = 0x52_41_43_45_03;

/// Settings of on-policy racing episodes (a TOML file for `dynlab collect car --race`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OnPolicySettings {
    /// Length of an episode \[s\]. Default 30.
    pub duration: f64,
    /// Range of the reference speed \[m/s\]; each episode draws one uniformly. Default
    /// `[1.5, 2.5]`.
    pub speed_range: [f64; 2],
    /// Standard deviation of the Gaussian noise added to the racer's steering \[rad\] at every
    /// control cycle (the noisy command is what the car gets and what is recorded). Default 0.05.
    pub steering_noise: f64,
    /// Standard deviation of the noise added to the racer's throttle at every cycle. Default 0.1.
    pub throttle_noise: f64,
    /// Largest lateral offset of the start from the centre line, as a fraction of the half
    /// width. Default 0.5.
    pub start_offset: f64,
    /// Estimate the racer's state from the noisy poses (as in the laps) or give it the
    /// simulator's true state. Default true.
    pub estimate: bool,
    /// The racer (its `reference_speed` is replaced by the drawn one).
    pub racer: RacerSettings,
}

impl Default for OnPolicySettings {
    fn default() -> Self {
        Self {
            duration: 30.0,
            speed_range: [1.5, 2.5],
            steering_noise: 0.05,
            throttle_noise: 0.1,
            start_offset: 0.5,
            estimate: true,
            racer: RacerSettings::default(),
        }
    }
}

impl OnPolicySettings {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), RacingError> {
        if !(self.duration.is_finite() && self.duration > 0.0) {
            return Err(RacingError::setting(
                "duration",
                self.duration,
                "an episode length in seconds > 0",
            ));
        }
        let [lo, hi] = self.speed_range;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return Err(RacingError::setting(
                "speed_range",
                format!("[{lo}, {hi}]"),
                "two reference speeds in m/s with 0 < low ≤ high",
            ));
        }
        for (name, v) in [
            ("steering_noise", self.steering_noise),
            ("throttle_noise", self.throttle_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(RacingError::setting(
                    name,
                    v,
                    "a standard deviation ≥ 0 (0: no noise)",
                ));
            }
        }
        if !(0.0..1.0).contains(&self.start_offset) {
            return Err(RacingError::setting(
                "start_offset",
                self.start_offset,
                "a fraction of the half width in [0, 1)",
            ));
        }
        Ok(())
    }
}

/// One on-policy episode on `track` in the world of `scenario`: the racer over `model` re-solves
/// every control cycle (`racer.hold` model steps of the model's `dt`), noise is added to its
/// command, and the episode records the measured pose and the true state (odometry) at every
/// model step and the applied command at every cycle, stamped in integer nanoseconds from the
/// episode start (the order at equal stamps: pose, odometry, command). Deterministic in `seed`.
pub fn racing_episode(
    model: &dyn CarDynamics,
    scenario: &CarScenario,
    track: &Track,
    settings: &OnPolicySettings,
    seed: u64,
    index: u64,
) -> Result<Episode, RacingError> {
    settings.validate()?;
    let mut start_rng = SimRng::new(derive_seed(seed, STREAM_START, 0));
    let mut noise_rng = SimRng::new(derive_seed(seed, STREAM_NOISE, 0));
    let mut pose_rng = SimRng::new(derive_seed(seed, STREAM_POSE, 0));
    let mut rs = settings.racer;
    rs.reference_speed = start_rng.uniform_in(settings.speed_range[0], settings.speed_range[1]);
    let mut racer = Racer::new(model, track, rs)?;
    let hold = rs.hold;
    let dt = racer.period() / hold as f64;
    let tick_ns = (dt * 1e9).round() as u64;
    let mut world = CarWorld::new(scenario)?;
    world.reset(track_start(track, settings.start_offset, &mut start_rng))?;
    let start = world.state();
    let limits = rs.limits;
    let mut est = CarStateEstimator::new(SavGol::default());
    let ticks = (settings.duration / dt).round() as u64;
    let mut samples = Vec::with_capacity(ticks as usize * 2 + ticks as usize / hold + 4);
    let mut input = CarInput::new(0.0, 0.0);
    for i in 0..=ticks {
        let t_ns = i * tick_ns;
        let truth = world.state();
        let pose = world.measure(&mut pose_rng);
        samples.push(Sample {
            t_ns,
            record: Record::CarPose(pose),
        });
        samples.push(Sample {
            t_ns,
            record: Record::CarOdom(truth),
        });
        let s = est.observe(
            settings.estimate,
            world.time(),
            [pose.x, pose.y, pose.theta],
            &truth,
            &start,
        );
        if i == ticks {
            break;
        }
        if (i as usize).is_multiple_of(hold) {
            let r = racer.step(s)?;
            let u = limits.clamp([
                r.input[0] + settings.steering_noise * noise_rng.normal(),
                r.input[1] + settings.throttle_noise * noise_rng.normal(),
            ]);
            input = CarInput::new(u[0], u[1]);
            samples.push(Sample {
                t_ns,
                record: Record::CarCmd(input),
            });
        }
        world.step(input, dt)?;
    }
    Ok(Episode {
        index,
        seed,
        duration_ns: samples.last().map_or(0, |s| s.t_ns),
        samples,
        end: EpisodeEnd::Completed,
    })
}

/// A standing start at a random centre-line vertex, facing along the track, with a random
/// lateral offset of at most `offset` half widths.
fn track_start(track: &Track, offset: f64, rng: &mut SimRng) -> CarState {
    let n = track.len().max(1);
    let i = (rng.uniform() * n as f64) as usize % n;
    let a = track.point(i);
    let b = track.point(i + 1);
    let psi = (b[1] - a[1]).atan2(b[0] - a[0]);
    let hw = track.locate(a).half_width;
    let lat = rng.uniform_in(-offset, offset) * hw;
    CarState {
        x: a[0] - psi.sin() * lat,
        y: a[1] + psi.cos() * lat,
        psi,
        ..CarState::default()
    }
}
