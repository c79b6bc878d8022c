//! Exploration policies: how the simulated operator pushes the block or drives the car while
//! data is collected.

use serde::{Deserialize, Serialize};

use crate::car::{CarInput, CarScenario, CarState};
use crate::error::SimError;
use crate::geometry::{Pose2, non_negative, positive, wrap_angle};
use crate::push::{PushAction, PushScenario};
use crate::rng::SimRng;

/// Pushing exploration after Tu & Lin: actions uniform over `[−1, 1] × [−π/2, π/2] × [0, 1]`,
/// episodes of a fixed number of pushes from starts jittered around the scenario's start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PushExplorer {
    /// Pushes per episode. Default 10 (Tu & Lin).
    pub pushes_per_episode: u32,
    /// Time between push starts \[s\]; must cover the longest push plus settling. Default 2.
    pub push_period: f64,
    /// Rate of recorded block poses \[Hz\]. Default 10.
    pub pose_rate: f64,
    /// Start jitter `[x, y, θ]` (uniform ±) around the scenario start. Default
    /// `[0.05, 0.05, π/4]`.
    pub start_jitter: [f64; 3],
}

impl Default for PushExplorer {
    fn default() -> Self {
        Self {
            pushes_per_episode: 10,
            push_period: 2.0,
            pose_rate: 10.0,
            start_jitter: [0.05, 0.05, std::f64::consts::FRAC_PI_4],
        }
    }
}

impl PushExplorer {
    /// Checks the settings against the scenario (the period must fit the longest push).
    pub fn validate(&self, scenario: &PushScenario) -> Result<(), SimError> {
        if self.pushes_per_episode == 0 {
            return Err(SimError::invalid(
                "explore.pushes_per_episode",
                "must be ≥ 1, got 0",
            ));
        }
        positive("explore.push_period", self.push_period)?;
        positive("explore.pose_rate", self.pose_rate)?;
        for (i, j) in self.start_jitter.iter().enumerate() {
            non_negative(&format!("explore.start_jitter[{i}]"), *j)?;
        }
        let need = scenario.max_push_time();
        if self.push_period < need {
            return Err(SimError::invalid(
                "explore.push_period",
                format!(
                    "must be ≥ the longest push with settling ({need:.3} s for this scenario), got {}",
                    self.push_period
                ),
            ));
        }
        Ok(())
    }

    /// A start pose around the scenario start that is on the table and clear of obstacles
    /// (after 1000 rejected draws, the scenario start itself).
    pub fn sample_start(&self, scenario: &PushScenario, rng: &mut SimRng) -> Pose2 {
        let s = scenario.start_pose();
        for _ in 0..1000 {
            let j = self.start_jitter;
            let p = Pose2::new(
                s.x + rng.uniform_in(-j[0], j[0]),
                s.y + rng.uniform_in(-j[1], j[1]),
                s.theta + rng.uniform_in(-j[2], j[2]),
            );
            if scenario.table.contains([p.x, p.y]) && !scenario.collides(p) {
                return p;
            }
        }
        s
    }

    /// An action uniform over the action space.
    pub fn sample_action(&self, rng: &mut SimRng) -> PushAction {
        use std::f64::consts::FRAC_PI_2;
        PushAction::new(
            rng.uniform_in(-1.0, 1.0),
            rng.uniform_in(-FRAC_PI_2, FRAC_PI_2),
            rng.uniform(),
        )
    }
}

/// Human-like random driving: Ornstein–Uhlenbeck steering and throttle, occasional aggressive
/// phases (full throttle with a steering flick: traction loss and drifting), a steer-home term
/// near the floor edges (or pure pursuit along the track), and a speed governor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CarExplorer {
    /// Episode length \[s\]. Default 30.
    pub duration: f64,
    /// Command rate \[Hz\]. Default 50.
    pub control_rate: f64,
    /// Pose (and odometry) rate \[Hz\]; a multiple of `control_rate`. Default 100.
    pub pose_rate: f64,
    /// Stationary standard deviation of the steering process \[rad\]. Default 0.15.
    pub steering_std: f64,
    /// Correlation time of the steering process \[s\]. Default 0.6.
    pub steering_tau: f64,
    /// Mean cruise throttle. Default 0.25 (≈ 1.4 m/s).
    pub throttle_mean: f64,
    /// Stationary standard deviation of the throttle process. Default 0.05.
    pub throttle_std: f64,
    /// Correlation time of the throttle process \[s\]. Default 1.5.
    pub throttle_tau: f64,
    /// Mean number of aggressive phases per second. Default 0.15.
    pub aggressive_rate: f64,
    /// Longest aggressive phase \[s\] (each lasts uniform in [0.3, this]). Default 1.0.
    pub aggressive_duration: f64,
    /// Throttle during an aggressive phase. Default 1.
    pub aggressive_throttle: f64,
    /// Steering flick during an aggressive phase \[rad\]. Default 0.35.
    pub aggressive_steering: f64,
    /// Distance from the floor edge where steering home starts \[m\]. Default 0.8.
    pub boundary_margin: f64,
    /// Throttle is cut above this speed \[m/s\]. Default 2.5.
    pub max_speed: f64,
}

