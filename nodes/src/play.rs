//! Playback logic of the `player` node, without DDS: which topics to play, when each message is
//! due, and when `/clock` ticks. The binary supplies a [`PlaySink`] that publishes and a
//! [`Timer`] that sleeps; tests supply recording fakes.
//!
//! Timing: messages are due in wall time at `pass_start + (log_time − bag_start) / rate`, in the
//! order the bag yields them (log-time order for bags written by rosbag2 and by us); a message
//! already late is published at once, so a slow consumer delays but never reorders. `/clock`
//! carries bag time `bag_start + (now − pass_start) · rate` at `clock_hz` in wall time, and once
//! more with each message's own log time just before it is published, so a sim-time node never
//! sees a message from its future. With `--loop` each pass starts when the previous one ends.

use std::collections::BTreeSet;

/// Player settings.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayOptions {
    /// Playback speed factor (1.0 = recorded speed). Must be positive and finite.
    pub rate: f64,
    /// Replay from the start when the end is reached, until shutdown.
    pub loop_playback: bool,
    /// `/clock` publication rate in wall-clock Hz; `None` publishes no `/clock`.
    pub clock_hz: Option<f64>,
    /// Only these bag topics (all when empty).
    pub topics: Vec<String>,
}

impl Default for PlayOptions {
    fn default() -> Self {
        PlayOptions {
            rate: 1.0,
            loop_playback: false,
            clock_hz: Some(100.0),
            topics: Vec::new(),
        }
    }
}

/// Errors of playback logic.
#[derive(Debug, thiserror::Error)]
pub enum PlayError {
    /// `--rate` not positive and finite.
    #[error("--rate {0} must be a positive number (1.0 plays at recorded speed)")]
    BadRate(f64),
    /// `--clock-rate` negative or not finite.
    #[error("--clock-rate {0} must be a positive number of Hz (0 turns /clock off)")]
    BadClockRate(f64),
    /// `--topics` names topics the bag does not have.
    #[error("topics {missing:?} are not in the bag; it has {available:?}")]
    UnknownTopics {
        /// Requested but absent.
        missing: Vec<String>,
        /// What the bag holds.
        available: Vec<String>,
    },
    /// Publishing failed.
    #[error("{0}")]
    Sink(String),
    /// Reading the bag failed.
    #[error("reading the bag: {0}")]
    Source(String),
}

impl PlayOptions {
    /// Checks rate and clock rate.
    pub fn validate(&self) -> Result<(), PlayError> {
        if !(self.rate.is_finite() && self.rate > 0.0) {
            return Err(PlayError::BadRate(self.rate));
        }
        if let Some(hz) = self.clock_hz
            && !(hz.is_finite() && hz > 0.0)
        {
            return Err(PlayError::BadClockRate(hz));
        }
        Ok(())
    }

    /// The bag topics to play, in the bag's order; an error names requested topics it lacks.
    pub fn select_topics<'a>(
        &self,
        bag_topics: &'a [String],
    ) -> Result<Vec<&'a String>, PlayError> {
        if self.topics.is_empty() {
            return Ok(bag_topics.iter().collect());
        }
        let wanted: BTreeSet<&str> = self.topics.iter().map(String::as_str).collect();
        let missing: Vec<String> = wanted
            .iter()
            .filter(|t| !bag_topics.iter().any(|b| b == *t))
            .map(|t| t.to_string())
            .collect();
        if !missing.is_empty() {
            return Err(PlayError::UnknownTopics {
                missing,
                available: bag_topics.to_vec(),
            });
        }
        Ok(bag_topics
            .iter()
            .filter(|t| wanted.contains(t.as_str()))
            .collect())
    }
}

/// Maps bag time to wall time for one pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaySchedule {
    /// Bag time at which the pass starts (the bag's first log time).
    pub bag_start_ns: i64,
    /// Wall time at which the pass started.
    pub wall_start_ns: i64,
    /// Speed factor.
    pub rate: f64,
}

impl PlaySchedule {
    /// Wall time at which a message logged at `log_time_ns` is due.
    pub fn due_wall_ns(&self, log_time_ns: i64) -> i64 {
        let offset = (log_time_ns - self.bag_start_ns).max(0) as f64 / self.rate;
        self.wall_start_ns + offset.round() as i64
    }

