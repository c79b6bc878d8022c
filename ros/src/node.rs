//! The node: a ros2-client context and node with our name resolution, parameters and QoS presets,
//! typed and raw publishers and subscriptions, discovery of other publishers, and a wait set.

use std::io;
use std::marker::PhantomData;
use std::sync::mpsc::{self, Receiver};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use dynlab_msgs::RosMessage;
use ros2_client::dds::rustdds::{
    self, DomainParticipant, QosPolicies, RTPSEntity, Timestamp, TopicKind, mio1,
    no_key::{DataWriter, SimpleDataReader},
};
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, NodeName, NodeOptions, QosProfile,
};
use serde::{Serialize, de::DeserializeOwned};

use crate::args::{NodeArgs, Remap};
use crate::clock::Clock;
use crate::names::{self, NameError};
use crate::param_services::ParamServices;
use crate::param_store::{ParamChange, ParamCheck, ParamDescriptor, ParamStore};
use crate::params::{ParamError, ParamValue, Parameters};
use crate::raw::{PUBLISHED_REPRESENTATION, RawAdapter, SerializedMessage};
use crate::rosout::RosoutRegistration;

/// The highest domain id ROS 2 accepts (`ROS_DOMAIN_ID` 0–232 on Linux).
pub const MAX_DOMAIN_ID: u16 = 232;

/// Errors of the node runtime.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// `ROS_DOMAIN_ID` is not a number in range.
    #[error(
        "ROS_DOMAIN_ID=`{0}` is not a domain id: set it to an integer from 0 to 232 (or unset it for 0)"
    )]
    DomainId(String),
    /// A name is not a valid ROS 2 name.
    #[error(transparent)]
    Name(#[from] NameError),
    /// A parameter is missing, mistyped or its file unreadable.
    #[error(transparent)]
    Param(Box<ParamError>),
    /// ros2-client or RustDDS refused to create an entity.
    #[error("cannot create {what}: {reason}")]
    Create {
        /// What was being created.
        what: String,
        /// The middleware's reason.
        reason: String,
    },
    /// A parameter declaration or a node-side set does not fit the parameter's type or range.
    #[error("parameter `{name}` of {node}: {reason}")]
    Parameter {
        /// The parameter.
        name: String,
        /// The node's fully qualified name.
        node: String,
        /// What does not fit.
        reason: String,
    },
    /// Publishing failed.
    #[error("publishing on {topic} failed: {reason}")]
    Publish {
        /// The topic.
        topic: String,
        /// The middleware's reason.
        reason: String,
    },
    /// A raw payload is not little-endian plain CDR.
    #[error(
        "cannot publish on {topic}: payload encapsulation {header:02x?} is not little-endian plain CDR \
         (00 01); raw publishing sends CDR_LE only"
    )]
    Encapsulation {
        /// The topic.
        topic: String,
        /// The first two header bytes found.
        header: [u8; 2],
    },
    /// Receiving failed.
    #[error("receiving on {topic} failed: {reason}")]
    Receive {
        /// The topic.
        topic: String,
        /// The middleware's reason.
        reason: String,
    },
    /// The wait set's poll failed.
    #[error("waiting for messages failed: {0}")]
    Wait(#[source] io::Error),
}

impl From<ParamError> for NodeError {
    fn from(e: ParamError) -> Self {
        NodeError::Param(Box::new(e))
    }
}

/// Reads the domain id from a `ROS_DOMAIN_ID` value: unset or empty means 0.
pub fn parse_domain_id(value: Option<&str>) -> Result<u16, NodeError> {
    match value.map(str::trim) {
        None | Some("") => Ok(0),
        Some(text) => match text.parse::<u16>() {
            Ok(id) if id <= MAX_DOMAIN_ID => Ok(id),
            _ => Err(NodeError::DomainId(text.to_owned())),
        },
    }
}

/// The domain id from the environment variable `ROS_DOMAIN_ID`.
pub fn domain_id_from_env() -> Result<u16, NodeError> {
    parse_domain_id(std::env::var("ROS_DOMAIN_ID").ok().as_deref())
}

