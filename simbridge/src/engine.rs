//! The simulation loop of `sim_node`, without DDS: time, modes, command hold and timeout.
//!
//! Time is an integer count of nanoseconds of simulation time from 0, advanced in whole physics
//! steps (pushing, `sim.dt` = 2 ms by default) or pose ticks (car, `1 / pose_rate`). The engine
//! never reads a clock: the binary paces it against the wall clock in real-time mode and lets it
//! run free in lock-step mode.
//!
//! # Modes
//!
//! **Real time** ([`Mode::RealTime`]): time always advances (the binary paces it at `rate` ×
//! real time).
//! - Pushing: one action is one push; actions arriving during a push wait in a queue (at most
//!   [`MAX_QUEUED_PUSHES`]; more are dropped with a warning) and start at the next step after the
//!   current push has settled. Poses are published every `1 / pose_rate` of simulation time.
//! - Car: a command is applied from the next pose tick on and held; when no command has arrived
//!   for longer than `cmd_timeout` (simulation time) the car gets the zero command (no steering,
//!   no throttle) until the next command. Pose and odometry are published at every tick.
//!   (Pushing needs no timeout: every push is finite and the pusher is lifted after it.)
//!
//! **Lock-step** ([`Mode::LockStep`]): time advances only while there is a command to execute,
//! as fast as the CPU allows, then the engine waits.
//! - Pushing: the pose at t = 0 is published at start. Each action runs one whole push (approach,
//!   push, settling); its poses are published at `k / pose_rate` after the push began (k ≥ 1)
//!   and at the end of settling; then the engine waits for the next action. The pose at a push's
//!   start is the previous push's last pose, so no stamp repeats.
//! - Car: the pose at t = 0 is published at start. Each command is held for `lockstep_period`
//!   (a whole number of pose ticks), publishing pose and odometry at every tick; then the
//!   engine waits. Commands that arrive meanwhile are queued in order.
//!
//! The same engine, fed the same actions, gives bit-identical poses whether it runs in
//! `sim_node` over DDS or headless (`dynlab collect … --actions`).

use std::collections::VecDeque;

use dynlab_sim::{
    CarInput, CarScenario, CarState, CarWorld, Pose2, PushAction, PushScenario, PushWorld,
    SimError, SimRng,
};

use crate::messages::SimWorld;

/// Pushes that may wait while one is running; more are dropped with a warning.
pub const MAX_QUEUED_PUSHES: usize = 64;
/// Car commands that may wait in lock-step mode; more are dropped with a warning.
pub const MAX_QUEUED_COMMANDS: usize = 10_000;

/// How simulation time advances.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Continuously, paced at `rate` × real time by the caller.
    RealTime,
    /// Only while executing a command (see the module docs).
    LockStep,
}

impl Mode {
    /// Parses `realtime` or `lockstep`.
    pub fn parse(text: &str) -> Option<Mode> {
        match text {
            "realtime" | "real_time" => Some(Mode::RealTime),
            "lockstep" | "lock_step" => Some(Mode::LockStep),
            _ => None,
        }
    }
}

/// Engine settings (the node's parameters without the DDS ones).
#[derive(Debug, Clone, PartialEq)]
pub struct EngineConfig {
    /// Time mode. Default real time.
    pub mode: Mode,
    /// Pose (and odometry, `/clock`) publication rate in simulation time \[Hz\]. Default 100.
    pub pose_rate: f64,
    /// Car: zero command after this long without a command \[s of simulation time\]. Default 0.5.
    pub cmd_timeout: f64,
    /// Car, lock-step: simulation time one command is held for \[s\]. Default 0.02 (50 Hz).
    pub lockstep_period: f64,
    /// Seed of the measurement noise stream. Default 0.
    pub seed: u64,
}

impl Default for EngineConfig {
    fn default() -> Self {
        EngineConfig {
            mode: Mode::RealTime,
            pose_rate: 100.0,
            cmd_timeout: 0.5,
            lockstep_period: 0.02,
            seed: 0,
        }
    }
}

