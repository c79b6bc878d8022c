//! [`Bag`]: reads a bag as typed, time-ordered messages, recovering what it can from damaged
//! files.
//!
//! Reading is linear over the whole file (read into memory), record by record, without trusting
//! the summary section: a file cut anywhere, with a half-written record, a bad chunk CRC or
//! garbage still yields every message before the damage. A chunk counts only when it is complete
//! and its CRC (when written) matches, so the messages recovered from a cut file are exactly the
//! messages of the chunks written before the cut. A chunk that is damaged inside but whose
//! framing is intact is skipped and reading goes on after it.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

use dynlab_msgs::RosMessage;
use mcap::records::{Record, op};

use crate::error::{BagError, TopicSummary};
use crate::metadata::read_metadata;
use crate::qos::QosProfile;

/// One topic of a bag, with what is known about it.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    /// Topic name, e.g. `/car/pose`.
    pub name: String,
    /// ROS type name from the schema, e.g. `geometry_msgs/msg/PoseStamped` (empty when the
    /// channel has no schema).
    pub type_name: String,
    /// Schema encoding (`ros2msg` for rosbag2 bags).
    pub schema_encoding: String,
    /// The full schema text (the type's definition followed by its dependencies).
    pub definition: String,
    /// Message encoding (`cdr`).
    pub message_encoding: String,
    /// The offered QoS profiles recorded with the topic (empty when none or unreadable).
    pub qos: Vec<QosProfile>,
    /// The RIHS01 type hash recorded with the topic (empty when none).
    pub type_hash: String,
    /// Messages read.
    pub count: u64,
    /// Log time of the earliest message.
    pub first_ns: Option<u64>,
    /// Log time of the latest message.
    pub last_ns: Option<u64>,
}

impl TopicInfo {
    /// Mean message rate over the topic's span, `(count − 1) / (last − first)`; `None` with
    /// fewer than two messages or a zero span.
    pub fn rate_hz(&self) -> Option<f64> {
        let (first, last) = (self.first_ns?, self.last_ns?);
        (self.count >= 2 && last > first)
            .then(|| (self.count - 1) as f64 / ((last - first) as f64 * 1e-9))
    }
}

/// One `.mcap` file of a bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileInfo {
    /// Path of the file.
    pub path: PathBuf,
    /// Size in bytes.
    pub bytes: u64,
    /// Messages read from it.
    pub message_count: u64,
    /// Chunks read whole from it (damaged chunks not counted).
    pub chunks: u64,
    /// Whether the file ended properly (footer and closing magic).
    pub complete: bool,
}

/// A chunk that was skipped because its content was damaged while the records around it were
/// intact.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkippedChunk {
    /// Byte offset of the chunk record.
    pub offset: u64,
    /// What was wrong.
    pub reason: String,
}

/// How reading one damaged file went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileRecovery {
    /// The file.
    pub path: PathBuf,
    /// Its size in bytes.
    pub file_bytes: u64,
    /// Bytes from the start up to the end of the last record that was read.
    pub readable_bytes: u64,
    /// Messages recovered from the file.
    pub messages: u64,
    /// Chunks read whole.
    pub chunks: u64,
    /// The chunk count the file's statistics record declares, when that record was readable
    /// (a cut file has lost it).
    pub declared_chunks: Option<u64>,
    /// Where reading stopped (byte offset), if it stopped before the end of the data.
    pub stopped_at: Option<u64>,
    /// Why reading stopped, or what was missing.
    pub reason: String,
    /// Damaged chunks skipped on the way.
    pub skipped_chunks: Vec<SkippedChunk>,
}

/// What a bag says it holds: from `metadata.yaml` (messages, start, duration) and the files'
/// statistics records (chunks). Each is `None` when nothing readable declares it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Declared {
    /// Messages `metadata.yaml` lists (only when it lists every file and all are present).
    pub messages: Option<u64>,
    /// Log time of the first message, from `metadata.yaml`.
    pub start_ns: Option<u64>,
    /// Time from first to last message, from `metadata.yaml`.
    pub duration_ns: Option<u64>,
    /// Chunks, summed over the files whose statistics record was readable (only when every
    /// file's was).
    pub chunks: Option<u64>,
}

/// For a damaged bag: how much was readable, where and why reading stopped.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Recovery {
    /// Messages recovered in total.
    pub messages: u64,
    /// Chunks read whole, over all files.
    pub chunks: u64,
    /// Damaged chunks skipped, over all files.
    pub skipped_chunks: u64,
    /// Log times of the first and last message recovered.
    pub span_ns: Option<(u64, u64)>,
    /// What the bag declares it holds, to compare with what was recovered.
    pub declared: Declared,
    /// The damaged files.
    pub files: Vec<FileRecovery>,
    /// Problems with the bag directory itself (missing or unusable `metadata.yaml`, missing
    /// files).
    pub notes: Vec<String>,
}

