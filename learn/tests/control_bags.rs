//! The bundled control data (`bags/push_wide`, `bags/car_track`, `bags/car_race`, made by
//! `launch_scripts/make_bags.sh`) are there and readable, and the training defaults for the car's
//! node-rk4 learn something on them in a short run (`launch_scripts/control.sh` trains on them).

use std::path::PathBuf;

use dynlab_learn::dynamics::data::SavGol;
use dynlab_learn::{
    Dataset, KindDefaults, ModelKind, Topics, TrainConfig, World, load_bags, train,
};

fn bag(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../bags")
        .join(name)
}

fn load(names: &[&str]) -> Dataset {
    let paths: Vec<PathBuf> = names.iter().map(|n| bag(n)).collect();
    for p in &paths {
        assert!(
            p.join("metadata.yaml").is_file(),
            "{} is missing: run launch_scripts/make_bags.sh",
            p.display()
        );
    }
    load_bags(&paths, None, &Topics::default(), &SavGol::default())
        .unwrap_or_else(|e| panic!("reading {names:?}: {e}"))
}

#[test]
fn the_wide_pushing_bag_has_one_pose_per_push_from_starts_on_both_sides() {
    let d = load(&["push_wide"]);
    assert_eq!(d.world, World::Push);
    // 500 episodes × 10 pushes, one pose per push: every push a transition
    assert_eq!(d.trajectories.len(), 500);
    assert_eq!(d.transitions(), 5000);
    // the starts cover both scenes' start headings (free +0.2π, obstacle −0.2π)
    let headings: Vec<f64> = d.trajectories.iter().map(|t| t.s[2]).collect();
    let near = |h: f64| headings.iter().filter(|&&x| (x - h).abs() < 0.2).count();
    let (free, obstacle) = (
        near(0.2 * std::f64::consts::PI),
        near(-0.2 * std::f64::consts::PI),
    );
    assert!(
        free >= 20 && obstacle >= 20,
        "starts near ±0.2π: {free}, {obstacle}"
    );
}

#[test]
fn the_car_track_bags_load_with_their_episodes() {
    for (name, episodes) in [("car_track", 10), ("car_race", 10)] {
        let d = load(&[name]);
        assert_eq!(d.world, World::Car, "{name}");
        assert_eq!(d.trajectories.len(), episodes, "{name}");
        // 30 s at 100 Hz each
        assert!(
            d.transitions() >= episodes * 2900,
            "{name}: {} transitions",
            d.transitions()
        );
    }
}

#[test]
fn car_node_rk4_with_the_defaults_beats_the_constant_model_after_a_short_run() {
    let d = load(&["car_track", "car_race"]);
    let defaults = KindDefaults::for_kind(World::Car, ModelKind::NodeRk4);
    // the car needs the multi-step loss: with k = 1 a node-rk4 model barely beats the
    // constant model (0.043 against 0.051 after 300 epochs on bags/car_nominal)
    assert!(
        defaults.steps >= 3,
        "car node-rk4 default k = {}",
        defaults.steps
    );
    let cfg = TrainConfig {
        kind: ModelKind::NodeRk4,
        steps: defaults.steps,
        epochs: defaults.epochs,
        // about one epoch: seconds, and enough to show the defaults learn
        max_samples: Some(60_000),
        threads: 2,
        ..Default::default()
    };
    let out = train(&d, &cfg, &mut |_| {}).unwrap();
    let ratio = out.best_validation_loss / out.baseline_validation_loss;
    // measured: 0.67 with k = 5; the same run with k = 1 ends at 0.82 of its constant model
    assert!(
        ratio < 0.75,
        "validation loss {:.4} against the constant model's {:.4} (ratio {ratio:.3})",
        out.best_validation_loss,
        out.baseline_validation_loss
    );
}
