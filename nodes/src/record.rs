//! Recording logic of the `recorder` node, without DDS: which discovered topics to record, with
//! what type, definition and QoS, and a bag writer that flushes on a period.
//!
//! The binary discovers publishers, subscribes raw, and hands every message to [`Recorder`];
//! [`Recorder::maybe_flush`] closes the open chunk and fsyncs at least every
//! [`RecordOptions::flush_period_ns`], so a recorder killed with SIGKILL leaves a bag that reads
//! up to its last flush.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use dynlab_bag::{BagError, BagSummary, BagWriter, QosDuration, TopicId, WriterOptions};
use dynlab_ros::qos::{self, Durability, History, Liveliness, QosProfile, Reliability};

/// Recorder settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordOptions {
    /// The bag directory to create.
    pub output: PathBuf,
    /// Fully qualified topics to record (after remapping). Empty with `all`.
    pub topics: Vec<String>,
    /// Record every topic discovered, as it appears.
    pub all: bool,
    /// Longest time between flushes of the bag to disk. Default 1 s.
    pub flush_period_ns: i64,
    /// Bag writer settings.
    pub writer: WriterOptions,
}

impl RecordOptions {
    /// Options for `output` with the defaults (flush every second, zstd chunks).
    pub fn new(output: impl Into<PathBuf>) -> RecordOptions {
        RecordOptions {
            output: output.into(),
            topics: Vec::new(),
            all: false,
            flush_period_ns: 1_000_000_000,
            writer: WriterOptions::default(),
        }
    }
}

/// Errors of recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Neither topics nor `--all`.
    #[error("nothing to record: name topics (`recorder -o DIR /car/pose /car/cmd`) or pass --all")]
    NoTopics,
    /// The bag could not be written.
    #[error(transparent)]
    Bag(#[from] BagError),
    /// A type name on the wire is not a ROS 2 DDS type name.
    #[error(
        "topic {topic}: type `{dds_type}` seen on the wire is not a ROS 2 type (pkg::msg::dds_::Type_)"
    )]
    ForeignType {
        /// The topic.
        topic: String,
        /// The DDS type name.
        dds_type: String,
    },
}

/// Whether a discovered topic should be recorded: a named topic, or with `all` any topic that is
/// not hidden (a token starting with `_`, as rosbag2 hides them).
pub fn wants_topic(options: &RecordOptions, topic: &str) -> bool {
    if options.topics.iter().any(|t| t == topic) {
        return true;
    }
    options.all && !topic.split('/').any(|tok| tok.starts_with('_'))
}

/// What the bag gets for one topic.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicPlan {
    /// Topic name.
    pub topic: String,
    /// ROS type name (`geometry_msgs/msg/PoseStamped`).
    pub type_name: String,
    /// The full `ros2msg` definition; empty when the type is not in the msgs registry.
    pub definition: String,
    /// Whether the definition is known.
    pub known_type: bool,
    /// Offered QoS profiles, as rosbag2 records them.
    pub qos: Vec<dynlab_bag::QosProfile>,
    /// The QoS the raw subscription uses.
    pub subscription_qos: QosProfile,
}

/// Reader history depth: deep enough that bursts wait for the writer instead of being dropped.
pub const SUBSCRIPTION_DEPTH: usize = 10_000;

/// Plans a topic seen on the wire with DDS type `dds_type`, offered by publishers with `offers`.
pub fn plan_topic(
    topic: &str,
    dds_type: &str,
    offers: &[QosProfile],
) -> Result<TopicPlan, RecordError> {
    let type_name =
        dynlab_msgs::dds_to_ros_type_name(dds_type).map_err(|_| RecordError::ForeignType {
            topic: topic.to_owned(),
            dds_type: dds_type.to_owned(),
        })?;
    let known = dynlab_msgs::lookup(&type_name);
    Ok(TopicPlan {
        topic: topic.to_owned(),
        definition: known.map(|t| t.definition.to_owned()).unwrap_or_default(),
        known_type: known.is_some(),
        type_name,
        qos: offers.iter().map(offered_qos).collect(),
        subscription_qos: qos::recording_profile(offers, SUBSCRIPTION_DEPTH),
    })
}

fn qos_duration(d: Option<Duration>) -> QosDuration {
    match d {
        None => QosDuration::INFINITE,
        Some(d) => QosDuration {
            sec: d.as_secs(),
            nsec: d.subsec_nanos() as u64,
        },
    }
}