fn create_err(what: impl Into<String>) -> impl FnOnce(ros2_client::CreateError) -> NodeError {
    let what = what.into();
    move |e| NodeError::Create {
        what,
        reason: e.to_string(),
    }
}

fn dds_create_err(what: impl Into<String>) -> impl FnOnce(rustdds::dds::CreateError) -> NodeError {
    let what = what.into();
    move |e| NodeError::Create {
        what,
        reason: e.to_string(),
    }
}

/// Nanoseconds since the Unix epoch of an RTPS timestamp.
pub fn timestamp_to_nanos(t: Timestamp) -> i64 {
    let ticks = t.to_ticks();
    let secs = (ticks >> 32) as i64;
    let frac = ticks & 0xffff_ffff;
    secs * 1_000_000_000 + ((frac * 1_000_000_000) >> 32) as i64
}

/// The RTPS timestamp of nanoseconds since the Unix epoch (clamped to the RTPS range).
pub fn nanos_to_timestamp(ns: i64) -> Timestamp {
    let ns = ns.max(0) as u64;
    let secs = (ns / 1_000_000_000).min(u32::MAX as u64 - 1);
    let frac = ((ns % 1_000_000_000) << 32) / 1_000_000_000;
    Timestamp::from_ticks((secs << 32) | frac)
}

/// A publisher discovered on the DDS network (for `recorder --all`).
#[derive(Debug, Clone, PartialEq)]
pub struct DiscoveredPublication {
    /// Fully qualified ROS topic name (`/car/pose`).
    pub topic: String,
    /// DDS type name as seen on the wire (`geometry_msgs::msg::dds_::PoseStamped_`).
    pub dds_type: String,
    /// The QoS the publisher offers.
    pub qos: QosProfile,
    /// The writer's GUID, 16 bytes.
    pub writer_guid: [u8; 16],
}

/// A ROS 2 node: name, namespace, parameters, remapping, and the entities it creates.
///
/// Besides the entities the node's code creates, every node offers the ROS 2 parameter services
/// (see [`crate::param_services`]), publishes its log lines on `/rosout` (see [`crate::rosout`])
/// and is listed with its readers and writers in `ros_discovery_info` (by ros2-client).
///
/// Fields drop in declaration order, and the order matters: the parameter service thread and
/// the `/rosout` publisher go first, then the ros2-client node, and the [`Context`] (which owns
/// the DDS participant) last. ros2-client's `Node` drops its own context handle before its
/// `/parameter_events` writer; were that handle the last one, the participant's event loop
/// would stop first and RustDDS would log "ERROR Cannot remove Writer GUID … Disconnected" at
/// every shutdown. Our `context` keeps the participant alive until every writer is removed.
pub struct Node {
    param_services: ParamServices,
    _rosout: RosoutRegistration,
    ros_node: ros2_client::Node,
    raw_publisher: Option<rustdds::Publisher>,
    raw_subscriber: Option<rustdds::Subscriber>,
    context: Context,
    name: String,
    namespace: String,
    remaps: Vec<Remap>,
    params: Parameters,
    store: Arc<Mutex<ParamStore>>,
    changes: Receiver<ParamChange>,
}

impl Node {
    /// Creates a node named `default_name` (or `__node:=`) in the domain of `ROS_DOMAIN_ID`,
    /// with the namespace, remaps and parameters of `args`.
    pub fn new(default_name: &str, args: &NodeArgs) -> Result<Node, NodeError> {
        Node::with_domain(default_name, args, domain_id_from_env()?)
    }

