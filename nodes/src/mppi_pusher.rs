//! The decision logic of `mppi_pusher`, without DDS: when to push, when to hold off, when the
//! goal is reached. Times are inputs (pose stamps and receipt times in seconds), so the logic is
//! testable and deterministic.
//!
//! - No goal yet, or no pose yet: hold.
//! - Pose stale (received longer than `stale_timeout` ago on the node's steady clock, see
//!   [`crate::stale`]): hold, no action. [`PusherLogic::check`] and [`PusherLogic::on_pose`]
//!   report going stale and coming back once each, for the node to log and to reset its MPPI
//!   warm start.
//! - Pose stamps going back (a restarted simulator, a looped bag): the push in flight is
//!   forgotten, so the wait below does not compare stamps of two different clocks.
//! - Pose within `goal_tolerance` (xy) and `angle_tolerance` of the goal: at goal, no action.
//! - A push was sent: wait until a pose stamped at least `push_wait` after the pose the push
//!   started from arrives (the simulator or robot has finished and settled the push).
//! - Otherwise: push (the caller runs MPPI on the latest pose).

use dynlab_control::mppi::goal_error;

use crate::stale::{PoseEvent, PoseWatch, StaleError};

/// Settings of the decision logic.
#[derive(Debug, Clone, PartialEq)]
pub struct PusherSettings {
    /// Goal reached when the xy distance is below this \[m\].
    pub goal_tolerance: f64,
    /// ... and the heading error below this \[rad\].
    pub angle_tolerance: f64,
    /// Hold off when the last pose was received longer ago than this \[s, steady clock\].
    pub stale_timeout: f64,
    /// After a push, wait for a pose stamped this long after the push's start pose \[s\].
    pub push_wait: f64,
}

impl Default for PusherSettings {
    fn default() -> Self {
        Self {
            goal_tolerance: 0.02,
            angle_tolerance: 0.1,
            stale_timeout: 1.0,
            push_wait: 1.8,
        }
    }
}

/// What to do now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// Nothing to do: no goal or no pose yet.
    Idle,
    /// The last pose is too old: no action until a fresh one arrives.
    Stale,
    /// A push is running: wait for its end.
    Waiting,
    /// The block is at the goal.
    AtGoal,
    /// Push now from this pose `[x, y, θ]`.
    Push([f64; 3]),
}

/// The state of the logic.
#[derive(Debug, Clone, PartialEq)]
pub struct PusherLogic {
    settings: PusherSettings,
    goal: Option<[f64; 3]>,
    /// Latest pose and its stamp \[s\].
    pose: Option<([f64; 3], f64)>,
    /// When the poses arrived.
    watch: PoseWatch,
    /// Stamp of the pose the last push started from.
    pushed_from: Option<f64>,
}

