//! The node clock: system time, or simulation time from `/clock` when `use_sim_time` is true.
//!
//! Node code receives a [`Clock`] and asks it for the time; it never reads the system clock
//! itself, so the same code runs live, in simulation and from a bag being played.

use std::cell::Cell;
use std::time::{SystemTime, UNIX_EPOCH};

use dynlab_msgs::rosgraph_msgs::Clock as ClockMsg;

use crate::node::{NodeError, Subscription};

enum Source {
    System,
    Sim {
        sub: Box<Subscription<ClockMsg>>,
        latest: Cell<Option<i64>>,
    },
    Manual(Cell<i64>),
}

/// A time source for node code.
pub struct Clock {
    source: Source,
}

impl Clock {
    /// The system clock (ns since the Unix epoch).
    pub fn system() -> Clock {
        Clock {
            source: Source::System,
        }
    }

    /// Simulation time from a `/clock` subscription (see [`crate::Node::clock`]).
    pub fn sim(sub: Subscription<ClockMsg>) -> Clock {
        Clock {
            source: Source::Sim {
                sub: Box::new(sub),
                latest: Cell::new(None),
            },
        }
    }

    /// A clock that only moves when [`Clock::set`] is called (tests, offline replay).
    pub fn manual(start_ns: i64) -> Clock {
        Clock {
            source: Source::Manual(Cell::new(start_ns)),
        }
    }

    /// Whether this clock follows `/clock`.
    pub fn is_sim(&self) -> bool {
        matches!(self.source, Source::Sim { .. })
    }

    /// Sets a manual clock; no effect on the others.
    pub fn set(&self, ns: i64) {
        if let Source::Manual(t) = &self.source {
            t.set(ns);
        }
    }

    /// The current time in ns. A sim clock first reads any `/clock` messages waiting; before the
    /// first one arrives it reads 0, as ROS 2 does.
    pub fn now_ns(&self) -> Result<i64, NodeError> {
        match &self.source {
            Source::System => Ok(SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_nanos() as i64)
                .unwrap_or(0)),
            Source::Sim { sub, latest } => {
                while let Some(msg) = sub.take()? {
                    latest.set(Some(msg.clock.to_nanos()));
                }
                Ok(latest.get().unwrap_or(0))
            }
            Source::Manual(t) => Ok(t.get()),
        }
    }

    /// Whether the clock has a time: always, except a sim clock before its first `/clock`.
    pub fn is_valid(&self) -> Result<bool, NodeError> {
        match &self.source {
            Source::Sim { latest, .. } => {
                self.now_ns()?;
                Ok(latest.get().is_some())
            }
            _ => Ok(true),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_clock_is_an_input() {
        let c = Clock::manual(5);
        assert_eq!(c.now_ns().unwrap(), 5);
        c.set(1_000);
        assert_eq!(c.now_ns().unwrap(), 1_000);
        assert!(!c.is_sim());
        assert!(c.is_valid().unwrap());
    }

    #[test]
    fn system_clock_is_after_2020() {
        assert!(Clock::system().now_ns().unwrap() > 1_577_836_800_000_000_000);
    }
}
