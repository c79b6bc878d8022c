//! Pushing and car simulators on rapier2d with hidden physical effects.
//!
//! Two worlds behave like the robots of the papers: [`PushWorld`] (a block pushed
//! quasi-statically on a table, after Tu & Lin) and [`CarWorld`] (a rear-wheel-driven 1:43 RC
//! car with Pacejka tires that grips gently and drifts under power, after Liniger et al. and
//! Kohler et al.). Each has named hidden effects, off by default and switched on by a scenario
//! file, and mocap-like measurement noise. Exploration policies ([`PushExplorer`],
//! [`CarExplorer`]) and a thread-count-independent episode generator turn a scenario and a seed
//! into time-stamped records ([`Sample`]) ready to be written to a bag.
//!
//! No DDS, no clocks, no unseeded randomness: seeds and time are inputs.
//!
//! ```
//! use dynlab_sim::{Pose2, PushAction, PushScenario, PushWorld};
//!
//! let mut world = PushWorld::new(&PushScenario::free())?;
//! world.reset(Pose2::new(0.4, 0.0, 0.0))?;
//! // Push the middle of the back face straight ahead for 0.05 m.
//! let outcome = world.apply(PushAction::new(0.0, 0.0, 0.5))?;
//! assert!((outcome.final_pose.x - 0.45).abs() < 2e-3);
//! # Ok::<(), dynlab_sim::SimError>(())
//! ```
#![warn(missing_docs)]

pub mod error;
pub mod geometry;
pub mod noise;
pub mod push;
pub mod rng;
mod scenario_file;

pub use error::SimError;
pub use geometry::{OrientedBox, Pose2, Region, RegionShape, wrap_angle};
pub use noise::MeasurementNoise;
pub use push::{
    PushAction, PushEffects, PushOutcome, PushScenario, PushWorld, SupportLayout, TimedPose,
};
pub use rng::{SimRng, derive_seed};
pub mod car;
pub mod episode;
pub mod explore;
pub mod track;
pub use car::{CarEffects, CarInput, CarScenario, CarState, CarWorld};
pub use episode::{
    Episode, EpisodeEnd, Record, Sample, car_episode, concatenate, generate_car_episodes,
    generate_push_episodes, push_episode,
};
pub use explore::{CarDriver, CarExplorer, PushExplorer};
pub use track::{Track, TrackLocation};