impl Default for CarExplorer {
    fn default() -> Self {
        Self {
            duration: 30.0,
            control_rate: 50.0,
            pose_rate: 100.0,
            steering_std: 0.15,
            steering_tau: 0.6,
            throttle_mean: 0.25,
            throttle_std: 0.05,
            throttle_tau: 1.5,
            aggressive_rate: 0.15,
            aggressive_duration: 1.0,
            aggressive_throttle: 1.0,
            aggressive_steering: 0.35,
            boundary_margin: 0.8,
            max_speed: 2.5,
        }
    }
}

impl CarExplorer {
    /// Checks every setting.
    pub fn validate(&self) -> Result<(), SimError> {
        positive("explore.duration", self.duration)?;
        positive("explore.control_rate", self.control_rate)?;
        positive("explore.pose_rate", self.pose_rate)?;
        let ratio = self.pose_rate / self.control_rate;
        if (ratio - ratio.round()).abs() > 1e-9 || ratio.round() < 1.0 {
            return Err(SimError::invalid(
                "explore.pose_rate",
                format!(
                    "must be a whole multiple of explore.control_rate ({}), got {}",
                    self.control_rate, self.pose_rate
                ),
            ));
        }
        non_negative("explore.steering_std", self.steering_std)?;
        positive("explore.steering_tau", self.steering_tau)?;
        non_negative("explore.throttle_std", self.throttle_std)?;
        positive("explore.throttle_tau", self.throttle_tau)?;
        crate::geometry::finite("explore.throttle_mean", self.throttle_mean)?;
        non_negative("explore.aggressive_rate", self.aggressive_rate)?;
        if !(self.aggressive_duration.is_finite() && self.aggressive_duration >= 0.3) {
            return Err(SimError::invalid(
                "explore.aggressive_duration",
                format!("must be ≥ 0.3 s, got {}", self.aggressive_duration),
            ));
        }
        crate::geometry::finite("explore.aggressive_throttle", self.aggressive_throttle)?;
        non_negative("explore.aggressive_steering", self.aggressive_steering)?;
        non_negative("explore.boundary_margin", self.boundary_margin)?;
        positive("explore.max_speed", self.max_speed)
    }

    /// A driver for one episode.
    pub fn driver(&self, scenario: &CarScenario) -> CarDriver {
        CarDriver {
            cfg: self.clone(),
            scenario: scenario.clone(),
            steer_ou: 0.0,
            throttle_ou: 0.0,
            aggressive_left: 0.0,
            aggressive_sign: 1.0,
            lateral_target: 0.0,
        }
    }

    /// A start state at rest: on the floor (away from the edges by half the margin) with a
    /// random heading, or on the track centre line facing along it.
    pub fn sample_start(&self, scenario: &CarScenario, rng: &mut SimRng) -> CarState {
        if let Some(t) = &scenario.track_data {
            let i = (rng.uniform() * t.len() as f64) as usize % t.len();
            let a = t.point(i);
            let b = t.point(i + 1);
            return CarState {
                x: a[0],
                y: a[1],
                psi: (b[1] - a[1]).atan2(b[0] - a[0]),
                ..CarState::default()
            };
        }
        let a = &scenario.arena;
        let m = [
            (0.5 * self.boundary_margin).min(0.25 * (a.max[0] - a.min[0])),
            (0.5 * self.boundary_margin).min(0.25 * (a.max[1] - a.min[1])),
        ];
        CarState {
            x: rng.uniform_in(a.min[0] + m[0], a.max[0] - m[0]),
            y: rng.uniform_in(a.min[1] + m[1], a.max[1] - m[1]),
            psi: rng.uniform_in(-std::f64::consts::PI, std::f64::consts::PI),
            ..CarState::default()
        }
    }
}

/// The per-episode state of a [`CarExplorer`].
#[derive(Debug, Clone)]
pub struct CarDriver {
    cfg: CarExplorer,
    scenario: CarScenario,
    steer_ou: f64,
    throttle_ou: f64,
    aggressive_left: f64,
    aggressive_sign: f64,
    lateral_target: f64,
}

