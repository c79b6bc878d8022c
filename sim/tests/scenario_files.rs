//! Scenario files: defaults, round trips, and errors that name the key.

use dynlab_sim::{CarScenario, PushExplorer, PushScenario, SimError, Track};

fn parse_err_push(text: &str) -> String {
    PushScenario::from_toml_str(text)
        .expect_err("must be rejected")
        .to_string()
}

fn parse_err_car(text: &str) -> String {
    CarScenario::from_toml_str(text)
        .expect_err("must be rejected")
        .to_string()
}

#[test]
fn empty_files_are_the_nominal_defaults() {
    assert_eq!(
        PushScenario::from_toml_str("").unwrap(),
        PushScenario::free()
    );
    assert_eq!(
        CarScenario::from_toml_str("").unwrap(),
        CarScenario::floor()
    );
}

#[test]
fn paper_scenarios_round_trip_through_toml() {
    for s in [PushScenario::free(), PushScenario::obstacle()] {
        let text = s.to_toml_string();
        assert_eq!(PushScenario::from_toml_str(&text).unwrap(), s, "{text}");
    }
    let o = PushScenario::obstacle();
    assert_eq!(o.obstacles.len(), 1);
    assert_eq!(o.obstacles[0].centre, [0.6, 0.2]);
    assert_eq!(o.obstacles[0].size, [0.1, 0.5]);
    assert_eq!(o.goal, [0.8, -0.1, 0.0]);
    assert!((o.start[2] + 0.2 * std::f64::consts::PI).abs() < 1e-15);
    let c = CarScenario::floor();
    assert_eq!(CarScenario::from_toml_str(&c.to_toml_string()).unwrap(), c);
}

#[test]
fn effects_switch_on_by_file() {
    let s = PushScenario::from_toml_str(
        "[effects.friction_patch]\nmu = 0.25\nregion = { shape = \"disc\", centre = [0.5, 0.0], radius = 0.05 }\n\
         [effects.table_tilt]\nangle = 0.03\n",
    )
    .unwrap();
    assert_eq!(s.effects.active(), vec!["table_tilt", "friction_patch"]);
    let c = CarScenario::from_toml_str(
        "[effects.aero_drag]\nc = 0.02\n[effects.motor_lag]\nenabled = false\n",
    )
    .unwrap();
    assert_eq!(c.effects.active(), vec!["aero_drag"]);
}

#[test]
fn unknown_keys_are_named() {
    let e = parse_err_push("[effects.friction_patch]\nmuu = 0.2\n");
    assert!(e.contains("effects.friction_patch.muu"), "{e}");
    assert!(e.contains("unknown field"), "{e}");
    let e = parse_err_push("[blok]\nmass = 1.0\n");
    assert!(e.contains("blok"), "{e}");
    let e = parse_err_car("[effects.tire_wear]\nrate = 1\n");
    assert!(e.contains("tire_wear"), "{e}");
}

#[test]
fn impossible_values_are_named_with_the_fix() {
    let e = PushScenario::from_toml_str("[block]\nmass = -1.0\n").unwrap_err();
    assert_eq!(e.key(), Some("block.mass"));
    assert!(e.to_string().contains("must be > 0, got -1"), "{e}");
    let e = parse_err_push("[effects.friction_patch]\nmu = -0.2\n");
    assert_eq!(e, "effects.friction_patch.mu: must be ≥ 0, got -0.2");
    let e = PushScenario::from_toml_str("[effects.com_offset]\noffset = [0.2, 0.0]\n").unwrap_err();
    assert_eq!(e.key(), Some("effects.com_offset.offset[0]"));
    let e = PushScenario::from_toml_str("[sim]\ndt = 0.5\n").unwrap_err();
    assert_eq!(e.key(), Some("sim.dt"));
    let e = PushScenario::from_toml_str(
        "[effects.friction_patch.region]\nshape = \"disc\"\nradius = 0.0\n",
    )
    .unwrap_err();
    assert_eq!(e.key(), Some("effects.friction_patch.region.radius"));
    let e =
        CarScenario::from_toml_str("[car]\nthrottle_min = 0.5\nthrottle_max = 0.2\n").unwrap_err();
    assert_eq!(e.key(), Some("car.throttle_max"));
    let e = CarScenario::from_toml_str("[car]\nsubstep = 0.01\n").unwrap_err();
    assert_eq!(e.key(), Some("car.substep"));
    let e = CarScenario::from_toml_str("[effects.motor_lag]\ntau = 0\n").unwrap_err();
    assert_eq!(e.key(), Some("effects.motor_lag.tau"));
    let e = CarScenario::from_toml_str("[noise]\nposition_std = -1\n").unwrap_err();
    assert_eq!(e.key(), Some("noise.position_std"));
}

#[test]
fn wrong_types_name_the_key() {
    let e = parse_err_push("[block]\nmass = \"heavy\"\n");
    assert!(e.contains("block.mass"), "{e}");
    let e = parse_err_car("start = [0.0, 1.0]\n");
    assert!(e.contains("start"), "{e}");
}

#[test]
fn explorer_period_must_fit_the_push() {
    let s = PushScenario::free();
    let e = PushExplorer {
        push_period: 0.5,
        ..PushExplorer::default()
    }
    .validate(&s)
    .unwrap_err();
    assert_eq!(e.key(), Some("explore.push_period"));
    assert!(PushExplorer::default().validate(&s).is_ok());
}

#[test]
fn files_and_tracks_load_from_disk() {
    let dir = tempfile::tempdir().unwrap();
    let track = r#"{"X":[0,1,1,0],"Y":[0,0,1,1],"X_i":[0.1,0.9,0.9,0.1],"Y_i":[0.1,0.1,0.9,0.9],"X_o":[-0.1,1.1,1.1,-0.1],"Y_o":[-0.1,-0.1,1.1,1.1]}"#;
    std::fs::write(dir.path().join("square.json"), track).unwrap();
    std::fs::write(
        dir.path().join("car.toml"),
        "[arena]\ntrack = \"square.json\"\n",
    )
    .unwrap();
    let s = CarScenario::from_file(dir.path().join("car.toml")).unwrap();
    let t = s.track_data.expect("track loaded");
    assert_eq!(t.len(), 4);
    assert!(t.contains([0.5, 0.05]));
    assert!(!t.contains([0.5, 0.5]));
    let missing = PushScenario::from_file(dir.path().join("nope.toml")).unwrap_err();
    assert!(matches!(missing, SimError::Io { .. }));
    assert!(missing.to_string().contains("nope.toml"));
    let bad = Track::from_json_str(r#"{"X":[0,1]}"#, "t.json").unwrap_err();
    assert!(
        bad.to_string().contains("X_i") || bad.to_string().contains("missing field"),
        "{bad}"
    );
}
