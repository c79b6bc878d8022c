//! `/rosout`: the node's log lines as `rcl_interfaces/msg/Log`, as rclcpp publishes them, so
//! `ros2 topic echo /rosout` and rqt_console show them.
//!
//! [`RosoutLayer`] is a `tracing` layer (installed by [`crate::init_logging`]) that forwards
//! every event at info level and above — the same events the node prints on stderr — to the
//! `/rosout` publisher of the node of this process, once [`crate::Node::new`] has created it.
//! The logger name is the node's name (`mppi_pusher`, or `ns.mppi_pusher` in a namespace), as
//! rcl names node loggers. Events of the DDS stack itself (RustDDS, ros2-client, mio) are not
//! forwarded: rclcpp does not send middleware logs to `/rosout` either, and publishing from
//! inside RustDDS's own threads could wait on the thread that is logging.

use std::cell::Cell;
use std::fmt::Write as _;
use std::sync::Mutex;

use ros2_client::Log;
use ros2_client::builtin_interfaces::Time;
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::{Context, Layer};

struct Sink {
    id: u64,
    name: String,
    publisher: ros2_client::Publisher<Log>,
}

static SINK: Mutex<Option<Sink>> = Mutex::new(None);
static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

thread_local! {
    static PUBLISHING: Cell<bool> = const { Cell::new(false) };
}

/// The rcl logger name of a node: its fully qualified name without the leading `/`, with `.`
/// between namespace and name (`/robot1/racer` → `robot1.racer`).
pub fn logger_name(node_fqn: &str) -> String {
    node_fqn.trim_start_matches('/').replace('/', ".")
}

/// The `Log` level of a tracing level (`None`: below info, not forwarded).
pub fn log_level(level: &Level) -> Option<u8> {
    match *level {
        Level::ERROR => Some(Log::ERROR),
        Level::WARN => Some(Log::WARN),
        Level::INFO => Some(Log::INFO),
        _ => None,
    }
}

/// Whether events of this target are forwarded (not those of the DDS stack).
pub fn forwarded_target(target: &str) -> bool {
    !["rustdds", "ros2_client", "mio", "speedy", "socket2"]
        .iter()
        .any(|p| target == *p || target.starts_with(&format!("{p}::")))
}

/// Keeps the node's `/rosout` publisher installed; dropping it removes it (before the node's
/// participant goes).
pub struct RosoutRegistration {
    id: u64,
}

/// Installs `publisher` as this process's `/rosout` output for the node `node_fqn`, replacing
/// any earlier one.
pub fn register(node_fqn: &str, publisher: ros2_client::Publisher<Log>) -> RosoutRegistration {
    let id = NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut sink = SINK.lock().unwrap_or_else(|p| p.into_inner());
    *sink = Some(Sink {
        id,
        name: logger_name(node_fqn),
        publisher,
    });
    RosoutRegistration { id }
}

impl Drop for RosoutRegistration {
    fn drop(&mut self) {
        let mut sink = SINK.lock().unwrap_or_else(|p| p.into_inner());
        if sink.as_ref().is_some_and(|s| s.id == self.id) {
            *sink = None;
        }
    }
}

/// The `tracing` layer that publishes log lines on `/rosout` (see the module documentation).
#[derive(Debug, Default, Clone, Copy)]
pub struct RosoutLayer;

/// Collects an event's message and its other fields (`key=value`, as the stderr format shows
/// them).
#[derive(Default)]
struct Text {
    message: String,
    fields: String,
}

impl Visit for Text {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.message.push_str(value);
        } else {
            let _ = write!(self.fields, " {}={value}", field.name());
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.message, "{value:?}");
        } else {
            let _ = write!(self.fields, " {}={value:?}", field.name());
        }
    }
}

impl<S: Subscriber> Layer<S> for RosoutLayer {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        let meta = event.metadata();
        let Some(level) = log_level(meta.level()) else {
            return;
        };
        if !forwarded_target(meta.target()) || PUBLISHING.with(Cell::get) {
            return;
        }
        // Waiting for the lock cannot deadlock: while a line is published, events of the DDS
        // stack are dropped above by target and events of this thread by `PUBLISHING`.
        let sink = SINK.lock().unwrap_or_else(|p| p.into_inner());
        let Some(sink) = sink.as_ref() else {
            return;
        };
        let mut text = Text::default();
        event.record(&mut text);
        let log = Log {
            stamp: Time::now(),
            level,
            name: sink.name.clone(),
            msg: text.message + &text.fields,
            file: meta.file().unwrap_or("").to_owned(),
            function: meta.module_path().unwrap_or(meta.target()).to_owned(),
            line: meta.line().unwrap_or(0),
        };
        PUBLISHING.with(|p| p.set(true));
        let _ = sink.publisher.publish(log);
        PUBLISHING.with(|p| p.set(false));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logger_names_follow_rcl() {
        assert_eq!(logger_name("/mppi_pusher"), "mppi_pusher");
        assert_eq!(logger_name("/robot1/racer"), "robot1.racer");
    }

    #[test]
    fn info_and_above_from_our_code_are_forwarded() {
        assert_eq!(log_level(&Level::ERROR), Some(40));
        assert_eq!(log_level(&Level::WARN), Some(30));
        assert_eq!(log_level(&Level::INFO), Some(20));
        assert_eq!(log_level(&Level::DEBUG), None);
        assert!(forwarded_target("mppi_pusher"));
        assert!(forwarded_target("dynlab_ros::param_services"));
        assert!(forwarded_target("rustdds_like_name"));
        assert!(!forwarded_target("rustdds::dds::pubsub"));
        assert!(!forwarded_target("ros2_client::node"));
    }
}
