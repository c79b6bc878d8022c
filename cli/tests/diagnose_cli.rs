//! `dynlab diagnose` end to end on a bundled bag with a hidden effect: terminal table,
//! `diagnosis.json` with the contract keys, `diagnosis.html`; the printed `train` command keeps a
//! model's custom effect and its training settings; and a clear error for a bag of the wrong
//! robot.

use std::path::Path;
use std::process::{Command, Output};

use dynlab_learn::dynamics::physics::{CustomEffect, PhysicsModel};
use dynlab_learn::file::TrainingMeta;
use dynlab_learn::train::default_physics_solver;
use dynlab_learn::{Model, ModelKind, TrainConfig, World, save_model};

fn repo(p: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(p)
}

/// The world's nominal physics model at its documented values, saved to `dir`.
fn nominal_model(dir: &Path, world: World) {
    save_physics(dir, world, None, None);
}

/// The world's nominal physics model, with a custom effect and a training record when given,
/// saved to `dir`.
fn save_physics(
    dir: &Path,
    world: World,
    custom: Option<CustomEffect>,
    training: Option<TrainingMeta>,
) {
    let (mut physics, dt) = match world {
        World::Car => (PhysicsModel::car(&[]).unwrap(), 0.01),
        World::Push => (PhysicsModel::pushing(&[]).unwrap(), 2.0),
    };
    if let Some(c) = custom {
        physics.add_custom(c).unwrap();
    }
    let m = Model::new(
        ModelKind::Physics,
        world,
        dt,
        None,
        None,
        Some(physics),
        default_physics_solver(world),
    )
    .unwrap();
    save_model(&m, dir, training, serde_json::Map::new()).unwrap();
}

/// `dynlab diagnose` of `model` on the bundled steering-offset bag with the candidate `effects`
/// and the options `extra` into `out`.
fn run_on_offset_bag(model: &Path, effects: &str, extra: &[&str], out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(["diagnose", "--model"])
        .arg(model)
        .arg("--bag")
        .arg(repo("bags/car_steering_offset"))
        .args(["--effects", effects])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

/// [`run_on_offset_bag`] without options: its standard output (the run must succeed).
fn diagnose_offset_bag(model: &Path, effects: &str, out: &Path) -> String {
    let o = run_on_offset_bag(model, effects, &[], out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn diagnose_names_the_steering_offset_of_the_bundled_bag_and_writes_json_and_html() {
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("model");
    nominal_model(&model, World::Car);
    let out = tmp.path().join("diag");
    let stdout = diagnose_offset_bag(&model, "steering_offset,aero_drag", &out);
    assert!(stdout.contains("verdict: steering_offset"), "{stdout}");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("diagnosis.json")).unwrap())
            .unwrap();
    assert_eq!(j["verdict"], "steering_offset", "{j}");
    let c = &j["candidates"][0];
    assert_eq!(c["effect"], "steering_offset");
    assert_eq!(c["significant"], true);
    let d0 = c["params"]["delta0"].as_f64().unwrap();
    assert!((d0 - 0.03).abs() < 0.005, "δ₀ = {d0}");
    assert!(c["param_std"]["delta0"].as_f64().unwrap() > 0.0);
    assert_eq!(j["candidates"][1]["significant"], false);
    // the train command to add it starts from the fitted offset
    let line = stdout
        .lines()
        .find(|l| l.starts_with("add them: dynlab train"))
        .unwrap_or_default();
    assert!(line.contains("--effects steering_offset"), "{stdout}");
    let set: f64 = line
        .split("--set steering_offset.delta0=")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    assert!((set - 0.03).abs() < 0.005, "{line}");
    let html = std::fs::read_to_string(out.join("diagnosis.html")).unwrap();
    assert!(html.contains("<section") && html.contains("steering_offset"));
}

/// Diagnoses the bundled offset bag with the span option `flag` at 0.1 s (and `extra`): the
/// offset is named and recovered and diagnosis.json records the span under `key`; the span
/// `bad` is refused by name with the `range`. The standard output and the page of the run at
/// 0.1 s.
fn offset_bag_with_span(
    flag: &str,
    key: &str,
    extra: &[&str],
    bad: &str,
    range: &str,
) -> [String; 2] {
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("model");
    nominal_model(&model, World::Car);
    let out = tmp.path().join("diag");
    let run = |span: &str| {
        let args: Vec<&str> = [flag, span]
            .into_iter()
            .chain(extra.iter().copied())
            .collect();
        run_on_offset_bag(&model, "steering_offset,aero_drag", &args, &out)
    };
    let o = run("0.1");
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("verdict: steering_offset"), "{stdout}");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("diagnosis.json")).unwrap())
            .unwrap();
    assert_eq!(j["config"][key], 0.1, "{j}");
    let d0 = j["candidates"][0]["params"]["delta0"].as_f64().unwrap();
    assert!((d0 - 0.03).abs() < 0.005, "δ₀ = {d0}");
    let html = std::fs::read_to_string(out.join("diagnosis.html")).unwrap();
    let o = run(bad);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(key) && err.contains(range), "{err}");
    [stdout, html]
}

