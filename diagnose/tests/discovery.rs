//! The term search beyond the effect library (`discovery`) on data with an out-of-library
//! effect, and custom effects in training.
//!
//! The data: the simulator's explorer drives the nominal car (its commands and start states are
//! kept); the car is then re-simulated with the physics model plus a known custom term (the
//! truth, e.g. a steering gain that falls with speed, `ω̇ += −c·δ·vₓ`), its poses get mocap-like
//! noise (0.5 mm, 2 mrad) and go through the same pipeline as a bag (`Dataset::from_samples`,
//! Savitzky–Golay velocities). Everything is seeded.

use dynlab_diagnose::diagnosis::simdata::{
    car_dataset, car_scenario, low_grip_band, over_low_grip_band, push_dataset, push_scenario,
};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, diagnose};
use dynlab_diagnose::discovery::{Discovery, DiscoveryConfig, discover_terms, discovery_html};
use dynlab_learn::dynamics::data::{CommandSample, PoseSample, SavGol, SplitMix64};
use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::dynamics::physics::features::library;
use dynlab_learn::dynamics::physics::{CustomEffect, Effect, PhysicsModel, Robot, Target};
use dynlab_learn::train::default_physics_solver;
use dynlab_learn::{Dataset, Model, ModelKind, TrainConfig, World, load_model, save_model, train};

const STEERING_GAIN_SPEED: &str = r#"
name = "steering_gain_speed"
[[term]]
state = "omega"
feature = "delta*vx"
coefficient = -120.0
"#;

