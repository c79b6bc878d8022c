//! `dynlab train --effects grip_patch` without `--set` values: the fit starts the patch from the
//! best of its starting points and finds a patch away from the default disc at the origin;
//! started from the defaults (given as `--set`) it does not.

use std::path::Path;
use std::process::{Command, Output};

fn dynlab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dynlab"))
        .args(args)
        .output()
        .expect("run dynlab")
}

fn ok(args: &[&str]) -> String {
    let o = dynlab(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "dynlab {args:?}: {err}");
    err
}

/// `grip_patch.*` of a saved model and its best validation loss.
fn fitted(dir: &Path) -> (Vec<(String, f64)>, f64) {
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("model.json")).unwrap()).unwrap();
    let params = j["physics"]["params"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|p| {
            let n = p["name"].as_str()?;
            n.starts_with("grip_patch.")
                .then(|| (n.to_string(), p["value"].as_f64().unwrap()))
        })
        .collect();
    (
        params,
        j["metrics"]["best_validation_loss"].as_f64().unwrap(),
    )
}

#[test]
fn a_grip_patch_away_from_the_origin_is_trained_from_the_best_start() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = tmp.path().join("patch.toml");
    std::fs::write(
        &scenario,
        r#"name = "car_grip_patch_off_centre"
start = [0.0, 0.0, 0.0]

[arena]
min = [-1.5, -1.5]
max = [1.5, 1.5]

[effects.grip_patch]
scale = 0.45

[effects.grip_patch.region]
shape = "disc"
centre = [-0.8, 0.7]
radius = 0.5

[noise]
position_std = 0.0005
yaw_std = 0.002
"#,
    )
    .unwrap();
    let bag = tmp.path().join("bag");
    let (s, b) = (scenario.to_str().unwrap(), bag.to_str().unwrap());
    ok(&[
        "collect",
        "car",
        "--scenario",
        s,
        "--episodes",
        "3",
        "--seed",
        "221",
        "--out",
        b,
    ]);
    let train = |out: &Path, extra: &[&str]| {
        let o = out.to_str().unwrap();
        let mut args = vec![
            "train",
            "--bag",
            b,
            "--kind",
            "physics",
            "--steps",
            "20",
            "--physics-windows",
            "400",
            "--effects",
            "grip_patch",
            "--out",
            o,
        ];
        args.extend_from_slice(extra);
        ok(&args)
    };
    let (screened, plain) = (tmp.path().join("screened"), tmp.path().join("plain"));
    let log = train(&screened, &[]);
    assert!(
        log.contains("physics fit: started grip_patch from cx = "),
        "{log}"
    );
    let log = train(
        &plain,
        &["--set", "grip_patch.cx=0", "--set", "grip_patch.cy=0"],
    );
    assert!(!log.contains("physics fit: started"), "{log}");
    let (p, loss) = fitted(&screened);
    let (p0, loss0) = fitted(&plain);
    let get = |p: &[(String, f64)], n: &str| p.iter().find(|(k, _)| k == n).unwrap().1;
    let off = (get(&p, "grip_patch.cx") + 0.8).hypot(get(&p, "grip_patch.cy") - 0.7);
    assert!(off < 0.25, "centre off by {off} m: {p:?}");
    assert!((get(&p, "grip_patch.k") - 0.45).abs() < 0.15, "{p:?}");
    assert!(
        loss < 0.8 * loss0,
        "validation loss {loss} against {loss0} from the defaults: {p0:?}"
    );
}