    /// Like [`Node::new`] with an explicit domain id (ros2-client ignores `ROS_DOMAIN_ID`).
    pub fn with_domain(
        default_name: &str,
        args: &NodeArgs,
        domain_id: u16,
    ) -> Result<Node, NodeError> {
        if domain_id > MAX_DOMAIN_ID {
            return Err(NodeError::DomainId(domain_id.to_string()));
        }
        let name = args.node_name(default_name);
        names::validate_node_name(&name)?;
        let namespace = names::normalize_namespace(&args.namespace())?;
        let fqn = if namespace == "/" {
            format!("/{name}")
        } else {
            format!("{namespace}/{name}")
        };
        let mut params = args.parameters(&fqn)?;
        let store = Arc::new(Mutex::new(ParamStore::new(&fqn)));
        params.record_into(Arc::clone(&store));
        let context = Context::with_options(ContextOptions::new().domain_id(domain_id)).map_err(
            create_err(format!("the DDS participant for domain {domain_id}")),
        )?;
        let node_name = NodeName::new(&namespace, &name).map_err(|e| NodeError::Create {
            what: format!("node {fqn}"),
            reason: e.to_string(),
        })?;
        // ros2-client's parameter services and rosout writer need its async Spinner (which
        // would also subscribe /clock with the wrong type); ours run without it.
        let options = NodeOptions::new()
            .enable_rosout(false)
            .start_parameter_services(false);
        let mut ros_node = context
            .new_node(node_name, options)
            .map_err(|e| NodeError::Create {
                what: format!("node {fqn}"),
                reason: format!("{e:?}"),
            })?;
        // Every node has use_sim_time, as in rclcpp (read-only here: the clock is chosen at
        // start); a value that is not a bool is refused here, naming the fix.
        params.get_or("use_sim_time", false)?;
        let rosout_publisher = ros_node
            .create_publisher::<ros2_client::Log>(
                &context.get_rosout_topic(),
                Some(crate::qos::rosout()),
            )
            .map_err(create_err("the /rosout publisher"))?;
        let rosout = crate::rosout::register(&fqn, rosout_publisher);
        let (tx, changes) = mpsc::channel();
        let param_services = ParamServices::start(
            &mut ros_node,
            &context.get_parameter_events_topic(),
            &fqn,
            Arc::clone(&store),
            tx,
        )?;
        Ok(Node {
            param_services,
            _rosout: rosout,
            ros_node,
            raw_publisher: None,
            raw_subscriber: None,
            context,
            name,
            namespace,
            remaps: args.remaps.clone(),
            params,
            store,
            changes,
        })
    }

    /// Offers a parameter over the parameter services with its current value and descriptor
    /// (replacing the read-only entry [`Parameters`] made when the node read it). Parameters
    /// declared [`ParamDescriptor::dynamic`] can then be set while the node runs; the node loop
    /// receives the accepted values from [`Node::poll_parameter_changes`].
    pub fn declare_parameter(
        &self,
        name: &str,
        value: ParamValue,
        descriptor: ParamDescriptor,
    ) -> Result<(), NodeError> {
        self.lock_store()
            .declare(name, value, descriptor)
            .map_err(|reason| NodeError::Parameter {
                name: name.to_owned(),
                node: self.fully_qualified_name(),
                reason,
            })
    }

    /// Like [`Node::declare_parameter`], with the node's own check of new values (run after
    /// the type and range checks; its `Err` is the reason a set is refused with).
    pub fn declare_parameter_checked(
        &self,
        name: &str,
        value: ParamValue,
        descriptor: ParamDescriptor,
        check: ParamCheck,
    ) -> Result<(), NodeError> {
        // One lock: no remote set can come between the declaration and its check.
        let mut store = self.lock_store();
        store
            .declare(name, value, descriptor)
            .map_err(|reason| NodeError::Parameter {
                name: name.to_owned(),
                node: self.fully_qualified_name(),
                reason,
            })?;
        store.set_check(name, check);
        Ok(())
    }

    /// Sets a declared parameter from the node's own code, e.g. `goal` when a goal arrives on a
    /// topic, so that `ros2 param get` shows what the node uses: checked for type, range and
    /// the node's check (read-only ones too may be set this way), announced on
    /// `/parameter_events`, not queued for [`Node::poll_parameter_changes`].
    pub fn set_parameter(&self, name: &str, value: ParamValue) -> Result<(), NodeError> {
        let change =
            self.lock_store()
                .update(name, &value)
                .map_err(|reason| NodeError::Parameter {
                    name: name.to_owned(),
                    node: self.fully_qualified_name(),
                    reason,
                })?;
        self.param_services.announce(&[change]);
        Ok(())
    }

