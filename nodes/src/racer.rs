//! The `racer` node's timing, without DDS: state estimate from poses, a fixed command delay
//! the optimiser knows about, and when each command is due.
//!
//! Over DDS a command cannot act at the instant of the pose it was computed from: the solve
//! takes time, and `sim_node` applies a command from its next tick on. Left alone this delay
//! varies from cycle to cycle with the solve time (10–40 ms of simulation time measured at a
//! fifth of real time) while the optimiser assumes none. [`RaceClock`] makes it fixed and known:
//! the command computed from the pose stamped `t` is published when the clock reaches
//! `t + delay` (immediately if the solve took longer: an overrun), and the optimiser starts
//! from the state predicted at `t + delay` by rolling the model forward under the commands
//! already sent for that interval. With `delay` = one control period this is the classic
//! one-cycle-delay receding horizon: the input of cycle k−1 acts while cycle k is solved.

use std::collections::VecDeque;

use dynlab_control::racing::{
    CarDynamics, CarStateEstimator, Input, Plant, RaceStep, Racer, RacingError, State,
};
use dynlab_learn::dynamics::data::SavGol;

/// Time tolerance for stamp comparisons \[s\] (stamps are whole nanoseconds).
const EPS: f64 = 1e-6;

/// A command ready to publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Planned {
    /// Simulation time from which the command should act \[s\].
    pub apply_at: f64,
    /// Stamp of the pose the state estimate came from \[s\].
    pub pose_stamp: f64,
    /// The state the optimiser started from (predicted at `apply_at`).
    pub predicted: State,
    /// The solve.
    pub step: RaceStep,
}

/// Receding-horizon racing with a known command delay, driven by pose stamps and a clock.
#[derive(Debug)]
pub struct RaceClock<'a> {
    racer: Racer<'a>,
    one: Plant<'a>,
    est: CarStateEstimator,
    latest: Option<(f64, State)>,
    delay_steps: usize,
    dt: f64,
    period: f64,
    sent: VecDeque<(f64, Input)>,
    next_solve: Option<f64>,
    overruns: usize,
}

impl<'a> RaceClock<'a> {
    /// Racing with `racer` (built on `model`), commands acting `delay_steps` model steps after
    /// the pose they were computed from (0: no delay assumed, the in-process loop's behaviour).
    pub fn new(
        racer: Racer<'a>,
        model: &'a dyn CarDynamics,
        delay_steps: usize,
    ) -> Result<Self, RacingError> {
        let one = Plant::new(model, 1)?;
        Ok(Self {
            period: racer.period(),
            dt: model.dt(),
            racer,
            one,
            est: CarStateEstimator::default(),
            latest: None,
            delay_steps,
            sent: VecDeque::new(),
            next_solve: None,
            overruns: 0,
        })
    }

    /// The same clock with its state estimate fitted as `fit` says (default: 15 poses); give it
    /// the fit the model's training data had ([`dynlab_learn::ModelFile::state_fit`]).
    pub fn with_state_fit(mut self, fit: SavGol) -> Self {
        self.est = CarStateEstimator::new(fit);
        self
    }

    /// The command delay \[s\].
    pub fn delay(&self) -> f64 {
        self.delay_steps as f64 * self.dt
    }

    /// Control period \[s\].
    pub fn period(&self) -> f64 {
        self.period
    }