/// A publisher's offered QoS as rosbag2 stores it. History is not part of DDS discovery data, so
/// it is `unknown` with depth 0 — what `ros2 bag record` stores for remote publishers too.
pub fn offered_qos(q: &QosProfile) -> dynlab_bag::QosProfile {
    dynlab_bag::QosProfile {
        history: match q.history {
            History::KeepAll => dynlab_bag::History::KeepAll,
            History::KeepLast { .. } => dynlab_bag::History::Unknown,
        },
        depth: 0,
        reliability: match q.reliability {
            Reliability::BestEffort => dynlab_bag::Reliability::BestEffort,
            Reliability::Reliable { .. } => dynlab_bag::Reliability::Reliable,
        },
        durability: match q.durability {
            Durability::Volatile => dynlab_bag::Durability::Volatile,
            Durability::TransientLocal => dynlab_bag::Durability::TransientLocal,
        },
        deadline: qos_duration(q.deadline),
        lifespan: qos_duration(q.lifespan),
        liveliness: match q.liveliness {
            Liveliness::Automatic => dynlab_bag::Liveliness::Automatic,
            Liveliness::ManualByTopic => dynlab_bag::Liveliness::ManualByTopic,
        },
        liveliness_lease_duration: qos_duration(q.liveliness_lease),
        avoid_ros_namespace_conventions: false,
    }
}

/// The QoS a player offers for a topic recorded with `recorded` profiles: the first recorded
/// profile's reliability and durability (what rosbag2's player does), else ROS 2's default.
pub fn playback_qos(recorded: &[dynlab_bag::QosProfile]) -> QosProfile {
    let Some(p) = recorded.first() else {
        return qos::default_profile();
    };
    let mut q = qos::default_profile();
    if p.reliability == dynlab_bag::Reliability::BestEffort {
        q.reliability = Reliability::BestEffort;
    }
    if p.durability == dynlab_bag::Durability::TransientLocal {
        q.durability = Durability::TransientLocal;
    }
    if p.history == dynlab_bag::History::KeepLast && p.depth > 0 {
        q.history = History::KeepLast {
            depth: p.depth as usize,
        };
    }
    q
}

/// Per-topic counters.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TopicStats {
    /// Messages written.
    pub written: u64,
}

/// Writes received messages to a bag, flushing on a period.
pub struct Recorder {
    writer: BagWriter,
    ids: BTreeMap<String, TopicId>,
    stats: BTreeMap<String, TopicStats>,
    flush_period_ns: i64,
    last_flush_ns: i64,
}

impl Recorder {
    /// Creates the bag; `now_ns` (any monotonic scale) starts the flush period.
    pub fn create(options: &RecordOptions, now_ns: i64) -> Result<Recorder, RecordError> {
        if options.topics.is_empty() && !options.all {
            return Err(RecordError::NoTopics);
        }
        let writer = BagWriter::create(&options.output, options.writer.clone())?;
        Ok(Recorder {
            writer,
            ids: BTreeMap::new(),
            stats: BTreeMap::new(),
            flush_period_ns: options.flush_period_ns.max(1),
            last_flush_ns: now_ns,
        })
    }

    /// Adds a topic to the bag (again: same id).
    pub fn add_topic(&mut self, plan: &TopicPlan) -> Result<TopicId, RecordError> {
        let id =
            self.writer
                .add_topic(&plan.topic, &plan.type_name, &plan.definition, &plan.qos)?;
        self.ids.insert(plan.topic.clone(), id);
        self.stats.entry(plan.topic.clone()).or_default();
        Ok(id)
    }

    /// The id of a topic already added.
    pub fn topic_id(&self, topic: &str) -> Option<TopicId> {
        self.ids.get(topic).copied()
    }

    /// Writes one serialized message.
    pub fn write(
        &mut self,
        topic: &str,
        log_time_ns: i64,
        publish_time_ns: i64,
        data: &[u8],
    ) -> Result<(), RecordError> {
        let Some(&id) = self.ids.get(topic) else {
            return Err(RecordError::Bag(BagError::InvalidName(format!(
                "topic {topic} was not added to the bag"
            ))));
        };
        self.writer.write_raw(
            id,
            log_time_ns.max(0) as u64,
            publish_time_ns.max(0) as u64,
            data,
        )?;
        if let Some(s) = self.stats.get_mut(topic) {
            s.written += 1;
        }
        Ok(())
    }

    /// Flushes (closes the open chunk, fsyncs, rewrites `metadata.yaml`) when a flush period has
    /// passed since the last one; returns whether it did.
    pub fn maybe_flush(&mut self, now_ns: i64) -> Result<bool, RecordError> {
        if now_ns - self.last_flush_ns < self.flush_period_ns {
            return Ok(false);
        }
        self.writer.flush()?;
        self.last_flush_ns = now_ns;
        Ok(true)
    }

    /// Time until the next flush is due.
    pub fn until_flush_ns(&self, now_ns: i64) -> i64 {
        (self.last_flush_ns + self.flush_period_ns - now_ns).max(0)
    }

    /// Messages written per topic.
    pub fn stats(&self) -> &BTreeMap<String, TopicStats> {
        &self.stats
    }

