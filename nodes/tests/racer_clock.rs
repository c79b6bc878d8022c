//! The racer node's timing without DDS: known command delay, state predicted over it.

use std::path::PathBuf;

use dynlab_control::racing::{CarDynamics, Racer, RacerSettings, true_car_model};
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