impl Recovery {
    /// One line: what was recovered against what the bag declares, e.g. `recovered 545 of 1800
    /// messages (30.3 %), 3 chunks (1 damaged chunk skipped), 3.017 s of 9.995 s`.
    pub fn summary(&self) -> String {
        let mut out = format!("recovered {}", self.messages);
        match self.declared.messages {
            Some(n) if n > 0 => out.push_str(&format!(
                " of {n} messages ({:.1} %)",
                100.0 * self.messages as f64 / n as f64
            )),
            _ => out.push_str(" messages"),
        }
        out.push_str(&format!(", {} chunks", self.chunks));
        if let Some(n) = self.declared.chunks {
            out.push_str(&format!(" of {n}"));
        }
        if self.skipped_chunks > 0 {
            out.push_str(&format!(
                " ({} damaged chunk{} skipped)",
                self.skipped_chunks,
                if self.skipped_chunks == 1 { "" } else { "s" }
            ));
        }
        let span = self.span_ns.map_or(0, |(a, b)| b - a);
        out.push_str(&format!(", {:.3} s", span as f64 * 1e-9));
        if let Some(d) = self.declared.duration_ns {
            out.push_str(&format!(" of {:.3} s", d as f64 * 1e-9));
        }
        out
    }
}

impl fmt::Display for Recovery {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "damaged bag: {}", self.summary())?;
        for note in &self.notes {
            writeln!(f, "  note: {note}")?;
        }
        for r in &self.files {
            write!(
                f,
                "  {}: {} messages from {} of {} bytes",
                r.path.display(),
                r.messages,
                r.readable_bytes,
                r.file_bytes
            )?;
            match r.stopped_at {
                Some(at) => writeln!(f, "; stopped at byte {at}: {}", r.reason)?,
                None => writeln!(f, "; {}", r.reason)?,
            }
            for s in &r.skipped_chunks {
                writeln!(f, "    skipped chunk at byte {}: {}", s.offset, s.reason)?;
            }
        }
        Ok(())
    }
}

/// One message of a bag, borrowed from it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawMessage<'a> {
    /// Topic name.
    pub topic: &'a str,
    /// ROS type name.
    pub type_name: &'a str,
    /// Time the recorder received the message.
    pub log_time_ns: u64,
    /// Time the message was published (as recorded).
    pub publish_time_ns: u64,
    /// The serialized message (CDR with its 4-byte encapsulation header).
    pub data: &'a [u8],
}

/// A decoded message with its bag times.
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped<T> {
    /// Time the recorder received the message.
    pub log_time_ns: u64,
    /// Time the message was published (as recorded).
    pub publish_time_ns: u64,
    /// The message.
    pub msg: T,
}

/// Everything [`Bag::info`] reports.
#[derive(Debug, Clone, PartialEq)]
pub struct BagInfo {
    /// The path the bag was opened from.
    pub path: PathBuf,
    /// Topics in order of first appearance.
    pub topics: Vec<TopicInfo>,
    /// Messages in the bag.
    pub message_count: u64,
    /// Earliest log time.
    pub start_ns: Option<u64>,
    /// Latest log time.
    pub end_ns: Option<u64>,
    /// `end − start` (0 for an empty bag).
    pub duration_ns: u64,
    /// The `.mcap` files read, in order.
    pub files: Vec<FileInfo>,
    /// Set for a damaged bag.
    pub recovery: Option<Recovery>,
}

fn fmt_stamp(ns: Option<u64>) -> String {
    match ns {
        Some(ns) => format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000),
        None => "-".to_string(),
    }
}

