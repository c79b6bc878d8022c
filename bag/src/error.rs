//! The error type of this crate.

use std::path::PathBuf;

use dynlab_msgs::CdrError;

/// One topic as named in an error message: name, type and message count.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicSummary {
    /// Topic name, e.g. `/car/pose`.
    pub name: String,
    /// ROS type name, e.g. `geometry_msgs/msg/PoseStamped`.
    pub type_name: String,
    /// Messages on the topic.
    pub count: u64,
}

/// Lists topics as `/a [pkg/msg/A, 12 msgs], /b [pkg/msg/B, 3 msgs]` (or `no topics`).
pub(crate) fn list_topics(topics: &[TopicSummary]) -> String {
    if topics.is_empty() {
        return "no topics".to_string();
    }
    topics
        .iter()
        .map(|t| format!("{} [{}, {} msgs]", t.name, t.type_name, t.count))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Everything that can go wrong writing or reading a bag. Each message names the problem, what
/// was readable, and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// A file system operation failed.
    #[error("{action} {}: {source}", path.display())]
    Io {
        /// What was being done (`creating bag directory`, `reading`, …).
        action: &'static str,
        /// The file or directory involved.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// [`crate::BagWriter::create`] was pointed at a directory that already has files in it.
    #[error(
        "bag directory {} already exists and is not empty: choose a new directory name \
         (rosbag2 never writes into an existing bag)",
        .0.display()
    )]
    DirectoryNotEmpty(PathBuf),
    /// The bag path has no usable directory name to derive the `.mcap` file name from.
    #[error("{} cannot be a bag directory: give a path that ends in a directory name", .0.display())]
    BadBagPath(PathBuf),
    /// The MCAP library refused a write.
    #[error("writing {}: {source}", path.display())]
    Mcap {
        /// The `.mcap` file being written.
        path: PathBuf,
        /// What the `mcap` crate reported.
        source: mcap::McapError,
    },
    /// A topic was added twice with different types.
    #[error(
        "topic {topic} is already in this bag as {existing}, cannot add it again as {requested}: \
         one topic carries one type; record the other type under another topic name"
    )]
    TopicTypeConflict {
        /// The topic.
        topic: String,
        /// The type it was first added with.
        existing: String,
        /// The type of the second attempt.
        requested: String,
    },
    /// A topic name or type name is not valid.
    #[error("{0}")]
    InvalidName(String),
    /// A [`crate::TopicId`] that this writer did not hand out.
    #[error("topic id {0} was not returned by add_topic on this writer")]
    UnknownTopicId(usize),
    /// A message was written (or read) as a type other than the topic's type.
    #[error(
        "topic {topic} carries {actual}, not {requested}: read it as {actual}, or pick the topic \
         that carries {requested}"
    )]
    TypeMismatch {
        /// The topic.
        topic: String,
        /// The type the topic carries.
        actual: String,
        /// The type asked for.
        requested: String,
    },
    /// Encoding a message for writing failed.
    #[error("encoding a message for topic {topic}: {source}")]
    Encode {
        /// The topic.
        topic: String,
        /// What the CDR encoder reported.
        source: CdrError,
    },
    /// A message in the bag did not decode as its topic's type.
    #[error(
        "message {index} on topic {topic} (log time {log_time_ns} ns) does not decode: {source}; \
         the bag may be damaged or the schema may not match the data"
    )]
    Decode {
        /// The topic.
        topic: String,
        /// Index of the message within its topic (0 = first).
        index: usize,
        /// Its log time.
        log_time_ns: u64,
        /// What the CDR decoder reported.
        source: CdrError,
    },
    /// A topic the caller needs is not in the bag.
    #[error(
        "topic {topic} not in bag {} (has {}); record it, or give the name it was recorded under \
         (e.g. a remapped topic)",
        bag.display(), list_topics(available)
    )]
    MissingTopic {
        /// The topic asked for.
        topic: String,
        /// The bag.
        bag: PathBuf,
        /// The topics that are in the bag.
        available: Vec<TopicSummary>,
    },
    /// The path holds no bag at all.
    #[error("{}: {reason}", path.display())]
    NotABag {
        /// The path given.
        path: PathBuf,
        /// Why it is not a bag and what to give instead.
        reason: String,
    },
    /// The bag exists but nothing in it could be read.
    #[error("nothing readable in bag {}: {details}", path.display())]
    Unreadable {
        /// The bag.
        path: PathBuf,
        /// Per file, what was found and where reading stopped.
        details: String,
    },
    /// `metadata.yaml` is present but cannot be used.
    #[error(
        "{}: {reason}; delete or repair it to read the bag from its .mcap files alone",
        path.display()
    )]
    BadMetadata {
        /// The metadata file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
}

impl BagError {
    pub(crate) fn io(
        action: &'static str,
        path: impl Into<PathBuf>,
        source: std::io::Error,
    ) -> Self {
        BagError::Io {
            action,
            path: path.into(),
            source,
        }
    }
}
