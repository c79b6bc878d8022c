//! The ROS 2 parameter services of a node (`rcl_interfaces/srv/*` on
//! `rq/<node>/<service>Request` → `rr/<node>/<service>Reply`) and `/parameter_events`, served on
//! a thread of their own so that `ros2 param` gets an answer however long the node loop's
//! iteration takes.
//!
//! The thread answers from the shared [`ParamStore`]; an accepted set is stored there at once
//! (so a following `get` sees it), published on `/parameter_events`, and queued for the node
//! loop, which applies it at a point of its own choosing through
//! [`crate::Node::poll_parameter_changes`]: the loop stays single-threaded and deterministic.
//!
//! The servers are ros2-client [`Server`]s with the DDS-RPC "Enhanced" service mapping, the one
//! of `rmw_fastrtps_cpp` (Jazzy's default middleware): request and reply are matched through the
//! related-sample-identity inline QoS. A client that sends none (a plain DDS writer, like our
//! Cyclone DDS test peer) is answered as well, with the request's own sample identity.
//! ros2-client registers the servers' readers and writers under the node in
//! `ros_discovery_info`, so `ros2 node info` lists them as service servers.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use ros2_client::builtin_interfaces::Time;
use ros2_client::dds::rustdds::mio1;
use ros2_client::parameters::raw;
use ros2_client::rcl_interfaces as rcl;
use ros2_client::{Message, Name, Server, ServiceMapping, ServiceTypeName};

use crate::node::NodeError;
use crate::param_store::{Declared, ParamChange, ParamRange, ParamStore};
use crate::params::ParamValue;

/// ROS 2 `ParameterType` codes.
pub mod ptype {
    /// Not set (unknown parameter).
    pub const NOT_SET: u8 = 0;
    /// `bool`.
    pub const BOOL: u8 = 1;
    /// `integer`.
    pub const INTEGER: u8 = 2;
    /// `double`.
    pub const DOUBLE: u8 = 3;
    /// `string`.
    pub const STRING: u8 = 4;
    /// `byte_array` (not used by dynlab nodes).
    pub const BYTE_ARRAY: u8 = 5;
    /// `bool_array`.
    pub const BOOL_ARRAY: u8 = 6;
    /// `integer_array`.
    pub const INTEGER_ARRAY: u8 = 7;
    /// `double_array`.
    pub const DOUBLE_ARRAY: u8 = 8;
    /// `string_array`.
    pub const STRING_ARRAY: u8 = 9;
}

/// The `ParameterType` code of a value.
pub fn type_code(v: &ParamValue) -> u8 {
    match v {
        ParamValue::Bool(_) => ptype::BOOL,
        ParamValue::Integer(_) => ptype::INTEGER,
        ParamValue::Double(_) => ptype::DOUBLE,
        ParamValue::String(_) => ptype::STRING,
        ParamValue::BoolArray(_) => ptype::BOOL_ARRAY,
        ParamValue::IntegerArray(_) => ptype::INTEGER_ARRAY,
        ParamValue::DoubleArray(_) => ptype::DOUBLE_ARRAY,
        ParamValue::StringArray(_) => ptype::STRING_ARRAY,
    }
}

fn not_set() -> raw::ParameterValue {
    raw::ParameterValue {
        ptype: ptype::NOT_SET,
        boolean_value: false,
        int_value: 0,
        double_value: 0.0,
        string_value: String::new(),
        byte_array: Vec::new(),
        bool_array: Vec::new(),
        int_array: Vec::new(),
        double_array: Vec::new(),
        string_array: Vec::new(),
    }
}

/// A value as `rcl_interfaces/msg/ParameterValue`.
pub fn to_wire(v: &ParamValue) -> raw::ParameterValue {
    let mut w = not_set();
    w.ptype = type_code(v);
    match v {
        ParamValue::Bool(b) => w.boolean_value = *b,
        ParamValue::Integer(i) => w.int_value = *i,
        ParamValue::Double(d) => w.double_value = *d,
        ParamValue::String(s) => w.string_value = s.clone(),
        ParamValue::BoolArray(a) => w.bool_array = a.clone(),
        ParamValue::IntegerArray(a) => w.int_array = a.clone(),
        ParamValue::DoubleArray(a) => w.double_array = a.clone(),
        ParamValue::StringArray(a) => w.string_array = a.clone(),
    }
    w
}