    /// The current value of a declared parameter (as the parameter services report it).
    pub fn parameter(&self, name: &str) -> Option<ParamValue> {
        self.lock_store().get(name).map(|d| d.value.clone())
    }

    /// The parameter changes accepted by the parameter services since the last call, oldest
    /// first. Call it once per loop iteration and apply them there: the loop decides when a
    /// change takes effect, so runs stay deterministic.
    pub fn poll_parameter_changes(&self) -> Vec<ParamChange> {
        self.changes.try_iter().collect()
    }

    fn lock_store(&self) -> std::sync::MutexGuard<'_, ParamStore> {
        self.store.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The node's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The node's namespace (`/` for the root).
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The fully qualified name, e.g. `/robot1/recorder`.
    pub fn fully_qualified_name(&self) -> String {
        names::expand_topic_name("~", &self.name, &self.namespace)
            .unwrap_or_else(|_| format!("/{}", self.name))
    }

    /// The DDS domain id.
    pub fn domain_id(&self) -> u16 {
        self.context.domain_id()
    }

    /// The node's parameters.
    pub fn params(&self) -> &Parameters {
        &self.params
    }

    /// The remap rules in effect.
    pub fn remaps(&self) -> &[Remap] {
        &self.remaps
    }

    /// Resolves a topic name (relative, absolute or `~`) with remapping, e.g. `pose` →
    /// `/robot1/pose`.
    pub fn resolve_topic(&self, topic: &str) -> Result<String, NodeError> {
        Ok(names::resolve_topic_name(
            topic,
            &self.name,
            &self.namespace,
            &self.remaps,
        )?)
    }

    /// The clock the node's code should use: following `/clock` when the parameter
    /// `use_sim_time` is true, the system clock otherwise.
    pub fn clock(&mut self) -> Result<Clock, NodeError> {
        if self.params.get_or("use_sim_time", false)? {
            let sub = self.create_subscription::<dynlab_msgs::rosgraph_msgs::Clock>(
                "/clock",
                crate::qos::clock(),
            )?;
            Ok(Clock::sim(sub))
        } else {
            Ok(Clock::system())
        }
    }

    /// The underlying ros2-client node, for what this wrapper does not cover.
    pub fn ros_node(&mut self) -> &mut ros2_client::Node {
        &mut self.ros_node
    }

    fn participant(&self) -> DomainParticipant {
        self.context.domain_participant()
    }

