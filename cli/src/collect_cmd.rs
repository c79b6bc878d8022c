//! `dynlab collect push|car`: headless data collection into bags, far faster than real time.
//!
//! Episodes come from the simulator's exploration policies (`dynlab_sim::PushExplorer`,
//! `CarExplorer`), generated in parallel; episode `i` always uses the seed derived from
//! `--seed` and `i`, so the bag is byte-identical for a given seed whatever `--threads` is.
//! Episodes are laid end to end on one simulated time line starting at 0, one second apart
//! (the gap splits them into separate trajectories for the offline tools). Messages are written
//! by `dynlab_simbridge::SimBagWriter`, the same code that defines what `sim_node` and
//! `explorer` publish, so a collected bag and a bag recorded over DDS hold the same topics,
//! types, frames and offered QoS.
//!
//! With `--actions FILE` no explorer runs: the given actions (JSON lines, `{"location": p,
//! "angle": φ, "length": ℓ}` or `{"steering": δ, "throttle": d}`) are replayed from the
//! scenario's start exactly as `sim_node` executes them in lock-step mode, for comparing a run
//! over DDS with a headless one.

use std::io::{BufRead, IsTerminal};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use dynlab_bag::{BagSummary, Compression, WriterOptions};
use dynlab_sim::episode::Episode;
use dynlab_sim::{
    CarExplorer, CarInput, CarScenario, PushAction, PushExplorer, PushScenario, Record, Sample,
    car_episode, concatenate, push_episode,
};
use dynlab_simbridge::engine::{Emit, EngineConfig, Mode, SimEngine};
use dynlab_simbridge::messages::{
    SimBagWriter, SimWorld, car_cmd_msg, car_input_from_msg, push_action_from_msg, push_action_msg,
};

/// Which world to collect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WorldArg {
    /// Planar pushing: /push/block_pose, /push/action.
    Push,
    /// RC car: /car/pose, /car/cmd, /car/odom.
    Car,
}

/// Chunk compression of the bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CompressionArg {
    /// zstd chunks (default; as rosbag2's zstd presets).
    Zstd,
    /// Uncompressed chunks.
    None,
}

/// `dynlab collect …`
#[derive(Debug, Args)]
pub struct CollectArgs {
    /// The world.
    #[arg(value_enum)]
    world: WorldArg,
    /// Scenario file (TOML, see sim/README.md); default: Tu & Lin's free-space scene or the
    /// nominal car on a 3 × 3 m floor.
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// Number of episodes (push: 10 pushes each by default; car: 30 s each by default).
    #[arg(long, value_name = "N", required_unless_present = "actions")]
    episodes: Option<u64>,
    /// Master seed: episode i uses a seed derived from it and i. With --actions: the noise seed.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// The bag directory to create (must not exist or be empty).
    #[arg(long, value_name = "BAG")]
    out: PathBuf,
    /// Worker threads (the output does not depend on it); default: all cores.
    #[arg(long, value_name = "T")]
    threads: Option<usize>,
    /// Explorer settings (TOML with the fields of PushExplorer or CarExplorer, e.g.
    /// `pushes_per_episode = 10` or `duration = 30.0`).
    #[arg(long, value_name = "FILE")]
    explore: Option<PathBuf>,
    /// Also write /clock at every pose stamp (off: stamps and log times are simulation time
    /// already, and `ros2 bag play --clock` publishes /clock from them).
    #[arg(long)]
    clock: bool,
    /// Also write /tf (the measured pose as table → block or world → car, at every pose) and
    /// /tf_static (once), as sim_node publishes them.
    #[arg(long)]
    tf: bool,
    /// Replay these actions (JSON lines) from the scenario start, as sim_node in lock-step mode,
    /// instead of exploring.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["episodes", "explore"])]
    actions: Option<PathBuf>,
    /// With --actions: pose (and odometry) rate (Hz), as sim_node's `pose_rate`.
    #[arg(long, default_value_t = 100.0)]
    pose_rate: f64,
    /// With --actions, car: simulation time each command is held (s), as sim_node's
    /// `lockstep_period`.
    #[arg(long, default_value_t = 0.02)]
    lockstep_period: f64,
    /// Chunk compression.
    #[arg(long, value_enum, default_value_t = CompressionArg::Zstd)]
    compression: CompressionArg,
    /// Car: drive the racer on the scenario's track instead of exploring (on-policy racing
    /// data): TOML with the fields of `dynlab_control::racing::OnPolicySettings` (every key
    /// optional, e.g. `speed_range = [1.5, 2.5]`, `steering_noise = 0.05`, `[racer]`).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["explore", "actions"])]
    race: Option<PathBuf>,
    /// With --race: the racer's model.
    #[arg(long, value_enum, default_value_t = RaceModelArg::Physics, requires = "race")]
    race_model: RaceModelArg,
    /// Time between episodes on the bag's time line (s). The offline tools split trajectories
    /// at gaps over 5 pose intervals: with one pose per push (`pose_rate = 0.5`) use ≥ 20.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    episode_gap: f64,
}

