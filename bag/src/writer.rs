//! [`BagWriter`]: writes a bag directory the way rosbag2 Jazzy's MCAP storage does.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use dynlab_msgs::RosMessage;

use crate::error::BagError;
use crate::metadata::{Metadata, MetadataFile, MetadataTopic};
use crate::qos::QosProfile;
use crate::type_hash::rihs01;

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// zstd, as rosbag2's `zstd_fast` / `zstd_small` presets write (the default here: a
    /// PoseStamped bag is 2.2× smaller than uncompressed and writes at about half the speed; see
    /// `bag/benches/bag_write.rs`).
    #[default]
    Zstd,
    /// Uncompressed chunks (rosbag2's own default).
    None,
}

/// How a [`BagWriter`] writes. Every field has a documented default.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriterOptions {
    /// Chunk compression. Default [`Compression::Zstd`].
    pub compression: Compression,
    /// Uncompressed bytes after which a chunk is closed and written. Default 1 MiB (the MCAP
    /// libraries' default); smaller chunks lose less data when the writer dies.
    pub chunk_size: u64,
    /// Log time after which an open chunk is closed even if it is not full, so a slow topic
    /// still reaches the file. Default 1 s.
    pub max_chunk_interval_ns: u64,
    /// The ROS distribution recorded in `metadata.yaml`. Default `jazzy`.
    pub ros_distro: String,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            compression: Compression::Zstd,
            chunk_size: 1024 * 1024,
            max_chunk_interval_ns: 1_000_000_000,
            ros_distro: "jazzy".to_string(),
        }
    }
}

/// A topic added to a [`BagWriter`]; pass it to [`BagWriter::write`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TopicId(usize);

/// What a finished bag holds.
#[derive(Debug, Clone, PartialEq)]
pub struct BagSummary {
    /// The bag directory.
    pub dir: PathBuf,
    /// The `.mcap` file.
    pub mcap_path: PathBuf,
    /// Messages written.
    pub message_count: u64,
    /// Per topic: name, type, message count.
    pub topics: Vec<(String, String, u64)>,
    /// Earliest log time (0 when empty).
    pub start_ns: u64,
    /// Latest log time (0 when empty).
    pub end_ns: u64,
    /// Size of the `.mcap` file in bytes.
    pub file_bytes: u64,
    /// Chunks written.
    pub chunk_count: u32,
}

struct WriterTopic {
    name: String,
    type_name: String,
    channel_id: u16,
    qos: Vec<QosProfile>,
    type_hash: String,
    count: u64,
}

/// The `.mcap` file: buffered writes plus a second handle for `fsync`.
struct McapFile {
    buf: BufWriter<File>,
}

impl Write for McapFile {
    fn write(&mut self, data: &[u8]) -> std::io::Result<usize> {
        self.buf.write(data)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.buf.flush()
    }
}

impl Seek for McapFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.buf.seek(pos)
    }
}

/// Writes a bag directory `<dir>/<dirname>_0.mcap` + `<dir>/metadata.yaml` as rosbag2 Jazzy
/// does: MCAP profile `ros2`, one `ros2msg` schema per type (the full definition with
/// dependencies), one `cdr` channel per topic with `offered_qos_profiles` and `topic_type_hash`
/// metadata, compressed chunks with message indexes, a summary with statistics, and a `rosbag2`
/// metadata record holding the serialized bag metadata.
///
/// Crash safety: chunks are buffered in memory and written whole, so the file only ever holds
/// complete chunks plus at most one partly written record at its end. A chunk is closed when it
/// reaches [`WriterOptions::chunk_size`] or when [`WriterOptions::max_chunk_interval_ns`] of
/// log time has passed since it opened; [`BagWriter::flush`] additionally fsyncs and rewrites
/// `metadata.yaml` (atomically), so a writer killed after a flush leaves a bag that reads up to
/// that flush. Dropping a writer without [`BagWriter::finish`] finishes the file on a best
/// effort basis; call `finish` to see errors.
///
/// ```
/// use dynlab_bag::{Bag, BagWriter, QosProfile, WriterOptions};
/// use dynlab_msgs::geometry_msgs::PoseStamped;
///
/// let dir = tempfile::tempdir()?;
/// let bag_dir = dir.path().join("push_run");
/// let mut writer = BagWriter::create(&bag_dir, WriterOptions::default())?;
/// let pose = writer.add_typed_topic::<PoseStamped>("/push/block_pose", &[QosProfile::sensor_data()])?;
/// for i in 0..10u64 {
///     let mut msg = PoseStamped::default();
///     msg.pose.position.x = i as f64 * 0.01;
///     writer.write(pose, 1_000_000_000 + i * 10_000_000, &msg)?;
/// }
/// let summary = writer.finish()?;
/// assert_eq!(summary.message_count, 10);
///
/// let bag = Bag::open(&bag_dir)?;
/// let poses = bag.read::<PoseStamped>("/push/block_pose")?;
/// assert_eq!(poses.len(), 10);
/// assert_eq!(poses[3].msg.pose.position.x, 0.03);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct BagWriter {
    dir: PathBuf,
    file_name: String,
    mcap_path: PathBuf,
    sync_handle: File,
    writer: Option<mcap::Writer<McapFile>>,
    options: WriterOptions,
    topics: Vec<WriterTopic>,
    schemas: BTreeMap<String, u16>,
    chunk_opened_at: Option<u64>,
    bounds: Option<(u64, u64)>,
    message_count: u64,
}

