//! rosbag2-compatible MCAP bags: writing, reading, `metadata.yaml`.
//!
//! [`BagWriter`] writes a bag directory exactly as rosbag2 (Jazzy) does with MCAP storage, so
//! `ros2 bag play`, Foxglove, PlotJuggler, `rosbags` and `mcap-ros2-support` read it; it flushes
//! whole chunks at least every second of log time, so a recorder that dies leaves a bag that
//! reads up to its last chunk. [`Bag`] reads a bag directory or a bare `.mcap` file as typed,
//! time-ordered messages, recovering everything before any damage and saying what happened
//! ([`Bag::recovery`]).
//!
//! ```
//! use dynlab_bag::{Bag, BagWriter, QosProfile, WriterOptions};
//! use dynlab_msgs::geometry_msgs::PoseStamped;
//!
//! let tmp = tempfile::tempdir()?;
//! let dir = tmp.path().join("car_run");
//! let mut w = BagWriter::create(&dir, WriterOptions::default())?;
//! let pose = w.add_typed_topic::<PoseStamped>("/car/pose", &[QosProfile::sensor_data()])?;
//! w.write(pose, 5_000_000_000, &PoseStamped::default())?;
//! w.finish()?;
//!
//! let bag = Bag::open(&dir)?;
//! let err = bag.read::<PoseStamped>("/car/cmd").unwrap_err();
//! assert!(err.to_string().contains("has /car/pose [geometry_msgs/msg/PoseStamped, 1 msgs]"));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]

mod error;
mod metadata;
mod qos;
mod reader;
mod repair;
pub mod tf;
mod type_hash;
mod writer;

pub use error::{BagError, TopicSummary};
pub use metadata::METADATA_VERSION;
pub use qos::{Durability, History, Liveliness, QosDuration, QosProfile, Reliability};
pub use reader::{
    Bag, BagInfo, Declared, FileInfo, FileRecovery, RawMessage, Recovery, SkippedChunk, Stamped,
    TopicInfo,
};
pub use repair::{DroppedMessage, RepairOptions, RepairReport, TopicRepair, repair};
pub use type_hash::rihs01;
pub use writer::{BagSummary, BagWriter, Compression, TopicId, WriterOptions};