/// The model inside the on-policy racer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RaceModelArg {
    /// The simulator's bicycle model with the scenario's car parameters and exact Jacobians
    /// (fast; no friction ellipse, no hidden effects).
    Physics,
    /// The simulator itself, with finite-difference Jacobians (exact, ≈ 4–5× slower).
    Simulator,
}

enum Scenario {
    Push(PushScenario),
    Car(CarScenario),
}

fn load_scenario(world: WorldArg, path: Option<&Path>) -> anyhow::Result<Scenario> {
    Ok(match (world, path) {
        (WorldArg::Push, None) => Scenario::Push(PushScenario::free()),
        (WorldArg::Car, None) => Scenario::Car(CarScenario::floor()),
        (WorldArg::Push, Some(p)) => Scenario::Push(
            PushScenario::from_file(p).context("bad scenario file: fix the key named above")?,
        ),
        (WorldArg::Car, Some(p)) => Scenario::Car(
            CarScenario::from_file(p).context("bad scenario file: fix the key named above")?,
        ),
    })
}

fn load_explorer<T: serde::de::DeserializeOwned + Default>(
    path: Option<&Path>,
) -> anyhow::Result<T> {
    let Some(path) = path else {
        return Ok(T::default());
    };
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read explorer file {}", path.display()))?;
    toml::from_str(&text).map_err(|e| {
        anyhow::anyhow!(
            "explorer file {}: {} (every key is optional; see the PushExplorer / CarExplorer docs)",
            path.display(),
            e.to_string().trim()
        )
    })
}

