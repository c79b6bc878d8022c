//! `dynlab bag …` end to end: import, info and export agree; bad input gives clear errors.

use std::path::Path;
use std::process::{Command, Output};

fn dynlab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(args)
        .output()
        .expect("run dynlab")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn pose_line(i: u64, x: f64) -> String {
    format!(
        r#"{{"topic":"/car/pose","type":"geometry_msgs/msg/PoseStamped","log_time_ns":{},"value":{{"header":{{"stamp":{{"sec":{i},"nanosec":0}},"frame_id":"world"}},"pose":{{"position":{{"x":{x:?},"y":-0.0,"z":1e-300}},"orientation":{{"x":0.0,"y":0.0,"z":0.0,"w":1.0}}}}}}}}"#,
        1_000_000_000 + i * 20_000_000
    )
}

fn cmd_line(i: u64) -> String {
    format!(
        r#"{{"topic":"/car/cmd","type":"ackermann_msgs/msg/AckermannDriveStamped","log_time_ns":{},"publish_time_ns":5,"value":{{"header":{{"stamp":{{"sec":0,"nanosec":0}},"frame_id":""}},"drive":{{"steering_angle":0.25,"steering_angle_velocity":0.0,"speed":0.0,"acceleration":-0.5,"jerk":0.0}}}}}}"#,
        1_000_000_000 + i * 50_000_000 + 1
    )
}

#[test]
fn import_info_export_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let mut lines: Vec<String> = (0..50).map(|i| pose_line(i, i as f64 * 0.1)).collect();
    lines.extend((0..20).map(cmd_line));
    let src = tmp.path().join("in.jsonl");
    std::fs::write(&src, lines.join("\n") + "\n").unwrap();
    let bag = tmp.path().join("bag");
    let out = dynlab(&[
        "bag",
        "import",
        src.to_str().unwrap(),
        "--out",
        bag.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("wrote 70 messages on 2 topics"));

    let info = dynlab(&["bag", "info", bag.to_str().unwrap()]);
    assert!(info.status.success());
    let info = text(&info.stdout);
    assert!(info.contains("messages:  70"), "{info}");
    assert!(
        info.lines()
            .any(|l| l.starts_with("/car/pose") && l.contains(" 50 ") && l.contains("50.00")),
        "{info}"
    );
    assert!(
        info.lines()
            .any(|l| l.starts_with("/car/cmd") && l.contains("20.00")),
        "{info}"
    );

    let export = dynlab(&[
        "bag",
        "export",
        bag.to_str().unwrap(),
        "--topic",
        "/car/pose",
    ]);
    assert!(export.status.success(), "{}", text(&export.stderr));
    let rows: Vec<serde_json::Value> = text(&export.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 50);
    for (i, (row, line)) in rows.iter().zip(&lines).enumerate() {
        let input: serde_json::Value = serde_json::from_str(line).unwrap();
        assert_eq!(row["value"], input["value"], "message {i}");
        assert_eq!(row["log_time_ns"], input["log_time_ns"]);
        assert_eq!(row["publish_time_ns"], input["log_time_ns"]);
    }
    // -0.0 and 1e-300 survive exactly.
    assert!(text(&export.stdout).contains(r#""y":-0.0,"z":1e-300"#));
    let all = dynlab(&["bag", "export", bag.to_str().unwrap()]);
    let all = text(&all.stdout);
    assert_eq!(all.lines().count(), 70);
    assert!(all.lines().nth(1).unwrap().starts_with(r#"{"topic":"/car/cmd","type":"ackermann_msgs/msg/AckermannDriveStamped","log_time_ns":1000000001,"publish_time_ns":5,"#));
}

#[test]
fn clear_errors_for_missing_topics_bad_lines_and_non_bags() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("in.jsonl");
    std::fs::write(&src, format!("{}\n{}\n", pose_line(0, 1.0), r#"{"topic":"/x","type":"geometry_msgs/msg/PoseStamped","log_time_ns":3,"value":{"pose":{}}}"#)).unwrap();
    let bag = tmp.path().join("bad");
    let out = dynlab(&[
        "bag",
        "import",
        src.to_str().unwrap(),
        "--out",
        bag.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.starts_with("error: ")
            && err.contains("in.jsonl line 2")
            && err.contains("PoseStamped"),
        "{err}"
    );
    assert!(
        !Path::new(&bag).exists(),
        "a failed import leaves no bag behind"
    );

    std::fs::write(&src, pose_line(0, 1.0) + "\n").unwrap();
    let good = tmp.path().join("good");
    assert!(
        dynlab(&[
            "bag",
            "import",
            src.to_str().unwrap(),
            "--out",
            good.to_str().unwrap()
        ])
        .status
        .success()
    );
    let out = dynlab(&[
        "bag",
        "export",
        good.to_str().unwrap(),
        "--topic",
        "/car/cmd",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).starts_with("error: topic /car/cmd not in bag"),
        "{}",
        text(&out.stderr)
    );
    assert!(text(&out.stderr).contains("(has /car/pose [geometry_msgs/msg/PoseStamped, 1 msgs])"));

    let out = dynlab(&[
        "bag",
        "import",
        src.to_str().unwrap(),
        "--out",
        good.to_str().unwrap(),
    ]);
    assert!(text(&out.stderr).contains("already exists and is not empty"));

    let out = dynlab(&["bag", "info", tmp.path().join("in.jsonl").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let err = text(&out.stderr);
    assert!(
        err.contains("not an MCAP file") && !err.contains("panicked"),
        "{err}"
    );
}
