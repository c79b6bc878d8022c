//! Trajectory optimisation through the learned car model (Kohler et al.): offline manoeuvres and
//! receding-horizon racing.
//!
//! The car state is `[x, y, ψ, vx, vy, ω]` (pose plus body-frame velocities), the input
//! `[δ, d]` (steering \[rad\], throttle). A [`Plant`] holds each input for `hold` model steps
//! (a control step of `hold · dt`), rolls the model out and linearises it about a trajectory
//! with the model's exact step Jacobians (`learn::Model::jacobians`, one batched call).
//!
//! The cost ([`Objective`]) is the paper's: quadratic target terms at chosen steps (their
//! eq. 4), an input magnitude and rate regulariser (eq. 5), one-sided quadratic barriers on the
//! input limits (eq. 6), and for racing the progress along a [`Track`] centre line with the
//! paper's quadratic excursion cost beyond the borders. Two optimisers minimise it:
//!
//! * [`solve_gd`]: the paper's batch gradient descent — the exact gradient `dℓ/du` by reverse
//!   mode (the adjoint recursion of eqs. 7–9), scaled by 512 step sizes in `[10⁻⁶, 1]`, all
//!   candidates rolled out in one batch, the best kept;
//! * [`solve_sqp`]: a trust-region SQP on Clarabel — the model linearised about the current
//!   trajectory with exact Jacobians, a Gauss–Newton QP in the input steps, input limits and the
//!   track borders as hard constraints (an elastic fallback when the linearised borders are
//!   infeasible), and a ratio test on the true cost.
//!
//! Outcomes are data: a [`Solution`] carries a [`SolveStatus`]; errors are only for bad input.
//! [`Racer`] re-solves every control cycle from a measured state with a shifted warm start;
//! [`CarStateEstimator`] turns measured poses into that state with a causal Savitzky–Golay fit;
//! [`Manoeuvre`] holds the offline scenarios (parallel parking, dynamic reverse, drifting turn).
//!
//! [`Track`]: dynlab_sim::Track

mod cost;
mod estimate;
mod gd;
mod laps;
mod manoeuvre;
mod onpolicy;
mod plant;
mod profile;
mod race;
mod sqp;
mod truth;

pub use cost::{InputLimits, Objective, Regulariser, Target, TrackTerms};
pub use estimate::CarStateEstimator;
pub use gd::{GdSettings, gradient, solve_gd, solve_gd_until};
pub use laps::{LapReport, LapSettings, TracePoint, run_laps};
pub use manoeuvre::Manoeuvre;
pub use onpolicy::{OnPolicySettings, racing_episode};
pub use plant::{CarDynamics, Input, Linearization, MAX_EXTRA, Plant, State};
pub use profile::SpeedProfile;
pub use race::{Optimizer, RaceStep, Racer, RacerSettings};
pub use sqp::{SqpSettings, solve_sqp, solve_sqp_until};
pub use truth::{SimCar, true_car_model};

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use dynlab_learn::LearnError;

/// Construction errors of the racing optimiser (outcomes of a solve are [`SolveStatus`]).
#[derive(Debug, thiserror::Error)]
pub enum RacingError {
    /// The model is not a car model.
    #[error(
        "the model is a {found} model; the racing optimiser needs a car model (train one on car bags: `dynlab train --world car`)"
    )]
    NotACarModel {
        /// The model's world.
        found: String,
    },
    /// A setting is out of range.
    #[error("invalid setting {name} = {value}: {hint}")]
    Setting {
        /// Setting name.
        name: &'static str,
        /// The value given.
        value: String,
        /// What to set instead.
        hint: String,
    },
    /// The model rejected its input (non-finite state or input).
    #[error(transparent)]
    Model(#[from] LearnError),
    /// The simulator rejected a scenario or a command.
    #[error(transparent)]
    Sim(#[from] dynlab_sim::SimError),
}

impl RacingError {
    pub(crate) fn setting(name: &'static str, value: impl ToString, hint: impl ToString) -> Self {
        Self::Setting {
            name,
            value: value.to_string(),
            hint: hint.to_string(),
        }
    }
}

/// How a solve ended. Every status comes with the best inputs found so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SolveStatus {
    /// Converged: no step improves the cost by more than the tolerance.
    Solved,
    /// Stopped at the iteration limit (the inputs are the best found).
    MaxIterations,
    /// The QP with hard track constraints is infeasible (and no elastic fallback was allowed).
    Infeasible,
    /// The QP solver failed numerically.
    NumericalError,
    /// The model produced non-finite states along the initial guess.
    ModelFailure,
    /// Stopped at the solve's wall-clock deadline (a racer's `solve_budget`); the inputs are
    /// the best found by then (the initial guess if no iteration fitted).
    Deadline,
}

