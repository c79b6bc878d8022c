//! [`repair`]: rewrites a damaged or truncated bag whole, as a fresh, valid bag.
//!
//! Everything the recovering reader ([`Bag::open`]) can read — every message of every chunk
//! before the damage and of every intact chunk after a skipped one — goes into a new bag
//! directory (MCAP with summary and footer, `metadata.yaml`) with the same topics, types,
//! definitions and offered QoS, the same log and publish times, in log-time order. Optionally,
//! messages with NaN or infinite fields (a motion capture reporting an occluded body) are dropped
//! and listed.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

use crate::error::BagError;
use crate::reader::{Bag, Recovery};
use crate::writer::{BagSummary, BagWriter, TopicId, WriterOptions};

/// How [`repair`] rewrites a bag.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RepairOptions {
    /// Drop messages with a NaN or infinite float field (any field of a type the
    /// `dynlab-msgs` registry knows; messages of other types are kept unchecked). Default off:
    /// every recovered message is kept.
    pub drop_nonfinite: bool,
    /// How the new bag is written (default: zstd chunks of 1 MiB).
    pub writer: WriterOptions,
}

/// What [`repair`] did to one topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicRepair {
    /// Topic name.
    pub name: String,
    /// ROS type name.
    pub type_name: String,
    /// Messages written to the new bag.
    pub kept: u64,
    /// Messages dropped for non-finite fields.
    pub dropped_nonfinite: u64,
    /// Messages dropped because they do not decode as their type (checked only with
    /// [`RepairOptions::drop_nonfinite`]).
    pub dropped_undecodable: u64,
    /// Whether the messages could be checked for non-finite fields (the type is known).
    pub checked: bool,
}

/// One dropped message, for the report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DroppedMessage {
    /// Topic.
    pub topic: String,
    /// Log time \[ns\].
    pub log_time_ns: u64,
    /// Why: the non-finite fields, or the decode error.
    pub reason: String,
}

/// What [`repair`] read, kept and dropped.
#[derive(Debug, Clone, PartialEq)]
pub struct RepairReport {
    /// The bag that was read.
    pub input: PathBuf,
    /// The recovering reader's account of the input (`None` when it was sound).
    pub recovery: Option<Recovery>,
    /// Messages read from the input.
    pub read: u64,
    /// Per topic, in the input's order.
    pub topics: Vec<TopicRepair>,
    /// Every dropped message, in log-time order.
    pub dropped: Vec<DroppedMessage>,
    /// The bag written.
    pub output: BagSummary,
}

impl RepairReport {
    /// Messages written.
    pub fn kept(&self) -> u64 {
        self.topics.iter().map(|t| t.kept).sum()
    }
}

impl fmt::Display for RepairReport {
    /// What was read (with the recovery summary of a damaged input), kept and dropped per topic,
    /// the first dropped messages, and the bag written.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.recovery {
            Some(r) => writeln!(
                f,
                "read {}: damaged bag: {}",
                self.input.display(),
                r.summary()
            )?,
            None => writeln!(
                f,
                "read {}: {} messages (the bag was not damaged)",
                self.input.display(),
                self.read
            )?,
        }
        let nonfinite: u64 = self.topics.iter().map(|t| t.dropped_nonfinite).sum();
        let undecodable: u64 = self.topics.iter().map(|t| t.dropped_undecodable).sum();
        write!(
            f,
            "kept {} of {} messages on {} topics",
            self.kept(),
            self.read,
            self.topics.len()
        )?;
        if nonfinite > 0 {
            write!(f, "; dropped {nonfinite} with non-finite fields")?;
        }
        if undecodable > 0 {
            write!(f, "; dropped {undecodable} that do not decode")?;
        }
        writeln!(f)?;
        let width = self.topics.iter().map(|t| t.name.len()).max().unwrap_or(0);
        let twidth = self
            .topics
            .iter()
            .map(|t| t.type_name.len())
            .max()
            .unwrap_or(0);
        for t in &self.topics {
            write!(
                f,
                "  {:<width$}  {:<twidth$}  kept {:>7}",
                t.name, t.type_name, t.kept
            )?;
            if t.dropped_nonfinite > 0 {
                write!(f, "  dropped {} (non-finite)", t.dropped_nonfinite)?;
            }
            if t.dropped_undecodable > 0 {
                write!(f, "  dropped {} (undecodable)", t.dropped_undecodable)?;
            }
            if !t.checked {
                write!(f, "  (type unknown: not checked)")?;
            }
            writeln!(f)?;
        }
        const SHOWN: usize = 10;
        for d in self.dropped.iter().take(SHOWN) {
            writeln!(
                f,
                "  dropped {} at {}.{:09}: {}",
                d.topic,
                d.log_time_ns / 1_000_000_000,
                d.log_time_ns % 1_000_000_000,
                d.reason
            )?;
        }
        if self.dropped.len() > SHOWN {
            writeln!(f, "  … and {} more", self.dropped.len() - SHOWN)?;
        }
        writeln!(
            f,
            "wrote {} ({} messages, {} chunks, {} bytes)",
            self.output.dir.display(),
            self.output.message_count,
            self.output.chunk_count,
            self.output.file_bytes
        )
    }
}

