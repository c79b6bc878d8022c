//! Episodes: time-ordered, time-stamped records of one exploration run, and a parallel
//! generator whose output does not depend on the number of threads.
//!
//! Records carry what the robot's topics would carry ([`Record`]); the bag layer converts
//! each to its ROS 2 message (`/push/block_pose`, `/push/action`, `/car/pose`, `/car/cmd`,
//! `/car/odom`) and writes them in order. Stamps are integer nanoseconds from the episode start,
//! computed from step counts (never accumulated floating-point time), so they are exact.
//! At equal stamps the order is: pose, odometry, then the command or action decided after
//! seeing that pose.

use serde::{Deserialize, Serialize};

use crate::car::{CarInput, CarScenario, CarState, CarWorld};
use crate::error::SimError;
use crate::explore::{CarExplorer, PushExplorer};
use crate::geometry::Pose2;
use crate::push::{PushAction, PushScenario, PushWorld};
use crate::rng::{SimRng, derive_seed, stream};

/// What a sample carries.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Record {
    /// Measured block pose (`/push/block_pose`, frame `table`).
    BlockPose(Pose2),
    /// A push (`/push/action`).
    PushAction(PushAction),
    /// Measured car pose (`/car/pose`, frame `world`).
    CarPose(Pose2),
    /// Car command (`/car/cmd`: steering angle and throttle).
    CarCmd(CarInput),
    /// Ground-truth car state (`/car/odom`, simulator only).
    CarOdom(CarState),
}

/// One time-stamped record.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Nanoseconds since the episode start (or since the bag start after [`concatenate`]).
    pub t_ns: u64,
    /// The record.
    pub record: Record,
}

/// Why an episode ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum EpisodeEnd {
    /// All pushes done or the full duration driven.
    Completed,
    /// The block left the table; the episode stopped early.
    LeftTable,
}

/// One episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Episode {
    /// Index in the generated set.
    pub index: u64,
    /// The seed this episode was generated from.
    pub seed: u64,
    /// Records in time order.
    pub samples: Vec<Sample>,
    /// Time of the last sample \[ns\].
    pub duration_ns: u64,
    /// Why it ended.
    pub end: EpisodeEnd,
}

/// The seed of episode `index` under `master_seed`.
pub fn episode_seed(master_seed: u64, index: u64) -> u64 {
    derive_seed(master_seed, stream::EPISODE, index)
}

fn to_ns(seconds: f64) -> u64 {
    (seconds * 1e9).round() as u64
}

/// One pushing episode: measured poses at `pose_rate`, one action every `push_period`, and a
/// final pose after the last push.
pub fn push_episode(
    scenario: &PushScenario,
    explorer: &PushExplorer,
    seed: u64,
    index: u64,
) -> Result<Episode, SimError> {
    explorer.validate(scenario)?;
    let mut world = PushWorld::new(scenario)?;
    let mut explore = SimRng::new(derive_seed(seed, stream::EXPLORE, 0));
    let mut noise = SimRng::new(derive_seed(seed, stream::NOISE, 0));
    world.reset(explorer.sample_start(scenario, &mut explore))?;

    let dt = scenario.sim.dt;
    let dt_ns = to_ns(dt);
    let period_steps = ((explorer.push_period / dt).round() as u64).max(1);
    let pose_every = ((1.0 / (explorer.pose_rate * dt)).round() as u64).max(1);
    let total = period_steps * explorer.pushes_per_episode as u64;
    let mut samples = Vec::new();
    let mut end = EpisodeEnd::Completed;
    let mut step = 0u64;
    loop {
        let at_push = step.is_multiple_of(period_steps);
        if step.is_multiple_of(pose_every) || at_push {
            samples.push(Sample {
                t_ns: step * dt_ns,
                record: Record::BlockPose(world.measure(&mut noise)),
            });
        }
        if step >= total {
            break;
        }
        if at_push {
            let pose = world.block_pose();
            if !scenario.table.contains([pose.x, pose.y]) {
                end = EpisodeEnd::LeftTable;
                break;
            }
            let action = explorer.sample_action(&mut explore);
            world.begin_push(action)?;
            samples.push(Sample {
                t_ns: step * dt_ns,
                record: Record::PushAction(action),
            });
        }
        world.step();
        step += 1;
    }
    Ok(Episode {
        index,
        seed,
        duration_ns: samples.last().map_or(0, |s| s.t_ns),
        samples,
        end,
    })
}

