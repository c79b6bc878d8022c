//! Thin node runtime over ros2-client: ROS 2 command line, parameters, QoS, sim time, shutdown.
//!
//! Every dynlab node starts the same way:
//!
//! ```no_run
//! use dynlab_ros::{Node, NodeArgs, Shutdown, WaitSet, qos};
//! use dynlab_msgs::geometry_msgs::PoseStamped;
//! use std::time::Duration;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let args = NodeArgs::from_env()?;            // splits off `--ros-args … --`
//! dynlab_ros::init_logging(args.log_level);
//! let shutdown = Shutdown::install()?;         // SIGINT/SIGTERM set a flag
//! let mut node = Node::new("listener", &args)?; // ROS_DOMAIN_ID, __node, __ns, -p, --params-file
//! let rate: f64 = node.params().get_or("rate", 100.0)?;
//! let clock = node.clock()?;                   // follows /clock if use_sim_time
//! let mut sub = node.create_subscription::<PoseStamped>("/car/pose", qos::sensor_data())?;
//! let mut waits = WaitSet::new()?;
//! waits.add(&mut sub)?;
//! while !shutdown.requested() {
//!     waits.wait(Duration::from_millis(100))?;
//!     while let Some(pose) = sub.take()? {
//!         println!("{} {:?} at {}", rate, pose.pose.position, clock.now_ns()?);
//!     }
//! }
//! # Ok(()) }
//! ```
//!
//! Algorithms never depend on this crate; it is only for nodes.
//!
//! # Design choices
//!
//! - **No async runtime.** RustDDS readers are mio 1 event sources, so a node loop blocks in one
//!   [`WaitSet`] (a `mio::Poll`) with a timeout that also bounds how late it sees a shutdown
//!   request. Node loops stay single-threaded and deterministic; nothing spawns tasks.
//!   ros2-client's async `Spinner` is not run: it would subscribe `/clock` with the type
//!   `builtin_interfaces/Time` (not `rosgraph_msgs/Clock`); sim time comes from our own
//!   [`Clock`], and the parameter services run on a thread of their own ([`param_services`]),
//!   handing accepted changes to the loop through [`Node::poll_parameter_changes`].
//! - **A ROS 2 citizen.** Every node serves the `rcl_interfaces` parameter services, publishes
//!   `/parameter_events` and its log lines on `/rosout` ([`rosout`]), is listed in
//!   `ros_discovery_info`, and shuts down without RustDDS errors (see [`Node`]).
//! - **Domain id.** ros2-client ignores `ROS_DOMAIN_ID`; [`Node::new`] reads and validates it.
//! - **Raw messages.** ros2-client has no untyped subscriptions; [`RawSubscription`] and
//!   [`RawPublisher`] are RustDDS readers and writers with a bytes-keeping adapter.
#![warn(missing_docs)]

pub mod args;
pub mod clock;
pub mod names;
pub mod node;
pub mod param_services;
pub mod param_store;
pub mod params;
pub mod qos;
pub mod raw;
pub mod rosout;
pub mod shutdown;

pub use args::{ArgsError, LogLevel, NodeArgs, ParamArg, Remap};
pub use clock::Clock;
pub use node::{
    DiscoveredPublication, Node, NodeError, Publisher, RawPublisher, RawSubscription, Received,
    Subscription, WaitSet, domain_id_from_env, parse_domain_id,
};
pub use param_store::{ParamChange, ParamCheck, ParamDescriptor, ParamRange, ParamStore};
pub use params::{FromParam, ParamError, ParamSource, ParamValue, Parameters};
pub use qos::{QosPreset, QosProfile};
pub use raw::SerializedMessage;
pub use shutdown::{Shutdown, ShutdownError};

/// Log filter directives after the level: RustDDS and ros2-client at warnings; ros2-client's
/// service request decoding at errors, because it warns on every request of a client that sends
/// no related-sample-identity (a plain DDS client) and then answers it correctly anyway.
const QUIET: &str = "rustdds=warn,ros2_client=warn,ros2_client::service::wrappers=error";

/// Sets up logging to stderr: `RUST_LOG` if set, else the `--log-level` threshold (default
/// `info`). RustDDS and ros2-client are held to warnings unless `RUST_LOG` says otherwise, since
/// their info messages describe every discovery step. The same lines at info level and above
/// also go to `/rosout` once the process's [`Node`] exists (see [`rosout`]). Safe to call more
/// than once.
pub fn init_logging(level: Option<LogLevel>) {
    use tracing_subscriber::EnvFilter;
    let level = level.unwrap_or(LogLevel::Info).directive();
    let filter = EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| EnvFilter::new(format!("{level},{QUIET}")));
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let _ = tracing_subscriber::registry()
        .with(filter)
        .with(tracing_subscriber::fmt::layer().with_writer(std::io::stderr))
        .with(rosout::RosoutLayer)
        .try_init();
}
