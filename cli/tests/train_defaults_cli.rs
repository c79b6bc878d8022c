//! `dynlab train` picks rollout steps, discount and epochs per world and kind when they are not
//! given, says which, and explicit flags win.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bag(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../bags")
        .join(name)
}

/// Trains briefly (`--max-samples`) and returns stderr and the recorded (steps, epochs, γ).
fn train(bag: &Path, kind: &str, extra: &[&str], out: &Path) -> (String, u64, u64, f64) {
    let o = Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(["train", "--bag"])
        .arg(bag)
        .args(["--kind", kind, "--max-samples", "1000", "--quiet", "--out"])
        .arg(out)
        .args(extra)
        .output()
        .expect("run dynlab");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "train failed: {err}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    let c = &m["training"]["config"];
    (
        err,
        c["steps"].as_u64().unwrap(),
        c["epochs"].as_u64().unwrap(),
        c["gamma"].as_f64().unwrap(),
    )
}

#[test]
fn the_car_network_kinds_default_to_the_multi_step_loss_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let (err, steps, epochs, gamma) =
        train(&bag("car_nominal"), "residual", &[], &dir.path().join("m"));
    assert!(
        err.contains("defaults for a car residual model: --steps 5 --gamma 0.9 --epochs 40"),
        "{err}"
    );
    assert_eq!((steps, epochs, gamma), (5, 40, 0.9));
}

#[test]
fn explicit_flags_win_over_the_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let (err, steps, epochs, gamma) = train(
        &bag("car_nominal"),
        "residual",
        &["--steps", "2", "--gamma", "0.5", "--epochs", "3"],
        &dir.path().join("m"),
    );
    assert!(!err.contains("defaults for"), "{err}");
    assert_eq!((steps, epochs, gamma), (2, 3, 0.5));
    // one flag given: only the other is a default
    let (err, steps, epochs, _) = train(
        &bag("car_nominal"),
        "residual",
        &["--steps", "2"],
        &dir.path().join("m2"),
    );
    assert!(
        err.contains("defaults for a car residual model: --gamma 0.9 --epochs 40"),
        "{err}"
    );
    assert_eq!((steps, epochs), (2, 40));
}

#[test]
fn pushing_keeps_one_step_and_300_epochs() {
    let dir = tempfile::tempdir().unwrap();
    let (err, steps, epochs, _) =
        train(&bag("push_nominal"), "node-rk4", &[], &dir.path().join("m"));
    assert!(
        err.contains("defaults for a push node-rk4 model: --steps 1 --epochs 300"),
        "{err}"
    );
    assert_eq!((steps, epochs), (1, 300));
}

#[test]
fn the_car_physics_model_defaults_to_undiscounted_50_step_rollouts() {
    let dir = tempfile::tempdir().unwrap();
    let (err, steps, _, gamma) = train(
        &bag("car_nominal"),
        "physics",
        &["--physics-windows", "100"],
        &dir.path().join("m"),
    );
    assert!(
        err.contains("defaults for a car physics model: --steps 50 --gamma 1 ("),
        "{err}"
    );
    assert_eq!((steps, gamma), (50, 1.0));
}

#[test]
fn a_discount_outside_0_to_1_is_refused_with_its_range() {
    let dir = tempfile::tempdir().unwrap();
    for g in ["1.5", "0", "nan"] {
        let o = Command::new(env!("CARGO_BIN_EXE_dynlab"))
            .args(["train", "--bag"])
            .arg(bag("car_nominal"))
            .args(["--kind", "physics", "--gamma", g, "--out"])
            .arg(dir.path().join("m"))
            .output()
            .expect("run dynlab");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "--gamma {g} was accepted");
        assert!(err.contains("the discount must be in (0, 1]"), "{err}");
        assert!(
            !dir.path().join("m").exists(),
            "a model was written for --gamma {g}"
        );
    }
}
