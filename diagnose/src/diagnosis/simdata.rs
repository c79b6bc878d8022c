//! Data sets straight from the simulator, in process (no bag): for tests, the recovery-rate
//! evaluation and benchmarks. The same pipeline as `dynlab train` reads a bag with (poses and
//! commands → [`Dataset::from_samples`]).

use dynlab_learn::dynamics::data::{CommandSample, PoseSample, SavGol};
use dynlab_learn::dynamics::physics::{Effect, PhysicsModel};
use dynlab_learn::train::default_physics_solver;
use dynlab_learn::{Dataset, Model, ModelKind, World};
use dynlab_sim::episode::{Record, concatenate, generate_car_episodes, generate_push_episodes};
use dynlab_sim::{CarExplorer, CarScenario, PushExplorer, PushScenario, Region, RegionShape};

use super::DiagnosisError;

/// The nominal physics model of `world` at its documented values (the simulator's nominal
/// world), stepping `dt` \[s\] with the default solver: the model the diagnosis tests hold
/// against simulator data.
pub fn nominal_model(world: World, dt: f64) -> Result<Model, DiagnosisError> {
    let physics = match world {
        World::Car => PhysicsModel::car(&[])?,
        World::Push => PhysicsModel::pushing(&[])?,
    };
    Ok(Model::new(
        ModelKind::Physics,
        world,
        dt,
        None,
        None,
        Some(physics),
        default_physics_solver(world),
    )?)
}

/// Gap between episodes on the time line \[ns\] (splits them into trajectories).
const GAP_NS: u64 = 1_000_000_000;

fn to_dataset(world: World, samples: &[dynlab_sim::Sample]) -> Result<Dataset, DiagnosisError> {
    let mut poses = Vec::new();
    let mut cmds = Vec::new();
    for s in samples {
        let t_ns = s.t_ns as i64;
        match s.record {
            Record::CarPose(p) | Record::BlockPose(p) => poses.push(PoseSample {
                t_ns,
                x: p.x,
                y: p.y,
                yaw: p.theta,
            }),
            Record::CarCmd(u) => cmds.push(CommandSample {
                t_ns,
                u: vec![u.steering, u.throttle],
            }),
            Record::PushAction(a) => cmds.push(CommandSample {
                t_ns,
                u: vec![a.location, a.angle, a.length],
            }),
            _ => {}
        }
    }
    Ok(Dataset::from_samples(
        world,
        &poses,
        &cmds,
        &SavGol::default(),
    )?)
}

/// `episodes` car episodes of `duration` seconds from `scenario`, seeded.
pub fn car_dataset(
    scenario: &CarScenario,
    episodes: u64,
    duration: f64,
    seed: u64,
    threads: usize,
) -> Result<Dataset, DiagnosisError> {
    let explorer = CarExplorer {
        duration,
        ..CarExplorer::default()
    };
    let eps = generate_car_episodes(scenario, &explorer, seed, episodes, threads.max(1))
        .map_err(|e| DiagnosisError::Simulator(e.to_string()))?;
    to_dataset(World::Car, &concatenate(&eps, 0, GAP_NS))
}

/// `episodes` pushing episodes of `pushes` pushes each from `scenario`, seeded.
pub fn push_dataset(
    scenario: &PushScenario,
    episodes: u64,
    pushes: u32,
    seed: u64,
    threads: usize,
) -> Result<Dataset, DiagnosisError> {
    let explorer = PushExplorer {
        pushes_per_episode: pushes,
        ..PushExplorer::default()
    };
    push_dataset_with(scenario, &explorer, episodes, seed, threads)
}

/// `episodes` pushing episodes from `scenario` driven by `explorer` (its pushes per episode,
/// start jitter, pose rate), seeded.
pub fn push_dataset_with(
    scenario: &PushScenario,
    explorer: &PushExplorer,
    episodes: u64,
    seed: u64,
    threads: usize,
) -> Result<Dataset, DiagnosisError> {
    let eps = generate_push_episodes(scenario, explorer, seed, episodes, threads.max(1))
        .map_err(|e| DiagnosisError::Simulator(e.to_string()))?;
    to_dataset(World::Push, &concatenate(&eps, 0, GAP_NS))
}

