//! The model run live against a stream of measurements: what the `model_server` node computes,
//! without DDS, so the same numbers can be reproduced offline (`dynlab compare --online FILE`).
//!
//! [`OnlinePredictor`] takes poses and commands as they arrive. At each pose (with a command
//! held, zero-order, from the latest command at or before the pose stamp) it estimates the model
//! state causally — the car's body velocities by the same Savitzky–Golay fit as the offline
//! pipeline, over the last `window` poses (the yaw: `yaw_window`) and evaluated at the newest
//! one — and predicts:
//!
//! - the state one model step ahead, stamped at `t + dt` (`/model/prediction`);
//! - the k-step path with the command held (`/model/predicted_path`);
//! - when a pose arrives at the stamp of an earlier prediction (within half a step), the error
//!   `measured − predicted` per state dimension, angle wrapped (`/model/error`).
//!
//! **Effect states.** A model with stateful effects (`motor_lag`'s filtered throttle `d_f`,
//! `steering_lag`'s wheel angle `δ_w`) needs them, and nothing measures them: the predictor keeps
//! them from the command stream it receives, exactly as the offline pipeline rebuilds them from a
//! bag ([`Model::extra_states_along`]): settled at the command held at the first pose that has
//! one, then advanced one model step per pose under the command held at the pose before. The
//! rollouts start from them ([`Prediction::extra`]).
//!
//! Stale input (a pose not newer than the last one, a command older than `max_command_age_s`),
//! NaN and infinite values are skipped with a warning; a gap longer than `max_gap_steps` model
//! steps restarts the state estimate (and the effect states). Nothing here panics on input.

use std::collections::VecDeque;

use dynlab_learn::dynamics::conventions::{unwrap_angles, wrap_angle};
use dynlab_learn::dynamics::data::{SavGol, Trajectory, car_states};
use dynlab_learn::{LearnError, Model, World};
use serde::{Deserialize, Serialize};

/// Settings of [`OnlinePredictor`]. Every field has a documented default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OnlineConfig {
    /// Steps of the predicted path (default 10).
    pub steps: usize,
    /// Savitzky–Golay settings of the car's velocity estimate (default: the offline pipeline's
    /// default; for a trained model, the fit its data had: [`dynlab_learn::ModelFile::state_fit`]).
    pub savgol: SavGol,
    /// A command older than this at a pose stamp is stale: no prediction \[s\] (default 0.5).
    pub max_command_age_s: f64,
    /// A pose interval longer than this many model steps restarts the estimate (default 5).
    pub max_gap_steps: f64,
}

impl Default for OnlineConfig {
    fn default() -> Self {
        Self {
            steps: 10,
            savgol: SavGol::default(),
            max_command_age_s: 0.5,
            max_gap_steps: 5.0,
        }
    }
}

/// A prediction made at one pose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    /// Stamp of the pose it was made from \[ns\].
    pub from_ns: i64,
    /// The estimated state at that pose (the model's input).
    pub state: Vec<f64>,
    /// The command held.
    pub command: Vec<f64>,
    /// Stamp of the one-step prediction: `from_ns + dt` \[ns\].
    pub t_ns: i64,
    /// The model's effect states at that pose, kept from the command stream (empty for models
    /// without them; names: [`Model::extra_state_names`]).
    #[serde(default)]
    pub extra: Vec<f64>,
    /// The predicted state one step ahead.
    pub next: Vec<f64>,
    /// The k-step path: states after 1…k steps (the first is `next`), at `from_ns + j·dt`.
    pub path: Vec<Vec<f64>>,
}

/// The error of an earlier one-step prediction, when its pose arrives.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PredictionError {
    /// Stamp of the measurement \[ns\].
    pub t_ns: i64,
    /// `measured − predicted` per state dimension (angle wrapped).
    pub error: Vec<f64>,
}

/// What one pose produced.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseOutcome {
    /// The new prediction (none while warming up or when skipped).
    pub prediction: Option<Prediction>,
    /// The error of the prediction made for this stamp, if any.
    pub error: Option<PredictionError>,
    /// Why the pose was skipped or gave no prediction, for a warning.
    pub warning: Option<String>,
}

/// The live predictor (see the module docs).
#[derive(Clone, Debug)]
pub struct OnlinePredictor {
    model: Model,
    cfg: OnlineConfig,
    poses: VecDeque<(i64, [f64; 3])>,
    commands: VecDeque<(i64, Vec<f64>)>,
    pending: VecDeque<(i64, Vec<f64>)>,
    dt_ns: i64,
    /// Effect states at the newest pose and the command held there (advanced at the next pose).
    extra: Option<(Vec<f64>, Vec<f64>)>,
}