/// Gaussian noise from a seeded generator (Box–Muller).
fn gauss(rng: &mut SplitMix64) -> f64 {
    let u1 = ((rng.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = ((rng.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// The explorer's commands and start states from the simulator, re-simulated with `truth`,
/// poses with noise (`noise` = 1: 0.5 mm, 2 mrad), through the bag pipeline.
fn car_data(truth: &PhysicsModel, seed: u64, episodes: u64, duration: f64) -> Dataset {
    car_data_steered(truth, seed, episodes, duration, |delta| delta)
}

/// [`car_data`] with the explorer's steering commands mapped by `steer` (commands `[δ, d]`).
fn car_data_steered(
    truth: &PhysicsModel,
    seed: u64,
    episodes: u64,
    duration: f64,
    steer: fn(f64) -> f64,
) -> Dataset {
    car_data_delayed(truth, seed, episodes, duration, steer, 0)
}

/// [`car_data_steered`] with the steering reaching the car `delay` samples after it is logged
/// (a transport delay; before an episode's first command, that command).
fn car_data_delayed(
    truth: &PhysicsModel,
    seed: u64,
    episodes: u64,
    duration: f64,
    steer: fn(f64) -> f64,
    delay: usize,
) -> Dataset {
    let sim = car_dataset(&car_scenario(None, 0.0), episodes, duration, 700 + seed, 1).unwrap();
    let dt = sim.pose_dt_s;
    let dt_ns = (dt * 1e9).round() as i64;
    let mut rng = SplitMix64::new(0xD15C_0000 ^ seed);
    let (mut poses, mut cmds) = (Vec::new(), Vec::new());
    let mut t0: i64 = 0;
    for t in &sim.trajectories {
        let n = t.len();
        let mut s = t.s[..6].to_vec();
        for i in 0..n {
            let t_ns = t0 + i as i64 * dt_ns;
            poses.push(PoseSample {
                t_ns,
                x: s[0] + 0.0005 * gauss(&mut rng),
                y: s[1] + 0.0005 * gauss(&mut rng),
                yaw: s[2] + 0.002 * gauss(&mut rng),
            });
            let u = [steer(t.u[i * 2]), t.u[i * 2 + 1]];
            cmds.push(CommandSample {
                t_ns,
                u: u.to_vec(),
            });
            let late = [steer(t.u[i.saturating_sub(delay) * 2]), u[1]];
            let mut next = vec![0.0; 6];
            truth.integrate_step(&Solver::rk4(), 1, &s, &late, dt, &mut next);
            s = next;
        }
        t0 += n as i64 * dt_ns + 1_000_000_000;
    }
    Dataset::from_samples(World::Car, &poses, &cmds, &SavGol::default()).unwrap()
}

fn truth_with(text: &str) -> PhysicsModel {
    let mut p = PhysicsModel::car(&[]).unwrap();
    p.add_custom(CustomEffect::from_toml(text).unwrap())
        .unwrap();
    p
}

fn physics_model(p: PhysicsModel, dt: f64) -> Model {
    Model::new(
        ModelKind::Physics,
        World::Car,
        dt,
        None,
        None,
        Some(p),
        default_physics_solver(World::Car),
    )
    .unwrap()
}

/// The library diagnosis with fewer windows and resamples than its defaults.
fn quick_diagnosis(seed: u64) -> DiagnoseConfig {
    DiagnoseConfig {
        seed,
        fit_windows: 300,
        score_windows: 1000,
        bootstrap: 500,
        ..DiagnoseConfig::default()
    }
}

fn search(model: &Model, data: &Dataset, seed: u64) -> Discovery {
    let cfg = DiscoveryConfig {
        seed,
        fit_windows: 200,
        score_windows: 1000,
        ..DiscoveryConfig::default()
    };
    discover_terms(model, data, &cfg).unwrap()
}

/// The search with its default windows (every setting but the seed at its default).
fn search_all(model: &Model, data: &Dataset, seed: u64) -> Discovery {
    let cfg = DiscoveryConfig {
        seed,
        ..DiscoveryConfig::default()
    };
    discover_terms(model, data, &cfg).unwrap()
}

#[test]
fn out_of_library_steering_gain_is_discovered_over_seeds() {
    let truth = truth_with(STEERING_GAIN_SPEED);
    let mut reductions = Vec::new();
    let mut coefs = Vec::new();
    for seed in 0..5 {
        let data = car_data(&truth, seed, 2, 12.0);
        let model = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
        let d = search(&model, &data, seed);
        let table = d.table();
        println!("seed {seed}\n{table}");
        let found = d.terms.iter().find(|t| t.significant).expect(&table);
        assert_eq!(found.state, "omega", "{table}");
        assert!(
            found.feature == "delta*vx" || found.feature == "delta*|v|",
            "{table}"
        );
        assert!(found.coefficient < 0.0, "{table}");
        assert!(d.error_reduction >= 0.4, "{table}");
        // the held-out windows left out of the score (rollouts through a spin) are few
        assert!(
            d.spin_windows * 100 <= 15 * (d.windows[1] + d.spin_windows),
            "{table}"
        );
        let eff = d.effect.as_ref().expect(&table);
        assert_eq!(
            CustomEffect::from_toml(d.effect_toml.as_ref().unwrap()).unwrap(),
            *eff
        );
        let back: Discovery = serde_json::from_str(&d.to_json()).unwrap();
        assert_eq!(back.terms.len(), d.terms.len());
        assert_eq!(back.effect, d.effect);
        assert_eq!(back.spin_windows, d.spin_windows);
        let html = discovery_html(&d);
        assert!(html.contains("<section") && html.contains(&found.symbol));
        reductions.push(d.error_reduction);
        coefs.push(found.coefficient);
    }
    let (lo, hi) = reductions
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &r| (a.min(r), b.max(r)));
    println!(
        "held-out reduction over 5 seeds: {:.1}–{:.1} %; coefficients {:?} (truth −120)",
        100.0 * lo,
        100.0 * hi,
        coefs
    );
}

#[test]
fn the_library_does_not_name_the_out_of_library_effect() {
    let truth = truth_with(STEERING_GAIN_SPEED);
    let data = car_data(&truth, 11, 2, 12.0);
    let model = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
    let cfg = quick_diagnosis(11);
    let diag = diagnose(&model, &data, &cfg).unwrap();
    println!("{}", diag.table());
    // no library name for it
    assert!(diag.verdict.is_none(), "{}", diag.table());
    assert!(
        diag.candidates.iter().all(|c| !c.significant),
        "{}",
        diag.table()
    );
    let d = search(&model, &data, 11);
    assert!(d.error_reduction >= 0.4, "{}", d.table());
}

/// A steering gain that falls with speed on a car that turns one way only: a constant steering
/// offset then lowers the error on every segment and passes the numbers, but the term search's
/// steering term removes more, so the library names nothing and the term is found.
#[test]
fn a_steering_offset_that_only_absorbs_a_speed_dependent_gain_is_not_named() {
    let truth = truth_with(
        r#"
name = "gain_falls_with_speed"
[[term]]
state = "delta"
feature = "delta*vx"
coefficient = -0.25
"#,
    );
    let data = car_data_steered(&truth, 12, 2, 12.0, f64::abs);
    let model = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
    let cfg = quick_diagnosis(12);
    let diag = diagnose(&model, &data, &cfg).unwrap();
    println!("{}", diag.table());
    let offset = diag
        .candidates
        .iter()
        .find(|c| c.effect == "steering_offset")
        .expect("steering_offset is a candidate");
    // the offset passes the numbers: the data are biased enough for the check to matter
    assert!(
        offset.error_reduction >= cfg.min_reduction && offset.ci_lower > 0.0,
        "{}",
        diag.table()
    );
    assert!(!offset.significant, "{}", diag.table());
    let note = offset.note.as_deref().unwrap_or_default();
    assert!(
        note.contains("a steering term") && note.contains("δ·vₓ"),
        "{note}"
    );
    assert!(diag.verdict.is_none(), "{}", diag.table());
}

/// Nominal data, 20 seeds (the model is the truth up to noise): nothing is significant.
#[test]
fn nominal_data_have_no_significant_term() {
    let truth = PhysicsModel::car(&[]).unwrap();
    for seed in 0..20 {
        let data = car_data(&truth, 100 + seed, 2, 12.0);
        let model = physics_model(truth.clone(), data.pose_dt_s);
        let d = search(&model, &data, seed);
        println!("nominal seed {seed}: {}", d.summary);
        assert!(d.terms.iter().all(|t| !t.significant), "{}", d.table());
        assert!(d.effect.is_none() && d.effect_toml.is_none());
    }
}

/// The car's fitted parameters 10 % off the documented values (seeded signs); the model is
/// trained on the data (`train --kind physics`), then searched: nothing is significant.
#[test]
fn perturbed_nominal_car_trained_then_searched_has_no_significant_term() {
    for seed in 0..3u64 {
        let mut truth = PhysicsModel::car(&[]).unwrap();
        let mut rng = SplitMix64::new(0xBEEF ^ seed);
        for name in ["Bf", "Df", "Br", "Dr", "Cm1", "Cm2", "Cr0"] {
            let i = truth.param_index(name).unwrap();
            let sign = if rng.next_u64().is_multiple_of(2) {
                1.1
            } else {
                0.9
            };
            truth.set_param(name, truth.params()[i] * sign).unwrap();
        }
        let data = car_data(&truth, 200 + seed, 2, 12.0);
        let cfg = TrainConfig {
            kind: ModelKind::Physics,
            steps: 10,
            seed,
            physics_iterations: 15,
            physics_max_windows: 400,
            ..TrainConfig::default()
        };
        let out = train(&data, &cfg, &mut |_| {}).unwrap();
        let d = search(&out.model, &data, seed);
        println!("perturbed seed {seed}: {}", d.summary);
        assert!(d.terms.iter().all(|t| !t.significant), "{}", d.table());
    }
}

/// Data whose quadratic drag `C_r2` is 20 times the model's: the drivetrain-shaped pairs
/// (`v̇ₓ` on `vₓ²`, `vₓ|vₓ|`, `d`, `d·vₓ`, `1`) are a nominal parameter, not an effect, and are
/// never tried (the pair count says so); whatever else the search finds is another shape.
#[test]
fn a_nominal_parameter_change_is_not_reported_as_a_term() {
    let mut truth = PhysicsModel::car(&[]).unwrap();
    let cr2 = truth.params()[truth.param_index("Cr2").unwrap()];
    truth.set_param("Cr2", 20.0 * cr2).unwrap();
    let data = car_data(&truth, 31, 2, 12.0);
    let model = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
    let d = search(&model, &data, 31);
    println!("{}", d.table());
    let shaped = ["vx*vx", "vx*|vx|", "d", "d*vx", "d*|vx|", "1"];
    assert!(
        d.terms
            .iter()
            .all(|t| !(t.state == "vx" && shaped.contains(&t.feature.as_str()))),
        "{}",
        d.table()
    );
    let grid = DiscoveryConfig::default().grid;
    // each bump alone and times the saturating slip of each axle
    let features = library(Robot::Car, None, 0).len() + 3 * grid * grid;
    // the steering angle takes features of the commands and the speed, but not `1` (the
    // library's steering offset), and the saturating steering term fitted to its residual
    let steering = library(Robot::Car, None, 0)
        .iter()
        .filter(|f| Target::Delta.searched_with(f) && Target::Delta.nominal_parameter(f).is_none())
        .count()
        + 1;
    assert!(
        steering >= 6,
        "δ·vₓ, δ·vₓ², δ·|v|, …, δ·vₓ²/(vₓ² + v₀²) are tried on δ"
    );
    // the grip takes the position alone: `x`, `y`, each bump and the bands (4 directions ×
    // `grid` offsets, tried on the grip only), the strip and the bump fitted to its residual,
    // but not `1` (the peak forces)
    let grip = library(Robot::Car, None, 0)
        .iter()
        .filter(|f| Target::Grip.searched_with(f) && Target::Grip.nominal_parameter(f).is_none())
        .count()
        + grid * grid
        + 4 * grid
        + 2;
    assert_eq!(
        grip,
        4 + grid * grid + 4 * grid,
        "x, y, bumps, bands and the two fitted regions are tried on μ"
    );
    // a lagged command is tried only through the input it lags: the throttle's rates on v̇ₓ
    // (and the steering's on δ, counted above), none on v̇_y, ω̇
    let lagged_elsewhere: usize = [Target::Vx, Target::Vy, Target::Omega]
        .iter()
        .map(|t| {
            library(Robot::Car, None, 0)
                .iter()
                .filter(|f| f.uses_input_lags() && !t.searched_with(f))
                .count()
        })
        .sum();
    assert_eq!(lagged_elsewhere, 3 + 6 + 6);
    // the world-frame ẍ, ÿ take the constant and the position (`1`, `x`, `y`, each bump), a
    // pull fixed in the world
    let world: usize = [Target::WorldX, Target::WorldY]
        .iter()
        .map(|t| {
            library(Robot::Car, None, 0)
                .iter()
                .filter(|f| t.searched_with(f))
                .count()
                + grid * grid
        })
        .sum();
    assert_eq!(world, 2 * (3 + grid * grid));
    // each command beyond the level fitted to the residual of what it drives: the steering's
    // on δ, the throttle's on v̇ₓ
    let levels = 2;
    assert_eq!(
        d.pairs_tried,
        3 * features - shaped.len() - lagged_elsewhere + steering + grip + world + levels,
        "{}",
        d.table()
    );
}

/// `train` with the discovered custom effect (the `--effects-file` path) lowers the held-out
/// error against the same training without it; the model file keeps the term and reloads.
#[test]
fn training_with_the_custom_effect_lowers_the_held_out_error() {
    let truth = truth_with(STEERING_GAIN_SPEED);
    let data = car_data(&truth, 31, 2, 12.0);
    let cfg = TrainConfig {
        kind: ModelKind::Physics,
        steps: 10,
        seed: 3,
        physics_iterations: 15,
        physics_max_windows: 400,
        ..TrainConfig::default()
    };
    // the search on the documented model finds the term ...
    let nominal = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
    let d = search(&nominal, &data, 3);
    // ... and training with it (nominal parameters fitted too) beats training without
    let before = train(&data, &cfg, &mut |_| {}).unwrap();
    let toml = d
        .effect_toml
        .clone()
        .unwrap_or_else(|| panic!("{}", d.table()));
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("discovered.toml");
    std::fs::write(&file, &toml).unwrap();
    let custom = dynlab_learn::train::read_custom_effect(&file).unwrap();
    let after = train(
        &data,
        &TrainConfig {
            custom_effects: vec![custom],
            ..cfg.clone()
        },
        &mut |_| {},
    )
    .unwrap();
    println!(
        "validation loss without {:.5}, with the custom effect {:.5}\n{}",
        before.best_validation_loss,
        after.best_validation_loss,
        after.model.physics().unwrap()
    );
    assert!(
        after.best_validation_loss < 0.8 * before.best_validation_loss,
        "{} vs {}",
        after.best_validation_loss,
        before.best_validation_loss
    );
    let p = after.model.physics().unwrap();
    let i = p.param_index("custom.discovered.0").unwrap();
    assert!(p.params()[i] < 0.0);
    assert!(p.equations().contains("ω̇ += −"), "{}", p.equations());
    // the model file records the term and reloads it
    let mdir = dir.path().join("model");
    save_model(&after.model, &mdir, None, Default::default()).unwrap();
    let text = std::fs::read_to_string(mdir.join("model.json")).unwrap();
    assert!(text.contains("custom_effects") && text.contains("custom.discovered.0"));
    let (back, _) = load_model(&mdir, None, None).unwrap();
    assert_eq!(back.physics().unwrap().params(), p.params());
    assert_eq!(back.physics().unwrap().param_names(), p.param_names());
}

/// The pusher's actions and start poses from the simulator, re-simulated push by push with
/// `truth`, one pose per push with noise (0.5 mm, 2 mrad), through the bag pipeline.
fn push_data(truth: &PhysicsModel, seed: u64, episodes: u64) -> Dataset {
    let sim = push_dataset(&push_scenario(None, 0.0), episodes, 10, 900 + seed, 1).unwrap();
    let solver = default_physics_solver(World::Push);
    let period: i64 = 2_000_000_000;
    let mut rng = SplitMix64::new(0x9054_0000 ^ seed);
    let (mut poses, mut cmds) = (Vec::new(), Vec::new());
    let mut t0: i64 = 0;
    for t in &sim.trajectories {
        let n = t.len();
        let mut s = t.s[..3].to_vec();
        for i in 0..n {
            let t_ns = t0 + i as i64 * period;
            poses.push(PoseSample {
                t_ns,
                x: s[0] + 0.0005 * gauss(&mut rng),
                y: s[1] + 0.0005 * gauss(&mut rng),
                yaw: s[2] + 0.002 * gauss(&mut rng),
            });
            if i + 1 < n {
                let u = &t.u[i * 3..i * 3 + 3];
                cmds.push(CommandSample {
                    t_ns,
                    u: u.to_vec(),
                });
                let mut next = vec![0.0; 3];
                truth.integrate_step(&solver, 1, &s, u, 1.0, &mut next);
                s = next;
            }
        }
        t0 += n as i64 * period + 10 * period;
    }
    Dataset::from_samples(World::Push, &poses, &cmds, &SavGol::default()).unwrap()
}

/// Pushing: a sideways drift of the block in its own frame while pushed (`ẏ_b += c·ℓ`, as an
/// uneven contact would give), outside the effect library: found with the right target,
/// feature and sign; nominal pushing data: nothing.
#[test]
fn pushing_block_frame_drift_is_discovered() {
    let mut truth = PhysicsModel::pushing(&[]).unwrap();
    truth
        .add_custom(
            CustomEffect::from_toml(
                "name = \"drift\"\n[[term]]\nstate = \"by\"\nfeature = \"l\"\ncoefficient = 0.006\n",
            )
            .unwrap(),
        )
        .unwrap();
    let nominal = PhysicsModel::pushing(&[]).unwrap();
    for (seed, truth) in [(0u64, &truth), (1, &nominal)] {
        let data = push_data(truth, seed, 20);
        let model = Model::new(
            ModelKind::Physics,
            World::Push,
            data.pose_dt_s,
            None,
            None,
            Some(nominal.clone()),
            default_physics_solver(World::Push),
        )
        .unwrap();
        let d = search_all(&model, &data, seed);
        println!("{}", d.table());
        if truth == &nominal {
            assert!(d.terms.iter().all(|t| !t.significant), "{}", d.table());
            continue;
        }
        let found = d
            .terms
            .iter()
            .find(|t| t.significant)
            .unwrap_or_else(|| panic!("{}", d.table()));
        assert_eq!(found.state, "by", "{}", d.table());
        assert!(found.feature == "l", "{}", d.table());
        assert!(found.coefficient > 0.0, "{}", d.table());
        assert!(d.error_reduction >= 0.4, "{}", d.table());
    }
}

/// More out-of-library terms (run with `--ignored`; prints what is found): a steering gain
/// falling with the square of speed, lateral damping growing with speed, and a slow zone on the
/// floor (a position basis function).
#[test]
#[ignore]
fn more_out_of_library_terms() {
    let truths = [
        ("omega", "delta*vx*vx", -60.0),
        ("vy", "vy*vx", -3.0),
        ("vx", "gauss(0.3,0.2,0.5)", -1.5),
    ];
    for (state, feature, c) in truths {
        let truth = truth_with(&format!(
            "name = \"t\"\n[[term]]\nstate = \"{state}\"\nfeature = \"{feature}\"\ncoefficient = {c}\n"
        ));
        for seed in 0..3 {
            let data = car_data(&truth, 40 + seed, 2, 12.0);
            let model = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
            let d = search(&model, &data, seed);
            println!("truth {state} += {c}·{feature}, seed {seed}: {}", d.summary);
        }
    }
}

/// A model with an effect state (`motor_lag`'s filtered throttle, rebuilt from the command
/// history at every window start) is searched like any other.
#[test]
fn a_model_with_an_effect_state_is_searched() {
    use dynlab_learn::dynamics::physics::Effect;
    let truth = PhysicsModel::car(&[]).unwrap();
    let data = car_data(&truth, 77, 2, 12.0);
    let mut p = PhysicsModel::car(&[Effect::MotorLag]).unwrap();
    p.set_param("motor_lag.tau", 0.01).unwrap();
    let model = physics_model(p, data.pose_dt_s);
    let d = search(&model, &data, 1);
    println!("{}", d.table());
    assert!(d.transitions > 1000 && d.baseline_error.is_finite());
}

/// The simulator's low-grip band (half the grip within 0.4 m of a line at 0.5 rad through
/// (0, 0.3), `launch_scripts/scenarios/car_grip_band.toml`), outside the library, on the
/// documented model: over 3 seeds the term the search tries for it is on the grip `μ`, negative
/// (less grip) and on a band or a bump centred within the band, and removes ≥ 20 % of the
/// held-out error; it passes the search's test in at least 2 (measured: 3 of 3, 51, 66 and
/// 25 %). (The bootstrap over whole held-out segments is wide for a region: only the segments
/// that cross it gain.)
#[test]
fn a_low_grip_band_is_a_grip_term_on_a_band() {
    let mut scenario = car_scenario(None, 1.0);
    scenario.effects.grip_patch = Some(low_grip_band());
    let mut significant = 0;
    for seed in 1..=3u64 {
        let data = car_dataset(&scenario, 4, 30.0, 900 + seed, 2).unwrap();
        let model = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
        let d = search_all(&model, &data, seed);
        println!("seed {seed}\n{}", d.table());
        let t = d
            .terms
            .iter()
            .find(|t| t.state == "grip")
            .unwrap_or_else(|| panic!("no grip term tried\n{}", d.table()));
        assert!(t.coefficient < 0.0, "less grip: {}", d.table());
        assert!(t.error_reduction >= 0.2, "{}", d.table());
        assert!(over_low_grip_band(&t.feature), "{}", d.table());
        significant += usize::from(t.significant);
    }
    assert!(
        significant >= 2,
        "the grip term passed the test in {significant} of 3 seeds"
    );
}

#[test]
fn a_steering_delay_is_discovered_as_a_term_on_the_lagged_steering_rate() {
    // the steering reaches the car 60 ms after it is logged; the model has no delay, and no
    // memoryless term can stand for one
    let car = PhysicsModel::car(&[]).unwrap();
    for seed in 0..3 {
        let dt = car_data(&car, seed, 1, 1.0).pose_dt_s;
        let delay = (0.06 / dt).round() as usize;
        let data = car_data_delayed(&car, seed, 2, 12.0, |d| d, delay);
        let model = physics_model(PhysicsModel::car(&[]).unwrap(), data.pose_dt_s);
        let d = search(&model, &data, seed);
        let table = d.table();
        println!("seed {seed}, delay {delay} samples\n{table}");
        let found = d.terms.iter().find(|t| t.significant).expect(&table);
        assert_eq!(found.state, "delta", "{table}");
        assert!(found.feature.starts_with("delta_rate("), "{table}");
        // δ − t_d·δ̇: the coefficient is minus the delay in seconds
        assert!(
            (-0.075..-0.045).contains(&found.coefficient),
            "delay {} s, truth 0.06 s\n{table}",
            -found.coefficient
        );
        assert!(d.error_reduction >= 0.4, "{table}");
        // the custom effect file carries the term, and a model with it has the lagged commands
        let eff = d.effect.clone().expect(&table);
        let mut with = PhysicsModel::car(&[]).unwrap();
        with.add_custom(eff).unwrap();
        assert_eq!(with.dim_effect_states(), 6);
    }
}

/// A low-grip strip (the simulator's band, `μ += −0.5·s(0.5, 0.263; 0.8)`) on a car without a
/// friction ellipse, diagnosed with a model fitted on that car's nominal data with the full one
/// (the datasheet's; nominal data hardly tell the weight): no library name, and the term
/// search's strip is fitted with the weight freed, which goes towards the car's 0 and is
/// reported in `nominal` for training to start from. Held at 1, the right strip removed 6.5 % of
/// the held-out error of the independent generator's car 0 with a band (freed: 85 %).
#[test]
fn a_grip_term_refits_the_friction_ellipse_weight_with_it() {
    let mut car = PhysicsModel::car(&[]).unwrap();
    car.set_param("ellipse", 0.0).unwrap();
    let mut truth = car.clone();
    truth
        .add_custom(
            CustomEffect::from_toml(
                "name = \"band\"\n[[term]]\nstate = \"grip\"\nfeature = \"strip(0.5,0.263,0.8)\"\ncoefficient = -0.5\n",
            )
            .unwrap(),
        )
        .unwrap();
    let seed = 7;
    let nominal = car_data(&car, 300 + seed, 4, 15.0);
    let cfg = TrainConfig {
        kind: ModelKind::Physics,
        seed,
        physics_iterations: 15,
        physics_max_windows: 400,
        ..TrainConfig::default()
    };
    let model = train(&nominal, &cfg, &mut |_| {}).unwrap().model;
    let data = car_data(&truth, seed, 4, 15.0);
    let cfg = DiagnoseConfig {
        effects: Some(vec![Effect::GripPatch]),
        ..quick_diagnosis(seed)
    };
    let diag = diagnose(&model, &data, &cfg).unwrap();
    println!("{}", diag.table());
    assert!(diag.effects.is_empty(), "{}", diag.table());
    let d = diag.discovery.as_ref().expect("a term search");
    let t = d
        .terms
        .iter()
        .find(|t| t.significant)
        .unwrap_or_else(|| panic!("no significant term\n{}", diag.table()));
    assert_eq!(t.state, "grip", "{}", diag.table());
    assert!(over_low_grip_band(&t.feature), "{}", diag.table());
    assert!((t.coefficient + 0.5).abs() < 0.15, "{}", diag.table());
    let e = d.nominal.get("ellipse").copied();
    assert!(
        e.is_some_and(|e| e < 0.3),
        "ellipse {e:?}\n{}",
        diag.table()
    );
    assert!(d.error_reduction >= 0.4, "{}", diag.table());
    assert!(d.table().contains("--set ellipse="), "{}", d.table());
}
