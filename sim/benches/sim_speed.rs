//! Headless simulation speed, single thread: pushes per second and car steps per second with
//! the real-time factor, nominal and with every hidden effect on. The peer measured in the same
//! run is the nominal world: the "ratio" column is the cost of the effects.
//!
//! Run: `cargo bench -p dynlab-sim`.

use std::hint::black_box;
use std::time::Instant;

use dynlab_sim::car::{AeroDrag, GripPatch, MotorLag, SteeringOffset};
use dynlab_sim::push::{ComOffset, FrictionPatch, PusherFriction, TableTilt};
use dynlab_sim::{
    CarExplorer, CarInput, CarScenario, CarWorld, PushExplorer, PushScenario, PushWorld, Region,
    SimRng,
};

fn push_all_effects() -> PushScenario {
    let mut s = PushScenario::free();
    s.effects.com_offset = Some(ComOffset::default());
    s.effects.table_tilt = Some(TableTilt::default());
    s.effects.friction_patch = Some(FrictionPatch {
        region: Region {
            centre: [0.4, 0.0],
            ..Region::default()
        },
        ..FrictionPatch::default()
    });
    s.effects.pusher_friction = Some(PusherFriction::default());
    s
}

fn car_all_effects() -> CarScenario {
    let mut s = CarScenario::floor();
    s.effects.aero_drag = Some(AeroDrag::default());
    s.effects.motor_lag = Some(MotorLag::default());
    s.effects.steering_offset = Some(SteeringOffset::default());
    s.effects.grip_patch = Some(GripPatch::default());
    s
}

/// Pushes per second and simulated seconds per wall second.
fn bench_push(s: &PushScenario, pushes: usize) -> (f64, f64) {
    let explorer = PushExplorer::default();
    let mut rng = SimRng::new(1);
    let mut world = PushWorld::new(s).expect("valid scenario");
    let start = s.start_pose();
    let mut sim_time = 0.0;
    let t0 = Instant::now();
    for i in 0..pushes {
        if i % 10 == 0 {
            world.reset(start).expect("finite");
        }
        let o = world
            .apply(explorer.sample_action(&mut rng))
            .expect("valid action");
        sim_time += o.duration;
        black_box(o.final_pose);
    }
    let wall = t0.elapsed().as_secs_f64();
    (pushes as f64 / wall, sim_time / wall)
}

/// Car steps (10 ms) per second and real-time factor, driven by the explorer.
fn bench_car(s: &CarScenario, steps: usize) -> (f64, f64) {
    let explorer = CarExplorer::default();
    let mut rng = SimRng::new(2);
    let mut world = CarWorld::new(s).expect("valid scenario");
    let mut driver = explorer.driver(s);
    let dt = 0.01;
    let t0 = Instant::now();
    let mut u = CarInput::default();
    for k in 0..steps {
        if k % 2 == 0 {
            u = driver.command(&world.state(), 2.0 * dt, &mut rng);
        }
        black_box(world.step(u, dt).expect("finite"));
    }
    let wall = t0.elapsed().as_secs_f64();
    (steps as f64 / wall, steps as f64 * dt / wall)
}

fn main() {
    // Warm up caches and the allocator.
    bench_push(&PushScenario::free(), 5);
    bench_car(&CarScenario::floor(), 1000);

    println!("dynlab-sim headless speed (single thread)");
    println!(
        "{:<28} {:>14} {:>16} {:>10}",
        "case", "rate", "real-time ×", "ratio"
    );
    let (p0, r0) = bench_push(&PushScenario::free(), 200);
    let (p1, r1) = bench_push(&push_all_effects(), 200);
    let (o0, ro) = bench_push(&PushScenario::obstacle(), 200);
    println!(
        "{:<28} {:>10.1} /s {:>16.1} {:>10.2}",
        "push, nominal (free)", p0, r0, 1.0
    );
    println!(
        "{:<28} {:>10.1} /s {:>16.1} {:>10.2}",
        "push, obstacle scene",
        o0,
        ro,
        o0 / p0
    );
    println!(
        "{:<28} {:>10.1} /s {:>16.1} {:>10.2}",
        "push, all effects",
        p1,
        r1,
        p1 / p0
    );
    let (c0, q0) = bench_car(&CarScenario::floor(), 200_000);
    let (c1, q1) = bench_car(&car_all_effects(), 200_000);
    println!(
        "{:<28} {:>10.0} /s {:>16.0} {:>10.2}",
        "car 10 ms step, nominal", c0, q0, 1.0
    );
    println!(
        "{:<28} {:>10.0} /s {:>16.0} {:>10.2}",
        "car 10 ms step, all effects",
        c1,
        q1,
        c1 / c0
    );
    println!(
        "rate: pushes (≈1.5 s simulated each, 500 Hz physics) or 10 ms car steps per wall second;"
    );
    println!("ratio: rate relative to the nominal world measured in the same run.");
}
