//! The `msg_cdr` tool: encodes and decodes JSON lines, names the line of an error.

use std::io::Write;
use std::process::{Command, Output, Stdio};

fn run(args: &[&str], stdin: &str) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_msg_cdr"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(stdin.as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

#[test]
fn encodes_json_lines_to_hex_lines() {
    let input = concat!(
        r#"{"type": "builtin_interfaces/msg/Time", "value": {"sec": -2, "nanosec": 16909060}}"#,
        "\n\n",
        r#"{"type": "rosgraph_msgs/Clock", "value": {"clock": {"sec": 1, "nanosec": 0}}}"#,
        "\n"
    );
    let out = run(&[], input);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        "00010000feffffff04030201\n000100000100000000000000\n"
    );
}

#[test]
fn decode_inverts_encode() {
    let value = r#"{"header":{"stamp":{"sec":3,"nanosec":4},"frame_id":"tâble"},"location":-0.5,"angle":"NaN","length":1.0}"#;
    let enc = run(
        &[],
        &format!(r#"{{"type":"dynlab_msgs/msg/PushAction","value":{value}}}"#),
    );
    assert!(enc.status.success());
    let hex = String::from_utf8(enc.stdout).unwrap();
    let dec = run(
        &["--decode"],
        &format!(
            r#"{{"type":"dynlab_msgs/msg/PushAction","hex":"{}"}}"#,
            hex.trim()
        ),
    );
    assert!(
        dec.status.success(),
        "{}",
        String::from_utf8_lossy(&dec.stderr)
    );
    let line: serde_json::Value = serde_json::from_slice(&dec.stdout).unwrap();
    assert_eq!(line["type"], "dynlab_msgs/msg/PushAction");
    assert_eq!(
        line["value"],
        serde_json::from_str::<serde_json::Value>(value).unwrap()
    );
}

#[test]
fn errors_name_the_line_and_the_problem() {
    let good = r#"{"type": "geometry_msgs/msg/Point", "value": {"x": 1, "y": 2, "z": 3}}"#;
    let cases = [
        (
            format!("{good}\n{good}\nnot json\n"),
            "line 3",
            "not a JSON object",
        ),
        (
            format!("{good}\n{{\"type\": \"foo/msg/Bar\", \"value\": {{}}}}\n"),
            "line 2",
            "unknown message type `foo/msg/Bar`",
        ),
        (
            r#"{"type": "geometry_msgs/msg/Point", "value": {"x": 1, "y": 2}}"#.to_string(),
            "line 1",
            "missing field `z`",
        ),
        (r#"{"value": {}}"#.to_string(), "line 1", "missing \"type\""),
    ];
    for (input, line, problem) in cases {
        let out = run(&[], &input);
        assert!(!out.status.success());
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(err.contains(line) && err.contains(problem), "{err}");
        // Output for the good lines before the bad one is still written.
        let good_lines = input.lines().take_while(|l| *l == good).count();
        assert_eq!(
            String::from_utf8(out.stdout).unwrap().lines().count(),
            good_lines
        );
    }
    let bad_hex = [
        (
            r#"{"type": "geometry_msgs/msg/Point", "hex": "000"}"#,
            "odd number of digits",
        ),
        (
            r#"{"type": "geometry_msgs/msg/Point", "hex": "00zz"}"#,
            "non-hex character at position 2",
        ),
        (
            r#"{"type": "geometry_msgs/msg/Point", "hex": "00010000"}"#,
            "does not decode as geometry_msgs/msg/Point",
        ),
    ];
    for (input, problem) in bad_hex {
        let out = run(&["--decode"], input);
        assert!(!out.status.success());
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(err.contains("line 1") && err.contains(problem), "{err}");
    }
}

#[test]
fn lists_types_and_schemas() {
    let out = run(&["--list"], "");
    let list = String::from_utf8(out.stdout).unwrap();
    assert_eq!(list.lines().count(), dynlab_msgs::all().len());
    let out = run(&["--schemas"], "");
    let schemas: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let odom = schemas
        .iter()
        .find(|s| s["type"] == "nav_msgs/msg/Odometry")
        .unwrap();
    assert_eq!(odom["dds_type"], "nav_msgs::msg::dds_::Odometry_");
    assert_eq!(
        odom["definition"],
        dynlab_msgs::lookup("nav_msgs/msg/Odometry")
            .unwrap()
            .definition
    );
}