    /// Bag time at wall time `wall_ns`.
    pub fn bag_time_ns(&self, wall_ns: i64) -> i64 {
        let offset = (wall_ns - self.wall_start_ns).max(0) as f64 * self.rate;
        self.bag_start_ns + offset.round() as i64
    }
}

/// Wall time for playback (nanoseconds on any monotonic scale).
pub trait Timer {
    /// The current time.
    fn now_ns(&mut self) -> i64;
    /// Sleeps until `deadline_ns` or a bit before (returning early is fine: the player re-checks).
    fn sleep_until(&mut self, deadline_ns: i64);
}

/// Where playback goes.
pub trait PlaySink {
    /// Publishes message `data` on the topic at `topic_index` of the selected topics.
    fn publish(&mut self, topic_index: usize, data: &[u8]) -> Result<(), String>;
    /// Publishes `/clock` with bag time `bag_time_ns`.
    fn clock(&mut self, bag_time_ns: i64) -> Result<(), String>;
}

/// One message to play: index into the selected topics, log time, serialized bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayMessage {
    /// Index into the selected topics.
    pub topic_index: usize,
    /// Log (receive) time in the bag.
    pub log_time_ns: i64,
    /// Serialized message.
    pub data: Vec<u8>,
}

/// How a pass ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PassEnd {
    /// Every message was published.
    Completed {
        /// Messages published in this pass.
        published: u64,
    },
    /// Shutdown was requested mid-pass.
    Interrupted {
        /// Messages published before it.
        published: u64,
    },
}

/// Longest single sleep, so a shutdown request is seen within this much wall time.
pub const MAX_SLEEP_NS: i64 = 50_000_000;