/// A topic name as ROS 2 accepts it (absolute or relative, `[A-Za-z0-9_/~{}]`).
fn check_topic_name(topic: &str) -> Result<(), BagError> {
    let ok = !topic.is_empty()
        && !topic.ends_with('/')
        && !topic.contains("//")
        && topic
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_/~{}".contains(c));
    if ok {
        Ok(())
    } else {
        Err(BagError::InvalidName(format!(
            "`{topic}` is not a ROS 2 topic name: use letters, digits, `_` and `/` separators, \
             e.g. /car/pose"
        )))
    }
}

fn check_type_name(type_name: &str) -> Result<(), BagError> {
    let parts: Vec<&str> = type_name.split('/').collect();
    let ok = parts.len() == 3
        && parts
            .iter()
            .all(|p| !p.is_empty() && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'));
    if ok {
        Ok(())
    } else {
        Err(BagError::InvalidName(format!(
            "`{type_name}` is not a ROS 2 type name: expected package/msg/Type, e.g. \
             geometry_msgs/msg/PoseStamped"
        )))
    }
}

impl BagWriter {
    /// Creates the bag directory `dir` (it must not exist, or be empty) and its `.mcap` file.
    pub fn create(dir: impl AsRef<Path>, options: WriterOptions) -> Result<Self, BagError> {
        let dir = dir.as_ref().to_path_buf();
        let name = dir
            .file_name()
            .and_then(|n| n.to_str())
            .filter(|n| !n.is_empty() && *n != "." && *n != "..")
            .ok_or_else(|| BagError::BadBagPath(dir.clone()))?
            .to_string();
        if dir.exists() {
            let mut entries =
                std::fs::read_dir(&dir).map_err(|e| BagError::io("reading directory", &dir, e))?;
            if entries.next().is_some() {
                return Err(BagError::DirectoryNotEmpty(dir));
            }
        } else {
            std::fs::create_dir_all(&dir)
                .map_err(|e| BagError::io("creating bag directory", &dir, e))?;
        }
        let file_name = format!("{name}_0.mcap");
        let mcap_path = dir.join(&file_name);
        let file =
            File::create_new(&mcap_path).map_err(|e| BagError::io("creating", &mcap_path, e))?;
        let sync_handle = file
            .try_clone()
            .map_err(|e| BagError::io("opening", &mcap_path, e))?;
        let compression = match options.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::None => None,
        };
        let write_options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(format!(
                "dynlab-bag {} (mcap-rs)",
                env!("CARGO_PKG_VERSION")
            ))
            .compression(compression)
            .chunk_size(Some(options.chunk_size.max(1)))
            // Buffer each chunk in memory and write it whole: the file never holds a chunk
            // with placeholder lengths, so a killed writer leaves only complete chunks.
            .disable_seeking(true)
            // One compression thread: deterministic output and no thread pool on small machines.
            .compression_threads(0);
        let writer = write_options
            .create(McapFile {
                buf: BufWriter::with_capacity(1 << 16, file),
            })
            .map_err(|source| BagError::Mcap {
                path: mcap_path.clone(),
                source,
            })?;
        let bag = BagWriter {
            dir,
            file_name,
            mcap_path,
            sync_handle,
            writer: Some(writer),
            options,
            topics: Vec::new(),
            schemas: BTreeMap::new(),
            chunk_opened_at: None,
            bounds: None,
            message_count: 0,
        };
        bag.write_metadata_yaml()?;
        Ok(bag)
    }

    /// The bag directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn mcap_err(&self, source: mcap::McapError) -> BagError {
        BagError::Mcap {
            path: self.mcap_path.clone(),
            source,
        }
    }

    fn mcap(&mut self) -> Result<&mut mcap::Writer<McapFile>, BagError> {
        let path = self.mcap_path.clone();
        self.writer.as_mut().ok_or(BagError::Mcap {
            path,
            source: mcap::McapError::AttemptedWriteAfterFailure,
        })
    }

    /// Adds a topic of type `type_name` whose full `ros2msg` definition (own text, then each
    /// dependency) is `definition`, offered with `qos`. Adding the same topic again with the
    /// same type returns the same id.
    pub fn add_topic(
        &mut self,
        topic: &str,
        type_name: &str,
        definition: &str,
        qos: &[QosProfile],
    ) -> Result<TopicId, BagError> {
        check_topic_name(topic)?;
        check_type_name(type_name)?;
        if let Some(i) = self.topics.iter().position(|t| t.name == topic) {
            let existing = &self.topics[i];
            if existing.type_name != type_name {
                return Err(BagError::TopicTypeConflict {
                    topic: topic.to_string(),
                    existing: existing.type_name.clone(),
                    requested: type_name.to_string(),
                });
            }
            return Ok(TopicId(i));
        }
        let schema_id = match self.schemas.get(type_name) {
            Some(&id) => id,
            None => {
                let id = self
                    .mcap()?
                    .add_schema(type_name, "ros2msg", definition.as_bytes())
                    .map_err(|e| self.mcap_err(e))?;
                self.schemas.insert(type_name.to_string(), id);
                id
            }
        };
        // rosbag2 writes an empty hash when the type description is unknown.
        let type_hash = rihs01(type_name, definition).unwrap_or_default();
        let metadata = BTreeMap::from([
            (
                "offered_qos_profiles".to_string(),
                QosProfile::list_to_yaml(qos, 0),
            ),
            ("topic_type_hash".to_string(), type_hash.clone()),
        ]);
        let channel_id = self
            .mcap()?
            .add_channel(schema_id, topic, "cdr", &metadata)
            .map_err(|e| self.mcap_err(e))?;
        self.topics.push(WriterTopic {
            name: topic.to_string(),
            type_name: type_name.to_string(),
            channel_id,
            qos: qos.to_vec(),
            type_hash,
            count: 0,
        });
        Ok(TopicId(self.topics.len() - 1))
    }

    /// Adds a topic carrying `T`, with `T`'s type name and definition.
    pub fn add_typed_topic<T: RosMessage>(
        &mut self,
        topic: &str,
        qos: &[QosProfile],
    ) -> Result<TopicId, BagError> {
        self.add_topic(topic, T::TYPE_NAME, T::definition(), qos)
    }

    /// Writes one serialized message (CDR with its encapsulation header) received at
    /// `log_time_ns` and published at `publish_time_ns`.
    pub fn write_raw(
        &mut self,
        topic: TopicId,
        log_time_ns: u64,
        publish_time_ns: u64,
        cdr: &[u8],
    ) -> Result<(), BagError> {
        let t = self
            .topics
            .get(topic.0)
            .ok_or(BagError::UnknownTopicId(topic.0))?;
        let channel_id = t.channel_id;
        let sequence = u32::try_from(t.count + 1).unwrap_or(u32::MAX);
        if let Some(opened) = self.chunk_opened_at
            && log_time_ns.saturating_sub(opened) >= self.options.max_chunk_interval_ns
        {
            self.mcap()?.flush().map_err(|e| self.mcap_err(e))?;
            self.chunk_opened_at = None;
        }
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        self.mcap()?
            .write_to_known_channel(&header, cdr)
            .map_err(|e| self.mcap_err(e))?;
        if self.chunk_opened_at.is_none() {
            self.chunk_opened_at = Some(log_time_ns);
        }
        self.topics[topic.0].count += 1;
        self.message_count += 1;
        self.bounds = Some(match self.bounds {
            None => (log_time_ns, log_time_ns),
            Some((a, b)) => (a.min(log_time_ns), b.max(log_time_ns)),
        });
        Ok(())
    }

    /// Serializes `msg` and writes it with publish time = log time. The topic must carry `T`.
    pub fn write<T: RosMessage>(
        &mut self,
        topic: TopicId,
        log_time_ns: u64,
        msg: &T,
    ) -> Result<(), BagError> {
        let t = self
            .topics
            .get(topic.0)
            .ok_or(BagError::UnknownTopicId(topic.0))?;
        if t.type_name != T::TYPE_NAME {
            return Err(BagError::TypeMismatch {
                topic: t.name.clone(),
                actual: t.type_name.clone(),
                requested: T::TYPE_NAME.to_string(),
            });
        }
        let cdr = dynlab_msgs::to_cdr(msg).map_err(|source| BagError::Encode {
            topic: t.name.clone(),
            source,
        })?;
        self.write_raw(topic, log_time_ns, log_time_ns, &cdr)
    }

    /// Closes and writes the open chunk, fsyncs the file, and atomically rewrites
    /// `metadata.yaml`: a writer killed after this leaves a bag that reads up to here.
    pub fn flush(&mut self) -> Result<(), BagError> {
        self.mcap()?.flush().map_err(|e| self.mcap_err(e))?;
        self.chunk_opened_at = None;
        self.sync_handle
            .sync_data()
            .map_err(|e| BagError::io("syncing", &self.mcap_path, e))?;
        self.write_metadata_yaml()
    }

    fn metadata(&self) -> Metadata {
        let (start, end) = self.bounds.unwrap_or((0, 0));
        Metadata {
            duration_ns: end - start,
            starting_time_ns: start,
            message_count: self.message_count,
            topics: self
                .topics
                .iter()
                .map(|t| MetadataTopic {
                    name: t.name.clone(),
                    type_name: t.type_name.clone(),
                    qos: t.qos.clone(),
                    type_description_hash: t.type_hash.clone(),
                    message_count: t.count,
                })
                .collect(),
            files: vec![MetadataFile {
                path: self.file_name.clone(),
                starting_time_ns: start,
                duration_ns: end - start,
                message_count: self.message_count,
            }],
            ros_distro: self.options.ros_distro.clone(),
        }
    }

    fn write_metadata_yaml(&self) -> Result<(), BagError> {
        let path = self.dir.join("metadata.yaml");
        let tmp = self.dir.join(".metadata.yaml.tmp");
        let text = self.metadata().file_yaml();
        let write = || -> std::io::Result<()> {
            let mut f = File::create(&tmp)?;
            f.write_all(text.as_bytes())?;
            f.sync_data()?;
            std::fs::rename(&tmp, &path)
        };
        write().map_err(|e| BagError::io("writing", &path, e))
    }

    /// Writes the `rosbag2` metadata record, the summary section and footer, fsyncs, and writes
    /// the final `metadata.yaml`.
    pub fn finish(mut self) -> Result<BagSummary, BagError> {
        let metadata = self.metadata();
        let record = mcap::records::Metadata {
            name: "rosbag2".to_string(),
            metadata: BTreeMap::from([
                ("serialized_metadata".to_string(), metadata.body_yaml(0)),
                ("ROS_DISTRO".to_string(), self.options.ros_distro.clone()),
            ]),
        };
        let mut writer = self
            .writer
            .take()
            .ok_or_else(|| self.mcap_err(mcap::McapError::AttemptedWriteAfterFailure))?;
        writer
            .write_metadata(&record)
            .map_err(|e| self.mcap_err(e))?;
        let summary = writer.finish().map_err(|e| self.mcap_err(e))?;
        let mut file = writer.into_inner();
        file.flush()
            .map_err(|e| BagError::io("writing", &self.mcap_path, e))?;
        self.sync_handle
            .sync_all()
            .map_err(|e| BagError::io("syncing", &self.mcap_path, e))?;
        self.write_metadata_yaml()?;
        let file_bytes = std::fs::metadata(&self.mcap_path)
            .map_err(|e| BagError::io("reading", &self.mcap_path, e))?
            .len();
        let (start_ns, end_ns) = self.bounds.unwrap_or((0, 0));
        Ok(BagSummary {
            dir: self.dir.clone(),
            mcap_path: self.mcap_path.clone(),
            message_count: self.message_count,
            topics: self
                .topics
                .iter()
                .map(|t| (t.name.clone(), t.type_name.clone(), t.count))
                .collect(),
            start_ns,
            end_ns,
            file_bytes,
            chunk_count: summary.stats.map(|s| s.chunk_count).unwrap_or(0),
        })
    }
}

impl Drop for BagWriter {
    fn drop(&mut self) {
        // Best effort for a writer that was not finished: close the file cleanly. (`finish`
        // takes the mcap writer, so this does nothing after it.)
        if let Some(mut writer) = self.writer.take() {
            let _ = writer.finish();
            let mut file = writer.into_inner();
            let _ = file.flush();
            let _ = self.write_metadata_yaml();
        }
    }
}
