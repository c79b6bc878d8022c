//! Training, derivatives, model files and determinism of every model kind on small synthetic
//! bags generated from the physics models of `dynlab-dynamics`.

mod common;

use std::path::Path;

use dynlab_dynamics::data::SavGol;
use dynlab_learn::file::{MODEL_JSON, WEIGHTS, read_meta};
use dynlab_learn::{
    Dataset, LearnError, Model, ModelKind, RolloutWorkspace, Split, Topics, TrainConfig, World,
    load_bags, load_model, save_model, train,
};

fn push_data(dir: &Path) -> Dataset {
    let bag = common::push_bag(dir, 24, 10, 7);
    load_bags(&[bag], None, &Topics::default(), &SavGol::default()).unwrap()
}

fn car_data(dir: &Path) -> Dataset {
    let bag = common::car_bag(dir, 2, 12.0, 100.0, 3);
    load_bags(&[bag], None, &Topics::default(), &SavGol::default()).unwrap()
}

fn small(kind: ModelKind, world: World) -> TrainConfig {
    TrainConfig {
        kind,
        steps: 2,
        epochs: if world == World::Push { 60 } else { 8 },
        hidden: Some(if world == World::Push {
            vec![32, 32]
        } else {
            vec![24, 24]
        }),
        physics_iterations: 8,
        physics_max_windows: 300,
        batch: 64,
        lr: 3e-3,
        ..Default::default()
    }
}

#[test]
fn every_push_kind_trains_far_below_the_constant_model() {
    let tmp = tempfile::tempdir().unwrap();
    let data = push_data(tmp.path());
    assert_eq!(data.world, World::Push);
    assert_eq!(data.trajectories.len(), 24);
    for kind in ModelKind::ALL {
        let out = train(&data, &small(kind, World::Push), &mut |_| {}).unwrap();
        let ratio = out.best_validation_loss / out.baseline_validation_loss;
        assert!(
            ratio < 0.3,
            "{kind}: validation loss {:.3e} vs constant model {:.3e}",
            out.best_validation_loss,
            out.baseline_validation_loss
        );
        if kind.has_network() {
            assert_eq!(out.curve.len(), 60, "{kind}");
            // the hybrid starts from the exact physics of this data: its checkpoint may be epoch 0
            assert!(out.best_epoch > 0 || kind == ModelKind::Hybrid, "{kind}");
        }
    }
}

#[test]
fn every_car_kind_trains_below_the_constant_model_and_reports_tve() {
    let tmp = tempfile::tempdir().unwrap();
    let data = car_data(tmp.path());
    assert_eq!(data.world, World::Car);
    for kind in ModelKind::ALL {
        let out = train(&data, &small(kind, World::Car), &mut |_| {}).unwrap();
        assert!(
            out.best_validation_loss < 0.8 * out.baseline_validation_loss,
            "{kind}: L_rel {:.3e} vs constant model {:.3e}",
            out.best_validation_loss,
            out.baseline_validation_loss
        );
        let rep = dynlab_learn::evaluate(&out.model, &data, 3, 1.0).unwrap();
        let tve = rep.tve.expect("car evaluation has TVE");
        assert!(tve.segments >= 10 && tve.tve.is_finite(), "{kind}: {tve:?}");
    }
}

/// Central finite differences of `model.step` in f64 around (s, u).
fn fd_jacobians(model: &Model, s: &[f64], u: &[f64], h: f64) -> (Vec<f64>, Vec<f64>) {
    let (ds, du) = (model.dim_s(), model.dim_u());
    let mut js = vec![0.0; ds * ds];
    let mut ju = vec![0.0; ds * du];
    let mut plus = vec![0.0; ds];
    let mut minus = vec![0.0; ds];
    for c in 0..ds + du {
        let (mut sp, mut sm, mut up, mut um) = (s.to_vec(), s.to_vec(), u.to_vec(), u.to_vec());
        if c < ds {
            sp[c] += h;
            sm[c] -= h;
        } else {
            up[c - ds] += h;
            um[c - ds] -= h;
        }
        model.step(&sp, &up, &mut plus).unwrap();
        model.step(&sm, &um, &mut minus).unwrap();
        for r in 0..ds {
            let d = (plus[r] - minus[r]) / (2.0 * h);
            if c < ds {
                js[r * ds + c] = d;
            } else {
                ju[r * du + c - ds] = d;
            }
        }
    }
    (js, ju)
}

