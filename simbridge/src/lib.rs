//! The simulator bridged to ROS 2 messages and bags, without DDS.
//!
//! [`engine`] runs a pushing or car world in real time or lock-step; [`messages`] turns its
//! records into ROS 2 messages and writes bags in the recorder's layout. The `sim_node` and
//! `explorer` binaries (in `dynlab-nodes`) wire both to topics, and `dynlab collect` uses the same
//! code headless, so a bag collected offline and one recorded over DDS hold the same messages.
#![warn(missing_docs)]

pub mod engine;
pub mod messages;

pub use engine::{Emit, EngineConfig, EngineError, Mode, SimEngine};
pub use messages::{SimBagWriter, SimWorld};
