//! When a controller's measurements stop: the staleness state machine of `racer` and
//! `mppi_pusher`, without DDS.
//!
//! A controller must not keep acting on a pose that no longer describes the robot. [`PoseWatch`]
//! tracks when the newest pose *arrived* and reports each change once:
//!
//! - [`PoseEvent::Stale`] when no pose has arrived for longer than the timeout (the controller
//!   holds its safe command and logs one warning),
//! - [`PoseEvent::Resumed`] when a pose arrives again (the controller restarts its state
//!   estimate and warm start from fresh data and logs one line),
//! - [`PoseEvent::Restarted`] when a pose is stamped earlier than the newest one without a gap:
//!   the pose source restarted its clock (a restarted simulator, a bag played in a loop), and
//!   anything built on the old stamps is void.
//!
//! **Which clock.** "No pose arrived" is measured on the node's own steady clock (the caller
//! passes `Instant`-based seconds), never on ROS time: with `use_sim_time` a stopped simulator
//! also stops `/clock`, so sim time would stand still and nothing would ever look old. Pose
//! *stamps* are only compared with each other (to see a clock restart). The times are inputs,
//! so the machine is deterministic and tested without a clock.

/// Why a [`PoseWatch`] could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StaleError {
    /// The timeout is not a positive finite number of seconds.
    #[error(
        "parameter stale_timeout: {0} s must be a positive number of seconds (e.g. 0.2 for a \
         100 Hz pose stream)"
    )]
    Timeout(f64),
}

/// A change of the pose stream, reported once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PoseEvent {
    /// No pose arrived for `silent` seconds (> the timeout): hold the safe command.
    Stale {
        /// Time since the newest pose arrived \[s, steady clock\].
        silent: f64,
    },
    /// Poses arrive again after being stale.
    Resumed {
        /// Time without a pose \[s, steady clock\].
        gap: f64,
        /// The new pose is stamped before the newest one seen before the gap (the source
        /// restarted its clock).
        restarted: bool,
    },
    /// Without a gap, a pose stamped before the newest one: the source restarted its clock.
    Restarted {
        /// The newest stamp before \[s\].
        from: f64,
        /// The new, earlier stamp \[s\].
        to: f64,
    },
}

/// The staleness state machine of one pose stream (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct PoseWatch {
    timeout: f64,
    /// Steady-clock time the newest pose arrived \[s\].
    received: Option<f64>,
    /// Newest stamp seen \[s\].
    stamp: Option<f64>,
    stale: bool,
}

impl PoseWatch {
    /// A watch that calls the stream stale after `timeout` seconds without a pose.
    pub fn new(timeout: f64) -> Result<Self, StaleError> {
        if !(timeout.is_finite() && timeout > 0.0) {
            return Err(StaleError::Timeout(timeout));
        }
        Ok(Self {
            timeout,
            received: None,
            stamp: None,
            stale: false,
        })
    }

    /// The timeout \[s\].
    pub fn timeout(&self) -> f64 {
        self.timeout
    }

    /// A pose stamped `stamp` \[s, any clock\] arrived at `now` \[s, steady clock\].
    pub fn on_pose(&mut self, now: f64, stamp: f64) -> Option<PoseEvent> {
        let back = self.stamp.is_some_and(|s| stamp < s);
        let event = if self.stale {
            Some(PoseEvent::Resumed {
                gap: self.received.map_or(0.0, |r| now - r),
                restarted: back,
            })
        } else if back {
            self.stamp
                .map(|from| PoseEvent::Restarted { from, to: stamp })
        } else {
            None
        };
        self.stale = false;
        self.received = Some(now);
        self.stamp = Some(if back {
            stamp
        } else {
            self.stamp.map_or(stamp, |s| s.max(stamp))
        });
        event
    }

    /// Checks the stream at `now` \[s, steady clock\]: [`PoseEvent::Stale`] once when the newest
    /// pose arrived longer than the timeout ago. Before the first pose nothing is stale (there
    /// is nothing to hold yet).
    pub fn check(&mut self, now: f64) -> Option<PoseEvent> {
        let silent = now - self.received?;
        if !self.stale && silent > self.timeout {
            self.stale = true;
            return Some(PoseEvent::Stale { silent });
        }
        None
    }

    /// Whether the stream is stale (since the last [`PoseWatch::check`] that said so).
    pub fn is_stale(&self) -> bool {
        self.stale
    }

    /// Whether the stream would be stale at `now` \[s, steady clock\] (no state change).
    pub fn stale_at(&self, now: f64) -> bool {
        self.stale || self.received.is_some_and(|r| now - r > self.timeout)
    }

    /// Whether any pose has arrived.
    pub fn has_pose(&self) -> bool {
        self.received.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn goes_stale_once_and_resumes_once() {
        let mut w = PoseWatch::new(0.2).unwrap();
        assert_eq!(
            w.check(100.0),
            None,
            "nothing is stale before the first pose"
        );
        assert!(!w.stale_at(100.0));
        for k in 0..10 {
            let t = 1.0 + 0.01 * k as f64;
            assert_eq!(w.on_pose(t, 5.0 + 0.01 * k as f64), None);
            assert_eq!(w.check(t + 0.005), None);
        }
        // newest pose arrived at 1.09
        assert_eq!(w.check(1.25), None, "0.16 s is within the timeout");
        assert!(!w.stale_at(1.25));
        assert!(w.stale_at(1.30));
        let e = w.check(1.30).expect("0.21 s without a pose is stale");
        match e {
            PoseEvent::Stale { silent } => assert!((silent - 0.21).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        assert!(w.is_stale());
        for k in 0..100 {
            assert_eq!(w.check(1.31 + k as f64), None, "stale is reported once");
        }
        let e = w.on_pose(3.09, 5.2).expect("resumption is reported");
        assert_eq!(
            e,
            PoseEvent::Resumed {
                gap: 3.09 - 1.09,
                restarted: false
            }
        );
        assert!(!w.is_stale());
        assert_eq!(w.on_pose(3.1, 5.21), None, "resumption is reported once");
        assert_eq!(w.check(3.2), None);
        assert!(matches!(w.check(3.4), Some(PoseEvent::Stale { .. })));
    }

    #[test]
    fn a_restarted_source_is_seen_by_its_stamps() {
        // a simulator killed and started again: the gap and then stamps from 0
        let mut w = PoseWatch::new(0.2).unwrap();
        w.on_pose(0.0, 41.0);
        assert!(matches!(w.check(1.0), Some(PoseEvent::Stale { .. })));
        assert_eq!(
            w.on_pose(4.0, 0.01),
            Some(PoseEvent::Resumed {
                gap: 4.0,
                restarted: true
            })
        );
        // the new stamps are the reference now: 0.02 is not "back"
        assert_eq!(w.on_pose(4.01, 0.02), None);
        // a bag played in a loop: back to its start without a gap
        assert_eq!(
            w.on_pose(4.02, 0.0),
            Some(PoseEvent::Restarted {
                from: 0.02,
                to: 0.0
            })
        );
        assert_eq!(w.on_pose(4.03, 0.01), None);
        // a repeated stamp is not a restart
        assert_eq!(w.on_pose(4.04, 0.01), None);
    }

    #[test]
    fn the_timeout_must_be_positive() {
        for t in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = PoseWatch::new(t).unwrap_err();
            assert!(e.to_string().contains("stale_timeout"), "{e}");
        }
        assert_eq!(PoseWatch::new(0.5).unwrap().timeout(), 0.5);
    }
}