/// One car episode: measured pose and ground-truth odometry at `pose_rate`, commands at
/// `control_rate`, each command held until the next.
pub fn car_episode(
    scenario: &CarScenario,
    explorer: &CarExplorer,
    seed: u64,
    index: u64,
) -> Result<Episode, SimError> {
    explorer.validate()?;
    let mut world = CarWorld::new(scenario)?;
    let mut explore = SimRng::new(derive_seed(seed, stream::EXPLORE, 0));
    let mut noise = SimRng::new(derive_seed(seed, stream::NOISE, 0));
    world.reset(explorer.sample_start(scenario, &mut explore))?;
    let mut driver = explorer.driver(scenario);

    let tick = 1.0 / explorer.pose_rate;
    let tick_ns = to_ns(tick);
    let cmd_every = (explorer.pose_rate / explorer.control_rate).round() as u64;
    let ticks = (explorer.duration * explorer.pose_rate).round() as u64;
    let cmd_dt = cmd_every as f64 * tick;
    let mut samples = Vec::with_capacity(ticks as usize * 3);
    let mut u = CarInput::default();
    for i in 0..=ticks {
        let t_ns = i * tick_ns;
        let state = world.state();
        samples.push(Sample {
            t_ns,
            record: Record::CarPose(world.measure(&mut noise)),
        });
        samples.push(Sample {
            t_ns,
            record: Record::CarOdom(state),
        });
        if i == ticks {
            break;
        }
        if i.is_multiple_of(cmd_every) {
            u = driver.command(&state, cmd_dt, &mut explore);
            samples.push(Sample {
                t_ns,
                record: Record::CarCmd(u),
            });
        }
        world.step(u, tick)?;
    }
    Ok(Episode {
        index,
        seed,
        duration_ns: samples.last().map_or(0, |s| s.t_ns),
        samples,
        end: EpisodeEnd::Completed,
    })
}

/// Runs `make(index, seed)` for `count` episodes on `threads` threads. Episode `i` always gets
/// [`episode_seed`]`(master_seed, i)` and the results come back in index order, so the output
/// is identical for any thread count.
pub fn generate<F>(
    count: u64,
    master_seed: u64,
    threads: usize,
    make: F,
) -> Result<Vec<Episode>, SimError>
where
    F: Fn(u64, u64) -> Result<Episode, SimError> + Sync,
{
    let threads = threads.clamp(1, count.max(1) as usize);
    let mut slots: Vec<Option<Result<Episode, SimError>>> = (0..count).map(|_| None).collect();
    std::thread::scope(|scope| {
        let make = &make;
        let handles: Vec<_> = (0..threads)
            .map(|w| {
                scope.spawn(move || {
                    let mut out = Vec::new();
                    let mut i = w as u64;
                    while i < count {
                        out.push((i, make(i, episode_seed(master_seed, i))));
                        i += threads as u64;
                    }
                    out
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(results) => {
                    for (i, r) in results {
                        slots[i as usize] = Some(r);
                    }
                }
                Err(payload) => std::panic::resume_unwind(payload),
            }
        }
    });
    slots
        .into_iter()
        .enumerate()
        .map(|(i, s)| {
            s.unwrap_or_else(|| {
                Err(SimError::Input {
                    what: "episode generator",
                    message: format!("episode {i} was not generated"),
                })
            })
        })
        .collect()
}

/// `count` pushing episodes from `master_seed` on `threads` threads.
pub fn generate_push_episodes(
    scenario: &PushScenario,
    explorer: &PushExplorer,
    master_seed: u64,
    count: u64,
    threads: usize,
) -> Result<Vec<Episode>, SimError> {
    explorer.validate(scenario)?;
    generate(count, master_seed, threads, |i, seed| {
        push_episode(scenario, explorer, seed, i)
    })
}

/// `count` car episodes from `master_seed` on `threads` threads.
pub fn generate_car_episodes(
    scenario: &CarScenario,
    explorer: &CarExplorer,
    master_seed: u64,
    count: u64,
    threads: usize,
) -> Result<Vec<Episode>, SimError> {
    explorer.validate()?;
    generate(count, master_seed, threads, |i, seed| {
        car_episode(scenario, explorer, seed, i)
    })
}

/// Lays episodes end to end on one time line: episode `k` starts `gap_ns` after the previous
/// one's last sample, the first at `start_ns`.
pub fn concatenate(episodes: &[Episode], start_ns: u64, gap_ns: u64) -> Vec<Sample> {
    let mut out = Vec::with_capacity(episodes.iter().map(|e| e.samples.len()).sum());
    let mut offset = start_ns;
    for e in episodes {
        out.extend(e.samples.iter().map(|s| Sample {
            t_ns: s.t_ns + offset,
            record: s.record,
        }));
        offset += e.duration_ns + gap_ns;
    }
    out
}