impl OnlinePredictor {
    /// A predictor for `model`.
    pub fn new(model: Model, cfg: OnlineConfig) -> Result<Self, LearnError> {
        cfg.savgol.validate()?;
        if cfg.steps == 0 {
            return Err(LearnError::InvalidSetting {
                name: "steps",
                value: "0".into(),
                hint: "predict at least 1 step".into(),
            });
        }
        if !(cfg.max_command_age_s > 0.0 && cfg.max_gap_steps > 0.0) {
            return Err(LearnError::InvalidSetting {
                name: "max_command_age_s / max_gap_steps",
                value: format!("{} / {}", cfg.max_command_age_s, cfg.max_gap_steps),
                hint: "both must be positive".into(),
            });
        }
        let dt_ns = (model.dt() * 1e9).round() as i64;
        Ok(Self {
            model,
            cfg,
            poses: VecDeque::new(),
            commands: VecDeque::new(),
            pending: VecDeque::new(),
            dt_ns: dt_ns.max(1),
            extra: None,
        })
    }

    /// The model's effect states at the newest pose (empty for models without them; `None`
    /// before the first pose with a command).
    pub fn extra_states(&self) -> Option<&[f64]> {
        self.extra.as_ref().map(|(e, _)| e.as_slice())
    }

    /// Advances the effect states to a new pose: one model step under the command held at the
    /// previous pose, or settled at the command held now when there is no earlier one (the
    /// recursion of [`Model::extra_states_along`]).
    fn track_extra(&mut self, t_ns: i64) {
        let now = self.command_at(t_ns).map(|(_, u)| u.clone());
        self.extra = match (self.extra.take(), now) {
            (Some((mut e, held)), Some(u)) => {
                self.model.advance_extra(&mut e, &held);
                Some((e, u))
            }
            (None, Some(u)) => Some((self.model.settled_extra(&u), u)),
            (prev, None) => prev,
        };
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The model step \[ns\].
    pub fn dt_ns(&self) -> i64 {
        self.dt_ns
    }

    /// Takes a command; returns a warning when it is skipped.
    pub fn on_command(&mut self, t_ns: i64, u: Vec<f64>) -> Option<String> {
        let du = self.model.dim_u();
        if u.len() != du {
            return Some(format!(
                "command at {t_ns} ns has {} values, the {} model takes {du}; skipped",
                u.len(),
                self.model.world()
            ));
        }
        if let Some(v) = u.iter().find(|v| !v.is_finite()) {
            return Some(format!("command at {t_ns} ns holds {v}; skipped"));
        }
        if let Some((last, _)) = self.commands.back()
            && t_ns < *last
        {
            return Some(format!(
                "command at {t_ns} ns is older than the last one ({last} ns); skipped"
            ));
        }
        self.commands.push_back((t_ns, u));
        while self.commands.len() > 256 {
            self.commands.pop_front();
        }
        None
    }

    fn command_at(&self, t_ns: i64) -> Option<&(i64, Vec<f64>)> {
        self.commands.iter().rev().find(|(t, _)| *t <= t_ns)
    }

    /// The current state estimate from the buffered poses (newest last).
    fn state(&self) -> Result<Option<Vec<f64>>, String> {
        match self.model.world() {
            World::Push => Ok(self.poses.back().map(|(_, p)| p.to_vec())),
            World::Car => {
                if self.poses.len() < self.cfg.savgol.span() {
                    return Ok(None);
                }
                let mut pose: Vec<[f64; 3]> = self.poses.iter().map(|(_, p)| *p).collect();
                let mut yaw: Vec<f64> = pose.iter().map(|p| p[2]).collect();
                unwrap_angles(&mut yaw);
                for (p, y) in pose.iter_mut().zip(yaw) {
                    p[2] = y;
                }
                let traj = Trajectory {
                    t_ns: self.poses.iter().map(|(t, _)| *t).collect(),
                    pose,
                    u: Vec::new(),
                    dim_u: 0,
                    dt: self.model.dt(),
                    resampled: false,
                };
                let s = car_states(&traj, &self.cfg.savgol).map_err(|e| e.to_string())?;
                Ok(s.last().map(|s| {
                    let mut v = s.to_vec();
                    v[2] = wrap_angle(v[2]);
                    v
                }))
            }
        }
    }

    /// Takes a measured pose; predicts and/or reports the error of an earlier prediction.
    pub fn on_pose(&mut self, t_ns: i64, x: f64, y: f64, yaw: f64) -> PoseOutcome {
        let mut out = PoseOutcome::default();
        if !(x.is_finite() && y.is_finite() && yaw.is_finite()) {
            out.warning = Some(format!(
                "pose at {t_ns} ns holds a non-finite value ({x}, {y}, {yaw}); skipped"
            ));
            return out;
        }
        if let Some((last, _)) = self.poses.back() {
            if t_ns <= *last {
                out.warning = Some(format!(
                    "pose at {t_ns} ns is not newer than the last one ({last} ns); skipped as stale"
                ));
                return out;
            }
            let gap = (t_ns - *last) as f64 / self.dt_ns as f64;
            if gap > self.cfg.max_gap_steps {
                out.warning = Some(format!(
                    "{:.3} s without poses before {t_ns} ns; state estimate restarted",
                    (t_ns - *last) as f64 * 1e-9
                ));
                self.poses.clear();
                self.pending.clear();
                self.extra = None;
            }
        }
        self.poses.push_back((t_ns, [x, y, yaw]));
        self.track_extra(t_ns);
        let keep = match self.model.world() {
            World::Car => self.cfg.savgol.span(),
            World::Push => 1,
        };
        while self.poses.len() > keep {
            self.poses.pop_front();
        }
        let state = match self.state() {
            Ok(s) => s,
            Err(e) => {
                out.warning = Some(format!("state estimate at {t_ns} ns failed: {e}; skipped"));
                return out;
            }
        };
        let Some(state) = state else {
            return out; // warming up
        };
        // the error of the prediction made for (about) this stamp
        let half = self.dt_ns / 2;
        while let Some((tp, _)) = self.pending.front() {
            if *tp < t_ns - half {
                self.pending.pop_front();
            } else {
                break;
            }
        }
        if let Some((tp, pred)) = self.pending.front()
            && (*tp - t_ns).abs() <= half
        {
            let angle = self.model.world().angle_dim();
            out.error = Some(PredictionError {
                t_ns,
                error: state
                    .iter()
                    .zip(pred)
                    .enumerate()
                    .map(
                        |(d, (m, p))| {
                            if d == angle { wrap_angle(m - p) } else { m - p }
                        },
                    )
                    .collect(),
            });
            self.pending.pop_front();
        }
        let Some((tc, u)) = self.command_at(t_ns).cloned() else {
            out.warning = Some(format!(
                "no command at or before {t_ns} ns yet; no prediction"
            ));
            return out;
        };
        if (t_ns - tc) as f64 * 1e-9 > self.cfg.max_command_age_s {
            out.warning = Some(format!(
                "the latest command is {:.3} s old at {t_ns} ns (stale); no prediction",
                (t_ns - tc) as f64 * 1e-9
            ));
            return out;
        }
        let k = self.cfg.steps;
        let ds = self.model.dim_s();
        let actions: Vec<f64> = (0..k).flat_map(|_| u.iter().copied()).collect();
        let mut path = vec![0.0; k * ds];
        let extra = match &self.extra {
            Some((e, _)) => e.clone(),
            None => self.model.settled_extra(&u),
        };
        match self
            .model
            .rollout_with_extra(&state, &extra, &actions, &mut path, None)
        {
            Ok(_) if path.iter().all(|v| v.is_finite()) => {}
            Ok(_) => {
                out.warning = Some(format!("the model diverged from the state at {t_ns} ns"));
                return out;
            }
            Err(e) => {
                out.warning = Some(format!("prediction at {t_ns} ns failed: {e}"));
                return out;
            }
        }
        let path: Vec<Vec<f64>> = path.chunks_exact(ds).map(<[f64]>::to_vec).collect();
        let t_next = t_ns + self.dt_ns;
        self.pending.push_back((t_next, path[0].clone()));
        out.prediction = Some(Prediction {
            from_ns: t_ns,
            state,
            command: u,
            extra,
            t_ns: t_next,
            next: path[0].clone(),
            path,
        });
        out
    }
}

/// Replays time-ordered poses and commands through an [`OnlinePredictor`] as they would arrive
/// live (a command and a pose with the same stamp: the command first) and returns every pose's
/// outcome with its stamp.
pub fn replay(
    predictor: &mut OnlinePredictor,
    poses: &[dynlab_learn::dynamics::data::PoseSample],
    commands: &[dynlab_learn::dynamics::data::CommandSample],
) -> Vec<(i64, PoseOutcome)> {
    let mut out = Vec::with_capacity(poses.len());
    let mut ci = 0;
    for p in poses {
        while ci < commands.len() && commands[ci].t_ns <= p.t_ns {
            predictor.on_command(commands[ci].t_ns, commands[ci].u.clone());
            ci += 1;
        }
        out.push((p.t_ns, predictor.on_pose(p.t_ns, p.x, p.y, p.yaw)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynlab_learn::ModelKind;
    use dynlab_learn::train::{default_physics_solver, physics_model};

    fn car() -> Model {
        Model::new(
            ModelKind::Physics,
            World::Car,
            0.01,
            None,
            None,
            Some(physics_model(World::Car, &[]).unwrap()),
            default_physics_solver(World::Car),
        )
        .unwrap()
    }

    #[test]
    fn predicts_after_warm_up_and_scores_the_earlier_prediction() {
        let mut p = OnlinePredictor::new(car(), OnlineConfig::default()).unwrap();
        assert!(p.on_command(0, vec![0.0, 0.3]).is_none());
        let mut predictions = 0;
        let mut errors = 0;
        for i in 0..40i64 {
            // straight line at 1 m/s along x
            let o = p.on_pose(i * 10_000_000, 0.01 * i as f64, 0.0, 0.0);
            assert!(o.warning.is_none(), "{:?}", o.warning);
            if i < 14 {
                assert!(o.prediction.is_none(), "warming up at {i}");
            } else {
                let pr = o.prediction.unwrap();
                assert_eq!(pr.t_ns, i * 10_000_000 + 10_000_000);
                assert_eq!(pr.path.len(), 10);
                assert!((pr.state[3] - 1.0).abs() < 1e-6, "vx {}", pr.state[3]);
                predictions += 1;
            }
            if let Some(e) = o.error {
                assert_eq!(e.error.len(), 6);
                assert_eq!(e.t_ns, i * 10_000_000);
                errors += 1;
            }
        }
        assert_eq!(predictions, 26);
        assert_eq!(errors, 25);
    }

    #[test]
    fn a_wider_fit_warms_up_over_its_span_and_gives_the_offline_state() {
        let savgol = SavGol {
            window: 21,
            yaw_window: Some(11),
            ..SavGol::default()
        };
        let cfg = OnlineConfig {
            savgol,
            ..OnlineConfig::default()
        };
        let mut p = OnlinePredictor::new(car(), cfg).unwrap();
        p.on_command(0, vec![0.1, 0.3]);
        let pose = |i: i64| {
            let t = i as f64 * 0.01;
            [t.cos(), 0.5 * t.sin() + 0.1 * t * t, 0.3 + 0.8 * t]
        };
        let mut poses = Vec::new();
        for i in 0..50i64 {
            poses.push(pose(i));
            let [x, y, yaw] = pose(i);
            let o = p.on_pose(i * 10_000_000, x, y, yaw);
            if poses.len() < 21 {
                assert!(
                    o.prediction.is_none(),
                    "a prediction from {} poses",
                    poses.len()
                );
                continue;
            }
            let traj = Trajectory {
                t_ns: (0..21).map(|k| k * 10_000_000).collect(),
                pose: poses[poses.len() - 21..].to_vec(),
                u: Vec::new(),
                dim_u: 0,
                dt: 0.01,
                resampled: false,
            };
            let want = *car_states(&traj, &savgol).unwrap().last().unwrap();
            let got = o
                .prediction
                .expect("a prediction once 21 poses are in")
                .state;
            for c in 0..6 {
                assert!(
                    (got[c] - want[c]).abs() < 1e-7,
                    "state {c}: {got:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn stale_nan_and_gaps_warn_and_never_panic() {
        let mut p = OnlinePredictor::new(car(), OnlineConfig::default()).unwrap();
        assert!(p.on_command(0, vec![f64::NAN, 0.0]).is_some());
        assert!(p.on_command(0, vec![0.0]).is_some());
        let o = p.on_pose(0, f64::NAN, 0.0, 0.0);
        assert!(o.warning.unwrap().contains("non-finite"));
        p.on_pose(10, 0.0, 0.0, 0.0);
        let o = p.on_pose(5, 0.0, 0.0, 0.0);
        assert!(o.warning.unwrap().contains("stale"));
        let o = p.on_pose(1_000_000_000, 0.0, 0.0, 0.0);
        assert!(o.warning.unwrap().contains("restarted"));
        // a stale command: poses far after the only command
        p.on_command(1_000_000_000, vec![0.0, 0.1]);
        let mut last = PoseOutcome::default();
        for i in 1..30i64 {
            last = p.on_pose(2_000_000_000 + i * 10_000_000, 0.01 * i as f64, 0.0, 0.0);
        }
        assert!(last.warning.unwrap().contains("stale"));
        assert!(last.prediction.is_none());
    }
}