    fn ros_topic(
        &mut self,
        resolved: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<rustdds::Topic, NodeError> {
        let (pkg, rest) = type_name
            .split_once('/')
            .ok_or_else(|| NameError::BadTypeName(type_name.to_owned()))?;
        let ty = rest
            .strip_prefix("msg/")
            .ok_or_else(|| NameError::BadTypeName(type_name.to_owned()))?;
        let name = Name::parse(resolved).map_err(|e| NodeError::Create {
            what: format!("topic {resolved}"),
            reason: e.to_string(),
        })?;
        self.ros_node
            .create_topic(&name, MessageTypeName::new(pkg, ty), qos)
            .map_err(create_err(format!("topic {resolved}")))
    }

    /// A typed publisher on `topic` (resolved and remapped) with the given QoS.
    pub fn create_publisher<M>(
        &mut self,
        topic: &str,
        qos: QosProfile,
    ) -> Result<Publisher<M>, NodeError>
    where
        M: RosMessage + Serialize,
    {
        let resolved = self.resolve_topic(topic)?;
        let t = self.ros_topic(&resolved, M::TYPE_NAME, &qos)?;
        let inner = self
            .ros_node
            .create_publisher::<M>(&t, Some(qos))
            .map_err(create_err(format!("publisher on {resolved}")))?;
        Ok(Publisher {
            inner,
            peers: Peers::new(self.participant(), &resolved),
        })
    }

    /// A typed subscription on `topic` (resolved and remapped) with the given QoS.
    pub fn create_subscription<M>(
        &mut self,
        topic: &str,
        qos: QosProfile,
    ) -> Result<Subscription<M>, NodeError>
    where
        M: RosMessage + DeserializeOwned + 'static,
    {
        let resolved = self.resolve_topic(topic)?;
        let t = self.ros_topic(&resolved, M::TYPE_NAME, &qos)?;
        let inner = self
            .ros_node
            .create_subscription::<M>(&t, Some(qos))
            .map_err(create_err(format!("subscription on {resolved}")))?;
        Ok(Subscription {
            inner,
            peers: Peers::new(self.participant(), &resolved),
            _m: PhantomData,
        })
    }

    fn raw_topic(
        &self,
        resolved: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<rustdds::Topic, NodeError> {
        let dds_type = if type_name.contains("::") {
            type_name.to_owned()
        } else {
            dynlab_msgs::ros_to_dds_type_name(type_name)
                .map_err(|_| NameError::BadTypeName(type_name.to_owned()))?
        };
        self.participant()
            .create_topic(
                names::dds_topic_name(resolved),
                dds_type,
                &QosPolicies::from(qos),
                TopicKind::NoKey,
            )
            .map_err(dds_create_err(format!("topic {resolved}")))
    }

    /// A publisher of serialized messages of the named type (`pkg/msg/Type` or the DDS form)
    /// on `topic` (resolved and remapped).
    pub fn create_raw_publisher(
        &mut self,
        topic: &str,
        type_name: &str,
        qos: QosProfile,
    ) -> Result<RawPublisher, NodeError> {
        let resolved = self.resolve_topic(topic)?;
        self.create_raw_publisher_exact(&resolved, type_name, qos)
    }

    /// Like [`Node::create_raw_publisher`] on a fully qualified name taken as is (no remapping),
    /// e.g. a name seen on the wire.
    pub fn create_raw_publisher_exact(
        &mut self,
        resolved: &str,
        type_name: &str,
        qos: QosProfile,
    ) -> Result<RawPublisher, NodeError> {
        names::expand_topic_name(resolved, &self.name, &self.namespace)?;
        let t = self.raw_topic(resolved, type_name, &qos)?;
        let participant = self.participant();
        let publisher = match &self.raw_publisher {
            Some(p) => p.clone(),
            None => {
                let p = participant
                    .create_publisher(&QosPolicies::from(crate::qos::default_profile()))
                    .map_err(dds_create_err("the raw DDS publisher"))?;
                self.raw_publisher = Some(p.clone());
                p
            }
        };
        let writer = publisher
            .create_datawriter_no_key::<SerializedMessage, RawAdapter>(
                &t,
                Some(QosPolicies::from(&qos)),
            )
            .map_err(dds_create_err(format!("raw publisher on {resolved}")))?;
        Ok(RawPublisher {
            writer,
            peers: Peers::new(participant, resolved),
        })
    }

    /// A subscription that keeps serialized messages of the named type on `topic` (resolved and
    /// remapped).
    pub fn create_raw_subscription(
        &mut self,
        topic: &str,
        type_name: &str,
        qos: QosProfile,
    ) -> Result<RawSubscription, NodeError> {
        let resolved = self.resolve_topic(topic)?;
        self.create_raw_subscription_exact(&resolved, type_name, qos)
    }

    /// Like [`Node::create_raw_subscription`] on a fully qualified name taken as is (no
    /// remapping), e.g. a topic discovered on the wire.
    pub fn create_raw_subscription_exact(
        &mut self,
        resolved: &str,
        type_name: &str,
        qos: QosProfile,
    ) -> Result<RawSubscription, NodeError> {
        names::expand_topic_name(resolved, &self.name, &self.namespace)?;
        let t = self.raw_topic(resolved, type_name, &qos)?;
        let participant = self.participant();
        let subscriber = match &self.raw_subscriber {
            Some(s) => s.clone(),
            None => {
                let s = participant
                    .create_subscriber(&QosPolicies::from(crate::qos::default_profile()))
                    .map_err(dds_create_err("the raw DDS subscriber"))?;
                self.raw_subscriber = Some(s.clone());
                s
            }
        };
        let reader = subscriber
            .create_simple_datareader_no_key::<SerializedMessage, RawAdapter>(
                &t,
                Some(QosPolicies::from(&qos)),
            )
            .map_err(dds_create_err(format!("raw subscription on {resolved}")))?;
        Ok(RawSubscription {
            reader,
            peers: Peers::new(participant, resolved),
        })
    }

    /// Publishers of ROS topics discovered on the network (not this process's own), with the
    /// type name seen on the wire and the QoS they offer.
    pub fn discovered_publications(&self) -> Vec<DiscoveredPublication> {
        let participant = self.participant();
        let own = participant.guid().prefix;
        participant
            .discovered_writers()
            .into_iter()
            .filter(|w| w.publication_topic_data.key.prefix != own)
            .filter_map(|w| {
                let data = &w.publication_topic_data;
                let topic = names::ros_topic_name(&data.topic_name)?;
                Some(DiscoveredPublication {
                    topic,
                    dds_type: data.type_name.clone(),
                    qos: QosProfile::from(&data.qos()),
                    writer_guid: ros2_client::Gid::from(data.key).to_bytes16(),
                })
            })
            .collect()
    }
}

/// Counts remote endpoints on one topic from the participant's discovery data.
struct Peers {
    participant: DomainParticipant,
    dds_topic: String,
    topic: String,
}

impl Peers {
    fn new(participant: DomainParticipant, resolved: &str) -> Peers {
        Peers {
            participant,
            dds_topic: names::dds_topic_name(resolved),
            topic: resolved.to_owned(),
        }
    }

    fn readers(&self) -> usize {
        let own = self.participant.guid().prefix;
        self.participant
            .discovered_readers()
            .iter()
            .filter(|r| r.reader_proxy.remote_reader_guid.prefix != own)
            .filter(|r| r.subscription_topic_data.topic_name() == &self.dds_topic)
            .count()
    }

    fn writers(&self) -> usize {
        let own = self.participant.guid().prefix;
        self.participant
            .discovered_writers()
            .iter()
            .filter(|w| w.publication_topic_data.key.prefix != own)
            .filter(|w| w.publication_topic_data.topic_name == self.dds_topic)
            .count()
    }
}

/// A typed publisher.
pub struct Publisher<M: Serialize> {
    inner: ros2_client::Publisher<M>,
    peers: Peers,
}

impl<M: RosMessage + Serialize> Publisher<M> {
    /// Publishes one message.
    pub fn publish(&self, msg: M) -> Result<(), NodeError> {
        self.inner.publish(msg).map_err(|e| NodeError::Publish {
            topic: self.peers.topic.clone(),
            reason: e.to_string(),
        })
    }

    /// The resolved topic name.
    pub fn topic(&self) -> &str {
        &self.peers.topic
    }

    /// Subscriptions on this topic in other processes, from discovery (QoS compatibility is not
    /// checked).
    pub fn subscription_count(&self) -> usize {
        self.peers.readers()
    }
}

/// A received message with its timestamps.
#[derive(Debug, Clone, PartialEq)]
pub struct Received<T> {
    /// The message (typed, or a [`SerializedMessage`]).
    pub msg: T,
    /// Reception time, ns since the Unix epoch (system clock of this host).
    pub received_ns: i64,
    /// The publisher's source timestamp, ns since the Unix epoch, if it sent one.
    pub source_ns: Option<i64>,
}

/// A typed subscription.
pub struct Subscription<M> {
    inner: ros2_client::Subscription<M>,
    peers: Peers,
    _m: PhantomData<M>,
}

impl<M: RosMessage + DeserializeOwned + 'static> Subscription<M> {
    /// Takes the next message, if one is waiting.
    pub fn take(&self) -> Result<Option<M>, NodeError> {
        Ok(self.take_received()?.map(|r| r.msg))
    }

    /// Takes the next message with its timestamps, if one is waiting.
    pub fn take_received(&self) -> Result<Option<Received<M>>, NodeError> {
        match self.inner.take() {
            Ok(Some((msg, info))) => Ok(Some(Received {
                msg,
                received_ns: info.received_timestamp().map(|t| t.to_nanos()).unwrap_or(0),
                source_ns: info.source_timestamp().map(|t| t.to_nanos()),
            })),
            Ok(None) => Ok(None),
            Err(e) => Err(NodeError::Receive {
                topic: self.peers.topic.clone(),
                reason: e.to_string(),
            }),
        }
    }

    /// Takes every waiting message and returns the newest (the usual need of a control loop).
    pub fn take_latest(&self) -> Result<Option<M>, NodeError> {
        let mut last = None;
        while let Some(m) = self.take()? {
            last = Some(m);
        }
        Ok(last)
    }

    /// The resolved topic name.
    pub fn topic(&self) -> &str {
        &self.peers.topic
    }

    /// Publishers on this topic in other processes, from discovery.
    pub fn publisher_count(&self) -> usize {
        self.peers.writers()
    }
}

impl<M: DeserializeOwned> mio1::event::Source for Subscription<M> {
    fn register(
        &mut self,
        r: &mio1::Registry,
        t: mio1::Token,
        i: mio1::Interest,
    ) -> io::Result<()> {
        mio1::event::Source::register(&mut self.inner, r, t, i)
    }
    fn reregister(
        &mut self,
        r: &mio1::Registry,
        t: mio1::Token,
        i: mio1::Interest,
    ) -> io::Result<()> {
        mio1::event::Source::reregister(&mut self.inner, r, t, i)
    }
    fn deregister(&mut self, r: &mio1::Registry) -> io::Result<()> {
        mio1::event::Source::deregister(&mut self.inner, r)
    }
}

/// A publisher of serialized messages (4-byte header + CDR body, as stored in bags).
pub struct RawPublisher {
    writer: DataWriter<SerializedMessage, RawAdapter>,
    peers: Peers,
}

impl RawPublisher {
    /// Publishes one serialized message unchanged (it must be little-endian plain CDR).
    pub fn publish(&self, data: &[u8]) -> Result<(), NodeError> {
        let header = [
            data.first().copied().unwrap_or(0xff),
            data.get(1).copied().unwrap_or(0xff),
        ];
        if data.len() < 4 || header != PUBLISHED_REPRESENTATION {
            return Err(NodeError::Encapsulation {
                topic: self.peers.topic.clone(),
                header,
            });
        }
        self.writer
            .write(
                SerializedMessage {
                    data: data.to_vec(),
                },
                Some(Timestamp::now()),
            )
            .map_err(|e| NodeError::Publish {
                topic: self.peers.topic.clone(),
                reason: e.to_string(),
            })
    }

