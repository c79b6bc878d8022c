//! The offline scenarios of Kohler et al. (Sec. IV-B): target states at an intermediate and the
//! final step, solved offline and played open-loop.
//!
//! The ORCA car's reverse throttle (−0.1) cannot overcome its rolling resistance, so every
//! manoeuvre here starts forwards at rest and uses drifts instead of reversing: a 1:43 car
//! "parks" by sliding sideways into the gap, "reverses" by a 180° drift.

use std::f64::consts::{FRAC_PI_2, PI};

use super::Problem;
use super::cost::{InputLimits, Objective, Regulariser, Target};
use super::plant::{Input, Plant, State};

/// An offline manoeuvre: horizon and target states, starting at rest at the origin facing +x.
#[derive(Debug, Clone, PartialEq)]
pub struct Manoeuvre {
    /// Name for reports.
    pub name: &'static str,
    /// Control steps n.
    pub horizon: usize,
    /// Target states (intermediate and final).
    pub targets: Vec<Target>,
    /// Initial guess: one input held over the horizon.
    pub initial: Input,
}

const POSE_W: State = [100.0, 100.0, 10.0, 0.0, 0.0, 0.0];
const END_W: State = [100.0, 100.0, 10.0, 1.0, 1.0, 0.1];

impl Manoeuvre {
    /// Parallel parking: drive 0.6 m ahead, then slide 0.25 m sideways into a gap, parallel to
    /// the start heading and nearly stopped (1.5 s at 20 Hz).
    pub fn parallel_parking() -> Self {
        Self {
            name: "parallel_parking",
            horizon: 30,
            targets: vec![
                Target {
                    step: 12,
                    state: [0.6, 0.0, 0.0, 0.0, 0.0, 0.0],
                    weight: POSE_W,
                },
                Target {
                    step: 30,
                    state: [1.0, 0.25, 0.0, 0.0, 0.0, 0.0],
                    weight: END_W,
                },
            ],
            initial: [0.0, 0.3],
        }
    }

    /// Dynamic reverse: accelerate, then a 180° drift, ending facing back towards the start
    /// (1.5 s).
    pub fn dynamic_reverse() -> Self {
        Self {
            name: "dynamic_reverse",
            horizon: 30,
            targets: vec![
                Target {
                    step: 14,
                    state: [0.8, 0.0, 0.0, 0.0, 0.0, 0.0],
                    weight: POSE_W,
                },
                Target {
                    step: 30,
                    state: [1.0, 0.3, PI, 0.0, 0.0, 0.0],
                    weight: END_W,
                },
            ],
            initial: [0.0, 0.3],
        }
    }

    /// Drifting turn: a fast quarter turn around a point at (0.8, 0.3), passing it heading
    /// +y and leaving heading −x (1.6 s).
    pub fn drifting_turn() -> Self {
        Self {
            name: "drifting_turn",
            horizon: 32,
            targets: vec![
                Target {
                    step: 16,
                    state: [1.0, 0.3, FRAC_PI_2, 0.0, 0.0, 0.0],
                    weight: POSE_W,
                },
                Target {
                    step: 32,
                    state: [0.6, 0.7, PI, 0.0, 0.0, 0.0],
                    weight: [100.0, 100.0, 10.0, 0.0, 0.0, 0.0],
                },
            ],
            initial: [0.1, 0.4],
        }
    }

    /// The three scenarios.
    pub fn all() -> Vec<Self> {
        vec![
            Self::parallel_parking(),
            Self::dynamic_reverse(),
            Self::drifting_turn(),
        ]
    }

    /// The optimisation problem on `plant` from rest at `start`.
    pub fn problem<'a>(&self, plant: Plant<'a>, start: State, limits: InputLimits) -> Problem<'a> {
        Problem {
            plant,
            s0: start,
            objective: Objective {
                targets: self.targets.clone(),
                track: None,
                limits,
                reg: Regulariser::default(),
                u_prev: None,
                start_segment: None,
            },
        }
    }

    /// The initial guess over the horizon.
    pub fn initial_inputs(&self) -> Vec<Input> {
        vec![self.initial; self.horizon]
    }

    /// The final target state.
    pub fn end_target(&self) -> State {
        self.targets
            .iter()
            .max_by_key(|t| t.step)
            .map_or([0.0; 6], |t| t.state)
    }
}