fn check_jacobians(model: &Model, s: &[f64], u: &[f64], h: f64, tol: f64) {
    let j = model.jacobians(s, u).unwrap();
    let mut next = vec![0.0; s.len()];
    model.step(s, u, &mut next).unwrap();
    for (a, b) in j.next.iter().zip(&next) {
        assert!(
            (a - b).abs() < 1e-5,
            "{}: next {a} vs step {b}",
            model.kind()
        );
    }
    let (fs, fu) = fd_jacobians(model, s, u, h);
    let scale = fs.iter().chain(&fu).fold(1e-3f64, |m, x| m.max(x.abs()));
    for (name, exact, fd) in [("ds", &j.ds, &fs), ("du", &j.du, &fu)] {
        for (i, (a, b)) in exact.iter().zip(fd.iter()).enumerate() {
            assert!(
                (a - b).abs() <= tol * scale,
                "{} {}: ∂s⁺/∂{name}[{i}] exact {a:.6e} vs finite difference {b:.6e}",
                model.world(),
                model.kind()
            );
        }
    }
}

#[test]
fn input_jacobians_of_every_kind_match_finite_differences() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let car = car_data(tmp.path());
    for kind in ModelKind::ALL {
        let mut cfg = small(kind, World::Push);
        cfg.epochs = 5;
        let m = train(&push, &cfg, &mut |_| {}).unwrap().model;
        check_jacobians(&m, &[0.42, -0.03, 0.7], &[0.3, -0.4, 0.6], 2e-3, 2e-3);
        let mut cfg = small(kind, World::Car);
        cfg.epochs = 2;
        let m = train(&car, &cfg, &mut |_| {}).unwrap().model;
        check_jacobians(
            &m,
            &[0.5, -0.2, 0.9, 1.2, 0.05, 0.4],
            &[0.1, 0.4],
            2e-3,
            2e-3,
        );
    }
}

#[test]
fn fast_rollout_matches_step_and_does_not_depend_on_threads() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let car = car_data(tmp.path());
    for (data, world) in [(&push, World::Push), (&car, World::Car)] {
        for kind in [
            ModelKind::Residual,
            ModelKind::NodeEuler,
            ModelKind::NodeRk4,
        ] {
            let mut cfg = small(kind, world);
            cfg.epochs = 2;
            let m = train(data, &cfg, &mut |_| {}).unwrap().model;
            assert!(m.has_fast_rollout());
            let (ds, du, n, horizon) = (m.dim_s(), m.dim_u(), 37, 5);
            let mut rng = dynlab_dynamics::data::SplitMix64::new(5);
            let s0: Vec<f32> = (0..n * ds)
                .map(|_| common::uniform(&mut rng, -0.5, 0.5) as f32)
                .collect();
            let acts: Vec<f32> = (0..n * horizon * du)
                .map(|_| common::uniform(&mut rng, -0.5, 0.5) as f32)
                .collect();
            let mut one = vec![0.0f32; n * horizon * ds];
            let mut two = vec![0.0f32; n * horizon * ds];
            m.rollout_f32(&s0, &acts, &mut one, &mut RolloutWorkspace::new(1))
                .unwrap();
            m.rollout_f32(&s0, &acts, &mut two, &mut RolloutWorkspace::new(3))
                .unwrap();
            assert_eq!(one, two, "{world} {kind}: thread count changed the rollout");
            // against the f64 step path, sample by sample
            for i in [0, 17, 36] {
                let mut s: Vec<f64> = s0[i * ds..(i + 1) * ds]
                    .iter()
                    .map(|&x| f64::from(x))
                    .collect();
                for t in 0..horizon {
                    let u: Vec<f64> = acts[(i * horizon + t) * du..(i * horizon + t + 1) * du]
                        .iter()
                        .map(|&x| f64::from(x))
                        .collect();
                    let mut next = vec![0.0; ds];
                    m.step(&s, &u, &mut next).unwrap();
                    for d in 0..ds {
                        let fast = f64::from(one[(i * horizon + t) * ds + d]);
                        assert!(
                            (fast - next[d]).abs() < 1e-4 * (1.0 + next[d].abs()),
                            "{world} {kind} sample {i} step {t} dim {d}: {fast} vs {}",
                            next[d]
                        );
                    }
                    s = next;
                }
            }
        }
    }
}