/// Plays one pass of `messages` (sorted by log time) starting now; `stop` is polled between
/// sleeps.
pub fn play_pass<I, S, T>(
    options: &PlayOptions,
    bag_start_ns: i64,
    messages: I,
    sink: &mut S,
    timer: &mut T,
    stop: &dyn Fn() -> bool,
) -> Result<PassEnd, PlayError>
where
    I: IntoIterator<Item = Result<PlayMessage, String>>,
    S: PlaySink,
    T: Timer,
{
    options.validate()?;
    let schedule = PlaySchedule {
        bag_start_ns,
        wall_start_ns: timer.now_ns(),
        rate: options.rate,
    };
    let clock_period_ns = options
        .clock_hz
        .map(|hz| (1e9 / hz).round().max(1.0) as i64);
    let mut next_clock_ns = schedule.wall_start_ns;
    let mut published = 0u64;
    for item in messages {
        let msg = item.map_err(PlayError::Source)?;
        let due = schedule.due_wall_ns(msg.log_time_ns);
        loop {
            if stop() {
                return Ok(PassEnd::Interrupted { published });
            }
            let now = timer.now_ns();
            if let Some(period) = clock_period_ns
                && now >= next_clock_ns
            {
                sink.clock(schedule.bag_time_ns(now).min(msg.log_time_ns))
                    .map_err(PlayError::Sink)?;
                // Skip ticks missed while blocked rather than bursting them.
                next_clock_ns += ((now - next_clock_ns) / period + 1) * period;
            }
            if now >= due {
                break;
            }
            let wake = match clock_period_ns {
                Some(_) => due.min(next_clock_ns),
                None => due,
            };
            timer.sleep_until(wake.min(now + MAX_SLEEP_NS));
        }
        if clock_period_ns.is_some() {
            sink.clock(msg.log_time_ns).map_err(PlayError::Sink)?;
        }
        sink.publish(msg.topic_index, &msg.data)
            .map_err(PlayError::Sink)?;
        published += 1;
    }
    Ok(PassEnd::Completed { published })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    /// A timer that jumps to each deadline, recording nothing but time.
    struct FakeTimer {
        now: i64,
    }

    impl Timer for FakeTimer {
        fn now_ns(&mut self) -> i64 {
            self.now
        }
        fn sleep_until(&mut self, deadline_ns: i64) {
            self.now = self.now.max(deadline_ns);
        }
    }

    #[derive(Default)]
    struct Log {
        published: Vec<(i64, usize, Vec<u8>)>,
        clocks: Vec<(i64, i64)>,
        now: i64,
    }

    struct Sink<'a> {
        log: &'a mut Log,
        timer_now: &'a Cell<i64>,
    }

    impl PlaySink for Sink<'_> {
        fn publish(&mut self, i: usize, data: &[u8]) -> Result<(), String> {
            self.log
                .published
                .push((self.timer_now.get(), i, data.to_vec()));
            Ok(())
        }
        fn clock(&mut self, t: i64) -> Result<(), String> {
            self.log.clocks.push((self.timer_now.get(), t));
            Ok(())
        }
    }

    /// Timer sharing its time with the sink so the sink can stamp publications.
    struct SharedTimer<'a> {
        now: &'a Cell<i64>,
    }

    impl Timer for SharedTimer<'_> {
        fn now_ns(&mut self) -> i64 {
            self.now.get()
        }
        fn sleep_until(&mut self, d: i64) {
            self.now.set(self.now.get().max(d));
        }
    }

    fn msgs(times: &[i64]) -> Vec<Result<PlayMessage, String>> {
        times
            .iter()
            .enumerate()
            .map(|(k, &t)| {
                Ok(PlayMessage {
                    topic_index: k % 2,
                    log_time_ns: t,
                    data: vec![k as u8],
                })
            })
            .collect()
    }

    fn run(options: &PlayOptions, times: &[i64], start_wall: i64) -> Log {
        let now = Cell::new(start_wall);
        let mut log = Log::default();
        let mut timer = SharedTimer { now: &now };
        let mut sink = Sink {
            log: &mut log,
            timer_now: &now,
        };
        let end = play_pass(
            options,
            times[0],
            msgs(times),
            &mut sink,
            &mut timer,
            &|| false,
        )
        .unwrap();
        assert_eq!(
            end,
            PassEnd::Completed {
                published: times.len() as u64
            }
        );
        log.now = now.get();
        log
    }

    const MS: i64 = 1_000_000;

    #[test]
    fn messages_are_published_in_order_at_their_log_time_offsets() {
        let times = [5_000 * MS, 5_010 * MS, 5_010 * MS, 5_100 * MS];
        let opts = PlayOptions {
            clock_hz: None,
            ..PlayOptions::default()
        };
        let log = run(&opts, &times, 1_000 * MS);
        let at: Vec<i64> = log.published.iter().map(|p| p.0).collect();
        assert_eq!(at, [1_000 * MS, 1_010 * MS, 1_010 * MS, 1_100 * MS]);
        let order: Vec<u8> = log.published.iter().map(|p| p.2[0]).collect();
        assert_eq!(order, [0, 1, 2, 3]);
        assert!(log.clocks.is_empty());
    }

    #[test]
    fn rate_scales_wall_time() {
        let times = [0, 100 * MS, 400 * MS];
        let fast = run(
            &PlayOptions {
                rate: 2.0,
                clock_hz: None,
                ..PlayOptions::default()
            },
            &times,
            0,
        );
        assert_eq!(
            fast.published.iter().map(|p| p.0).collect::<Vec<_>>(),
            [0, 50 * MS, 200 * MS]
        );
        let slow = run(
            &PlayOptions {
                rate: 0.5,
                clock_hz: None,
                ..PlayOptions::default()
            },
            &times,
            0,
        );
        assert_eq!(
            slow.published.iter().map(|p| p.0).collect::<Vec<_>>(),
            [0, 200 * MS, 800 * MS]
        );
    }

    #[test]
    fn clock_ticks_at_its_rate_in_bag_time_and_never_runs_ahead_of_a_message() {
        let times = [10_000 * MS, 10_100 * MS];
        let opts = PlayOptions {
            rate: 2.0,
            clock_hz: Some(100.0),
            ..PlayOptions::default()
        };
        let log = run(&opts, &times, 0);
        // 50 ms of wall time at 100 Hz → ticks at 0, 10, …, 50 ms, plus one per message.
        let periodic: Vec<&(i64, i64)> =
            log.clocks.iter().filter(|c| c.0 % (10 * MS) == 0).collect();
        assert!(periodic.len() >= 6, "{:?}", log.clocks);
        for (wall, bag) in &log.clocks {
            assert_eq!(
                *bag,
                (10_000 * MS + wall * 2).min(10_100 * MS),
                "{:?}",
                log.clocks
            );
        }
        let mut sorted = log.clocks.clone();
        sorted.sort_by_key(|c| c.1);
        assert_eq!(sorted, log.clocks, "clock went backwards");
        // the clock tick for a message precedes it
        let last_clock_before_msg = log
            .clocks
            .iter()
            .filter(|c| c.0 <= log.published[1].0)
            .map(|c| c.1)
            .max();
        assert_eq!(last_clock_before_msg, Some(10_100 * MS));
    }

    #[test]
    fn late_messages_go_out_at_once_without_reordering() {
        // A timer that is always 1 s late: everything is overdue.
        struct Late {
            now: i64,
        }
        impl Timer for Late {
            fn now_ns(&mut self) -> i64 {
                self.now += 1_000 * MS;
                self.now
            }
            fn sleep_until(&mut self, _: i64) {}
        }
        let now = Cell::new(0);
        let mut log = Log::default();
        let mut sink = Sink {
            log: &mut log,
            timer_now: &now,
        };
        let times = [0, MS, 2 * MS];
        let opts = PlayOptions {
            clock_hz: None,
            ..PlayOptions::default()
        };
        play_pass(
            &opts,
            0,
            msgs(&times),
            &mut sink,
            &mut Late { now: 0 },
            &|| false,
        )
        .unwrap();
        assert_eq!(
            log.published.iter().map(|p| p.2[0]).collect::<Vec<_>>(),
            [0, 1, 2]
        );
    }

    #[test]
    fn stop_interrupts_a_pass() {
        let mut timer = FakeTimer { now: 0 };
        let now = Cell::new(0);
        let mut log = Log::default();
        let mut sink = Sink {
            log: &mut log,
            timer_now: &now,
        };
        let calls = Cell::new(0);
        let stop = || {
            calls.set(calls.get() + 1);
            calls.get() > 3
        };
        let times = [0, 10 * MS, 1_000 * MS, 2_000 * MS];
        let end = play_pass(
            &PlayOptions::default(),
            0,
            msgs(&times),
            &mut sink,
            &mut timer,
            &stop,
        )
        .unwrap();
        assert!(
            matches!(end, PassEnd::Interrupted { published } if published < 4),
            "{end:?}"
        );
    }

    #[test]
    fn source_errors_stop_playback() {
        let mut timer = FakeTimer { now: 0 };
        let now = Cell::new(0);
        let mut log = Log::default();
        let mut sink = Sink {
            log: &mut log,
            timer_now: &now,
        };
        let items = vec![
            Ok(PlayMessage {
                topic_index: 0,
                log_time_ns: 0,
                data: vec![],
            }),
            Err("truncated".into()),
        ];
        let err = play_pass(
            &PlayOptions::default(),
            0,
            items,
            &mut sink,
            &mut timer,
            &|| false,
        )
        .unwrap_err();
        assert!(err.to_string().contains("truncated"));
        assert_eq!(log.published.len(), 1);
    }

    #[test]
    fn options_are_validated_and_topics_selected() {
        assert!(matches!(
            PlayOptions {
                rate: 0.0,
                ..Default::default()
            }
            .validate(),
            Err(PlayError::BadRate(_))
        ));
        assert!(matches!(
            PlayOptions {
                rate: f64::NAN,
                ..Default::default()
            }
            .validate(),
            Err(PlayError::BadRate(_))
        ));
        assert!(matches!(
            PlayOptions {
                clock_hz: Some(-1.0),
                ..Default::default()
            }
            .validate(),
            Err(PlayError::BadClockRate(_))
        ));
        let bag = vec!["/a".to_string(), "/b".to_string(), "/c".to_string()];
        let all = PlayOptions::default();
        assert_eq!(all.select_topics(&bag).unwrap().len(), 3);
        let some = PlayOptions {
            topics: vec!["/c".into(), "/a".into()],
            ..Default::default()
        };
        assert_eq!(some.select_topics(&bag).unwrap(), [&bag[0], &bag[2]]);
        let bad = PlayOptions {
            topics: vec!["/x".into()],
            ..Default::default()
        };
        let err = bad.select_topics(&bag).unwrap_err().to_string();
        assert!(err.contains("/x") && err.contains("/a"), "{err}");
    }

    #[test]
    fn schedule_maps_both_ways() {
        let s = PlaySchedule {
            bag_start_ns: 100,
            wall_start_ns: 1_000,
            rate: 4.0,
        };
        assert_eq!(s.due_wall_ns(500), 1_100);
        assert_eq!(s.bag_time_ns(1_100), 500);
        assert_eq!(s.due_wall_ns(50), 1_000); // before the start: due at once
    }
}
