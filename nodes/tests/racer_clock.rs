//! The racer node's timing without DDS: known command delay, state predicted over it.

use std::path::PathBuf;

use dynlab_control::racing::{CarDynamics, Plant, Racer, RacerSettings, true_car_model};
use dynlab_nodes::racer::{RaceClock, run_headless};
use dynlab_sim::{CarScenario, Track};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn scenario() -> CarScenario {
    CarScenario::from_file(root().join("launch_scripts/scenarios/car_track.toml")).unwrap()
}

fn track() -> Track {
    Track::from_file(root().join("launch_scripts/tracks/default.json")).unwrap()
}

fn report(
    model: &dyn CarDynamics,
    delay_steps: usize,
    solve_ticks: usize,
    seconds: f64,
) -> dynlab_nodes::racer::HeadlessReport {
    let (s, t) = (scenario(), track());
    let racer = Racer::new(model, &t, RacerSettings::default()).unwrap();
    let mut clock = RaceClock::new(racer, model, delay_steps).unwrap();
    run_headless(&mut clock, &s, &t, seconds, solve_ticks).unwrap()
}

fn physics() -> dynlab_learn::Model {
    true_car_model(&scenario().car, 0.01).unwrap()
}

#[test]
fn the_state_is_predicted_over_the_delay_under_the_commands_already_sent() {
    let model = physics();
    let t = track();
    let racer = Racer::new(&model, &t, RacerSettings::default()).unwrap();
    let mut clock = RaceClock::new(racer, &model, 3).unwrap();
    assert!((clock.delay() - 0.03).abs() < 1e-12);
    let start = scenario().start;
    assert!(clock.plan(0.0).unwrap().is_none(), "no state estimate yet");
    for k in 0..15 {
        clock.on_pose(0.01 * k as f64, start);
    }
    let (stamp, s) = clock.estimate().unwrap();
    assert!((stamp - 0.14).abs() < 1e-12);
    let planned = clock.plan(stamp).unwrap().unwrap();
    assert!((planned.apply_at - 0.17).abs() < 1e-9);
    // nothing sent before: the car stands under the zero command over the first delay
    let rest = Plant::new(&model, 1)
        .unwrap()
        .rollout(&s, &[[0.0, 0.0]; 3])
        .unwrap()[3];
    for (a, b) in planned.predicted.iter().zip(&rest) {
        assert!((a - b).abs() < 1e-12, "{:?} vs {rest:?}", planned.predicted);
    }
    // 10 ms before the command acts: one zero step, then two steps of the command
    let u = planned.step.input;
    assert!(u[1] > 0.0, "the racer accelerates from rest: {u:?}");
    let moving = [s[0], s[1], s[2], 0.5, 0.0, 0.0];
    let want = Plant::new(&model, 1)
        .unwrap()
        .rollout(&moving, &[[0.0, 0.0], u, u])
        .unwrap()[3];
    let got = clock.predict(0.16, moving).unwrap();
    for (a, b) in got.iter().zip(&want) {
        assert!((a - b).abs() < 1e-12, "{got:?} vs {want:?}");
    }
    // no delay: the measurement itself
    let racer = Racer::new(&model, &t, RacerSettings::default()).unwrap();
    let none = RaceClock::new(racer, &model, 0).unwrap();
    assert_eq!(none.predict(0.16, moving).unwrap(), moving);
}

#[test]
fn with_a_known_delay_the_headless_racer_stays_on_the_track_and_commands_act_on_time() {
    let model = physics();
    // commands act 30 ms after their pose, solves take 30 ms of simulation time
    let r = report(&model, 3, 3, 6.0);
    assert_eq!(r.excursions, 0, "{r:?}");
    assert!(r.progress > 8.0, "progress {} m in 6 s", r.progress);
    assert_eq!(r.overruns, 0);
    // solves every 50 ms from the pose at k · 50 ms (the first once 15 poses are in):
    // every command acts 30 ms after its control instant
    assert!(r.commands.len() > 100);
    let t0 = r.commands[0].0;
    for (k, (t, _)) in r.commands.iter().enumerate() {
        let want = t0 + 0.05 * k as f64;
        assert!((t - want).abs() < 1e-6, "command {k} at {t}, want {want}");
    }
    assert!((t0 - 0.17).abs() < 1e-6, "first command at {t0}");
}

/// Debugging aid: `DYNLAB_RACER_MODEL=DIR [DELAY_STEPS=5 SOLVE_TICKS=3 SECONDS=10] cargo test
/// --release -p dynlab-nodes --test racer_clock -- --ignored --nocapture`.
#[test]
#[ignore]
fn headless_run_of_a_learned_model() {
    let Ok(dir) = std::env::var("DYNLAB_RACER_MODEL") else {
        return;
    };
    let env = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let (model, _) = dynlab_learn::load_model(std::path::Path::new(&dir), None, None).unwrap();
    let r = report(
        &model,
        env("DELAY_STEPS", 5.0) as usize,
        env("SOLVE_TICKS", 3.0) as usize,
        env("SECONDS", 10.0),
    );
    println!(
        "progress {:.2} m, laps {}, excursions {}, min border {:.3} m, overruns {}",
        r.progress, r.laps, r.excursions, r.min_border_distance, r.overruns
    );
    for (t, u) in r.commands.iter().take(400) {
        println!("{t:.2} {:.3} {:.3}", u[0], u[1]);
    }
}
