//! How strongly the hidden effects of scenario files change what the nominal simulator would
//! predict, on the explorer's own driving or pushing.
//!
//! Car: the explorer drives the scenario's world (3 episodes × 30 s, commands at 50 Hz); before
//! every command the nominal world (`CarScenario::floor()`) is put in the same state and stepped
//! with the same command; the RMS of the 20 ms one-step differences in `vx`, `vy`, `ω` is what a
//! diagnosis sees of the effect. Pushing: 200 explorer pushes from jittered starts, each applied
//! to the scenario's world and to the nominal one (`PushScenario::free()`); mean distance and
//! heading difference of the final poses.
//!
//! Run: `cargo run --release -p dynlab-sim --example effect_strength -- launch_scripts/scenarios/car_steering_gain.toml …`
//! (a file whose name contains `push_` is a pushing scenario).

use dynlab_sim::{
    CarExplorer, CarScenario, CarWorld, PushExplorer, PushScenario, PushWorld, SimError, SimRng,
    derive_seed, wrap_angle,
};

fn car(path: &str) -> Result<(), SimError> {
    let s = CarScenario::from_file(path)?;
    let nominal = CarScenario::floor();
    let explorer = CarExplorer::default();
    let dt = 1.0 / explorer.control_rate;
    let steps = (explorer.duration / dt).round() as usize;
    let mut sums = [0.0f64; 3];
    let mut n = 0usize;
    let mut speed_sum = 0.0;
    for episode in 0..3u64 {
        let mut rng = SimRng::new(derive_seed(99, 7, episode));
        let mut world = CarWorld::new(&s)?;
        world.reset(explorer.sample_start(&s, &mut rng))?;
        let mut driver = explorer.driver(&s);
        let mut reference = CarWorld::new(&nominal)?;
        for _ in 0..steps {
            let x = world.state();
            let u = driver.command(&x, dt, &mut rng);
            let y = world.step(u, dt)?;
            reference.reset(x)?;
            let z = reference.step(u, dt)?;
            sums[0] += (y.vx - z.vx).powi(2);
            sums[1] += (y.vy - z.vy).powi(2);
            sums[2] += (y.omega - z.omega).powi(2);
            speed_sum += y.speed();
            n += 1;
        }
    }
    let rms = sums.map(|s| (s / n as f64).sqrt());
    println!(
        "{path}: RMS one-step residual vx {:.4} m/s, vy {:.4} m/s, ω {:.4} rad/s (mean speed {:.2} m/s)",
        rms[0],
        rms[1],
        rms[2],
        speed_sum / n as f64
    );
    Ok(())
}

fn push(path: &str) -> Result<(), SimError> {
    let s = PushScenario::from_file(path)?;
    let nominal = PushScenario::free();
    let explorer = PushExplorer::default();
    let mut rng = SimRng::new(5);
    let (mut dp, mut dtheta) = (0.0, 0.0);
    let n = 200;
    for _ in 0..n {
        let start = explorer.sample_start(&s, &mut rng);
        let a = explorer.sample_action(&mut rng);
        let mut w = PushWorld::new(&s)?;
        w.reset(start)?;
        let o = w.apply(a)?;
        let mut w = PushWorld::new(&nominal)?;
        w.reset(start)?;
        let q = w.apply(a)?;
        dp += o.final_pose.distance(q.final_pose);
        dtheta += wrap_angle(o.final_pose.theta - q.final_pose.theta).abs();
    }
    println!(
        "{path}: final pose differs by {:.2} mm and {:.4} rad per push (mean of {n})",
        1000.0 * dp / n as f64,
        dtheta / n as f64
    );
    Ok(())
}

fn main() -> Result<(), SimError> {
    for path in std::env::args().skip(1) {
        if path.contains("push_") {
            push(&path)?;
        } else {
            car(&path)?;
        }
    }
    Ok(())
}