/// `--model-states 0.1`: the states re-estimated with the model; the offset is still named and
/// recovered, the terminal and the page say what the option shows and hides, diagnosis.json
/// records it; a half-span out of range is refused by name.
#[test]
fn diagnose_with_states_from_the_model_names_the_offset_and_says_what_it_hides() {
    let [stdout, html] =
        offset_bag_with_span("--model-states", "model_states", &[], "0.7", "(0, 0.5]");
    assert!(
        stdout.contains("the states re-estimated with the model over ±0.1 s)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("a command delay") && stdout.contains("without --model-states"),
        "{stdout}"
    );
    assert!(html.contains("States from the model:"), "{html}");
}

/// `--fitted-starts 0.1 --score poses`: every model started from its own fit to the poses
/// before each window; the offset is named and recovered, the terminal and the page say how the
/// models are started and scored; a span out of range is refused by name.
#[test]
fn diagnose_with_fitted_starts_scored_on_the_poses_names_the_offset() {
    let [stdout, html] = offset_bag_with_span(
        "--fitted-starts",
        "fitted_starts",
        &["--score", "poses"],
        "0.5",
        "(0, 0.3]",
    );
    assert!(
        stdout.contains(
            "scored on the poses, each model started from its own fit to the 0.1 s of poses before each window)"
        ),
        "{stdout}"
    );
    assert!(
        html.contains("Fitted starts:")
            && html.contains("nothing it is compared with is an estimate"),
        "{html}"
    );
}

/// A model trained with `--effects-file` (and `--steps 3 --seed 4`) and diagnosed again: the
/// command that adds what the diagnosis found keeps the model's custom effect, written out at
/// the model's coefficients, and trains as the model was trained.
#[test]
fn the_train_command_keeps_the_models_custom_effect_and_training_settings() {
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("model");
    let drag = CustomEffect::from_toml(
        "name = \"speed_drag\"\n[[term]]\nstate = \"vx\"\nfeature = \"vx*|v|\"\ncoefficient = -1.5e-3\n",
    )
    .unwrap();
    let training = TrainingMeta {
        bags: Vec::new(),
        config: TrainConfig {
            kind: ModelKind::Physics,
            steps: 3,
            seed: 4,
            ..TrainConfig::default()
        },
        best_epoch: 1,
        epochs_run: 1,
        windows: (100, 20),
        savgol: Vec::new(),
    };
    save_physics(&model, World::Car, Some(drag), Some(training));
    let out = tmp.path().join("diag");
    let stdout = diagnose_offset_bag(&model, "steering_offset", &out);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("add them: dynlab train"))
        .unwrap_or_else(|| panic!("{stdout}"));
    let file = out.join("model_effect_speed_drag.toml");
    assert!(
        line.contains("--effects steering_offset")
            && line.contains(&format!("--effects-file {}", file.display())),
        "{line}"
    );
    assert!(
        line.contains(" --steps 3 ") && line.contains(" --seed 4 "),
        "{line}"
    );
    let kept = CustomEffect::from_toml(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(kept.name(), "speed_drag");
    assert_eq!(kept.terms().len(), 1);
    assert_eq!(kept.terms()[0].feature.name(), "vx*|v|");
    assert!((kept.terms()[0].coefficient + 1.5e-3).abs() < 1e-12);
}

#[test]
fn diagnose_rejects_a_bag_of_the_other_robot_with_a_clear_message() {
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("model");
    nominal_model(&model, World::Car);
    let o = Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(["diagnose", "--model"])
        .arg(&model)
        .arg("--bag")
        .arg(repo("bags/push_nominal"))
        .arg("--out")
        .arg(tmp.path().join("d"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("/car/pose"), "{err}");
}

/// `dynlab diagnose` on `bag` with `--effects com_offset`: (terminal, diagnosis.json, html).
fn diagnose_push(model: &Path, bag: &Path, out: &Path) -> (String, serde_json::Value, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args([
            "diagnose",
            "--no-drift",
            "--effects",
            "com_offset",
            "--model",
        ])
        .arg(model)
        .arg("--bag")
        .arg(bag)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j = serde_json::from_str(&std::fs::read_to_string(out.join("diagnosis.json")).unwrap())
        .unwrap();
    let html = std::fs::read_to_string(out.join("diagnosis.html")).unwrap();
    (String::from_utf8_lossy(&o.stdout).into_owned(), j, html)
}

#[test]
fn pushes_that_all_start_at_one_pose_get_a_caution_that_place_and_heading_go_together() {
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("model");
    nominal_model(&model, World::Push);
    // the bundled bag's world and explorer, every episode from the scenario's start
    let explore = tmp.path().join("explore.toml");
    std::fs::write(&explore, "start_jitter = [0.0, 0.0, 0.0]\n").unwrap();
    let bag = tmp.path().join("one_start");
    let o = Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args([
            "collect",
            "push",
            "--episodes",
            "20",
            "--seed",
            "7",
            "--scenario",
        ])
        .arg(repo("launch_scripts/scenarios/push_com_offset.toml"))
        .arg("--explore")
        .arg(&explore)
        .arg("--out")
        .arg(&bag)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (stdout, j, html) = diagnose_push(&model, &bag, &tmp.path().join("d1"));
    assert_eq!(j["verdict"], "com_offset", "{stdout}");
    assert_eq!(j["one_start"]["trajectories"], 20, "{j}");
    let spread = j["one_start"]["spread"][0].as_f64().unwrap();
    assert!(spread <= 0.01, "{spread}");
    assert!(
        j["summary"]
            .as_str()
            .unwrap()
            .contains("caution: all 20 trajectories start at one pose"),
        "{}",
        j["summary"]
    );
    assert!(
        stdout.contains("data: every one of the 20 trajectories starts at"),
        "{stdout}"
    );
    assert!(html.contains("Data: every one of the 20 trajectories"));
    // the bundled bag's starts are spread (±5 cm, ±45°): no caution
    let (stdout, j, _) = diagnose_push(
        &model,
        &repo("bags/push_com_offset"),
        &tmp.path().join("d2"),
    );
    assert_eq!(j["verdict"], "com_offset", "{stdout}");
    assert!(j["one_start"].is_null(), "{j}");
    assert!(!stdout.contains("caution") && !stdout.contains("data: every one"));
}