/// Errors building or running the engine.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// A setting is unusable; names the parameter and what to set.
    #[error("parameter {name}: {message}")]
    Param {
        /// Parameter name.
        name: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The simulator refused the scenario or an input.
    #[error(transparent)]
    Sim(#[from] SimError),
}

fn param(name: &'static str, message: impl Into<String>) -> EngineError {
    EngineError::Param {
        name,
        message: message.into(),
    }
}

/// Something the engine produced while advancing.
#[derive(Debug, Clone, PartialEq)]
pub enum Emit {
    /// A measured pose to publish (with `/clock` at the same time).
    Pose {
        /// Simulation time \[ns\].
        t_ns: u64,
        /// Measured pose.
        pose: Pose2,
    },
    /// Ground-truth car state to publish on `/car/odom`.
    Odom {
        /// Simulation time \[ns\].
        t_ns: u64,
        /// Ground truth.
        state: CarState,
    },
    /// A push began.
    PushStarted {
        /// Simulation time \[ns\].
        t_ns: u64,
        /// The push.
        action: PushAction,
    },
    /// A push ended (after settling).
    PushDone {
        /// Simulation time \[ns\].
        t_ns: u64,
        /// Ground-truth block pose.
        pose: Pose2,
        /// Whether the pusher touched the block.
        contact_made: bool,
    },
    /// No command for longer than `cmd_timeout`: the car now holds the zero command.
    CommandTimedOut {
        /// Simulation time \[ns\].
        t_ns: u64,
    },
    /// A command or action was dropped because the queue is full.
    Dropped {
        /// Simulation time \[ns\].
        t_ns: u64,
    },
}

struct PushSim {
    world: PushWorld,
    queue: VecDeque<PushAction>,
    dt_ns: u64,
    pose_every: u64,
    steps_in_push: u64,
}

struct CarSim {
    world: CarWorld,
    tick: f64,
    tick_ns: u64,
    held: CarInput,
    last_cmd_ns: Option<u64>,
    timed_out: bool,
    queue: VecDeque<CarInput>,
    ticks_per_command: u64,
    ticks_left: u64,
}

enum Sim {
    Push(Box<PushSim>),
    Car(Box<CarSim>),
}

/// The simulation loop of one world.
pub struct SimEngine {
    sim: Sim,
    cfg: EngineConfig,
    noise: SimRng,
    t_ns: u64,
}

fn to_ns(seconds: f64) -> u64 {
    (seconds * 1e9).round() as u64
}

impl SimEngine {
    fn check(cfg: &EngineConfig) -> Result<(), EngineError> {
        if !(cfg.pose_rate.is_finite() && cfg.pose_rate > 0.0 && cfg.pose_rate <= 10_000.0) {
            return Err(param(
                "pose_rate",
                format!("must be in (0, 10000] Hz, got {}", cfg.pose_rate),
            ));
        }
        if !(cfg.cmd_timeout.is_finite() && cfg.cmd_timeout > 0.0) {
            return Err(param(
                "cmd_timeout",
                format!(
                    "must be a positive number of seconds, got {}",
                    cfg.cmd_timeout
                ),
            ));
        }
        Ok(())
    }

    /// A pushing engine with the block at the scenario's start pose.
    pub fn push(scenario: &PushScenario, cfg: EngineConfig) -> Result<SimEngine, EngineError> {
        Self::check(&cfg)?;
        let world = PushWorld::new(scenario)?;
        let dt = world.dt();
        let ratio = 1.0 / (cfg.pose_rate * dt);
        if ratio < 1.0 - 1e-9 || (ratio - ratio.round()).abs() > 1e-6 {
            return Err(param(
                "pose_rate",
                format!(
                    "must divide the physics rate {} Hz (sim.dt = {dt} s) into whole steps, got {}; try {}",
                    1.0 / dt,
                    cfg.pose_rate,
                    1.0 / (dt * ratio.round().max(1.0))
                ),
            ));
        }
        Ok(SimEngine {
            noise: SimRng::new(cfg.seed),
            sim: Sim::Push(Box::new(PushSim {
                world,
                queue: VecDeque::new(),
                dt_ns: to_ns(dt),
                pose_every: (ratio.round() as u64).max(1),
                steps_in_push: 0,
            })),
            cfg,
            t_ns: 0,
        })
    }

    /// A car engine with the car at rest at the scenario's start.
    pub fn car(scenario: &CarScenario, cfg: EngineConfig) -> Result<SimEngine, EngineError> {
        Self::check(&cfg)?;
        let tick = 1.0 / cfg.pose_rate;
        let ticks = cfg.lockstep_period * cfg.pose_rate;
        if !(ticks.is_finite() && ticks.round() >= 1.0 && (ticks - ticks.round()).abs() < 1e-6) {
            return Err(param(
                "lockstep_period",
                format!(
                    "must be a whole number (≥ 1) of pose ticks (1 / pose_rate = {tick} s), got {}",
                    cfg.lockstep_period
                ),
            ));
        }
        Ok(SimEngine {
            noise: SimRng::new(cfg.seed),
            sim: Sim::Car(Box::new(CarSim {
                world: CarWorld::new(scenario)?,
                tick,
                tick_ns: to_ns(tick),
                held: CarInput::default(),
                last_cmd_ns: None,
                timed_out: false,
                queue: VecDeque::new(),
                ticks_per_command: ticks.round() as u64,
                ticks_left: 0,
            })),
            cfg,
            t_ns: 0,
        })
    }

    /// Which world.
    pub fn world(&self) -> SimWorld {
        match self.sim {
            Sim::Push(_) => SimWorld::Push,
            Sim::Car(_) => SimWorld::Car,
        }
    }

    /// The settings.
    pub fn config(&self) -> &EngineConfig {
        &self.cfg
    }

    /// Simulation time \[ns\].
    pub fn time_ns(&self) -> u64 {
        self.t_ns
    }

    /// Simulation time of the next [`SimEngine::advance`] \[ns\] (one physics step or pose tick on).
    pub fn next_time_ns(&self) -> u64 {
        self.t_ns
            + match &self.sim {
                Sim::Push(p) => p.dt_ns,
                Sim::Car(c) => c.tick_ns,
            }
    }

    /// The car's parameters (limits for command validation); `None` for pushing.
    pub fn car_params(&self) -> Option<&dynlab_sim::car::CarParams> {
        match &self.sim {
            Sim::Car(c) => Some(&c.world.scenario().car),
            Sim::Push(_) => None,
        }
    }

    /// What is published at start: the pose (and for the car the odometry) at t = 0.
    pub fn start(&mut self, out: &mut Vec<Emit>) {
        self.emit_pose(out);
    }

    fn emit_pose(&mut self, out: &mut Vec<Emit>) {
        let t_ns = self.t_ns;
        match &self.sim {
            Sim::Push(p) => out.push(Emit::Pose {
                t_ns,
                pose: p.world.measure(&mut self.noise),
            }),
            Sim::Car(c) => {
                out.push(Emit::Pose {
                    t_ns,
                    pose: c.world.measure(&mut self.noise),
                });
                out.push(Emit::Odom {
                    t_ns,
                    state: c.world.state(),
                });
            }
        }
    }

    /// Queues a push (validated and clamped by the caller). Ignored by a car engine.
    pub fn push_action(&mut self, action: PushAction, out: &mut Vec<Emit>) {
        if let Sim::Push(p) = &mut self.sim {
            if p.queue.len() >= MAX_QUEUED_PUSHES {
                out.push(Emit::Dropped { t_ns: self.t_ns });
            } else {
                p.queue.push_back(action);
            }
        }
    }

    /// Takes a car command (validated and clamped by the caller). Ignored by a pushing engine.
    pub fn car_command(&mut self, u: CarInput, out: &mut Vec<Emit>) {
        if let Sim::Car(c) = &mut self.sim {
            match self.cfg.mode {
                Mode::RealTime => {
                    c.held = u;
                    c.last_cmd_ns = Some(self.t_ns);
                    c.timed_out = false;
                }
                Mode::LockStep => {
                    if c.queue.len() >= MAX_QUEUED_COMMANDS {
                        out.push(Emit::Dropped { t_ns: self.t_ns });
                    } else {
                        c.queue.push_back(u);
                    }
                }
            }
        }
    }

    /// Whether [`SimEngine::advance`] would advance time now (always in real time; in lock-step
    /// only while a command is being executed or waiting).
    pub fn has_work(&self) -> bool {
        match (&self.sim, self.cfg.mode) {
            (_, Mode::RealTime) => true,
            (Sim::Push(p), Mode::LockStep) => p.world.push_active() || !p.queue.is_empty(),
            (Sim::Car(c), Mode::LockStep) => c.ticks_left > 0 || !c.queue.is_empty(),
        }
    }

    /// Advances one physics step (pushing) or one pose tick (car) if [`SimEngine::has_work`];
    /// returns whether time advanced.
    pub fn advance(&mut self, out: &mut Vec<Emit>) -> Result<bool, EngineError> {
        if !self.has_work() {
            return Ok(false);
        }
        let mode = self.cfg.mode;
        let cmd_timeout_ns = to_ns(self.cfg.cmd_timeout);
        let publish = match &mut self.sim {
            Sim::Push(p) => {
                if !p.world.push_active()
                    && let Some(action) = p.queue.pop_front()
                {
                    p.world.begin_push(action)?;
                    p.steps_in_push = 0;
                    out.push(Emit::PushStarted {
                        t_ns: self.t_ns,
                        action,
                    });
                }
                let was_active = p.world.push_active();
                p.world.step();
                self.t_ns += p.dt_ns;
                p.steps_in_push += 1;
                let ended = was_active && !p.world.push_active();
                if ended {
                    let outcome = p.world.take_outcome();
                    out.push(Emit::PushDone {
                        t_ns: self.t_ns,
                        pose: p.world.block_pose(),
                        contact_made: outcome.is_some_and(|o| o.contact_made),
                    });
                }
                match mode {
                    Mode::RealTime => (self.t_ns / p.dt_ns).is_multiple_of(p.pose_every),
                    Mode::LockStep => p.steps_in_push.is_multiple_of(p.pose_every) || ended,
                }
            }
            Sim::Car(c) => {
                let u = match mode {
                    Mode::RealTime => {
                        let stale = c
                            .last_cmd_ns
                            .is_none_or(|t| self.t_ns.saturating_sub(t) > cmd_timeout_ns);
                        if stale && c.last_cmd_ns.is_some() && !c.timed_out {
                            c.timed_out = true;
                            out.push(Emit::CommandTimedOut { t_ns: self.t_ns });
                        }
                        if stale { CarInput::default() } else { c.held }
                    }
                    Mode::LockStep => {
                        if c.ticks_left == 0
                            && let Some(u) = c.queue.pop_front()
                        {
                            c.held = u;
                            c.ticks_left = c.ticks_per_command;
                        }
                        c.ticks_left = c.ticks_left.saturating_sub(1);
                        c.held
                    }
                };
                c.world.step(u, c.tick)?;
                self.t_ns += c.tick_ns;
                true
            }
        };
        if publish {
            self.emit_pose(out);
        }
        Ok(true)
    }

    /// Runs lock-step work to completion (headless replay); returns the steps taken.
    pub fn run_until_idle(&mut self, out: &mut Vec<Emit>) -> Result<u64, EngineError> {
        let mut n = 0;
        while self.advance(out)? {
            n += 1;
        }
        Ok(n)
    }

    /// Ground-truth block pose (pushing) or car pose.
    pub fn true_pose(&self) -> Pose2 {
        match &self.sim {
            Sim::Push(p) => p.world.block_pose(),
            Sim::Car(c) => c.world.state().pose(),
        }
    }
}