    /// The racer.
    pub fn racer(&self) -> &Racer<'a> {
        &self.racer
    }

    /// Replaces the racer, e.g. one built with a new reference speed (`ros2 param set /racer
    /// reference_speed 2.5`); the state estimate, the commands sent and the solve schedule are
    /// kept, the next solve starts the new racer from its initial guess.
    pub fn replace_racer(&mut self, racer: Racer<'a>) {
        self.period = racer.period();
        self.racer = racer;
    }

    /// Commands published after their `apply_at` (the solve took longer than the delay).
    pub fn overruns(&self) -> usize {
        self.overruns
    }

    /// Adds a measured pose `(x, y, ψ)` stamped `t` \[s\].
    pub fn on_pose(&mut self, t: f64, pose: [f64; 3]) {
        if let Some(s) = self.est.push(t, pose) {
            self.latest = Some((t, s));
        }
    }

    /// The newest state estimate and its stamp.
    pub fn estimate(&self) -> Option<(f64, State)> {
        self.latest
    }

    /// Starts over after the poses stopped or their clock restarted ([`crate::stale`]): forgets
    /// the state estimate and its pose window (a Savitzky–Golay fit across a gap would read the
    /// gap as motion, and poses stamped before the old window would be dropped), the commands
    /// sent, the solve schedule and the optimiser's warm start. The next estimate comes after a
    /// full window of fresh poses (15 at the default fit: 0.15 s at 100 Hz).
    pub fn restart(&mut self) {
        self.est.reset();
        self.latest = None;
        self.sent.clear();
        self.next_solve = None;
        self.racer.reset();
    }

    /// The input acting at time `t` by the commands sent so far (zero before the first: the
    /// simulator holds the zero command until one arrives).
    fn input_at(&self, t: f64) -> Input {
        self.sent
            .iter()
            .rev()
            .find(|(at, _)| *at <= t + EPS)
            .map_or([0.0, 0.0], |(_, u)| *u)
    }

    /// The state at `t + delay` from the state `s` at `t`, rolled forward on the model under
    /// the commands already sent for that interval (`s` itself when the delay is 0).
    pub fn predict(&self, t: f64, s: State) -> Result<State, RacingError> {
        if self.delay_steps == 0 {
            return Ok(s);
        }
        let inputs: Vec<Input> = (0..self.delay_steps)
            .map(|j| self.input_at(t + j as f64 * self.dt))
            .collect();
        // a model with effect states (motor lag, steering servo) starts from the racer's, kept
        // from the commands it sent
        let plant = self.one.with_extra(&self.racer.extra_states())?;
        let states = plant.rollout(&s, &inputs)?;
        let end = states.last().copied().unwrap_or(s);
        // a model that diverged over a few steps is worse than the delay: use the measurement
        Ok(if end.iter().all(|v| v.is_finite()) {
            end
        } else {
            s
        })
    }

    /// Solves when a control period has passed on the clock (`now` \[s\]) and a state estimate
    /// exists: from the state predicted at `stamp + delay`. The caller publishes the command
    /// once the clock reaches its `apply_at` ([`RaceClock::due`]).
    pub fn plan(&mut self, now: f64) -> Result<Option<Planned>, RacingError> {
        let Some((stamp, s)) = self.latest else {
            return Ok(None);
        };
        if self.next_solve.is_some_and(|n| now + EPS < n) {
            return Ok(None);
        }
        let predicted = self.predict(stamp, s)?;
        let step = self.racer.step(predicted)?;
        let apply_at = stamp + self.delay();
        self.sent.push_back((apply_at, step.input));
        // keep what can still act within the longest prediction window
        while self.sent.len() > 2 && self.sent[1].0 + self.delay() + self.period < apply_at {
            self.sent.pop_front();
        }
        self.next_solve = Some(match self.next_solve {
            Some(n) => (n + self.period).max(now),
            None => now + self.period,
        });
        Ok(Some(Planned {
            apply_at,
            pose_stamp: stamp,
            predicted,
            step,
        }))
    }

    /// Whether a planned command is due at clock time `now`; counts an overrun when it is
    /// already late by a model step or more at the first check.
    pub fn due(&mut self, planned: &Planned, now: f64, first_check: bool) -> bool {
        let due = now + EPS >= planned.apply_at;
        if due && first_check && self.delay_steps > 0 && now > planned.apply_at + self.dt - EPS {
            self.overruns += 1;
        }
        due
    }
}

/// The command the racer holds while its poses are stale: zero throttle, steering as last
/// commanded (centred before any command).
///
/// Why not centred: the car is still moving when the poses stop (a motion-capture dropout, a
/// restarted simulator whose car is coasting) and the last steering angle is the one that
/// keeps it on the arc the optimiser planned through the current curve; snapping the wheels
/// straight at speed is a steering step the racer never planned, which turns a coasting car in a
/// bend towards the outer border. With zero throttle the car slows on drag and rolling
/// resistance along that arc. (`sim_node` itself gives the zero command, steering centred, after
/// its own `cmd_timeout` without commands: a stopped racer is covered there.)
pub fn held_input(last: Option<Input>) -> Input {
    [last.map_or(0.0, |u| u[0]), 0.0]
}