/// A `rcl_interfaces/msg/ParameterValue` as a value, or why it cannot be one.
pub fn from_wire(w: &raw::ParameterValue) -> Result<ParamValue, String> {
    Ok(match w.ptype {
        ptype::BOOL => ParamValue::Bool(w.boolean_value),
        ptype::INTEGER => ParamValue::Integer(w.int_value),
        ptype::DOUBLE => ParamValue::Double(w.double_value),
        ptype::STRING => ParamValue::String(w.string_value.clone()),
        ptype::BOOL_ARRAY => ParamValue::BoolArray(w.bool_array.clone()),
        ptype::INTEGER_ARRAY => ParamValue::IntegerArray(w.int_array.clone()),
        ptype::DOUBLE_ARRAY => ParamValue::DoubleArray(w.double_array.clone()),
        ptype::STRING_ARRAY => ParamValue::StringArray(w.string_array.clone()),
        ptype::NOT_SET => {
            return Err(
                "type NOT_SET (undeclaring a parameter) is not supported: dynlab nodes keep their parameters"
                    .to_owned(),
            );
        }
        ptype::BYTE_ARRAY => {
            return Err("byte_array parameters are not used by dynlab nodes".to_owned());
        }
        t => return Err(format!("unknown parameter type code {t}")),
    })
}

/// The `rcl_interfaces/msg/ParameterDescriptor` of a declared parameter (`None`: not declared).
pub fn describe(name: &str, d: Option<&Declared>) -> raw::ParameterDescriptor {
    let Some(d) = d else {
        return raw::ParameterDescriptor {
            name: name.to_owned(),
            r#type: ptype::NOT_SET,
            description: "not declared by this node".to_owned(),
            additional_constraints: String::new(),
            read_only: true,
            dynamic_typing: false,
            floating_point_range: Vec::new(),
            integer_range: Vec::new(),
        };
    };
    let (floating_point_range, integer_range) = match &d.descriptor.range {
        Some(ParamRange::Double { from, to, step }) => (
            vec![raw::FloatingPointRange {
                from_value: *from,
                to_value: *to,
                step: *step,
            }],
            Vec::new(),
        ),
        Some(ParamRange::Integer { from, to, step }) => (
            Vec::new(),
            vec![raw::IntegerRange {
                from_value: *from,
                to_value: *to,
                step: *step,
            }],
        ),
        None => (Vec::new(), Vec::new()),
    };
    raw::ParameterDescriptor {
        name: name.to_owned(),
        r#type: type_code(&d.value),
        description: d.descriptor.description.clone(),
        additional_constraints: d.descriptor.additional_constraints.clone(),
        read_only: d.descriptor.read_only,
        dynamic_typing: false,
        floating_point_range,
        integer_range,
    }
}

/// The set request's entries as values; an entry whose value cannot be a dynlab value carries
/// the reason instead.
fn request_values(req: &rcl::SetParametersRequest) -> Vec<(String, Result<ParamValue, String>)> {
    req.parameter
        .iter()
        .map(|p| (p.name.clone(), from_wire(&p.value)))
        .collect()
}

fn result(r: Result<(), String>) -> raw::SetParametersResult {
    match r {
        Ok(()) => raw::SetParametersResult {
            successful: true,
            reason: String::new(),
        },
        Err(reason) => raw::SetParametersResult {
            successful: false,
            reason,
        },
    }
}

/// Answers a `SetParameters` request from the store: one result per entry, each applied on its
/// own. Returns the results and the accepted changes.
pub fn answer_set(
    store: &mut ParamStore,
    req: &rcl::SetParametersRequest,
) -> (Vec<raw::SetParametersResult>, Vec<ParamChange>) {
    let mut results = Vec::new();
    let mut changes = Vec::new();
    for (name, value) in request_values(req) {
        let r = value.and_then(|v| {
            let mut one = store.set_each(&[(name.clone(), v)]);
            one.pop().unwrap_or_else(|| Err("empty".to_owned()))
        });
        match r {
            Ok(c) => {
                changes.push(c);
                results.push(result(Ok(())));
            }
            Err(reason) => results.push(result(Err(reason))),
        }
    }
    (results, changes)
}

