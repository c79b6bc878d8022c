//! The two robots ("worlds"): their states, actions, topics and which part of the state a network
//! learns.

use dynlab_dynamics::physics::Robot;
use serde::{Deserialize, Serialize};

use crate::LearnError;

/// Which robot a model or a data set belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum World {
    /// Planar pushing (Tu & Lin): state `(x, y, θ)`, action `(p, φ, ℓ)`, one model step per push.
    Push,
    /// RC car (Kohler et al.): state `(x, y, ψ, vx, vy, ω)`, input `(δ, d)`, one model step per
    /// pose interval.
    Car,
}

impl World {
    /// `push` or `car`.
    pub fn name(self) -> &'static str {
        match self {
            World::Push => "push",
            World::Car => "car",
        }
    }

    /// Parses `push` / `car`.
    pub fn from_name(name: &str) -> Result<Self, LearnError> {
        match name {
            "push" | "pushing" => Ok(World::Push),
            "car" => Ok(World::Car),
            other => Err(LearnError::setting("world", other, "use push or car")),
        }
    }

    /// Model state dimension (3 or 6).
    pub fn state_dim(self) -> usize {
        match self {
            World::Push => 3,
            World::Car => 6,
        }
    }

    /// Action dimension (3 or 2).
    pub fn action_dim(self) -> usize {
        match self {
            World::Push => 3,
            World::Car => 2,
        }
    }

    /// The state dimensions a network predicts: the whole pose for pushing, the body-frame
    /// velocities `(vx, vy, ω)` for the car (Kohler et al.: the pose integrates from them).
    pub fn learned_dims(self) -> std::ops::Range<usize> {
        match self {
            World::Push => 0..3,
            World::Car => 3..6,
        }
    }

    /// Index of the angle in the state (θ or ψ); its errors are wrapped to `[−π, π)`.
    pub fn angle_dim(self) -> usize {
        2
    }

    /// State names.
    pub fn state_names(self) -> &'static [&'static str] {
        match self {
            World::Push => &["x", "y", "theta"],
            World::Car => &["x", "y", "psi", "vx", "vy", "omega"],
        }
    }

    /// Action names.
    pub fn action_names(self) -> &'static [&'static str] {
        match self {
            World::Push => &["p", "phi", "l"],
            World::Car => &["delta", "d"],
        }
    }

    /// Default pose topic of the topic contract.
    pub fn default_pose_topic(self) -> &'static str {
        match self {
            World::Push => "/push/block_pose",
            World::Car => "/car/pose",
        }
    }

    /// Default command topic of the topic contract.
    pub fn default_cmd_topic(self) -> &'static str {
        match self {
            World::Push => "/push/action",
            World::Car => "/car/cmd",
        }
    }

    /// The physics model's robot.
    pub fn robot(self) -> Robot {
        match self {
            World::Push => Robot::Pushing,
            World::Car => Robot::Car,
        }
    }
}

impl std::fmt::Display for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