#[test]
fn model_file_round_trip_gives_identical_predictions() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let car = car_data(tmp.path());
    for (data, world, s, u) in [
        (
            &push,
            World::Push,
            vec![0.4, 0.02, -0.3],
            vec![0.1, 0.2, 0.8],
        ),
        (
            &car,
            World::Car,
            vec![0.1, 0.2, 0.3, 1.1, 0.0, 0.2],
            vec![0.05, 0.4],
        ),
    ] {
        for kind in ModelKind::ALL {
            let mut cfg = small(kind, world);
            cfg.epochs = 2;
            cfg.effects = match (kind.has_physics(), world) {
                (true, World::Push) => vec!["com_offset".into()],
                (true, World::Car) => vec!["aero_drag".into()],
                _ => vec![],
            };
            let m = train(data, &cfg, &mut |_| {}).unwrap().model;
            let dir = tmp.path().join(format!("{world}-{kind}"));
            save_model(&m, &dir, None, Default::default()).unwrap();
            let (back, meta) = load_model(&dir, Some(kind), Some(world)).unwrap();
            assert_eq!(meta.kind, kind);
            assert_eq!(back, m, "{world} {kind}: loaded model differs");
            let (mut a, mut b) = (vec![0.0; s.len()], vec![0.0; s.len()]);
            m.step(&s, &u, &mut a).unwrap();
            back.step(&s, &u, &mut b).unwrap();
            assert_eq!(a, b, "{world} {kind}");
            assert_eq!(dir.join(WEIGHTS).exists(), kind.has_network());
        }
    }
}