/// Answers a `SetParametersAtomically` request: all entries or none.
pub fn answer_set_atomically(
    store: &mut ParamStore,
    req: &rcl::SetParametersRequest,
) -> (raw::SetParametersResult, Vec<ParamChange>) {
    let mut values = Vec::new();
    for (name, value) in request_values(req) {
        match value {
            Ok(v) => values.push((name, v)),
            Err(reason) => return (result(Err(format!("`{name}`: {reason}"))), Vec::new()),
        }
    }
    match store.set_all(&values) {
        Ok(changes) => (result(Ok(())), changes),
        Err(reason) => (result(Err(reason)), Vec::new()),
    }
}

type Srv<Q, R> = Server<Q, R>;

struct Servers {
    list: Srv<rcl::ListParametersRequest, rcl::ListParametersResponse>,
    get: Srv<rcl::GetParametersRequest, rcl::GetParametersResponse>,
    types: Srv<rcl::GetParameterTypesRequest, rcl::GetParameterTypesResponse>,
    set: Srv<rcl::SetParametersRequest, rcl::SetParametersResponse>,
    set_atomically: Srv<rcl::SetParametersRequest, rcl::SetParametersAtomicallyResponse>,
    describe: Srv<rcl::DescribeParametersRequest, rcl::DescribeParametersResponse>,
}

fn server<Q, R>(
    node: &mut ros2_client::Node,
    fqn: &str,
    service: &str,
    ty: &str,
) -> Result<Server<Q, R>, NodeError>
where
    Q: Message + Clone + 'static,
    R: Message + 'static,
{
    let name = Name::new(fqn, service).map_err(|e| NodeError::Create {
        what: format!("service {fqn}/{service}"),
        reason: e.to_string(),
    })?;
    let qos = crate::qos::services();
    node.create_server(
        ServiceMapping::Enhanced,
        &name,
        &ServiceTypeName::new("rcl_interfaces", ty),
        qos.clone(),
        qos,
    )
    .map_err(|e| NodeError::Create {
        what: format!("service {fqn}/{service}"),
        reason: e.to_string(),
    })
}

/// The running parameter services of one node. Dropping it stops the thread (and removes its
/// DDS entities) before the node itself goes.
pub struct ParamServices {
    stop: Arc<AtomicBool>,
    waker: Arc<mio1::Waker>,
    thread: Option<JoinHandle<()>>,
    events: Events,
    fqn: String,
}

type Events = Arc<Mutex<ros2_client::Publisher<raw::ParameterEvent>>>;

/// The `/parameter_events` message announcing `changes` of the node `fqn`.
pub fn parameter_event(fqn: &str, changes: &[ParamChange]) -> raw::ParameterEvent {
    raw::ParameterEvent {
        stamp: Time::now(),
        node: fqn.to_owned(),
        new_parameters: Vec::new(),
        changed_parameters: changes
            .iter()
            .map(|c| raw::Parameter {
                name: c.name.clone(),
                value: to_wire(&c.value),
            })
            .collect(),
        deleted_parameters: Vec::new(),
    }
}

fn publish_event(events: &Events, fqn: &str, changes: &[ParamChange]) {
    let publisher = events.lock().unwrap_or_else(|p| p.into_inner());
    if let Err(e) = publisher.publish(parameter_event(fqn, changes)) {
        tracing::warn!("/parameter_events: publishing failed: {e}");
    }
}

const WAKE: mio1::Token = mio1::Token(usize::MAX);