    /// The resolved topic name.
    pub fn topic(&self) -> &str {
        &self.peers.topic
    }

    /// Subscriptions on this topic in other processes, from discovery.
    pub fn subscription_count(&self) -> usize {
        self.peers.readers()
    }

    /// For a reliable publisher: waits up to `max_wait` until every matched subscription has
    /// acknowledged everything published; `false` on timeout. Call before exiting so the last
    /// messages are not lost with the process.
    pub fn wait_for_acknowledgments(&self, max_wait: Duration) -> bool {
        self.writer
            .wait_for_acknowledgments(max_wait)
            .unwrap_or(false)
    }
}

/// A subscription keeping serialized messages.
pub struct RawSubscription {
    reader: SimpleDataReader<SerializedMessage, RawAdapter>,
    peers: Peers,
}

impl RawSubscription {
    /// Takes the next serialized message with its timestamps, if one is waiting.
    pub fn take(&self) -> Result<Option<Received<SerializedMessage>>, NodeError> {
        self.reader.drain_read_notifications();
        match self.reader.try_take_one() {
            Ok(Some(dcc)) => Ok(Some(Received {
                received_ns: timestamp_to_nanos(dcc.receive_instant),
                source_ns: dcc.source_timestamp().map(timestamp_to_nanos),
                msg: dcc.into_value(),
            })),
            Ok(None) => Ok(None),
            Err(e) => Err(NodeError::Receive {
                topic: self.peers.topic.clone(),
                reason: e.to_string(),
            }),
        }
    }

