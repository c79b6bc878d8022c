//! The parameter services answer a client that matches replies to requests the way
//! `rmw_fastrtps_cpp` does (DDS-RPC "Enhanced" mapping: the request's identity travels as
//! related-sample-identity inline QoS and comes back on the reply). The client is ros2-client's
//! own `Client` on a second DDS participant; the Cyclone DDS interop test covers plain clients.
//! Accepted changes reach the node loop through `poll_parameter_changes`.

use std::time::{Duration, Instant};

use dynlab_ros::{Node, NodeArgs, ParamDescriptor, ParamValue};
use ros2_client::parameters::raw;
use ros2_client::rcl_interfaces as rcl;
use ros2_client::{
    Context, ContextOptions, Name, NodeName, NodeOptions, ServiceMapping, ServiceTypeName,
};

const DOMAIN: u16 = 96;

/// Sends `req` until a reply for exactly that request arrives (a request written before the
/// server's reader matched is not delivered); panics after 20 s.
fn call<Q, R>(client: &ros2_client::Client<Q, R>, req: Q) -> R
where
    Q: ros2_client::Message + Clone + 'static,
    R: ros2_client::Message + 'static,
{
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        let id = client.send_request(req.clone()).expect("request written");
        let wait = Instant::now() + Duration::from_millis(300);
        while Instant::now() < wait {
            match client.receive_response() {
                Ok(Some((rid, resp))) if rid == id => return resp,
                Ok(_) => std::thread::sleep(Duration::from_millis(5)),
                Err(e) => panic!("reply unreadable: {e}"),
            }
        }
    }
    panic!("no reply within 20 s");
}

fn double(v: f64) -> raw::ParameterValue {
    raw::ParameterValue {
        ptype: 3,
        boolean_value: false,
        int_value: 0,
        double_value: v,
        string_value: String::new(),
        byte_array: vec![],
        bool_array: vec![],
        int_array: vec![],
        double_array: vec![],
        string_array: vec![],
    }
}

#[test]
fn an_enhanced_mapping_client_gets_its_replies_and_the_loop_gets_the_change() {
    let args = NodeArgs::parse(["--ros-args", "-p", "horizon:=8"]).unwrap();
    let node = Node::with_domain("enhanced_check", &args, DOMAIN).unwrap();
    let horizon: i64 = node.params().get_or("horizon", 20).unwrap();
    assert_eq!(horizon, 8);
    node.declare_parameter(
        "goal_tolerance",
        ParamValue::Double(0.02),
        ParamDescriptor::dynamic("goal distance [m]").range(0.0, 1.0),
    )
    .unwrap();

    let context = Context::with_options(ContextOptions::new().domain_id(DOMAIN)).unwrap();
    let mut peer = context
        .new_node(
            NodeName::new("/", "enhanced_client").unwrap(),
            NodeOptions::new()
                .enable_rosout(false)
                .start_parameter_services(false),
        )
        .unwrap();
    let qos = dynlab_ros::qos::services();
    let set = peer
        .create_client::<rcl::SetParametersRequest, rcl::SetParametersResponse>(
            ServiceMapping::Enhanced,
            &Name::new("/enhanced_check", "set_parameters").unwrap(),
            &ServiceTypeName::new("rcl_interfaces", "SetParameters"),
            qos.clone(),
            qos.clone(),
        )
        .unwrap();
    let get = peer
        .create_client::<rcl::GetParametersRequest, rcl::GetParametersResponse>(
            ServiceMapping::Enhanced,
            &Name::new("/enhanced_check", "get_parameters").unwrap(),
            &ServiceTypeName::new("rcl_interfaces", "GetParameters"),
            qos.clone(),
            qos,
        )
        .unwrap();

    let resp = call(
        &set,
        rcl::SetParametersRequest {
            parameter: vec![
                raw::Parameter {
                    name: "goal_tolerance".into(),
                    value: double(0.05),
                },
                raw::Parameter {
                    name: "horizon".into(),
                    value: double(3.0),
                },
            ],
        },
    );
    assert!(resp.results[0].successful, "{}", resp.results[0].reason);
    assert!(!resp.results[1].successful);
    assert!(
        resp.results[1]
            .reason
            .starts_with("read-only: restart the node with -p horizon:=value"),
        "{}",
        resp.results[1].reason
    );

    let resp = call(
        &get,
        rcl::GetParametersRequest {
            names: vec![
                "goal_tolerance".into(),
                "horizon".into(),
                "use_sim_time".into(),
            ],
        },
    );
    let v: Vec<(u8, f64, i64, bool)> = resp
        .values
        .iter()
        .map(|v| (v.ptype, v.double_value, v.int_value, v.boolean_value))
        .collect();
    assert_eq!(
        v,
        [(3, 0.05, 0, false), (2, 0.0, 8, false), (1, 0.0, 0, false)]
    );

    // The change is queued for the loop once per accepted set (a request resent before the
    // first reply came is a second set of the same value).
    let changes = node.poll_parameter_changes();
    assert!(!changes.is_empty());
    assert!(
        changes
            .iter()
            .all(|c| c.name == "goal_tolerance" && c.value == ParamValue::Double(0.05))
    );
    assert_eq!(
        node.parameter("goal_tolerance"),
        Some(ParamValue::Double(0.05))
    );
    assert!(node.poll_parameter_changes().is_empty());
}