impl ParamServices {
    /// Creates the six services and the `/parameter_events` publisher on `node` and starts the
    /// thread that serves them from `store`, sending accepted changes to `changes`.
    pub fn start(
        node: &mut ros2_client::Node,
        events_topic: &ros2_client::dds::rustdds::Topic,
        fqn: &str,
        store: Arc<Mutex<ParamStore>>,
        changes: Sender<ParamChange>,
    ) -> Result<ParamServices, NodeError> {
        let mut servers = Servers {
            list: server(node, fqn, "list_parameters", "ListParameters")?,
            get: server(node, fqn, "get_parameters", "GetParameters")?,
            types: server(node, fqn, "get_parameter_types", "GetParameterTypes")?,
            set: server(node, fqn, "set_parameters", "SetParameters")?,
            set_atomically: server(
                node,
                fqn,
                "set_parameters_atomically",
                "SetParametersAtomically",
            )?,
            describe: server(node, fqn, "describe_parameters", "DescribeParameters")?,
        };
        let events = node
            .create_publisher::<raw::ParameterEvent>(
                events_topic,
                Some(crate::qos::parameter_events()),
            )
            .map_err(|e| NodeError::Create {
                what: "the /parameter_events publisher".to_owned(),
                reason: e.to_string(),
            })?;
        let poll = mio1::Poll::new().map_err(NodeError::Wait)?;
        let waker = Arc::new(mio1::Waker::new(poll.registry(), WAKE).map_err(NodeError::Wait)?);
        {
            let r = poll.registry();
            let i = mio1::Interest::READABLE;
            let reg = |e: std::io::Error| NodeError::Wait(e);
            r.register(&mut servers.list, mio1::Token(0), i)
                .map_err(reg)?;
            r.register(&mut servers.get, mio1::Token(1), i)
                .map_err(reg)?;
            r.register(&mut servers.types, mio1::Token(2), i)
                .map_err(reg)?;
            r.register(&mut servers.set, mio1::Token(3), i)
                .map_err(reg)?;
            r.register(&mut servers.set_atomically, mio1::Token(4), i)
                .map_err(reg)?;
            r.register(&mut servers.describe, mio1::Token(5), i)
                .map_err(reg)?;
        }
        let stop = Arc::new(AtomicBool::new(false));
        let events = Arc::new(Mutex::new(events));
        let worker = Worker {
            servers,
            ctx: Ctx {
                events: Arc::clone(&events),
                store,
                changes,
                fqn: fqn.to_owned(),
            },
        };
        let stop_t = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("param-services".to_owned())
            .spawn(move || worker.run(poll, &stop_t))
            .map_err(|e| NodeError::Create {
                what: "the parameter service thread".to_owned(),
                reason: e.to_string(),
            })?;
        Ok(ParamServices {
            stop,
            waker,
            thread: Some(thread),
            events,
            fqn: fqn.to_owned(),
        })
    }

    /// Announces changes the node made itself on `/parameter_events`.
    pub fn announce(&self, changes: &[ParamChange]) {
        publish_event(&self.events, &self.fqn, changes);
    }
}