/// Rewrites the bag at `input` (a bag directory or an `.mcap` file, damaged or not) as a new bag
/// directory `output` (which must not exist or be empty): every message the recovering reader
/// can read, with its topic's type, definition and offered QoS, log and publish time; with
/// [`RepairOptions::drop_nonfinite`], messages with NaN or infinite fields are left out and
/// listed. Fails when nothing is readable, or when the output cannot be written (the partial
/// output directory is then removed if this call created it).
pub fn repair(
    input: impl AsRef<Path>,
    output: impl AsRef<Path>,
    options: &RepairOptions,
) -> Result<RepairReport, BagError> {
    let (input, output) = (input.as_ref(), output.as_ref());
    let bag = Bag::open(input)?;
    let existed = output.exists();
    let mut writer = BagWriter::create(output, options.writer.clone())?;
    match write_all(&bag, &mut writer, options) {
        Ok((topics, dropped)) => {
            let summary = writer.finish()?;
            Ok(RepairReport {
                input: input.to_path_buf(),
                recovery: bag.recovery().cloned(),
                read: bag.message_count(),
                topics,
                dropped,
                output: summary,
            })
        }
        Err(e) => {
            drop(writer);
            if !existed {
                let _ = std::fs::remove_dir_all(output);
            }
            Err(e)
        }
    }
}

type Written = (Vec<TopicRepair>, Vec<DroppedMessage>);

fn write_all(
    bag: &Bag,
    writer: &mut BagWriter,
    options: &RepairOptions,
) -> Result<Written, BagError> {
    let mut ids: HashMap<(&str, &str), (TopicId, usize)> = HashMap::new();
    let mut topics = Vec::new();
    for t in bag.topics() {
        let id = writer.add_topic(&t.name, &t.type_name, &t.definition, &t.qos)?;
        ids.insert((t.name.as_str(), t.type_name.as_str()), (id, topics.len()));
        topics.push(TopicRepair {
            name: t.name.clone(),
            type_name: t.type_name.clone(),
            kept: 0,
            dropped_nonfinite: 0,
            dropped_undecodable: 0,
            checked: dynlab_msgs::lookup(&t.type_name).is_some(),
        });
    }
    let mut dropped = Vec::new();
    for m in bag.messages() {
        let Some(&(id, index)) = ids.get(&(m.topic, m.type_name)) else {
            continue; // every message belongs to a listed topic
        };
        if options.drop_nonfinite
            && let Some(t) = dynlab_msgs::lookup(m.type_name)
        {
            let reason = match (t.non_finite_fields)(m.data) {
                Ok(fields) if fields.is_empty() => None,
                Ok(fields) => {
                    topics[index].dropped_nonfinite += 1;
                    Some(
                        fields
                            .iter()
                            .map(|f| f.to_string())
                            .collect::<Vec<_>>()
                            .join(", "),
                    )
                }
                Err(e) => {
                    topics[index].dropped_undecodable += 1;
                    Some(e.to_string())
                }
            };
            if let Some(reason) = reason {
                dropped.push(DroppedMessage {
                    topic: m.topic.to_string(),
                    log_time_ns: m.log_time_ns,
                    reason,
                });
                continue;
            }
        }
        writer.write_raw(id, m.log_time_ns, m.publish_time_ns, m.data)?;
        topics[index].kept += 1;
    }
    Ok((topics, dropped))
}
