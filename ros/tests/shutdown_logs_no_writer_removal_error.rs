//! Regression: every node logged `ERROR rustdds::dds::pubsub: Cannot remove Writer GUID {…} :
//! TrySendError::Disconnected` at shutdown. ros2-client's `Node` drops its handle of the context
//! (the last owner of the DDS participant) before its `/parameter_events` writer, so the
//! participant's event loop had stopped when that writer asked to be removed. `dynlab_ros::Node`
//! now keeps its own context handle until after the ros2-client node is gone.
//!
//! The test captures the log (RustDDS logs through `log`, bridged into `tracing`) while a node
//! with a publisher, a subscription and running parameter services is created and dropped.

use std::io::Write;
use std::sync::{Arc, Mutex};

use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_ros::{Node, NodeArgs, qos};

#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn dropping_a_node_removes_its_writers_without_an_error() {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let log = Captured::default();
    let sink = log.clone();
    tracing_subscriber::registry()
        .with(tracing_subscriber::EnvFilter::new("warn"))
        .with(
            tracing_subscriber::fmt::layer()
                .with_ansi(false)
                .with_writer(move || sink.clone()),
        )
        .try_init()
        .expect("the only subscriber of this test binary");

    let args = NodeArgs::parse(["--ros-args", "-p", "rate:=5.0"]).unwrap();
    for round in 0..2 {
        let mut node = Node::with_domain("shutdown_check", &args, 97).unwrap();
        let rate: f64 = node.params().get_or("rate", 1.0).unwrap();
        assert_eq!(rate, 5.0);
        let publisher = node
            .create_publisher::<PoseStamped>("/shutdown_check/pose", qos::default_profile())
            .unwrap();
        let sub = node
            .create_subscription::<PoseStamped>("/shutdown_check/pose", qos::sensor_data())
            .unwrap();
        publisher.publish(PoseStamped::default()).unwrap();
        // the usual order in a node binary: entities go before the node…
        if round == 0 {
            drop(sub);
            drop(publisher);
            drop(node);
        } else {
            // …but a publisher that outlives its node must not log an error either
            drop(node);
            drop(sub);
            drop(publisher);
        }
    }
    let text = String::from_utf8(log.0.lock().unwrap().clone()).unwrap();
    assert!(!text.contains("Cannot remove"), "{text}");
    assert!(!text.contains("ERROR"), "{text}");
}