    /// The resolved topic name.
    pub fn topic(&self) -> &str {
        &self.peers.topic
    }

    /// Publishers on this topic in other processes, from discovery.
    pub fn publisher_count(&self) -> usize {
        self.peers.writers()
    }
}

impl mio1::event::Source for RawSubscription {
    fn register(
        &mut self,
        r: &mio1::Registry,
        t: mio1::Token,
        i: mio1::Interest,
    ) -> io::Result<()> {
        mio1::event::Source::register(&mut self.reader, r, t, i)
    }
    fn reregister(
        &mut self,
        r: &mio1::Registry,
        t: mio1::Token,
        i: mio1::Interest,
    ) -> io::Result<()> {
        mio1::event::Source::reregister(&mut self.reader, r, t, i)
    }
    fn deregister(&mut self, r: &mio1::Registry) -> io::Result<()> {
        mio1::event::Source::deregister(&mut self.reader, r)
    }
}

/// Blocks a node loop until a subscription has data or a timeout passes, without an async
/// runtime: RustDDS readers are mio 1 event sources, so one `mio::Poll` waits on all of them.
///
/// Events are edge-triggered: after [`WaitSet::wait`] returns, take from the subscriptions until
/// they are empty.
pub struct WaitSet {
    poll: mio1::Poll,
    events: mio1::Events,
    next_token: usize,
}

impl WaitSet {
    /// An empty wait set.
    pub fn new() -> Result<WaitSet, NodeError> {
        Ok(WaitSet {
            poll: mio1::Poll::new().map_err(NodeError::Wait)?,
            events: mio1::Events::with_capacity(64),
            next_token: 0,
        })
    }