#[test]
fn corrupt_and_mismatched_model_files_are_rejected_with_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let mut cfg = small(ModelKind::NodeRk4, World::Push);
    cfg.epochs = 1;
    let m = train(&push, &cfg, &mut |_| {}).unwrap().model;
    let dir = tmp.path().join("m");
    save_model(&m, &dir, None, Default::default()).unwrap();
    let json = std::fs::read_to_string(dir.join(MODEL_JSON)).unwrap();
    let weights = std::fs::read(dir.join(WEIGHTS)).unwrap();
    let restore = || {
        std::fs::write(dir.join(MODEL_JSON), &json).unwrap();
        std::fs::write(dir.join(WEIGHTS), &weights).unwrap();
    };
    // wrong kind, wrong world
    let e = load_model(&dir, Some(ModelKind::Residual), None).unwrap_err();
    assert!(matches!(e, LearnError::KindMismatch { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("holds a node-rk4 model, not a residual model"),
        "{e}"
    );
    let e = load_model(&dir, None, Some(World::Car)).unwrap_err();
    assert!(matches!(e, LearnError::WorldMismatch { .. }), "{e}");
    // newer format
    std::fs::write(
        dir.join(MODEL_JSON),
        json.replace("\"format_version\": 1", "\"format_version\": 7"),
    )
    .unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(
        e.to_string().contains("format version 7") && e.to_string().contains("update dynlab"),
        "{e}"
    );
    restore();
    // a recorded velocity fit live estimators would take, but no fit: an even window
    let bad = dir.with_file_name("bad_fit");
    let record = dynlab_learn::file::TrainingMeta {
        bags: Vec::new(),
        config: Default::default(),
        best_epoch: 0,
        epochs_run: 1,
        windows: (1, 1),
        savgol: vec![SavGol {
            window: 14,
            ..SavGol::default()
        }],
    };
    save_model(&m, &bad, Some(record), Default::default()).unwrap();
    let e = load_model(&bad, None, None).unwrap_err();
    assert!(matches!(e, LearnError::CorruptModel { .. }), "{e}");
    assert!(
        e.to_string().contains("training.savgol[0]") && e.to_string().contains("odd"),
        "{e}"
    );
    // not JSON
    std::fs::write(dir.join(MODEL_JSON), &json[..json.len() / 2]).unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(
        matches!(e, LearnError::CorruptModel { .. }) && e.to_string().contains("not valid JSON"),
        "{e}"
    );
    restore();
    // unknown kind
    std::fs::write(
        dir.join(MODEL_JSON),
        json.replace("\"kind\": \"node-rk4\"", "\"kind\": \"node-rk7\""),
    )
    .unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(matches!(e, LearnError::CorruptModel { .. }), "{e}");
    restore();
    // a bad normalisation (std 0)
    let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
    v["normalization"]["input_std"][0] = serde_json::json!(0.0);
    std::fs::write(dir.join(MODEL_JSON), serde_json::to_string(&v).unwrap()).unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(e.to_string().contains("std"), "{e}");
    restore();
    // network spec disagreeing with the weights
    let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
    v["network"]["sizes"][1] = serde_json::json!(33);
    std::fs::write(dir.join(MODEL_JSON), serde_json::to_string(&v).unwrap()).unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(
        e.to_string()
            .contains("model.json says the network is [6, 33"),
        "{e}"
    );
    restore();
    // truncated weights
    std::fs::write(dir.join(WEIGHTS), &weights[..weights.len() / 3]).unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(matches!(e, LearnError::CorruptModel { .. }), "{e}");
    restore();
    // missing weights
    std::fs::remove_file(dir.join(WEIGHTS)).unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(e.to_string().contains(WEIGHTS), "{e}");
    restore();
    // a physics parameter out of bounds
    let mut pcfg = small(ModelKind::Physics, World::Push);
    pcfg.physics_iterations = 1;
    let p = train(&push, &pcfg, &mut |_| {}).unwrap().model;
    let pdir = tmp.path().join("p");
    save_model(&p, &pdir, None, Default::default()).unwrap();
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(pdir.join(MODEL_JSON)).unwrap()).unwrap();
    v["physics"]["params"][0]["value"] = serde_json::json!(-5.0);
    std::fs::write(pdir.join(MODEL_JSON), serde_json::to_string(&v).unwrap()).unwrap();
    let e = load_model(&pdir, None, None).unwrap_err();
    assert!(e.to_string().contains("outside its bounds"), "{e}");
    // not a directory
    let e = load_model(&tmp.path().join("nope"), None, None).unwrap_err();
    assert!(e.to_string().contains("not a model directory"), "{e}");
    // the intact file still loads
    assert!(read_meta(&dir).is_ok());
}

#[test]
fn training_is_bit_identical_for_a_seed_and_any_thread_count() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    for kind in [ModelKind::NodeRk4, ModelKind::NodeDopri5, ModelKind::Hybrid] {
        let mut files = Vec::new();
        for (i, threads) in [1usize, 1, 2, 3].into_iter().enumerate() {
            let mut cfg = small(kind, World::Push);
            cfg.epochs = 4;
            cfg.batch = 200;
            cfg.chunk = 64;
            cfg.threads = threads;
            let out = train(&push, &cfg, &mut |_| {}).unwrap();
            let dir = tmp.path().join(format!("{kind}-{i}"));
            save_model(&out.model, &dir, None, Default::default()).unwrap();
            files.push((
                std::fs::read(dir.join(MODEL_JSON)).unwrap(),
                std::fs::read(dir.join(WEIGHTS)).unwrap(),
            ));
        }
        assert!(
            files[0] == files[1],
            "{kind}: same seed, different model files"
        );
        assert!(
            files[0] == files[2],
            "{kind}: 2 threads changed the model file"
        );
        assert!(
            files[0] == files[3],
            "{kind}: 3 threads changed the model file"
        );
        let mut cfg = small(kind, World::Push);
        cfg.epochs = 4;
        cfg.batch = 200;
        cfg.chunk = 64;
        cfg.seed = 1;
        let other = train(&push, &cfg, &mut |_| {}).unwrap();
        let dir = tmp.path().join(format!("{kind}-seed1"));
        save_model(&other.model, &dir, None, Default::default()).unwrap();
        assert!(
            std::fs::read(dir.join(WEIGHTS)).unwrap() != files[0].1,
            "{kind}: the seed changed nothing"
        );
    }
}

