//! ROS 2 node binaries: recorder, player and the robot nodes.
//!
//! The logic of each node lives in a small module here, testable without DDS; the binaries in
//! `src/bin/` only wire it to [`dynlab_ros`] entities:
//!
//! | module | binary | what |
//! |---|---|---|
//! | [`record`] | `recorder` | topics discovered → rosbag2-compatible MCAP bag, flushed every second |
//! | [`play`] | `player` | bag → topics with original timing, `--rate`, `--loop`, `/clock` |
//! | [`mppi_pusher`] | `mppi_pusher` | when to push, hold off (stale pose) or stop (goal reached) |
//! | [`racer`] | `racer` | state estimate, known command delay (state predicted over it), when each command is due |
//! | [`stale`] | `racer`, `mppi_pusher` | when poses stop (steady clock), return, or restart their clock: each change reported once |
//! | [`start`] | all parameter-only nodes | command line, logging, shutdown flag, unknown-parameter warnings |
//! | [`probe`] | `dds_probe` | publish / receive `PoseStamped` and measure latency (benchmarks) |
#![warn(missing_docs)]

pub mod mppi_pusher;
pub mod play;
pub mod probe;
pub mod racer;
pub mod record;
pub mod stale;
pub mod start;

pub use start::{StartError, Started, start_node};