impl SolveStatus {
    /// Whether the result can be used as a converged solution.
    pub fn is_solved(self) -> bool {
        self == SolveStatus::Solved
    }
}

impl std::fmt::Display for SolveStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SolveStatus::Solved => "solved",
            SolveStatus::MaxIterations => "max-iterations",
            SolveStatus::Infeasible => "infeasible",
            SolveStatus::NumericalError => "numerical-error",
            SolveStatus::ModelFailure => "model-failure",
            SolveStatus::Deadline => "deadline",
        })
    }
}

/// A wall-clock deadline for one or more solves (the solves of a racing cycle share one), with
/// the longest optimiser iteration any of them took so far: an iteration (or a solve) is only
/// started while more time than that is left, so the deadline is overrun by at most the part
/// of one iteration that took longer than all before it.
#[derive(Debug)]
pub struct Deadline {
    at: Instant,
    longest_ns: AtomicU64,
}

impl Deadline {
    /// A deadline at the instant `at`.
    pub fn at(at: Instant) -> Self {
        Self {
            at,
            longest_ns: AtomicU64::new(0),
        }
    }

    /// A deadline `budget` from now.
    pub fn after(budget: Duration) -> Self {
        Self::at(Instant::now() + budget)
    }

    /// The instant of the deadline.
    pub fn instant(&self) -> Instant {
        self.at
    }

    /// The longest iteration recorded so far.
    pub fn longest_iteration(&self) -> Duration {
        Duration::from_nanos(self.longest_ns.load(Ordering::Relaxed))
    }

    /// Whether an iteration may start now: more time is left than the longest iteration so
    /// far (before any was recorded: whether the deadline is still ahead).
    pub fn allows_iteration(&self) -> bool {
        let now = Instant::now();
        now < self.at && self.at - now > self.longest_iteration()
    }

    /// A share of the time left for one of `parts` solves run one after the other: a deadline
    /// at `now + (time left) / parts` (now, if none is left) that starts from this one's longest
    /// iteration. Record its longest iteration back here when its solve is done.
    pub fn share(&self, parts: usize) -> Deadline {
        let now = Instant::now();
        let left = self.at.saturating_duration_since(now);
        let parts = u32::try_from(parts.max(1)).unwrap_or(u32::MAX);
        Deadline {
            at: now + left / parts,
            longest_ns: AtomicU64::new(self.longest_ns.load(Ordering::Relaxed)),
        }
    }

    /// Records the duration of one iteration (of any solve sharing the deadline).
    pub fn record(&self, iteration: Duration) {
        let ns = u64::try_from(iteration.as_nanos()).unwrap_or(u64::MAX);
        self.longest_ns.fetch_max(ns, Ordering::Relaxed);
    }
}

/// The optimisation problem: a plant, its initial state and the cost.
#[derive(Debug, Clone)]
pub struct Problem<'a> {
    /// The model with its input hold.
    pub plant: Plant<'a>,
    /// Initial state `x₀`.
    pub s0: State,
    /// The cost.
    pub objective: Objective<'a>,
}

/// The result of a solve.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Optimised inputs, one per control step.
    pub inputs: Vec<Input>,
    /// Predicted states `x₀ … x_n`.
    pub states: Vec<State>,
    /// Cost `ℓ` of the inputs.
    pub cost: f64,
    /// How the solve ended.
    pub status: SolveStatus,
    /// Iterations taken.
    pub iterations: usize,
    /// Cost after each iteration (the first entry is the initial guess).
    pub history: Vec<f64>,
    /// QPs that needed the elastic fallback (SQP only).
    pub elastic_qps: usize,
}