#[test]
fn overlapping_split_has_more_validation_windows_from_training_trajectories() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let mut cfg = small(ModelKind::Residual, World::Push);
    cfg.epochs = 1;
    cfg.split = Split::OverlappingWindows;
    let a = train(&push, &cfg, &mut |_| {}).unwrap();
    cfg.split = Split::Trajectories;
    let b = train(&push, &cfg, &mut |_| {}).unwrap();
    // 24 trajectories × 9 windows of 2 steps = 216; 20 % either way
    assert_eq!(a.windows.0 + a.windows.1, 216);
    assert_eq!(b.windows.0 + b.windows.1, 216);
    assert_eq!(
        b.windows.1 % 9,
        0,
        "a trajectory split takes whole trajectories"
    );
    assert_eq!(b.validation_segments.len() * 9, b.windows.1);
    assert!(a.validation_segments.is_empty());
}

#[test]
fn symmetry_augmentation_adds_moved_training_copies_and_leaves_validation_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let mut cfg = small(ModelKind::Residual, World::Push);
    cfg.epochs = 1;
    let plain = train(&push, &cfg, &mut |_| {}).unwrap();
    cfg.augment_se2 = 3;
    let aug = train(&push, &cfg, &mut |_| {}).unwrap();
    assert_eq!(aug.windows.0, 4 * plain.windows.0);
    assert_eq!(aug.windows.1, plain.windows.1);
    assert_eq!(aug.validation_segments, plain.validation_segments);
    // Copies could reach the validation set through overlapping windows, and the car is not
    // invariant: both are refused with the reason.
    cfg.split = Split::OverlappingWindows;
    let e = train(&push, &cfg, &mut |_| {}).unwrap_err().to_string();
    assert!(
        e.contains("augment_se2") && e.contains("split by trajectories"),
        "{e}"
    );
    let car = car_data(tmp.path());
    let mut cfg = small(ModelKind::Residual, World::Car);
    cfg.augment_se2 = 2;
    let e = train(&car, &cfg, &mut |_| {}).unwrap_err().to_string();
    assert!(e.contains("pushing data"), "{e}");
}

#[test]
fn bad_input_gives_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    // effects on a network-only kind
    let cfg = TrainConfig {
        kind: ModelKind::NodeRk4,
        effects: vec!["com_offset".into()],
        ..Default::default()
    };
    let e = train(&push, &cfg, &mut |_| {}).unwrap_err();
    assert!(
        e.to_string().contains("use --kind physics or hybrid"),
        "{e}"
    );
    // an effect of the other robot
    let cfg = TrainConfig {
        kind: ModelKind::Physics,
        effects: vec!["aero_drag".into()],
        ..Default::default()
    };
    let e = train(&push, &cfg, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("aero_drag"), "{e}");
    // too many steps for 11-pose trajectories
    let cfg = TrainConfig {
        steps: 11,
        ..Default::default()
    };
    let e = train(&push, &cfg, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("too little data"), "{e}");
    // NaN in a model input
    let m = train(
        &push,
        &TrainConfig {
            epochs: 1,
            ..small(ModelKind::Residual, World::Push)
        },
        &mut |_| {},
    )
    .unwrap()
    .model;
    let mut out = vec![0.0; 3];
    let e = m
        .step(&[0.0, f64::NAN, 0.0], &[0.0; 3], &mut out)
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("non-finite value in states at index 1"),
        "{e}"
    );
    // a bag without commands
    let dir = tmp.path().join("poses_only");
    let mut w = dynlab_bag::BagWriter::create(&dir, Default::default()).unwrap();
    let t = w
        .add_typed_topic::<dynlab_msgs::geometry_msgs::PoseStamped>(
            "/push/block_pose",
            &[dynlab_bag::QosProfile::default_profile()],
        )
        .unwrap();
    w.write(t, 1, &dynlab_msgs::geometry_msgs::PoseStamped::default())
        .unwrap();
    w.finish().unwrap();
    let e = load_bags(&[dir], None, &Topics::default(), &SavGol::default()).unwrap_err();
    assert!(e.to_string().contains("/push/action"), "{e}");
}