    /// Finishes the bag (summary, footer, final `metadata.yaml`).
    pub fn finish(self) -> Result<BagSummary, RecordError> {
        Ok(self.writer.finish()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynlab_msgs::geometry_msgs::PoseStamped;

    #[test]
    fn topic_selection() {
        let mut o = RecordOptions::new("x");
        o.topics = vec!["/car/pose".into()];
        assert!(wants_topic(&o, "/car/pose"));
        assert!(!wants_topic(&o, "/car/cmd"));
        o.all = true;
        assert!(wants_topic(&o, "/car/cmd"));
        assert!(!wants_topic(&o, "/_hidden/x"));
        assert!(!wants_topic(&o, "/a/_private"));
    }

    #[test]
    fn plans_known_and_unknown_types_from_wire_names() {
        let plan = plan_topic(
            "/car/pose",
            "geometry_msgs::msg::dds_::PoseStamped_",
            &[qos::sensor_data()],
        )
        .unwrap();
        assert_eq!(plan.type_name, "geometry_msgs/msg/PoseStamped");
        assert!(plan.known_type);
        assert!(
            plan.definition.contains("MSG: std_msgs/Header"),
            "{}",
            plan.definition
        );
        assert_eq!(plan.qos[0].reliability, dynlab_bag::Reliability::BestEffort);
        assert_eq!(plan.subscription_qos.reliability, Reliability::BestEffort);
        let unknown =
            plan_topic("/x", "my_pkg::msg::dds_::Thing_", &[qos::default_profile()]).unwrap();
        assert_eq!(unknown.type_name, "my_pkg/msg/Thing");
        assert!(!unknown.known_type && unknown.definition.is_empty());
        assert!(matches!(
            unknown.subscription_qos.reliability,
            Reliability::Reliable { .. }
        ));
        assert!(matches!(
            plan_topic("/x", "PoseStamped", &[]),
            Err(RecordError::ForeignType { .. })
        ));
    }

    #[test]
    fn offered_qos_is_recorded_as_rosbag2_does() {
        let q = offered_qos(&qos::sensor_data());
        assert_eq!(q.reliability, dynlab_bag::Reliability::BestEffort);
        assert_eq!(q.durability, dynlab_bag::Durability::Volatile);
        assert_eq!(q.history, dynlab_bag::History::Unknown);
        assert_eq!(q.deadline, QosDuration::INFINITE);
        let mut latched = qos::latched();
        latched.deadline = Some(Duration::from_millis(1500));
        let q = offered_qos(&latched);
        assert_eq!(q.durability, dynlab_bag::Durability::TransientLocal);
        assert_eq!(
            q.deadline,
            QosDuration {
                sec: 1,
                nsec: 500_000_000
            }
        );
        // and back for playback
        assert_eq!(
            playback_qos(&[offered_qos(&qos::sensor_data())]).reliability,
            Reliability::BestEffort
        );
        assert_eq!(
            playback_qos(&[offered_qos(&qos::latched())]).durability,
            Durability::TransientLocal
        );
        assert_eq!(playback_qos(&[]), qos::default_profile());
        assert_eq!(
            playback_qos(&[dynlab_bag::QosProfile::sensor_data()]).history,
            History::KeepLast { depth: 5 }
        );
    }

    #[test]
    fn recorder_writes_and_flushes_on_its_period() {
        let dir = tempfile::tempdir().unwrap();
        let mut o = RecordOptions::new(dir.path().join("bag"));
        o.all = true;
        let mut rec = Recorder::create(&o, 0).unwrap();
        let plan = plan_topic(
            "/car/pose",
            "geometry_msgs::msg::dds_::PoseStamped_",
            &[qos::sensor_data()],
        )
        .unwrap();
        rec.add_topic(&plan).unwrap();
        let mut msg = PoseStamped::default();
        for i in 0..5 {
            msg.pose.position.x = i as f64;
            let data = dynlab_msgs::to_cdr(&msg).unwrap();
            rec.write("/car/pose", 1_000 + i, 900 + i, &data).unwrap();
        }
        assert!(!rec.maybe_flush(999_999_999).unwrap());
        assert_eq!(rec.until_flush_ns(999_999_999), 1);
        assert!(rec.maybe_flush(1_000_000_000).unwrap());
        assert!(!rec.maybe_flush(1_500_000_000).unwrap());
        assert!(rec.write("/unknown", 0, 0, &[0, 1, 0, 0]).is_err());
        assert_eq!(rec.stats()["/car/pose"].written, 5);
        let summary = rec.finish().unwrap();
        assert_eq!(summary.message_count, 5);
        assert!(matches!(
            Recorder::create(&RecordOptions::new(dir.path().join("b2")), 0),
            Err(RecordError::NoTopics)
        ));
    }
}