impl Drop for ParamServices {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = self.waker.wake();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Worker {
    servers: Servers,
    ctx: Ctx,
}

/// What the answers need besides the servers.
struct Ctx {
    events: Events,
    store: Arc<Mutex<ParamStore>>,
    changes: Sender<ParamChange>,
    fqn: String,
}

/// Answers every request waiting on `server` with `answer`. A request that cannot be decoded
/// (e.g. from a client with another service mapping) is consumed and logged; the rest wait for
/// the next round.
fn drain<Q, R>(server: &Server<Q, R>, fqn: &str, service: &str, mut answer: impl FnMut(Q) -> R)
where
    Q: Message + 'static,
    R: Message + 'static,
{
    loop {
        match server.receive_request() {
            Ok(Some((id, req))) => {
                if let Err(e) = server.send_response(id, answer(req)) {
                    tracing::warn!("{fqn}/{service}: the reply could not be sent: {e}");
                }
            }
            Ok(None) => return,
            Err(e) => {
                tracing::warn!("{fqn}/{service}: a request could not be read: {e}");
                return;
            }
        }
    }
}

impl Worker {
    fn run(mut self, mut poll: mio1::Poll, stop: &AtomicBool) {
        let mut events = mio1::Events::with_capacity(16);
        while !stop.load(Ordering::SeqCst) {
            // Edge-triggered: serve everything waiting, then sleep until the next request. The
            // timeout bounds how long a request left after a read error waits.
            self.serve();
            match poll.poll(&mut events, Some(Duration::from_millis(500))) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    tracing::warn!("parameter services stopped: waiting failed: {e}");
                    return;
                }
            }
        }
    }

    fn serve(&mut self) {
        let (sv, ctx) = (&self.servers, &self.ctx);
        let fqn = ctx.fqn.as_str();
        drain(&sv.list, fqn, "list_parameters", |req| {
            let (names, prefixes) = ctx.store().list(&req.prefixes, req.depth);
            rcl::ListParametersResponse {
                result: rcl::ListParametersResult { names, prefixes },
            }
        });
        drain(&sv.get, fqn, "get_parameters", |req| {
            let s = ctx.store();
            rcl::GetParametersResponse {
                values: req
                    .names
                    .iter()
                    .map(|n| s.get(n).map(|d| to_wire(&d.value)).unwrap_or_else(not_set))
                    .collect(),
            }
        });
        drain(&sv.types, fqn, "get_parameter_types", |req| {
            let s = ctx.store();
            rcl::GetParameterTypesResponse {
                values: req
                    .names
                    .iter()
                    .map(|n| {
                        s.get(n)
                            .map(|d| type_code(&d.value))
                            .unwrap_or(ptype::NOT_SET)
                    })
                    .collect(),
            }
        });
        drain(&sv.describe, fqn, "describe_parameters", |req| {
            let s = ctx.store();
            rcl::DescribeParametersResponse {
                values: req.names.iter().map(|n| describe(n, s.get(n))).collect(),
            }
        });
        drain(&sv.set, fqn, "set_parameters", |req| {
            let (results, changes) = answer_set(&mut ctx.store(), &req);
            ctx.log_refusals(&req, &results);
            ctx.announce(changes);
            rcl::SetParametersResponse { results }
        });
        drain(
            &sv.set_atomically,
            fqn,
            "set_parameters_atomically",
            |req| {
                let (result, changes) = answer_set_atomically(&mut ctx.store(), &req);
                ctx.log_refusals(&req, std::slice::from_ref(&result));
                ctx.announce(changes);
                rcl::SetParametersAtomicallyResponse { result }
            },
        );
    }
}

impl Ctx {
    fn store(&self) -> std::sync::MutexGuard<'_, ParamStore> {
        // Every change to the store is one insert, so a lock poisoned by a panic elsewhere
        // still guards a consistent store.
        self.store.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn log_refusals(&self, req: &rcl::SetParametersRequest, results: &[raw::SetParametersResult]) {
        let names: Vec<&str> = req.parameter.iter().map(|p| p.name.as_str()).collect();
        for (i, r) in results.iter().enumerate().filter(|(_, r)| !r.successful) {
            let name = if results.len() == names.len() {
                names[i].to_owned()
            } else {
                names.join(", ")
            };
            tracing::warn!("parameter set refused: {name}: {}", r.reason);
        }
    }

