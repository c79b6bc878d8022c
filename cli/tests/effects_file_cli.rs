//! `dynlab train --effects-file` end to end on the bundled aero-drag bag: a custom drag term is
//! fitted (negative, printed as an equation), the model file records it and `eval-model`
//! reloads the model; a bad file gets a clear error naming the file and the known features.

use std::path::Path;
use std::process::Command;

fn repo(p: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(p)
}

fn dynlab() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dynlab"))
}

#[test]
fn train_with_an_effects_file_fits_the_term_and_the_model_reloads() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("speed_drag.toml");
    std::fs::write(
        &file,
        "name = \"speed_drag\"\n[[term]]\nstate = \"vx\"\nfeature = \"vx*|v|\"\ncoefficient = 0.0\n",
    )
    .unwrap();
    let out = tmp.path().join("m");
    let o = dynlab()
        .args(["train", "--kind", "physics", "--steps", "3"])
        .args(["--physics-windows", "300", "--effects", "steering_offset"])
        .arg("--bag")
        .arg(repo("bags/car_aero_drag"))
        .arg("--effects-file")
        .arg(&file)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("custom effect speed_drag:"), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("(custom.speed_drag.0)"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(line.contains("v̇ₓ += −"), "{line}");
    let meta = std::fs::read_to_string(out.join("model.json")).unwrap();
    assert!(meta.contains("\"custom_effects\"") && meta.contains("vx*|v|"));
    let o = dynlab()
        .args(["eval-model", "--steps", "5", "--model"])
        .arg(&out)
        .arg("--bag")
        .arg(repo("bags/car_aero_drag"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // a bad file: unknown feature
    std::fs::write(
        &file,
        "name = \"speed_drag\"\n[[term]]\nstate = \"vx\"\nfeature = \"vx*speed\"\ncoefficient = 0.0\n",
    )
    .unwrap();
    let o = dynlab()
        .args(["train", "--kind", "physics", "--bag"])
        .arg(repo("bags/car_aero_drag"))
        .arg("--effects-file")
        .arg(&file)
        .arg("--out")
        .arg(tmp.path().join("m2"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("speed_drag.toml") && err.contains("'speed'") && err.contains("|v|"),
        "{err}"
    );
}