#[test]
fn adjoint_gradients_train_like_backpropagation_through_the_solver() {
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    for kind in [ModelKind::NodeRk4, ModelKind::NodeDopri5] {
        let mut cfg = small(kind, World::Push);
        cfg.epochs = 10;
        let disc = train(&push, &cfg, &mut |_| {}).unwrap();
        cfg.adjoint = true;
        let adj = train(&push, &cfg, &mut |_| {}).unwrap();
        let (a, b) = (disc.best_validation_loss, adj.best_validation_loss);
        assert!(a != b, "{kind}: the adjoint option changed nothing");
        assert!(
            (a - b).abs() < 0.05 * a,
            "{kind}: discrete {a:.4e} vs adjoint {b:.4e}"
        );
    }
}

#[test]
fn a_sample_budget_stops_training_mid_epoch_with_a_validated_record() {
    let tmp = tempfile::tempdir().unwrap();
    let data = push_data(tmp.path());
    let cfg = TrainConfig {
        max_samples: Some(100),
        ..small(ModelKind::Residual, World::Push)
    };
    let out = train(&data, &cfg, &mut |_| {}).unwrap();
    // 100 samples at batch 64 end inside the first epoch (~170 training windows): one record,
    // validated, then stop.
    assert_eq!(out.curve.len(), 1);
    let last = &out.curve[0];
    assert_eq!(last.epoch, 1);
    assert_eq!(last.samples, 128);
    assert!(out.best_validation_loss.is_finite());
}

#[test]
fn a_square_block_model_file_loads_with_its_side_as_the_width() {
    // a pushing model file written before the block had a width: parameters a, c, L, kappa
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let mut cfg = small(ModelKind::Physics, World::Push);
    cfg.effects = vec!["com_offset".into()];
    let m = train(&push, &cfg, &mut |_| {}).unwrap().model;
    let dir = tmp.path().join("square");
    save_model(&m, &dir, None, Default::default()).unwrap();
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(MODEL_JSON)).unwrap()).unwrap();
    let params = v["physics"]["params"].as_array_mut().unwrap();
    let names: Vec<&str> = params.iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names[..5], ["a", "c", "L", "kappa", "b"]);
    params[0]["value"] = serde_json::json!(0.09);
    params[4]["value"] = serde_json::json!(0.09);
    std::fs::write(dir.join(MODEL_JSON), serde_json::to_string(&v).unwrap()).unwrap();
    let (expected, _) = load_model(&dir, None, None).unwrap();
    v["physics"]["params"].as_array_mut().unwrap().remove(4);
    let square = serde_json::to_string(&v).unwrap();
    std::fs::write(dir.join(MODEL_JSON), &square).unwrap();
    let (back, _) = load_model(&dir, None, None).unwrap();
    let p = back.physics().unwrap();
    for n in ["a", "b"] {
        assert_eq!(p.params()[p.param_index(n).unwrap()], 0.09, "{n}");
    }
    // the same model as the file with a = b = 0.09
    assert_eq!(p.params(), expected.physics().unwrap().params());
    assert_same_step(&back, &expected, &[0.4, 0.02, -0.3], &[0.6, 0.2, 0.8]);
    assert_corrupt_without_param(&dir, &square, 3, "kappa");
}

/// Both models take the same step from `s` under `u`.
fn assert_same_step(a: &Model, b: &Model, s: &[f64], u: &[f64]) {
    let (mut x, mut y) = (vec![0.0; s.len()], vec![0.0; s.len()]);
    a.step(s, u, &mut x).unwrap();
    b.step(s, u, &mut y).unwrap();
    assert_eq!(x, y);
}

/// The model file `file` written to `dir` without its physics parameter `at` (`name`) is corrupt,
/// and the error names the parameter: only the documented upgrades fill one in.
fn assert_corrupt_without_param(dir: &Path, file: &str, at: usize, name: &str) {
    let mut v: serde_json::Value = serde_json::from_str(file).unwrap();
    v["physics"]["params"].as_array_mut().unwrap().remove(at);
    std::fs::write(dir.join(MODEL_JSON), serde_json::to_string(&v).unwrap()).unwrap();
    let e = load_model(dir, None, None).unwrap_err();
    assert!(
        matches!(e, LearnError::CorruptModel { .. }) && e.to_string().contains(name),
        "{e}"
    );
}