/// Runs `dynlab collect`.
pub fn run(args: CollectArgs) -> anyhow::Result<()> {
    let scenario = load_scenario(args.world, args.scenario.as_deref())?;
    let options = WriterOptions {
        compression: match args.compression {
            CompressionArg::Zstd => Compression::Zstd,
            CompressionArg::None => Compression::None,
        },
        ..WriterOptions::default()
    };
    let world = match args.world {
        WorldArg::Push => SimWorld::Push,
        WorldArg::Car => SimWorld::Car,
    };
    let started = Instant::now();
    if let Some(actions) = &args.actions {
        let summary = replay(&args, &scenario, actions, world, options)?;
        print_summary(&summary, None, started);
        return Ok(());
    }
    if args.race.is_some() && args.world != WorldArg::Car {
        bail!("--race drives the car racer: use `dynlab collect car --race FILE`");
    }
    let count = args.episodes.unwrap_or(0);
    if count == 0 {
        bail!("--episodes must be at least 1");
    }
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let done = AtomicU64::new(0);
    let progress = Mutex::new(());
    // A live line on a terminal; in a log, a line at every tenth of the episodes.
    let terminal = std::io::stderr().is_terminal();
    let tick = |i: u64| {
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Ok(_guard) = progress.lock() {
            if terminal {
                eprint!("\rcollect {}: episode {n}/{count} (#{i})    ", world.name());
            } else if n == count || n.is_multiple_of(count.div_ceil(10)) {
                eprintln!("collect {}: {n}/{count} episodes", world.name());
            }
        }
    };
    let episodes: Vec<Episode> = match &scenario {
        Scenario::Push(s) => {
            let explorer: PushExplorer = load_explorer(args.explore.as_deref())?;
            explorer
                .validate(s)
                .context("bad explorer settings (the key is named above)")?;
            dynlab_sim::episode::generate(count, args.seed, threads, |i, seed| {
                let e = push_episode(s, &explorer, seed, i);
                tick(i);
                e
            })?
        }
        Scenario::Car(s) if args.race.is_some() => race_episodes(&args, s, count, threads, &tick)?,
        Scenario::Car(s) => {
            let explorer: CarExplorer = load_explorer(args.explore.as_deref())?;
            explorer
                .validate()
                .context("bad explorer settings (the key is named above)")?;
            dynlab_sim::episode::generate(count, args.seed, threads, |i, seed| {
                let e = car_episode(s, &explorer, seed, i);
                tick(i);
                e
            })?
        }
    };
    if terminal {
        eprintln!();
    }
    let left_table = episodes
        .iter()
        .filter(|e| e.end == dynlab_sim::EpisodeEnd::LeftTable)
        .count();
    if !(args.episode_gap.is_finite() && args.episode_gap >= 0.0) {
        anyhow::bail!(
            "--episode-gap must be a finite number of seconds ≥ 0, got {}",
            args.episode_gap
        );
    }
    let gap_ns = (args.episode_gap * 1e9).round() as u64;
    let samples = concatenate(&episodes, 0, gap_ns);
    let summary = write_bag(&args, &scenario, world, options, &samples)?;
    print_summary(&summary, Some((count, left_table)), started);
    Ok(())
}

/// On-policy racing episodes (`--race`): the racer on the scenario's track.
fn race_episodes(
    args: &CollectArgs,
    scenario: &CarScenario,
    count: u64,
    threads: usize,
    tick: &(dyn Fn(u64) + Sync),
) -> anyhow::Result<Vec<Episode>> {
    use dynlab_control::racing::{CarDynamics, OnPolicySettings, SimCar, racing_episode};
    let mut settings: OnPolicySettings = match args.race.as_deref() {
        None => OnPolicySettings::default(),
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read --race file {}", path.display()))?;
            toml::from_str(&text).map_err(|e| {
                anyhow::anyhow!(
                    "--race file {}: {} (every key is optional; see OnPolicySettings and, under [racer], RacerSettings)",
                    path.display(),
                    e.to_string().trim()
                )
            })?
        }
    };
    settings.racer.limits.steering_max = scenario.car.steering_max;
    settings.racer.limits.throttle_min = scenario.car.throttle_min;
    settings.racer.limits.throttle_max = scenario.car.throttle_max;
    settings
        .validate()
        .context("bad --race settings (the key is named above)")?;
    let track = scenario.track_data.clone().context(
        "--race needs a scenario with a track (e.g. launch_scripts/scenarios/car_track.toml)",
    )?;
    let dt = 0.01;
    let physics;
    let sim;
    let model: &dyn CarDynamics = match args.race_model {
        RaceModelArg::Physics => {
            physics = dynlab_control::racing::true_car_model(&scenario.car, dt)?;
            &physics
        }
        RaceModelArg::Simulator => {
            sim = SimCar::new(scenario, dt)?;
            &sim
        }
    };
    Ok(dynlab_sim::episode::generate(
        count,
        args.seed,
        threads,
        |i, seed| {
            let e = racing_episode(model, scenario, &track, &settings, seed, i).map_err(|e| {
                dynlab_sim::SimError::Input {
                    what: "racing episode",
                    message: e.to_string(),
                }
            });
            tick(i);
            e
        },
    )?)
}