    /// Publishes accepted changes on `/parameter_events`, logs them and queues them for the
    /// node loop.
    fn announce(&self, changes: Vec<ParamChange>) {
        if changes.is_empty() {
            return;
        }
        publish_event(&self.events, &self.fqn, &changes);
        for c in changes {
            tracing::info!("parameter {} set to {}", c.name, c.value);
            // The node loop may have ended already (node shutting down): nothing to apply then.
            let _ = self.changes.send(c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::param_store::ParamDescriptor;

    fn store() -> ParamStore {
        let mut s = ParamStore::new("/racer");
        s.declare(
            "reference_speed",
            ParamValue::Double(2.0),
            ParamDescriptor::dynamic("reference speed [m/s]").range(0.1, 10.0),
        )
        .unwrap();
        s.declare(
            "horizon",
            ParamValue::Integer(20),
            ParamDescriptor::read_only("steps"),
        )
        .unwrap();
        s
    }

    fn req(entries: &[(&str, ParamValue)]) -> rcl::SetParametersRequest {
        rcl::SetParametersRequest {
            parameter: entries
                .iter()
                .map(|(n, v)| raw::Parameter {
                    name: n.to_string(),
                    value: to_wire(v),
                })
                .collect(),
        }
    }

    #[test]
    fn values_round_trip_through_the_wire_type() {
        for v in [
            ParamValue::Bool(true),
            ParamValue::Integer(-7),
            ParamValue::Double(0.1),
            ParamValue::String("0.6,0.05,0".into()),
            ParamValue::BoolArray(vec![true, false]),
            ParamValue::IntegerArray(vec![1, 2]),
            ParamValue::DoubleArray(vec![0.5]),
            ParamValue::StringArray(vec!["a".into()]),
        ] {
            let w = to_wire(&v);
            assert_eq!(w.ptype, type_code(&v));
            assert_eq!(from_wire(&w).unwrap(), v);
        }
        let err = from_wire(&not_set()).unwrap_err();
        assert!(err.contains("NOT_SET"), "{err}");
    }

    #[test]
    fn set_answers_each_entry_with_its_reason() {
        let mut s = store();
        let (results, changes) = answer_set(
            &mut s,
            &req(&[
                ("reference_speed", ParamValue::Double(2.5)),
                ("horizon", ParamValue::Integer(5)),
                ("reference_speed", ParamValue::Double(50.0)),
            ]),
        );
        assert!(results[0].successful && results[0].reason.is_empty());
        assert!(!results[1].successful);
        assert!(
            results[1]
                .reason
                .starts_with("read-only: restart the node with -p horizon:=value")
        );
        assert!(
            !results[2].successful && results[2].reason.contains("outside the range [0.1, 10]")
        );
        assert_eq!(
            changes,
            vec![ParamChange {
                name: "reference_speed".into(),
                value: ParamValue::Double(2.5)
            }]
        );
        assert_eq!(
            s.get("reference_speed").unwrap().value,
            ParamValue::Double(2.5)
        );
    }

    #[test]
    fn set_atomically_is_all_or_nothing() {
        let mut s = store();
        let (r, changes) = answer_set_atomically(
            &mut s,
            &req(&[
                ("reference_speed", ParamValue::Double(3.0)),
                ("horizon", ParamValue::Integer(5)),
            ]),
        );
        assert!(!r.successful && r.reason.contains("read-only"));
        assert!(changes.is_empty());
        assert_eq!(
            s.get("reference_speed").unwrap().value,
            ParamValue::Double(2.0)
        );
    }

    #[test]
    fn descriptors_carry_read_only_and_range() {
        let s = store();
        let d = describe("reference_speed", s.get("reference_speed"));
        assert_eq!(d.r#type, ptype::DOUBLE);
        assert!(!d.read_only);
        assert_eq!(d.floating_point_range.len(), 1);
        assert_eq!(d.floating_point_range[0].from_value, 0.1);
        assert!(d.integer_range.is_empty());
        let d = describe("horizon", s.get("horizon"));
        assert!(d.read_only && d.floating_point_range.is_empty());
        let d = describe("nope", None);
        assert_eq!(d.r#type, ptype::NOT_SET);
    }

    /// The CDR layout of `rcl_interfaces/msg/SetParametersResult` and of a `ParameterValue`
    /// holding a double, byte for byte (little endian, offsets from the body start), written
    /// from the `.msg` definitions.
    #[test]
    fn wire_layout_matches_the_rcl_interfaces_definitions() {
        let r = result(Err("no".into()));
        let bytes = cdr_encoding::to_vec::<_, byteorder::LittleEndian>(&r).unwrap();
        // bool successful; string reason (u32 length incl. NUL at offset 4, then "no\0")
        assert_eq!(bytes, [0, 0, 0, 0, 3, 0, 0, 0, b'n', b'o', 0]);

        let v = to_wire(&ParamValue::Double(0.5));
        let bytes = cdr_encoding::to_vec::<_, byteorder::LittleEndian>(&v).unwrap();
        let mut want = vec![3u8, 0]; // uint8 type = DOUBLE, bool bool_value
        want.extend([0; 6]); // pad to 8 for int64 integer_value
        want.extend(0i64.to_le_bytes());
        want.extend(0.5f64.to_le_bytes()); // double_value at 16
        want.extend(1u32.to_le_bytes()); // string_value "" = length 1 + NUL
        want.push(0);
        want.extend([0; 3]); // pad to 4
        want.extend([0u8; 4 * 5]); // five empty sequences
        assert_eq!(bytes, want);
    }
}
