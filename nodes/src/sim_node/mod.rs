//! The simulator node: [`engine`] runs a pushing or car world in real time or lock-step,
//! [`messages`] turns its records into ROS 2 messages and bags. Both are free of DDS; the
//! `sim_node` and `explorer` binaries wire them to topics, and `dynlab collect` writes the same
//! messages headless.

pub mod engine;
pub mod messages;

pub use engine::{Emit, EngineConfig, EngineError, Mode, SimEngine};
pub use messages::{SimBagWriter, SimWorld};