fn write_bag(
    args: &CollectArgs,
    scenario: &Scenario,
    world: SimWorld,
    options: WriterOptions,
    samples: &[Sample],
) -> anyhow::Result<BagSummary> {
    let out = &args.out;
    let mut w = SimBagWriter::create(out, world, args.clock, options)
        .with_context(|| format!("creating bag {}", out.display()))?;
    if args.tf {
        let car = match scenario {
            Scenario::Car(s) => s.car.clone(),
            Scenario::Push(_) => Default::default(),
        };
        w = w.with_tf(&car)?;
    }
    for s in samples {
        w.write(s)?;
    }
    Ok(w.finish()?)
}

fn print_summary(summary: &BagSummary, episodes: Option<(u64, usize)>, started: Instant) {
    let wall = started.elapsed().as_secs_f64();
    let sim = (summary.end_ns.saturating_sub(summary.start_ns)) as f64 * 1e-9;
    if let Some((n, left)) = episodes {
        eprint!("collected {n} episodes");
        if left > 0 {
            eprint!(" ({left} ended early: the block left the table)");
        }
        eprintln!();
    }
    eprintln!(
        "bag {}: {} messages, {:.1} s simulated in {:.2} s ({:.0}× real time), {:.2} MB",
        summary.dir.display(),
        summary.message_count,
        sim,
        wall,
        sim / wall.max(1e-9),
        summary.file_bytes as f64 / 1e6
    );
    for (name, ty, n) in &summary.topics {
        eprintln!("  {name} [{ty}]: {n}");
    }
}

/// Reads JSON lines of `T`; blank lines and lines starting with `#` are skipped.
fn read_actions<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<Vec<T>> {
    let file = std::fs::File::open(path)
        .with_context(|| format!("cannot open actions file {}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let line = line.with_context(|| format!("reading {}", path.display()))?;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        out.push(
            serde_json::from_str(t)
                .with_context(|| format!("{} line {}: not an action", path.display(), i + 1))?,
        );
    }
    Ok(out)
}