#[test]
fn a_car_model_file_without_the_ellipse_weight_loads_with_the_full_ellipse() {
    // a car model file written before the friction ellipse had a weight: no `ellipse` entry
    let tmp = tempfile::tempdir().unwrap();
    let car = car_data(tmp.path());
    let mut cfg = small(ModelKind::Physics, World::Car);
    cfg.physics_iterations = 2;
    let m = train(&car, &cfg, &mut |_| {}).unwrap().model;
    let dir = tmp.path().join("before");
    save_model(&m, &dir, None, Default::default()).unwrap();
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(MODEL_JSON)).unwrap()).unwrap();
    let params = v["physics"]["params"].as_array_mut().unwrap();
    let at = params.iter().position(|p| p["name"] == "ellipse").unwrap();
    assert_eq!(params[at - 1]["name"], "v_reg");
    params[at]["value"] = serde_json::json!(1.0);
    std::fs::write(dir.join(MODEL_JSON), serde_json::to_string(&v).unwrap()).unwrap();
    let (expected, _) = load_model(&dir, None, None).unwrap();
    v["physics"]["params"].as_array_mut().unwrap().remove(at);
    let before = serde_json::to_string(&v).unwrap();
    std::fs::write(dir.join(MODEL_JSON), &before).unwrap();
    let (back, _) = load_model(&dir, None, None).unwrap();
    assert_eq!(
        back.physics().unwrap().params(),
        expected.physics().unwrap().params()
    );
    assert_same_step(
        &back,
        &expected,
        &[0.1, -0.2, 0.3, 1.2, -0.2, 0.5],
        &[0.2, 0.9],
    );
    assert_corrupt_without_param(&dir, &before, 4, "Bf");
}

#[test]
fn the_limit_surface_is_saved_and_a_bad_one_is_rejected() {
    use dynlab_dynamics::physics::LimitSurface;
    let tmp = tempfile::tempdir().unwrap();
    let push = push_data(tmp.path());
    let mut cfg = small(ModelKind::Physics, World::Push);
    cfg.physics_iterations = 2;
    cfg.physics_max_windows = 50;
    cfg.limit_surface = LimitSurface::SupportPoints;
    let m = train(&push, &cfg, &mut |_| {}).unwrap().model;
    assert_eq!(
        m.physics().unwrap().limit_surface(),
        LimitSurface::SupportPoints
    );
    let dir = tmp.path().join("support");
    save_model(&m, &dir, None, Default::default()).unwrap();
    let json = std::fs::read_to_string(dir.join(MODEL_JSON)).unwrap();
    assert!(
        json.contains("\"limit_surface\": \"support_points\""),
        "{json}"
    );
    let (back, _) = load_model(&dir, None, None).unwrap();
    assert_eq!(
        back.physics().unwrap().limit_surface(),
        LimitSurface::SupportPoints
    );
    let (s, u) = ([0.4, 0.02, -0.3], [0.6, 0.2, 0.8]);
    let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
    m.step(&s, &u, &mut a).unwrap();
    back.step(&s, &u, &mut b).unwrap();
    assert_eq!(a, b);
    // a file without the entry is the ellipsoid, a misspelt one is corrupt
    std::fs::write(
        dir.join(MODEL_JSON),
        json.replace("\"limit_surface\": \"support_points\",", ""),
    )
    .unwrap();
    let (back, _) = load_model(&dir, None, None).unwrap();
    assert_eq!(
        back.physics().unwrap().limit_surface(),
        LimitSurface::Ellipsoid
    );
    std::fs::write(dir.join(MODEL_JSON), json.replace("support_points", "cube")).unwrap();
    let e = load_model(&dir, None, None).unwrap_err();
    assert!(
        matches!(e, LearnError::CorruptModel { .. })
            && e.to_string().contains("cube")
            && e.to_string().contains("support_points"),
        "{e}"
    );
}