impl CarDriver {
    /// The next command, `dt` after the previous one, seeing the car in `state`.
    /// Draws the same count of random numbers every call.
    pub fn command(&mut self, state: &CarState, dt: f64, rng: &mut SimRng) -> CarInput {
        let c = &self.cfg;
        let car = &self.scenario.car;
        let n = [rng.normal(), rng.normal(), rng.normal()];
        let start_aggressive = rng.bernoulli(c.aggressive_rate * dt);
        let agg_len = rng.uniform_in(0.3, c.aggressive_duration);
        let agg_sign = if rng.bernoulli(0.5) { 1.0 } else { -1.0 };

        // Ornstein–Uhlenbeck processes (exact discretisation).
        let a_s = (-dt / c.steering_tau).exp();
        self.steer_ou = a_s * self.steer_ou + c.steering_std * (1.0 - a_s * a_s).sqrt() * n[0];
        let a_t = (-dt / c.throttle_tau).exp();
        self.throttle_ou =
            a_t * self.throttle_ou + c.throttle_std * (1.0 - a_t * a_t).sqrt() * n[1];
        self.lateral_target = a_t * self.lateral_target + 0.5 * (1.0 - a_t * a_t).sqrt() * n[2];

        let pose = state.pose();
        let (mut steering, homing) = match &self.scenario.track_data {
            Some(track) => {
                // Pure pursuit towards a point ahead on the track, offset sideways by a slow
                // random fraction of the half width.
                let pr = track.project([pose.x, pose.y]);
                let lookahead = 0.15 + 0.12 * state.speed();
                let p = track.ahead(pr.segment, lookahead);
                let ahead_pr = track.project(p);
                let off = (0.5 * self.lateral_target).clamp(-0.4, 0.4) * ahead_pr.half_width;
                let (s, co) = ahead_pr.heading.sin_cos();
                let target = [p[0] - off * s, p[1] + off * co];
                let alpha = wrap_angle((target[1] - pose.y).atan2(target[0] - pose.x) - pose.theta);
                let ld = (target[0] - pose.x).hypot(target[1] - pose.y).max(1e-3);
                let pursuit = (2.0 * car.wheelbase() * alpha.sin() / ld).atan();
                let off_track =
                    ((pr.lateral.abs() - 0.5 * pr.half_width) / pr.half_width).clamp(0.0, 1.0);
                (pursuit + 0.3 * self.steer_ou, off_track)
            }
            None => {
                // Steer home when the point 0.4 s ahead is within the margin of an edge.
                let a = &self.scenario.arena;
                let (s, co) = pose.theta.sin_cos();
                let look = 0.4 * state.vx.max(0.0);
                let p = [pose.x + look * co, pose.y + look * s];
                let d_wall = (p[0] - a.min[0])
                    .min(a.max[0] - p[0])
                    .min(p[1] - a.min[1])
                    .min(a.max[1] - p[1]);
                let w = if c.boundary_margin > 0.0 {
                    ((c.boundary_margin - d_wall) / c.boundary_margin).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let centre = a.centre();
                let bearing = (centre[1] - pose.y).atan2(centre[0] - pose.x);
                let home = (2.0 * wrap_angle(bearing - pose.theta))
                    .clamp(-car.steering_max, car.steering_max);
                ((1.0 - w) * self.steer_ou + w * home, w)
            }
        };

        let mut throttle = c.throttle_mean + self.throttle_ou;
        if self.aggressive_left > 0.0 {
            self.aggressive_left -= dt;
            if homing > 0.3 {
                self.aggressive_left = 0.0;
            }
            throttle = c.aggressive_throttle;
            steering = if self.scenario.track_data.is_some() {
                // On a track: keep pursuing and add a smaller flick (power oversteer in a bend).
                steering + 0.3 * self.aggressive_sign * c.aggressive_steering
            } else {
                self.aggressive_sign * c.aggressive_steering + 0.3 * self.steer_ou
            };
        } else if start_aggressive && homing == 0.0 {
            self.aggressive_left = agg_len;
            self.aggressive_sign = agg_sign;
        }
        // Slow down while steering home; cut the throttle above the speed limit.
        throttle = throttle.min(c.throttle_mean + (1.0 - homing) * 1.0);
        if homing > 0.5 {
            throttle = throttle.min(0.22);
        }
        if state.speed() > c.max_speed {
            throttle = 0.0;
        }
        CarInput::new(
            steering.clamp(-car.steering_max, car.steering_max),
            throttle.clamp(car.throttle_min, car.throttle_max),
        )
    }
}