fn replay(
    args: &CollectArgs,
    scenario: &Scenario,
    actions: &Path,
    world: SimWorld,
    options: WriterOptions,
) -> anyhow::Result<BagSummary> {
    let cfg = EngineConfig {
        mode: Mode::LockStep,
        pose_rate: args.pose_rate,
        lockstep_period: args.lockstep_period,
        seed: args.seed,
        ..EngineConfig::default()
    };
    let mut engine = match scenario {
        Scenario::Push(s) => SimEngine::push(s, cfg)?,
        Scenario::Car(s) => SimEngine::car(s, cfg)?,
    };
    let mut samples = Vec::new();
    let mut emits = Vec::new();
    engine.start(&mut emits);
    let to_samples = |emits: &mut Vec<Emit>, samples: &mut Vec<Sample>| {
        for e in emits.drain(..) {
            match e {
                Emit::Pose { t_ns, pose } => samples.push(Sample {
                    t_ns,
                    record: match world {
                        SimWorld::Push => Record::BlockPose(pose),
                        SimWorld::Car => Record::CarPose(pose),
                    },
                }),
                Emit::Odom { t_ns, state } => samples.push(Sample {
                    t_ns,
                    record: Record::CarOdom(state),
                }),
                _ => {}
            }
        }
    };
    to_samples(&mut emits, &mut samples);
    match world {
        SimWorld::Push => {
            for (i, given) in read_actions::<PushAction>(actions)?.into_iter().enumerate() {
                let t = engine.time_ns();
                let (a, issues) = push_action_from_msg(&push_action_msg(t, given))
                    .map_err(|e| anyhow::anyhow!("action {}: {e}", i + 1))?;
                for issue in issues {
                    eprintln!("warning: action {}: {issue}", i + 1);
                }
                samples.push(Sample {
                    t_ns: t,
                    record: Record::PushAction(given),
                });
                engine.push_action(a, &mut emits);
                engine.run_until_idle(&mut emits)?;
                to_samples(&mut emits, &mut samples);
            }
        }
        SimWorld::Car => {
            let car = engine
                .car_params()
                .cloned()
                .context("car engine without car parameters")?;
            for (i, given) in read_actions::<CarInput>(actions)?.into_iter().enumerate() {
                let t = engine.time_ns();
                let (u, issues) = car_input_from_msg(&car_cmd_msg(t, given), &car)
                    .map_err(|e| anyhow::anyhow!("command {}: {e}", i + 1))?;
                for issue in issues {
                    eprintln!("warning: command {}: {issue}", i + 1);
                }
                samples.push(Sample {
                    t_ns: t,
                    record: Record::CarCmd(given),
                });
                engine.car_command(u, &mut emits);
                engine.run_until_idle(&mut emits)?;
                to_samples(&mut emits, &mut samples);
            }
        }
    }
    write_bag(args, scenario, world, options, &samples)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: CollectArgs,
    }

    fn collect(args: &[&str]) -> anyhow::Result<()> {
        let cli = Cli::try_parse_from(std::iter::once("collect").chain(args.iter().copied()))?;
        run(cli.args)
    }

    fn bytes(dir: &Path) -> Vec<u8> {
        let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        std::fs::read(dir.join(format!("{name}_0.mcap"))).unwrap()
    }

    #[test]
    fn same_seed_same_bytes_on_one_and_two_threads() {
        let tmp = tempfile::tempdir().unwrap();
        let explore = tmp.path().join("explore.toml");
        std::fs::write(&explore, "duration = 2.0\n").unwrap();
        for (world, extra) in [("push", None), ("car", Some(&explore))] {
            let mut dirs = Vec::new();
            for (threads, seed) in [("1", "4"), ("2", "4"), ("2", "5")] {
                let out = tmp
                    .path()
                    .join(format!("{world}{threads}{seed}"))
                    .join("bag");
                let out_s = out.to_str().unwrap().to_string();
                let mut args = vec![
                    world,
                    "--episodes",
                    "3",
                    "--seed",
                    seed,
                    "--threads",
                    threads,
                    "--out",
                    &out_s,
                ];
                let e = extra.map(|p| p.to_str().unwrap().to_string());
                if let Some(e) = &e {
                    args.extend(["--explore", e.as_str()]);
                }
                collect(&args).unwrap();
                dirs.push(out);
            }
            assert!(bytes(&dirs[0]).len() > 1000);
            assert_eq!(
                bytes(&dirs[0]),
                bytes(&dirs[1]),
                "{world}: threads changed the bag"
            );
            assert_ne!(
                bytes(&dirs[0]),
                bytes(&dirs[2]),
                "{world}: the seed had no effect"
            );
        }
    }

    #[test]
    fn on_policy_racing_bags_load_for_training_with_the_car_topics_and_rates() {
        let tmp = tempfile::tempdir().unwrap();
        let race = tmp.path().join("race.toml");
        std::fs::write(&race, "duration = 1.0\nspeed_range = [1.8, 2.2]\n").unwrap();
        let out = tmp.path().join("bag");
        let scenario = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../launch_scripts/scenarios/car_track.toml"
        );
        collect(&[
            "car",
            "--scenario",
            scenario,
            "--race",
            race.to_str().unwrap(),
            "--episodes",
            "2",
            "--seed",
            "3",
            "--out",
            out.to_str().unwrap(),
        ])
        .unwrap();
        let bag = dynlab_bag::Bag::open(&out).unwrap();
        let cmds = bag
            .read::<dynlab_msgs::ackermann_msgs::AckermannDriveStamped>("/car/cmd")
            .unwrap();
        let poses = bag
            .read::<dynlab_msgs::geometry_msgs::PoseStamped>("/car/pose")
            .unwrap();
        // two 1 s episodes: 101 poses (100 Hz) and 20 commands (20 Hz) each
        assert_eq!((poses.len(), cmds.len()), (202, 40));
        let data = dynlab_learn::dataset::load_bags(
            &[out],
            None,
            &dynlab_learn::dataset::Topics::default(),
            &dynlab_learn::dynamics::data::SavGol::default(),
        )
        .unwrap();
        assert_eq!(data.world, dynlab_learn::World::Car);
        assert_eq!(data.trajectories.len(), 2, "the episode gap splits them");
        assert!((data.pose_dt_s - 0.01).abs() < 1e-9, "{}", data.pose_dt_s);
        // the racer drives: the data is at speed, not a standing car
        let vmax = data
            .trajectories
            .iter()
            .flat_map(|t| t.s.chunks(t.dim_s).map(|s| s[3]))
            .fold(0.0f64, f64::max);
        assert!(vmax > 0.8, "top speed in the data {vmax} m/s");
        // --race needs a track
        let err = collect(&[
            "car",
            "--race",
            race.to_str().unwrap(),
            "--episodes",
            "1",
            "--out",
            tmp.path().join("bag2").to_str().unwrap(),
        ])
        .unwrap_err();
        assert!(format!("{err:#}").contains("track"), "{err:#}");
        std::fs::write(&race, "speed_rang = [1.8, 2.2]\n").unwrap();
        let err = collect(&[
            "car",
            "--scenario",
            scenario,
            "--race",
            race.to_str().unwrap(),
            "--episodes",
            "1",
            "--out",
            tmp.path().join("bag3").to_str().unwrap(),
        ])
        .unwrap_err();
        assert!(format!("{err:#}").contains("speed_rang"), "{err:#}");
    }

    #[test]
    fn bad_explorer_and_scenario_files_name_the_key() {
        let tmp = tempfile::tempdir().unwrap();
        let explore = tmp.path().join("explore.toml");
        std::fs::write(&explore, "pushes_per_episod = 3\n").unwrap();
        let out = tmp.path().join("bag");
        let err = collect(&[
            "push",
            "--episodes",
            "1",
            "--explore",
            explore.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .unwrap_err();
        assert!(format!("{err:#}").contains("pushes_per_episod"), "{err:#}");
        std::fs::write(&explore, "push_period = 0.5\n").unwrap();
        let err = collect(&[
            "push",
            "--episodes",
            "1",
            "--explore",
            explore.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .unwrap_err();
        assert!(
            format!("{err:#}").contains("explore.push_period"),
            "{err:#}"
        );
        let scenario = tmp.path().join("car.toml");
        std::fs::write(&scenario, "[effects.aero_drag]\nc = -1.0\n").unwrap();
        let err = collect(&[
            "car",
            "--episodes",
            "1",
            "--scenario",
            scenario.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .unwrap_err();
        assert!(
            format!("{err:#}").contains("effects.aero_drag.c"),
            "{err:#}"
        );
        assert!(!out.exists());
    }

    #[test]
    fn replayed_actions_are_clamped_like_the_node_does() {
        let tmp = tempfile::tempdir().unwrap();
        let actions = tmp.path().join("a.jsonl");
        std::fs::write(
            &actions,
            "# two pushes\n{\"location\": 2.0, \"angle\": 0.0, \"length\": 0.5}\n\n{\"location\": 0.0, \"angle\": 0.0, \"length\": 0.5}\n",
        )
        .unwrap();
        let out = tmp.path().join("bag");
        collect(&[
            "push",
            "--actions",
            actions.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .unwrap();
        let bag = dynlab_bag::Bag::open(&out).unwrap();
        let acts = bag
            .read::<dynlab_msgs::dynlab_msgs::PushAction>("/push/action")
            .unwrap();
        // the bag keeps the action as sent; the simulator executed the clamped one
        assert_eq!(acts.len(), 2);
        assert_eq!(acts[0].msg.location, 2.0);
        let poses = bag
            .read::<dynlab_msgs::geometry_msgs::PoseStamped>("/push/block_pose")
            .unwrap();
        assert!(poses.len() > 100);
        assert_eq!(poses[0].log_time_ns, 0);
        std::fs::write(&actions, "{\"location\": 0.0}\n").unwrap();
        let err = collect(&[
            "push",
            "--actions",
            actions.to_str().unwrap(),
            "--out",
            tmp.path().join("bag2").to_str().unwrap(),
        ])
        .unwrap_err();
        assert!(format!("{err:#}").contains("line 1"), "{err:#}");
    }
}
