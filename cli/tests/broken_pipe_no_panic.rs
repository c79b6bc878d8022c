//! Regression: `dynlab bag info BAG | head -n 1` panicked with "failed printing to stdout: Broken
//! pipe" when `head` closed the pipe before dynlab had printed everything. The CLI must end
//! quietly instead, as other command-line tools do.

use std::process::{Command, Stdio};

#[test]
fn closed_stdout_ends_quietly_without_a_panic() {
    let bag = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../bags/car_nominal");
    let mut child = Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(["bag", "info"])
        .arg(&bag)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn dynlab");
    // Close the read end at once: dynlab is still opening the bag and prints into a closed pipe.
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("wait for dynlab");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("panicked"),
        "dynlab panicked on a closed pipe:\n{stderr}"
    );
    assert_ne!(
        out.status.code(),
        Some(101),
        "exit code 101 is Rust's panic exit"
    );
}