impl PusherLogic {
    /// New logic with `settings`; an error names a bad `stale_timeout`.
    pub fn new(settings: PusherSettings) -> Result<Self, StaleError> {
        Ok(Self {
            watch: PoseWatch::new(settings.stale_timeout)?,
            settings,
            goal: None,
            pose: None,
            pushed_from: None,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &PusherSettings {
        &self.settings
    }

    /// The settings, to change; the node changes them when `ros2 param set` changes `goal_tolerance` or
    /// `angle_tolerance` (the next decision uses them).
    pub fn settings_mut(&mut self) -> &mut PusherSettings {
        &mut self.settings
    }

    /// A new goal.
    pub fn on_goal(&mut self, goal: [f64; 3]) {
        self.goal = Some(goal);
    }

    /// The current goal.
    pub fn goal(&self) -> Option<[f64; 3]> {
        self.goal
    }

    /// A pose measurement, stamped `stamp` \[s\], received at `received` \[s, steady clock\].
    /// Non-finite poses are ignored (they are not fresh either). Returns the stream's change,
    /// once: [`PoseEvent::Resumed`] after a stale spell, [`PoseEvent::Restarted`] when the
    /// stamps went back without one.
    pub fn on_pose(&mut self, pose: [f64; 3], stamp: f64, received: f64) -> Option<PoseEvent> {
        if !pose.iter().all(|v| v.is_finite()) {
            return None;
        }
        let event = self.watch.on_pose(received, stamp);
        if let Some(
            PoseEvent::Resumed {
                restarted: true, ..
            }
            | PoseEvent::Restarted { .. },
        ) = event
        {
            self.pushed_from = None;
        }
        self.pose = Some((pose, stamp));
        event
    }

    /// Checks the pose stream at `now` \[s, steady clock\]: [`PoseEvent::Stale`] once when the
    /// newest pose arrived longer than `stale_timeout` ago.
    pub fn check(&mut self, now: f64) -> Option<PoseEvent> {
        self.watch.check(now)
    }

    /// Decides at time `now` \[s\] (the steady clock of the receipt times).
    pub fn decide(&self, now: f64) -> Decision {
        let (Some(goal), Some((pose, stamp))) = (self.goal, self.pose) else {
            return Decision::Idle;
        };
        if self.watch.stale_at(now) {
            return Decision::Stale;
        }
        if let Some(from) = self.pushed_from
            && stamp < from + self.settings.push_wait
        {
            return Decision::Waiting;
        }
        let e = goal_error(pose, goal);
        if e[0].hypot(e[1]) < self.settings.goal_tolerance
            && e[2].abs() < self.settings.angle_tolerance
        {
            return Decision::AtGoal;
        }
        Decision::Push(pose)
    }

    /// Stamp of the latest pose \[s\].
    pub fn pose_stamp(&self) -> Option<f64> {
        self.pose.map(|p| p.1)
    }

    /// Records that a push was sent from the latest pose.
    pub fn pushed(&mut self) {
        self.pushed_from = self.pose.map(|p| p.1);
    }
}

/// Reads a goal `"x,y,θ"` (m, m, rad), as the `goal` parameter gives it.
pub fn parse_goal(text: &str) -> Result<[f64; 3], String> {
    let v: Result<Vec<f64>, _> = text.split(',').map(|s| s.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => Ok([v[0], v[1], v[2]]),
        _ => Err(format!(
            "`{text}` is not a goal: give three comma-separated finite numbers \"x,y,θ\" (m, m, rad), e.g. \"0.6,0.05,0\""
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pushes_waits_for_the_push_and_stops_at_the_goal() {
        let mut l = PusherLogic::new(PusherSettings::default()).unwrap();
        assert_eq!(l.decide(0.0), Decision::Idle);
        l.on_pose([0.4, 0.0, 0.0], 0.0, 0.0);
        assert_eq!(l.decide(0.0), Decision::Idle, "no goal yet");
        l.on_goal([0.8, 0.0, 0.0]);
        assert_eq!(l.decide(0.1), Decision::Push([0.4, 0.0, 0.0]));
        l.pushed();
        l.on_pose([0.45, 0.0, 0.0], 1.0, 1.0);
        assert_eq!(l.decide(1.0), Decision::Waiting, "push still running");
        l.on_pose([0.5, 0.0, 0.0], 1.9, 1.9);
        assert_eq!(l.decide(1.9), Decision::Push([0.5, 0.0, 0.0]));
        l.pushed();
        l.on_pose([0.79, 0.005, 0.05], 4.0, 4.0);
        assert_eq!(l.decide(4.0), Decision::AtGoal);
        // a new goal resumes pushing
        l.on_goal([0.6, 0.0, 0.0]);
        assert!(matches!(l.decide(4.0), Decision::Push(_)));
    }

    #[test]
    fn holds_off_while_the_pose_is_stale() {
        let mut l = PusherLogic::new(PusherSettings {
            stale_timeout: 0.5,
            ..PusherSettings::default()
        })
        .unwrap();
        l.on_goal([0.8, 0.0, 0.0]);
        l.on_pose([0.4, 0.0, 0.0], 10.0, 10.0);
        assert!(matches!(l.decide(10.4), Decision::Push(_)));
        assert_eq!(l.decide(10.6), Decision::Stale);
        l.on_pose([f64::NAN, 0.0, 0.0], 11.0, 11.0);
        assert_eq!(l.decide(11.0), Decision::Stale, "a NaN pose is not fresh");
        l.on_pose([0.4, 0.0, 0.0], 11.0, 11.0);
        assert!(matches!(l.decide(11.0), Decision::Push(_)));
    }

    #[test]
    fn says_stale_once_and_resumes_after_a_simulator_restart() {
        // regression: after `sim_node` was restarted its stamps began again at 0, and the
        // pusher waited for a pose stamped `push_wait` after the last push of the old run
        let mut l = PusherLogic::new(PusherSettings {
            stale_timeout: 0.5,
            ..PusherSettings::default()
        })
        .unwrap();
        l.on_goal([0.8, 0.0, 0.0]);
        assert_eq!(l.on_pose([0.4, 0.0, 0.0], 40.0, 10.0), None);
        assert!(matches!(l.decide(10.0), Decision::Push(_)));
        l.pushed();
        assert_eq!(l.check(10.4), None);
        assert!(matches!(l.check(10.6), Some(PoseEvent::Stale { .. })));
        assert_eq!(l.check(11.0), None, "stale is said once");
        assert_eq!(l.decide(11.0), Decision::Stale);
        // the simulator comes back with its clock from 0 and the block at its start
        let e = l.on_pose([0.4, 0.0, 0.0], 0.01, 14.0);
        assert_eq!(
            e,
            Some(PoseEvent::Resumed {
                gap: 4.0,
                restarted: true
            })
        );
        assert!(
            matches!(l.decide(14.0), Decision::Push(_)),
            "the push of the old run is not waited for: {:?}",
            l.decide(14.0)
        );
        // the same clock after a dropout: the push in flight is still waited for
        l.pushed();
        assert!(matches!(l.check(15.0), Some(PoseEvent::Stale { .. })));
        let e = l.on_pose([0.42, 0.0, 0.0], 1.0, 16.0);
        assert!(matches!(
            e,
            Some(PoseEvent::Resumed {
                restarted: false,
                ..
            })
        ));
        assert_eq!(l.decide(16.0), Decision::Waiting);
        l.on_pose([0.45, 0.0, 0.0], 1.9, 16.1);
        assert!(matches!(l.decide(16.1), Decision::Push(_)));
    }

    #[test]
    fn goals_are_three_finite_numbers() {
        assert_eq!(parse_goal("0.6, 0.05,0").unwrap(), [0.6, 0.05, 0.0]);
        for bad in [
            "",
            "0.6,0.05",
            "0.6,0.05,0,1",
            "a,b,c",
            "0.6,NaN,0",
            "0.6,inf,0",
        ] {
            let err = parse_goal(bad).unwrap_err();
            assert!(err.contains("x,y,θ"), "{bad}: {err}");
        }
    }

    #[test]
    fn changed_tolerances_apply_to_the_next_decision() {
        let mut l = PusherLogic::new(PusherSettings::default()).unwrap();
        l.on_goal([0.8, 0.0, 0.0]);
        l.on_pose([0.75, 0.0, 0.0], 0.0, 0.0);
        assert!(matches!(l.decide(0.0), Decision::Push(_)));
        l.settings_mut().goal_tolerance = 0.1;
        assert_eq!(l.decide(0.0), Decision::AtGoal);
    }

    #[test]
    fn the_goal_check_wraps_the_angle() {
        let mut l = PusherLogic::new(PusherSettings::default()).unwrap();
        l.on_goal([0.8, 0.0, std::f64::consts::PI - 0.02]);
        l.on_pose([0.8, 0.0, -std::f64::consts::PI + 0.02], 0.0, 0.0);
        assert_eq!(l.decide(0.0), Decision::AtGoal);
    }
}
