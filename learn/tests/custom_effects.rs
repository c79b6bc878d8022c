//! Custom effects (`--effects-file`): reading the file, training with one, exact input
//! Jacobians through the terms, and the model file round trip.

mod common;

use dynlab_dynamics::data::SavGol;
use dynlab_dynamics::physics::CustomEffect;
use dynlab_learn::train::read_custom_effect;
use dynlab_learn::{
    LearnError, ModelKind, Topics, TrainConfig, World, load_bags, load_model, save_model, train,
};

const DRIFT: &str = r#"
name = "side_drift"
[[term]]
state = "by"
feature = "l*p"
coefficient = 0.001
[[term]]
state = "theta"
feature = "l*phi"
coefficient = 0.0
"#;

#[test]
fn bad_effect_files_give_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope.toml");
    let e = read_custom_effect(&missing).unwrap_err();
    assert!(matches!(e, LearnError::Io { .. }), "{e}");
    assert!(e.to_string().contains("nope.toml"));
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, DRIFT.replace("l*phi", "l*psi")).unwrap();
    let e = read_custom_effect(&bad).unwrap_err().to_string();
    assert!(
        e.contains("bad.toml") && e.contains("'psi'") && e.contains("cos_phi"),
        "{e}"
    );
    std::fs::write(&bad, DRIFT.replace("state = \"by\"\n", "")).unwrap();
    let e = read_custom_effect(&bad).unwrap_err().to_string();
    assert!(e.contains("state"), "{e}");
    // custom effects belong to physics models
    let cfg = TrainConfig {
        kind: ModelKind::NodeRk4,
        custom_effects: vec![CustomEffect::from_toml(DRIFT).unwrap()],
        ..TrainConfig::default()
    };
    let e = cfg.validate().unwrap_err().to_string();
    assert!(
        e.contains("custom effects belong to a physics model"),
        "{e}"
    );
}

#[test]
fn pushing_model_with_a_custom_effect_trains_round_trips_and_has_exact_jacobians() {
    let tmp = tempfile::tempdir().unwrap();
    let bag = common::push_bag(tmp.path(), 24, 10, 7);
    let data = load_bags(&[bag], None, &Topics::default(), &SavGol::default()).unwrap();
    let file = tmp.path().join("drift.toml");
    std::fs::write(&file, DRIFT).unwrap();
    for kind in [ModelKind::Physics, ModelKind::Hybrid] {
        let cfg = TrainConfig {
            kind,
            steps: 2,
            epochs: 3,
            hidden: Some(vec![16]),
            physics_iterations: 5,
            physics_max_windows: 200,
            custom_effects: vec![read_custom_effect(&file).unwrap()],
            ..TrainConfig::default()
        };
        let out = train(&data, &cfg, &mut |_| {}).unwrap();
        let m = out.model;
        let p = m.physics().unwrap();
        assert_eq!(
            p.param_names()[p.params().len() - 2..],
            ["custom.side_drift.0", "custom.side_drift.1"]
        );
        assert!(p.equations().contains("ẏ_b += "), "{}", p.equations());
        // exact input Jacobians against central differences (the hybrid's network is f32:
        // a larger step and tolerance, as in tests/models.rs)
        let (s, u) = ([0.42, -0.03, 0.7], [0.3, -0.4, 0.6]);
        let j = m.jacobians(&s, &u).unwrap();
        let (h, tol) = if kind == ModelKind::Physics {
            (1e-6, 1e-4)
        } else {
            (2e-3, 2e-3)
        };
        for c in 0..3 {
            let (mut sp, mut sm) = (s, s);
            sp[c] += h;
            sm[c] -= h;
            let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
            m.step(&sp, &u, &mut a).unwrap();
            m.step(&sm, &u, &mut b).unwrap();
            for r in 0..3 {
                let fd = (a[r] - b[r]) / (2.0 * h);
                assert!(
                    (fd - j.ds[r * 3 + c]).abs() < tol * (1.0 + fd.abs()),
                    "{kind} ds {r}{c}"
                );
            }
            let (mut up, mut um) = (u, u);
            up[c] += h;
            um[c] -= h;
            m.step(&s, &up, &mut a).unwrap();
            m.step(&s, &um, &mut b).unwrap();
            for r in 0..3 {
                let fd = (a[r] - b[r]) / (2.0 * h);
                assert!(
                    (fd - j.du[r * 3 + c]).abs() < tol * (1.0 + fd.abs()),
                    "{kind} du {r}{c}"
                );
            }
        }
        // the file keeps the terms; the reloaded model predicts the same
        let dir = tmp.path().join(format!("model_{kind}"));
        save_model(&m, &dir, None, Default::default()).unwrap();
        let (back, meta) = load_model(&dir, Some(kind), Some(World::Push)).unwrap();
        let pm = meta.physics.unwrap();
        assert_eq!(pm.custom_effects.len(), 1);
        assert_eq!(pm.custom_effects[0].name(), "side_drift");
        let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
        m.step(&s, &u, &mut a).unwrap();
        back.step(&s, &u, &mut b).unwrap();
        assert_eq!(a, b);
    }
}