/// What [`StaleHold`] tells the node to do about the pose stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HoldEvent {
    /// The poses went stale: log once, forget the plan ([`RaceClock::restart`]), hold.
    Stale {
        /// Time since the newest pose arrived \[s, steady clock\].
        silent: f64,
    },
    /// Poses arrive again: log once, [`RaceClock::restart`]; the hold goes on until the first
    /// command solved from fresh poses is published.
    Resumed {
        /// Time without poses \[s, steady clock\].
        gap: f64,
        /// The pose stamps went back (a restarted simulator).
        restarted: bool,
    },
    /// Without a gap, the pose stamps went back (a looped bag): log once, [`RaceClock::restart`]
    /// (the old window and schedule belong to another clock).
    Restarted {
        /// The newest stamp before \[s\].
        from: f64,
        /// The new, earlier stamp \[s\].
        to: f64,
    },
}

/// The racer's hold on stale poses, on the node's steady clock (see [`crate::stale`] for why not
/// ROS time): a [`PoseWatch`](crate::stale::PoseWatch) plus the held command, repeated every
/// control period while holding so that a robot (or `sim_node`) with a command timeout of its
/// own keeps a defined command.
#[derive(Debug, Clone)]
pub struct StaleHold {
    watch: crate::stale::PoseWatch,
    period: f64,
    holding: bool,
    next_hold: f64,
    last: Option<Input>,
}

impl StaleHold {
    /// Holds after `timeout` \[s\] without a pose, repeating the held command every `period` \[s\].
    pub fn new(timeout: f64, period: f64) -> Result<Self, crate::stale::StaleError> {
        Ok(Self {
            watch: crate::stale::PoseWatch::new(timeout)?,
            period,
            holding: false,
            next_hold: f64::NEG_INFINITY,
            last: None,
        })
    }

    /// A pose stamped `stamp` \[s\] arrived at `now` \[s, steady clock\].
    pub fn on_pose(&mut self, now: f64, stamp: f64) -> Option<HoldEvent> {
        use crate::stale::PoseEvent;
        match self.watch.on_pose(now, stamp)? {
            PoseEvent::Resumed { gap, restarted } => Some(HoldEvent::Resumed { gap, restarted }),
            PoseEvent::Restarted { from, to } => Some(HoldEvent::Restarted { from, to }),
            PoseEvent::Stale { silent } => Some(HoldEvent::Stale { silent }),
        }
    }

    /// Checks for stale poses at `now` \[s, steady clock\]; reports the change once.
    pub fn check(&mut self, now: f64) -> Option<HoldEvent> {
        match self.watch.check(now)? {
            crate::stale::PoseEvent::Stale { silent } => {
                self.holding = true;
                self.next_hold = now;
                Some(HoldEvent::Stale { silent })
            }
            _ => None,
        }
    }

    /// Whether the racer holds (poses stale, or fresh again but no command solved from them
    /// yet): solved commands are not to be published from stale data.
    pub fn holding(&self) -> bool {
        self.holding
    }

    /// The held command when one is due at `now` \[s, steady clock\] (at once on holding, then
    /// every period).
    pub fn due(&mut self, now: f64) -> Option<Input> {
        if !self.holding || now < self.next_hold {
            return None;
        }
        self.next_hold = (self.next_hold + self.period).max(now);
        let u = held_input(self.last);
        self.last = Some(u);
        Some(u)
    }

    /// A command solved from fresh poses was published: the hold (if any) ends.
    pub fn published(&mut self, u: Input) {
        self.last = Some(u);
        if !self.watch.is_stale() {
            self.holding = false;
        }
    }
}

/// What a headless run measured (the simulator's ground truth against the track).
#[derive(Debug, Clone, PartialEq)]
pub struct HeadlessReport {
    /// Simulated time \[s\].
    pub time: f64,
    /// Distance along the centre line \[m\].
    pub progress: f64,
    /// Completed laps.
    pub laps: usize,
    /// Times the car's centre left the track.
    pub excursions: usize,
    /// Smallest distance of the car's centre to a border \[m\].
    pub min_border_distance: f64,
    /// Every command as applied: `(time applied [s], input)`.
    pub commands: Vec<(f64, Input)>,
    /// Commands published late (see [`RaceClock::overruns`]).
    pub overruns: usize,
}