/// The car world with only `effect` on, at the strength the tests and the recovery evaluation
/// use (the simulator's documented defaults unless noted), and mocap-like noise scaled by
/// `noise` (1: 0.5 mm, 0.002 rad). `None`: the nominal car.
pub fn car_scenario(effect: Option<Effect>, noise: f64) -> CarScenario {
    use dynlab_sim::car::{
        AeroDrag, CommandDelay, GripPatch, MotorLag, SteeringOffset, SteeringRateLimit,
    };
    let mut s = CarScenario::default();
    s.noise.position_std = 0.0005 * noise;
    s.noise.yaw_std = 0.002 * noise;
    match effect {
        Some(Effect::AeroDrag) => s.effects.aero_drag = Some(AeroDrag::default()),
        Some(Effect::MotorLag) => {
            s.effects.motor_lag = Some(MotorLag {
                enabled: true,
                tau: 0.2,
            })
        }
        Some(Effect::SteeringOffset) => s.effects.steering_offset = Some(SteeringOffset::default()),
        Some(Effect::GripPatch) => {
            s.effects.grip_patch = Some(GripPatch {
                enabled: true,
                scale: 0.5,
                region: Region {
                    shape: RegionShape::Disc,
                    centre: [0.5, 0.0],
                    radius: 0.6,
                    ..Region::default()
                },
            })
        }
        // the servo: a 50 ms lag with a hard 3 rad/s rate clamp (the library's rate limit
        // is smooth)
        Some(Effect::SteeringLag) => {
            s.effects.steering_rate_limit = Some(SteeringRateLimit {
                enabled: true,
                rate: 3.0,
                tau: 0.05,
            })
        }
        // both commands applied 60 ms late (exact; the library's delay a Padé filter)
        Some(Effect::CommandDelay) => s.effects.command_delay = Some(CommandDelay::default()),
        _ => {}
    }
    s
}

/// The low-grip band outside the library (`launch_scripts/scenarios/car_grip_band.toml`): both
/// tires' peak force halved within 0.4 m of the line through (0, 0.3) at 0.5 rad, across the
/// floor.
pub fn low_grip_band() -> dynlab_sim::car::GripPatch {
    dynlab_sim::car::GripPatch {
        enabled: true,
        scale: 0.5,
        region: Region {
            shape: RegionShape::Band,
            centre: [0.0, 0.3],
            angle: 0.5,
            width: 0.8,
            ..Region::default()
        },
    }
}

/// Whether a term's feature has a position factor over [`low_grip_band`] on the 3 × 3 m
/// floor: a bump centred in it, or a band or strip whose centre line crosses it.
pub fn over_low_grip_band(feature: &str) -> bool {
    use dynlab_learn::dynamics::physics::features::{Atom, Feature};
    let band = low_grip_band().region;
    let inside = |x: f64, y: f64| {
        let (s, c) = band.angle.sin_cos();
        (-s * (x - band.centre[0]) + c * (y - band.centre[1])).abs() <= 0.5 * band.width
    };
    let Ok(f) = Feature::parse(feature) else {
        return false;
    };
    f.factors().iter().any(|a| match *a {
        Atom::Gauss { cx, cy, .. } => inside(cx, cy),
        Atom::Band { a, d, .. } | Atom::Strip { a, d, .. } => (-15..=15).any(|i| {
            let s = 0.1 * f64::from(i);
            let (x, y) = (-a.sin() * d + a.cos() * s, a.cos() * d + a.sin() * s);
            x.abs() <= 1.5 && y.abs() <= 1.5 && inside(x, y)
        }),
        _ => false,
    })
}

/// The pushing world with only `effect` on (see [`car_scenario`]).
pub fn push_scenario(effect: Option<Effect>, noise: f64) -> PushScenario {
    let mut s = PushScenario::default();
    s.noise.position_std = 0.0005 * noise;
    s.noise.yaw_std = 0.002 * noise;
    if let Some(e) = effect {
        add_push_effect(&mut s, e);
    }
    s
}

/// Turns pushing `effect` on in world `s` at the strength the recovery hides it with (a car
/// effect changes nothing).
pub fn add_push_effect(s: &mut PushScenario, effect: Effect) {
    use dynlab_sim::push::{ComOffset, FrictionPatch, PusherFriction, TableTilt};
    match effect {
        Effect::ComOffset => {
            s.effects.com_offset = Some(ComOffset {
                enabled: true,
                offset: [0.02, 0.01],
            })
        }
        Effect::TableTilt => s.effects.table_tilt = Some(TableTilt::default()),
        Effect::FrictionPatch => {
            s.effects.friction_patch = Some(FrictionPatch {
                enabled: true,
                mu: 0.5,
                region: Region {
                    shape: RegionShape::Disc,
                    centre: [0.5, 0.1],
                    radius: 0.1,
                    ..Region::default()
                },
            })
        }
        Effect::PusherFriction => s.effects.pusher_friction = Some(PusherFriction::default()),
        // a pad 2.4 cm wide whose face looks along world x, as launch_scripts/scenarios/
        // push_flat_pusher.toml
        Effect::FlatPusher => {
            s.pusher.pad_half_width = 0.012;
            s.pusher.pad_yaw = 0.0;
        }
        _ => {}
    }
}