impl fmt::Display for BagInfo {
    /// A table of topics (type, count, rate, first and last stamp), the duration, the files and
    /// any recovery notes.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "bag:       {}", self.path.display())?;
        writeln!(
            f,
            "duration:  {:.3} s  ({} .. {})",
            self.duration_ns as f64 * 1e-9,
            fmt_stamp(self.start_ns),
            fmt_stamp(self.end_ns)
        )?;
        writeln!(f, "messages:  {}", self.message_count)?;
        let headers = [
            "topic",
            "type",
            "count",
            "rate Hz",
            "first stamp",
            "last stamp",
        ];
        let rows: Vec<[String; 6]> = self
            .topics
            .iter()
            .map(|t| {
                [
                    t.name.clone(),
                    t.type_name.clone(),
                    t.count.to_string(),
                    t.rate_hz()
                        .map(|r| format!("{r:.2}"))
                        .unwrap_or_else(|| "-".into()),
                    fmt_stamp(t.first_ns),
                    fmt_stamp(t.last_ns),
                ]
            })
            .collect();
        let mut widths = headers.map(str::len);
        for row in &rows {
            for (w, cell) in widths.iter_mut().zip(row) {
                *w = (*w).max(cell.chars().count());
            }
        }
        let line = |f: &mut fmt::Formatter<'_>, cells: [&str; 6]| -> fmt::Result {
            let [a, b, c, d, e, g] = cells;
            let [wa, wb, wc, wd, we, wg] = widths;
            let text = format!("{a:<wa$}  {b:<wb$}  {c:>wc$}  {d:>wd$}  {e:<we$}  {g:<wg$}");
            writeln!(f, "{}", text.trim_end())
        };
        writeln!(f)?;
        line(f, headers)?;
        for row in &rows {
            line(f, [&row[0], &row[1], &row[2], &row[3], &row[4], &row[5]])?;
        }
        writeln!(f)?;
        for file in &self.files {
            writeln!(
                f,
                "file:      {}  ({} bytes, {} messages{})",
                file.path.display(),
                file.bytes,
                file.message_count,
                if file.complete { "" } else { ", incomplete" }
            )?;
        }
        if let Some(r) = &self.recovery {
            write!(f, "{r}")?;
        }
        Ok(())
    }
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    topic: u32,
    log_time_ns: u64,
    publish_time_ns: u64,
    start: usize,
    len: usize,
}

/// A bag opened for reading: a bag directory (with or without `metadata.yaml`) or a bare
/// `.mcap` file, read whole into memory.
#[derive(Debug)]
pub struct Bag {
    path: PathBuf,
    topics: Vec<TopicInfo>,
    files: Vec<FileInfo>,
    entries: Vec<Entry>,
    data: Vec<u8>,
    recovery: Option<Recovery>,
}

/// Which `.mcap` files a path means, notes about the directory, and what `metadata.yaml`
/// declares (when it is used).
type ResolvedFiles = (Vec<PathBuf>, Vec<String>, Declared);