/// Errors of a headless run.
#[derive(Debug, thiserror::Error)]
pub enum HeadlessError {
    /// The racer failed.
    #[error(transparent)]
    Racing(#[from] RacingError),
    /// The simulation engine failed.
    #[error(transparent)]
    Engine(#[from] dynlab_simbridge::engine::EngineError),
}

/// Runs the node's loop without DDS for `seconds` of simulation time: `sim_node`'s engine
/// (real-time mode, a command acts from the tick after it arrives) and [`RaceClock`], with a
/// perfect transport (every pose delivered, every command arriving before the next tick) and
/// solves taking no simulation time. `solve_ticks` adds a solve time in ticks: the command is
/// held back for that many ticks after its solve (and no earlier than its `apply_at`), which
/// reproduces the timing of the node over DDS at a slowed simulation.
pub fn run_headless(
    clock: &mut RaceClock<'_>,
    scenario: &dynlab_sim::CarScenario,
    track: &dynlab_sim::Track,
    seconds: f64,
    solve_ticks: usize,
) -> Result<HeadlessReport, HeadlessError> {
    use dynlab_simbridge::engine::{Emit, EngineConfig, SimEngine};
    let mut engine = SimEngine::car(
        scenario,
        EngineConfig {
            seed: scenario.seed,
            ..EngineConfig::default()
        },
    )?;
    let mut emits = Vec::new();
    engine.start(&mut emits);
    let len = track.length();
    let mut loc: Option<dynlab_sim::TrackLocation> = None;
    let mut rep = HeadlessReport {
        time: 0.0,
        progress: 0.0,
        laps: 0,
        excursions: 0,
        min_border_distance: f64::INFINITY,
        commands: Vec::new(),
        overruns: 0,
    };
    let mut off = false;
    // (earliest tick time it may act [s], planned)
    let mut pending: VecDeque<(f64, Planned, bool)> = VecDeque::new();
    let tick = 1.0 / EngineConfig::default().pose_rate;
    loop {
        for e in emits.drain(..) {
            match e {
                Emit::Pose { t_ns, pose } => {
                    clock.on_pose(t_ns as f64 * 1e-9, [pose.x, pose.y, pose.theta]);
                }
                Emit::Odom { state, .. } => {
                    let nl = match loc {
                        Some(l) => track.locate_near([state.x, state.y], l.segment, 12),
                        None => track.locate([state.x, state.y]),
                    };
                    if let Some(l) = loc {
                        let mut d = nl.arc - l.arc;
                        if d > 0.5 * len {
                            d -= len;
                        } else if d < -0.5 * len {
                            d += len;
                        }
                        rep.progress += d;
                    }
                    loc = Some(nl);
                    let border = nl.half_width - nl.lateral.abs();
                    rep.min_border_distance = rep.min_border_distance.min(border);
                    if border < 0.0 && !off {
                        rep.excursions += 1;
                    }
                    off = border < 0.0;
                }
                _ => {}
            }
        }
        let now = engine.time_ns() as f64 * 1e-9;
        if now >= seconds - EPS {
            break;
        }
        if let Some(p) = clock.plan(now)? {
            pending.push_back((now + solve_ticks as f64 * tick, p, false));
        }
        while let Some((ready, p, checked)) = pending.front_mut() {
            if now + EPS < *ready {
                break;
            }
            let first = !*checked;
            *checked = true;
            if !clock.due(p, now, first) {
                break;
            }
            let u = p.step.input;
            engine.car_command(dynlab_sim::CarInput::new(u[0], u[1]), &mut emits);
            rep.commands.push((now, u));
            pending.pop_front();
        }
        engine.advance(&mut emits)?;
    }
    rep.time = engine.time_ns() as f64 * 1e-9;
    rep.laps = (rep.progress / len).floor().max(0.0) as usize;
    rep.overruns = clock.overruns();
    Ok(rep)
}