    /// Adds a subscription (typed or raw); returns its index, reported by [`WaitSet::wait`].
    pub fn add<S: mio1::event::Source + ?Sized>(
        &mut self,
        source: &mut S,
    ) -> Result<usize, NodeError> {
        let index = self.next_token;
        self.poll
            .registry()
            .register(source, mio1::Token(index), mio1::Interest::READABLE)
            .map_err(NodeError::Wait)?;
        self.next_token += 1;
        Ok(index)
    }

    /// Waits up to `timeout` for data; returns the indices of subscriptions that got some (empty
    /// on timeout).
    pub fn wait(&mut self, timeout: Duration) -> Result<Vec<usize>, NodeError> {
        match self.poll.poll(&mut self.events, Some(timeout)) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::Interrupted => return Ok(Vec::new()),
            Err(e) => return Err(NodeError::Wait(e)),
        }
        let mut ready: Vec<usize> = self.events.iter().map(|e| e.token().0).collect();
        ready.sort_unstable();
        ready.dedup();
        Ok(ready)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn domain_ids_are_validated() {
        assert_eq!(parse_domain_id(None).unwrap(), 0);
        assert_eq!(parse_domain_id(Some("")).unwrap(), 0);
        assert_eq!(parse_domain_id(Some("7")).unwrap(), 7);
        assert_eq!(parse_domain_id(Some(" 232 ")).unwrap(), 232);
        for bad in ["233", "-1", "seven", "70000"] {
            let err = parse_domain_id(Some(bad)).unwrap_err().to_string();
            assert!(err.contains(bad) && err.contains("0 to 232"), "{err}");
        }
    }

    #[test]
    fn rtps_timestamps_convert_to_nanoseconds() {
        for ns in [0i64, 1, 999_999_999, 1_700_000_000_123_456_789] {
            let back = timestamp_to_nanos(nanos_to_timestamp(ns));
            assert!((back - ns).abs() <= 1, "{ns} -> {back}");
        }
        assert_eq!(timestamp_to_nanos(nanos_to_timestamp(-5)), 0);
    }
}