fn resolve_files(path: &Path) -> Result<ResolvedFiles, BagError> {
    let not_a_bag = |reason: String| BagError::NotABag {
        path: path.to_path_buf(),
        reason,
    };
    if !path.exists() {
        return Err(not_a_bag(
            "does not exist; give a bag directory (with metadata.yaml) or an .mcap file".into(),
        ));
    }
    if path.is_file() {
        return Ok((vec![path.to_path_buf()], Vec::new(), Declared::default()));
    }
    let mut notes = Vec::new();
    let meta_path = path.join("metadata.yaml");
    if meta_path.exists() {
        match read_metadata(&meta_path) {
            Ok(meta) => {
                if meta.version > u64::from(crate::METADATA_VERSION) {
                    notes.push(format!(
                        "metadata.yaml has version {}, newer than the {} this reader knows; \
                         the bag is read from its .mcap files",
                        meta.version,
                        crate::METADATA_VERSION
                    ));
                }
                // Like rosbag2 and rosbags, file names are taken relative to the bag directory.
                let listed: Vec<PathBuf> = meta
                    .relative_file_paths
                    .iter()
                    .map(|p| path.join(Path::new(p).file_name().unwrap_or(p.as_ref())))
                    .collect();
                let (present, missing): (Vec<_>, Vec<_>) =
                    listed.into_iter().partition(|p| p.is_file());
                if !missing.is_empty() {
                    notes.push(format!(
                        "metadata.yaml lists files that are missing: {}",
                        missing
                            .iter()
                            .map(|p| p.display().to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ));
                }
                if !present.is_empty() {
                    let declared = Declared {
                        messages: missing.is_empty().then_some(meta.message_count).flatten(),
                        start_ns: meta.starting_time_ns,
                        duration_ns: meta.duration_ns,
                        chunks: None,
                    };
                    return Ok((present, notes, declared));
                }
                if meta.relative_file_paths.is_empty() {
                    notes.push("metadata.yaml lists no files".into());
                }
            }
            Err(e @ BagError::BadMetadata { .. }) if e.to_string().contains("not supported") => {
                return Err(e);
            }
            Err(e) => notes.push(format!(
                "{e}; reading the .mcap files in the directory instead"
            )),
        }
    } else {
        notes.push(
            "no metadata.yaml (the recorder did not finish?); reading the .mcap files in the \
             directory"
                .into(),
        );
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(path)
        .map_err(|e| BagError::io("reading directory", path, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    // rosbag2 splits are <name>_<index>.mcap: order by that index, then by name.
    let index = |p: &PathBuf| -> (u64, String) {
        let stem = p
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_string();
        let n = stem
            .rsplit('_')
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap_or(u64::MAX);
        (n, stem)
    };
    found.sort_by_key(index);
    if found.is_empty() {
        return Err(not_a_bag(format!(
            "is a directory without .mcap files{}; give a bag directory written by rosbag2 or \
             dynlab, or an .mcap file",
            if meta_path.exists() {
                ""
            } else {
                " or metadata.yaml"
            }
        )));
    }
    Ok((found, notes, Declared::default()))
}

/// The largest uncompressed chunk this reader will inflate (rosbag2 chunks are 1–4 MiB).
const MAX_CHUNK_BYTES: u64 = 2 << 30;

/// Schemas and channels of one file, and the messages read.
struct FileReader<'b> {
    bag: &'b mut BagBuilder,
    schemas: HashMap<u16, (String, String, String)>,
    channels: HashMap<u16, u32>,
    messages: u64,
    chunks: u64,
}

#[derive(Default)]
struct BagBuilder {
    topics: Vec<TopicInfo>,
    topic_index: HashMap<(String, String), u32>,
    entries: Vec<Entry>,
    data: Vec<u8>,
}

/// A record from a chunk or the data section, kept until the chunk proves whole.
enum Pending {
    Schema(u16, String, String, String),
    Channel(mcap::records::Channel),
    Message(mcap::records::MessageHeader, Vec<u8>),
}

impl FileReader<'_> {
    fn to_pending(record: Record<'_>) -> Option<Pending> {
        match record {
            Record::Schema { header, data } => Some(Pending::Schema(
                header.id,
                header.name,
                header.encoding,
                String::from_utf8_lossy(&data).into_owned(),
            )),
            Record::Channel(c) => Some(Pending::Channel(c)),
            Record::Message { header, data } => Some(Pending::Message(header, data.into_owned())),
            _ => None,
        }
    }

    /// Checks a batch of records (one chunk) against the known schemas and channels without
    /// changing anything; `Err` names the first inconsistency.
    fn check(&self, batch: &[Pending]) -> Result<(), String> {
        let mut schemas: Vec<u16> = Vec::new();
        let mut channels: Vec<u16> = Vec::new();
        for p in batch {
            match p {
                Pending::Schema(id, ..) => schemas.push(*id),
                Pending::Channel(c) => {
                    if c.schema_id != 0
                        && !self.schemas.contains_key(&c.schema_id)
                        && !schemas.contains(&c.schema_id)
                    {
                        return Err(format!(
                            "channel {} ({}) refers to unknown schema {}",
                            c.id, c.topic, c.schema_id
                        ));
                    }
                    channels.push(c.id);
                }
                Pending::Message(h, _) => {
                    if !self.channels.contains_key(&h.channel_id)
                        && !channels.contains(&h.channel_id)
                    {
                        return Err(format!("message for unknown channel {}", h.channel_id));
                    }
                }
            }
        }
        Ok(())
    }

    fn apply(&mut self, batch: Vec<Pending>) {
        for p in batch {
            match p {
                Pending::Schema(id, name, encoding, text) => {
                    self.schemas.entry(id).or_insert((name, encoding, text));
                }
                Pending::Channel(c) => {
                    if self.channels.contains_key(&c.id) {
                        continue;
                    }
                    let (type_name, encoding, definition) =
                        self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                    let key = (c.topic.clone(), type_name.clone());
                    let next = self.bag.topics.len() as u32;
                    let idx = *self.bag.topic_index.entry(key).or_insert(next);
                    if idx == next {
                        let qos = c
                            .metadata
                            .get("offered_qos_profiles")
                            .and_then(|t| QosProfile::list_from_yaml_text(t).ok())
                            .unwrap_or_default();
                        self.bag.topics.push(TopicInfo {
                            name: c.topic.clone(),
                            type_name,
                            schema_encoding: encoding,
                            definition,
                            message_encoding: c.message_encoding.clone(),
                            qos,
                            type_hash: c
                                .metadata
                                .get("topic_type_hash")
                                .cloned()
                                .unwrap_or_default(),
                            count: 0,
                            first_ns: None,
                            last_ns: None,
                        });
                    }
                    self.channels.insert(c.id, idx);
                }
                Pending::Message(h, data) => {
                    let Some(&topic) = self.channels.get(&h.channel_id) else {
                        continue;
                    };
                    let t = &mut self.bag.topics[topic as usize];
                    t.count += 1;
                    t.first_ns = Some(t.first_ns.map_or(h.log_time, |f| f.min(h.log_time)));
                    t.last_ns = Some(t.last_ns.map_or(h.log_time, |l| l.max(h.log_time)));
                    self.bag.entries.push(Entry {
                        topic,
                        log_time_ns: h.log_time,
                        publish_time_ns: h.publish_time,
                        start: self.bag.data.len(),
                        len: data.len(),
                    });
                    self.bag.data.extend_from_slice(&data);
                    self.messages += 1;
                }
            }
        }
    }

    /// Reads the records of one chunk record body; `Err` says why the chunk is unusable.
    fn read_chunk(body: &[u8]) -> Result<Vec<Pending>, String> {
        let record = mcap::parse_record(op::CHUNK, body).map_err(|e| format!("bad chunk: {e}"))?;
        let Record::Chunk { header, data } = record else {
            return Err("bad chunk record".into());
        };
        if header.uncompressed_size > MAX_CHUNK_BYTES {
            return Err(format!(
                "chunk claims {} uncompressed bytes (more than this reader accepts)",
                header.uncompressed_size
            ));
        }
        if header.compression.is_empty() && header.uncompressed_size != header.compressed_size {
            return Err("uncompressed chunk whose sizes disagree".into());
        }
        let records = decompress_chunk(&header.compression, &data, header.uncompressed_size)?;
        if header.uncompressed_crc != 0 {
            let computed = crc32fast::hash(&records);
            if computed != header.uncompressed_crc {
                return Err(format!(
                    "chunk CRC mismatch (stored {:08x}, computed {computed:08x}): the chunk's \
                     bytes were changed",
                    header.uncompressed_crc
                ));
            }
        }
        let mut batch = Vec::new();
        let mut pos = 0usize;
        while pos < records.len() {
            let Some(head) = records.get(pos..pos + 9) else {
                return Err("chunk content ends inside a record header".into());
            };
            let mut len_bytes = [0u8; 8];
            len_bytes.copy_from_slice(&head[1..9]);
            let len = u64::from_le_bytes(len_bytes);
            if len > (records.len() - pos - 9) as u64 {
                return Err(format!(
                    "a {} record in the chunk claims {len} bytes, more than the chunk holds",
                    op_name(head[0])
                ));
            }
            let body = &records[pos + 9..pos + 9 + len as usize];
            if matches!(head[0], op::SCHEMA | op::CHANNEL | op::MESSAGE) {
                let record = mcap::parse_record(head[0], body)
                    .map_err(|e| format!("damaged {} record in chunk: {e}", op_name(head[0])))?;
                batch.extend(Self::to_pending(record));
            }
            pos += 9 + len as usize;
        }
        Ok(batch)
    }
}

/// The records of a chunk: decompressed with output bounded by the size the chunk header states
/// (a damaged header must not make the reader allocate more than the data yields).
fn decompress_chunk(compression: &str, data: &[u8], size: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let mut out = Vec::new();
    let result = match compression {
        "" => {
            out.extend_from_slice(data);
            Ok(0)
        }
        "zstd" => zstd::stream::read::Decoder::new(data)
            .and_then(|d| d.take(size.saturating_add(1)).read_to_end(&mut out)),
        "lz4" => lz4::Decoder::new(data)
            .and_then(|d| d.take(size.saturating_add(1)).read_to_end(&mut out)),
        other => {
            return Err(format!(
                "chunk compression `{other}` is not supported (only zstd, lz4 or none)"
            ));
        }
    };
    result.map_err(|e| format!("{compression} chunk does not decompress: {e}"))?;
    if out.len() as u64 != size {
        return Err(format!(
            "chunk decompresses to {} bytes, its header says {size}",
            out.len()
        ));
    }
    Ok(out)
}

/// Whether a record that starts at `pos` looks plausible (for resuming after a damaged chunk).
fn plausible_record_at(data: &[u8], pos: usize) -> bool {
    if pos == data.len() {
        return true;
    }
    let Some(head) = data.get(pos..pos + 9) else {
        return false;
    };
    let opcode = head[0];
    let len = u64::from_le_bytes(head[1..9].try_into().unwrap_or([0xff; 8]));
    (0x01..=0x0f).contains(&opcode) && len <= (data.len() - pos - 9) as u64
}

fn op_name(opcode: u8) -> String {
    let name = match opcode {
        op::HEADER => "header",
        op::FOOTER => "footer",
        op::SCHEMA => "schema",
        op::CHANNEL => "channel",
        op::MESSAGE => "message",
        op::CHUNK => "chunk",
        op::MESSAGE_INDEX => "message index",
        op::CHUNK_INDEX => "chunk index",
        op::ATTACHMENT => "attachment",
        op::ATTACHMENT_INDEX => "attachment index",
        op::STATISTICS => "statistics",
        op::METADATA => "metadata",
        op::METADATA_INDEX => "metadata index",
        op::SUMMARY_OFFSET => "summary offset",
        op::DATA_END => "data end",
        _ => return format!("opcode 0x{opcode:02x}"),
    };
    name.to_string()
}

/// Reads one file into `bag`; returns its info, its recovery record if damaged, and the chunk
/// count its statistics record declares (when readable).
fn read_file(
    bag: &mut BagBuilder,
    path: &Path,
    data: &[u8],
) -> (FileInfo, Option<FileRecovery>, Option<u64>) {
    let mut fr = FileReader {
        bag,
        schemas: HashMap::new(),
        channels: HashMap::new(),
        messages: 0,
        chunks: 0,
    };
    let mut skipped = Vec::new();
    let mut declared_chunks = None;
    let len = data.len();
    let mut pos = 0usize;
    let mut complete = false;
    let mut data_end = false;
    let mut stop: Option<(Option<u64>, String)> = None;
    if len == 0 {
        stop = Some((Some(0), "the file is empty".into()));
    } else if len < mcap::MAGIC.len() || &data[..mcap::MAGIC.len()] != mcap::MAGIC {
        let what = if mcap::MAGIC.starts_with(data) {
            "the file ends inside the MCAP magic bytes"
        } else {
            "not an MCAP file (it does not start with the MCAP magic bytes)"
        };
        stop = Some((Some(0), what.into()));
    } else {
        pos = mcap::MAGIC.len();
    }
    while stop.is_none() {
        if pos == len {
            stop = Some((
                None,
                if data_end {
                    "the file ends without its footer (the summary was cut off); all data was read"
                        .into()
                } else {
                    "the file ends after its last complete record, without a summary or footer \
                     (the writer did not finish: killed or still recording?)"
                        .into()
                },
            ));
            break;
        }
        let Some(head) = data.get(pos..pos + 9) else {
            stop = Some((
                Some(pos as u64),
                format!(
                    "the file is cut inside a record header ({} bytes left)",
                    len - pos
                ),
            ));
            break;
        };
        let opcode = head[0];
        let mut len_bytes = [0u8; 8];
        len_bytes.copy_from_slice(&head[1..9]);
        let rec_len = u64::from_le_bytes(len_bytes);
        let available = (len - pos - 9) as u64;
        if opcode == 0 || (0x10..0x80).contains(&opcode) {
            stop = Some((
                Some(pos as u64),
                format!("invalid record opcode 0x{opcode:02x}: the file is corrupt from here"),
            ));
            break;
        }
        if rec_len > available {
            stop = Some((
                Some(pos as u64),
                format!(
                    "the file is cut inside a {} record ({rec_len} bytes long, {available} present)",
                    op_name(opcode)
                ),
            ));
            break;
        }
        let body = &data[pos + 9..pos + 9 + rec_len as usize];
        let next = pos + 9 + rec_len as usize;
        match opcode {
            op::CHUNK => match FileReader::read_chunk(body).and_then(|batch| {
                fr.check(&batch)?;
                Ok(batch)
            }) {
                Ok(batch) => {
                    fr.chunks += 1;
                    fr.apply(batch)
                }
                Err(reason) => {
                    if plausible_record_at(data, next) {
                        skipped.push(SkippedChunk {
                            offset: pos as u64,
                            reason,
                        });
                    } else {
                        stop = Some((Some(pos as u64), format!("damaged chunk: {reason}")));
                        break;
                    }
                }
            },
            op::SCHEMA | op::CHANNEL | op::MESSAGE => {
                match mcap::parse_record(opcode, body)
                    .map_err(|e| e.to_string())
                    .and_then(|r| {
                        let batch: Vec<Pending> = FileReader::to_pending(r).into_iter().collect();
                        fr.check(&batch)?;
                        Ok(batch)
                    }) {
                    Ok(batch) => {
                        // Schemas and channels repeat in the summary section; only data-section
                        // messages count (a message record never appears in the summary).
                        fr.apply(batch)
                    }
                    Err(reason) => {
                        stop = Some((
                            Some(pos as u64),
                            format!("damaged {} record: {reason}", op_name(opcode)),
                        ));
                        break;
                    }
                }
            }
            op::DATA_END => data_end = true,
            op::STATISTICS => {
                if let Ok(Record::Statistics(st)) = mcap::parse_record(opcode, body) {
                    declared_chunks = Some(u64::from(st.chunk_count));
                }
            }
            op::FOOTER => {
                let end = next + mcap::MAGIC.len();
                if data.get(next..end) == Some(mcap::MAGIC) {
                    complete = true;
                    pos = end;
                } else {
                    stop = Some((
                        None,
                        "the footer is not followed by the closing magic bytes; all data was read"
                            .into(),
                    ));
                    pos = next;
                }
                break;
            }
            // Headers, indexes, statistics, metadata, attachments and private records carry no
            // messages.
            _ => {}
        }
        pos = next;
    }
    if data_end && let Some((Some(_), reason)) = &mut stop {
        reason.push_str(
            " (after the data section: every message was read, only the summary is damaged)",
        );
    }
    let readable = if stop.as_ref().is_some_and(|(at, _)| at.is_some()) {
        stop.as_ref().and_then(|(at, _)| *at).unwrap_or(0)
    } else {
        pos as u64
    };
    let info = FileInfo {
        path: path.to_path_buf(),
        bytes: len as u64,
        message_count: fr.messages,
        chunks: fr.chunks,
        complete,
    };
    let recovery = (stop.is_some() || !skipped.is_empty()).then(|| {
        let (stopped_at, reason) = stop.unwrap_or((None, "some chunks were damaged".into()));
        FileRecovery {
            path: path.to_path_buf(),
            file_bytes: len as u64,
            readable_bytes: readable,
            messages: fr.messages,
            chunks: fr.chunks,
            declared_chunks,
            stopped_at,
            reason,
            skipped_chunks: skipped,
        }
    });
    (info, recovery, declared_chunks)
}

impl Bag {
    /// Opens a bag directory (reading the files `metadata.yaml` lists, or every `.mcap` file
    /// when there is none) or a single `.mcap` file. Damaged files are read up to the damage and
    /// reported by [`Bag::recovery`]; the result is an error only when nothing at all could be
    /// read.
    pub fn open(path: impl AsRef<Path>) -> Result<Bag, BagError> {
        let path = path.as_ref();
        let (files, mut notes, mut declared) = resolve_files(path)?;
        let listed_count = declared.messages;
        let mut builder = BagBuilder::default();
        let mut infos = Vec::new();
        let mut damaged = Vec::new();
        let mut declared_chunks = Some(0u64);
        for file in &files {
            let data = std::fs::read(file).map_err(|e| BagError::io("reading", file, e))?;
            let (info, recovery, chunks) = read_file(&mut builder, file, &data);
            declared_chunks = declared_chunks.zip(chunks).map(|(a, b)| a + b);
            infos.push(info);
            damaged.extend(recovery);
        }
        declared.chunks = declared_chunks;
        let total = builder.entries.len() as u64;
        let chunks = infos.iter().map(|i| i.chunks).sum();
        let skipped_chunks = damaged
            .iter()
            .map(|r: &FileRecovery| r.skipped_chunks.len() as u64)
            .sum();
        if total == 0 && !damaged.is_empty() {
            let recovery = Recovery {
                messages: 0,
                chunks,
                skipped_chunks,
                span_ns: None,
                declared,
                files: damaged,
                notes,
            };
            let mut details: Vec<String> = recovery
                .files
                .iter()
                .map(|r| {
                    format!(
                        "{}: {} ({} of {} bytes readable)",
                        r.path.display(),
                        r.reason,
                        r.readable_bytes,
                        r.file_bytes
                    )
                })
                .collect();
            details.extend(recovery.notes.iter().cloned());
            return Err(BagError::Unreadable {
                path: path.to_path_buf(),
                details: details.join("; "),
            });
        }
        if let Some(listed) = listed_count
            && listed != total
        {
            notes.push(format!(
                "metadata.yaml lists {listed} messages, {total} were readable from the files"
            ));
        }
        builder.entries.sort_by_key(|e| e.log_time_ns);
        let span_ns = builder
            .entries
            .first()
            .zip(builder.entries.last())
            .map(|(a, b)| (a.log_time_ns, b.log_time_ns));
        let recovery = (!damaged.is_empty() || !notes.is_empty()).then_some(Recovery {
            messages: total,
            chunks,
            skipped_chunks,
            span_ns,
            declared,
            files: damaged,
            notes,
        });
        Ok(Bag {
            path: path.to_path_buf(),
            topics: builder.topics,
            files: infos,
            entries: builder.entries,
            data: builder.data,
            recovery,
        })
    }

    /// The path the bag was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of messages in the bag.
    pub fn message_count(&self) -> u64 {
        self.entries.len() as u64
    }

    /// Topics, types, counts, times, rates, files and recovery notes.
    pub fn info(&self) -> BagInfo {
        let start_ns = self.entries.first().map(|e| e.log_time_ns);
        let end_ns = self.entries.last().map(|e| e.log_time_ns);
        BagInfo {
            path: self.path.clone(),
            topics: self.topics.clone(),
            message_count: self.message_count(),
            start_ns,
            end_ns,
            duration_ns: end_ns.zip(start_ns).map(|(e, s)| e - s).unwrap_or(0),
            files: self.files.clone(),
            recovery: self.recovery.clone(),
        }
    }

    /// The topics, in order of first appearance.
    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    /// Looks up a topic by name.
    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    fn raw(&self, e: &Entry) -> RawMessage<'_> {
        let t = &self.topics[e.topic as usize];
        RawMessage {
            topic: &t.name,
            type_name: &t.type_name,
            log_time_ns: e.log_time_ns,
            publish_time_ns: e.publish_time_ns,
            data: &self.data[e.start..e.start + e.len],
        }
    }

    /// All messages of all topics, ordered by log time; messages with equal log times keep
    /// their order in the files.
    pub fn messages(&self) -> impl Iterator<Item = RawMessage<'_>> {
        self.entries.iter().map(|e| self.raw(e))
    }

    /// The messages of `topic` in log-time order, still serialized.
    pub fn raw_messages<'a>(
        &'a self,
        topic: &str,
    ) -> Result<impl Iterator<Item = RawMessage<'a>> + 'a, BagError> {
        let indices: Vec<u32> = self
            .topics
            .iter()
            .enumerate()
            .filter(|(_, t)| t.name == topic)
            .map(|(i, _)| i as u32)
            .collect();
        if indices.is_empty() {
            return Err(self.missing_topic(topic));
        }
        Ok(self
            .entries
            .iter()
            .filter(move |e| indices.contains(&e.topic))
            .map(|e| self.raw(e)))
    }

    fn missing_topic(&self, topic: &str) -> BagError {
        BagError::MissingTopic {
            topic: topic.to_string(),
            bag: self.path.clone(),
            available: self
                .topics
                .iter()
                .map(|t| TopicSummary {
                    name: t.name.clone(),
                    type_name: t.type_name.clone(),
                    count: t.count,
                })
                .collect(),
        }
    }

    /// Decodes every message of `topic` as `T`, in log-time order. Errors if the topic is not in
    /// the bag (naming the topics that are), if it carries another type, or if a message does
    /// not decode (naming its index and time).
    pub fn read<T: RosMessage>(&self, topic: &str) -> Result<Vec<Stamped<T>>, BagError> {
        let candidates: Vec<(usize, &TopicInfo)> = self
            .topics
            .iter()
            .enumerate()
            .filter(|(_, t)| t.name == topic)
            .collect();
        let Some(&(idx, _)) = candidates.iter().find(|(_, t)| t.type_name == T::TYPE_NAME) else {
            return Err(match candidates.first() {
                None => self.missing_topic(topic),
                Some((_, t)) => BagError::TypeMismatch {
                    topic: topic.to_string(),
                    actual: t.type_name.clone(),
                    requested: T::TYPE_NAME.to_string(),
                },
            });
        };
        self.entries
            .iter()
            .filter(|e| e.topic as usize == idx)
            .enumerate()
            .map(|(index, e)| {
                let raw = self.raw(e);
                dynlab_msgs::from_cdr::<T>(raw.data)
                    .map(|msg| Stamped {
                        log_time_ns: e.log_time_ns,
                        publish_time_ns: e.publish_time_ns,
                        msg,
                    })
                    .map_err(|source| BagError::Decode {
                        topic: topic.to_string(),
                        index,
                        log_time_ns: e.log_time_ns,
                        source,
                    })
            })
            .collect()
    }

    /// Checks that every topic in `topics` is present; the error names the first missing one and
    /// lists the topics the bag has.
    pub fn require_topics(&self, topics: &[&str]) -> Result<(), BagError> {
        match topics.iter().find(|t| self.topic(t).is_none()) {
            Some(t) => Err(self.missing_topic(t)),
            None => Ok(()),
        }
    }

    /// For a damaged bag (or a bag directory with a missing or unusable `metadata.yaml`): how
    /// many messages were readable, where and why reading stopped. `None` for a sound bag.
    pub fn recovery(&self) -> Option<&Recovery> {
        self.recovery.as_ref()
    }
}
