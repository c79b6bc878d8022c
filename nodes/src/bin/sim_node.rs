//! `sim_node [--ros-args -p world:=car -p scenario:=FILE … | --params-file FILE]`: the pushing or
//! car simulator as a ROS 2 node, publishing like a real robot.
//!
//! Publishes `/push/block_pose` or `/car/pose` (`geometry_msgs/PoseStamped`, frame `table` /
//! `world`, measured: with the scenario's mocap-like noise), `/car/odom` (`nav_msgs/Odometry`,
//! ground-truth pose and body-frame velocities — simulator only, a real car has no such topic)
//! `/clock` (simulation time, from 0, at every pose), `/tf` (`tf2_msgs/TFMessage`: the measured
//! pose as `table` → `block` or `world` → `car`, at every pose, reliable like tf2's broadcaster)
//! and `/tf_static` (once, latched: `world` → `table`, or `car` → `car/front_axle` and
//! `car/rear_axle`; see `dynlab_simbridge::messages`); takes `/push/action`
//! (`dynlab_msgs/PushAction`) or `/car/cmd` (`ackermann_msgs/AckermannDriveStamped`:
//! `steering_angle` = δ, `acceleration` = throttle). Every topic can be remapped
//! (`-r /car/pose:=/mocap/car/pose`).
//!
//! Parameters (`-p name:=value` or a `--params-file` YAML with `sim_node: ros__parameters:`):
//!
//! | name | default | meaning |
//! |---|---|---|
//! | `world` | `push` | `push` or `car` |
//! | `scenario` | built-in | scenario TOML file (see sim/README.md); default Tu & Lin's free scene / the nominal car on a 3 × 3 m floor |
//! | `mode` | `realtime` | `realtime` (paced at `rate` × real time) or `lockstep` (advances only to execute commands; see `dynlab_simbridge::engine`) |
//! | `rate` | 1.0 | real-time factor in `realtime` mode (10 = ten times faster than real time) |
//! | `pose_rate` | 100.0 | pose, odometry and `/clock` rate in simulation time \[Hz\] |
//! | `cmd_timeout` | 0.5 | car: zero command after this long without `/car/cmd` [s, simulation time] |
//! | `lockstep_period` | 0.02 | car, `lockstep`: simulation time each command is held \[s\] |
//! | `seed` | scenario's `seed` | measurement-noise seed |
//! | `pose_qos` | `sensor_data` | QoS of pose and odometry: `sensor_data` (best effort, as a mocap driver) or `reliable` (every pose arrives: tests, lock-step control) |
//!
//! Bad input is never fatal: a command with a NaN or infinite field is ignored and a field out of
//! range is clamped, each with a warning naming the field. SIGINT/SIGTERM stop the node cleanly.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use dynlab_msgs::ackermann_msgs::AckermannDriveStamped;
use dynlab_msgs::dynlab_msgs::PushAction as PushActionMsg;
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_msgs::nav_msgs::Odometry;
use dynlab_msgs::rosgraph_msgs::Clock as ClockMsg;
use dynlab_msgs::tf2_msgs::TFMessage;
use dynlab_nodes::{Started, start_node};
use dynlab_ros::qos::{self, History, QosProfile};
use dynlab_ros::{Publisher, Subscription, WaitSet};
use dynlab_sim::{CarScenario, PushScenario};
use dynlab_simbridge::engine::{Emit, EngineConfig, Mode, SimEngine};
use dynlab_simbridge::messages::{
    self as m, InputIssue, SimWorld, car_input_from_msg, push_action_from_msg,
};

/// Longest wait between checks of the shutdown flag and the command subscription.
const MAX_WAIT: Duration = Duration::from_millis(50);
/// Lock-step: most steps between checks of the subscription and the shutdown flag.
const LOCKSTEP_BATCH: usize = 2_000;
/// Real time: when the simulation falls this far behind the wall clock, it stops catching up.
const MAX_LAG: Duration = Duration::from_millis(500);

const KNOWN_PARAMS: &[&str] = &[
    "world",
    "scenario",
    "mode",
    "rate",
    "pose_rate",
    "cmd_timeout",
    "lockstep_period",
    "seed",
    "pose_qos",
    "use_sim_time",
];

struct Publishers {
    world: SimWorld,
    pose: Publisher<PoseStamped>,
    odom: Option<Publisher<Odometry>>,
    clock: Publisher<ClockMsg>,
    tf: Publisher<TFMessage>,
}

impl Publishers {
    fn publish(&self, emits: &mut Vec<Emit>) -> anyhow::Result<()> {
        for e in emits.drain(..) {
            match e {
                Emit::Pose { t_ns, pose } => {
                    self.clock.publish(m::clock_msg(t_ns))?;
                    self.pose.publish(match self.world {
                        SimWorld::Push => m::block_pose_msg(t_ns, pose),
                        SimWorld::Car => m::car_pose_msg(t_ns, pose),
                    })?;
                    self.tf.publish(m::tf_msg(self.world, t_ns, pose))?;
                }
                Emit::Odom { t_ns, state } => {
                    if let Some(o) = &self.odom {
                        o.publish(m::car_odom_msg(t_ns, &state))?;
                    }
                }
                Emit::PushStarted { t_ns, action } => tracing::debug!(
                    t = t_ns as f64 * 1e-9,
                    "push p = {:.3}, φ = {:.3}, ℓ = {:.3}",
                    action.location,
                    action.angle,
                    action.length
                ),
                Emit::PushDone {
                    t_ns,
                    pose,
                    contact_made,
                } => tracing::debug!(
                    t = t_ns as f64 * 1e-9,
                    contact_made,
                    "push done, block at ({:.4}, {:.4}, {:.4})",
                    pose.x,
                    pose.y,
                    pose.theta
                ),
                Emit::CommandTimedOut { t_ns } => tracing::warn!(
                    t = t_ns as f64 * 1e-9,
                    "no /car/cmd for longer than cmd_timeout: holding the zero command"
                ),
                Emit::Dropped { t_ns } => tracing::warn!(
                    t = t_ns as f64 * 1e-9,
                    "command queue full: a command was dropped (send commands no faster than they execute)"
                ),
            }
        }
        Ok(())
    }
}

enum Commands {
    Push(Subscription<PushActionMsg>),
    Car(Subscription<AckermannDriveStamped>),
}

fn warn_issues(topic: &str, issues: &[InputIssue]) {
    for i in issues {
        tracing::warn!("{topic}: {i}");
    }
}

/// Feeds every waiting command to the engine.
fn take_commands(
    commands: &Commands,
    engine: &mut SimEngine,
    emits: &mut Vec<Emit>,
) -> anyhow::Result<()> {
    match commands {
        Commands::Push(sub) => {
            while let Some(msg) = sub.take()? {
                match push_action_from_msg(&msg) {
                    Ok((a, issues)) => {
                        warn_issues(sub.topic(), &issues);
                        engine.push_action(a, emits);
                    }
                    Err(e) => tracing::warn!("{}: {e}", sub.topic()),
                }
            }
        }
        Commands::Car(sub) => {
            let car = engine.car_params().cloned().unwrap_or_default();
            while let Some(msg) = sub.take()? {
                match car_input_from_msg(&msg, &car) {
                    Ok((u, issues)) => {
                        warn_issues(sub.topic(), &issues);
                        engine.car_command(u, emits);
                    }
                    Err(e) => tracing::warn!("{}: {e}", sub.topic()),
                }
            }
        }
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let Started { mut node, shutdown } = start_node("sim_node", KNOWN_PARAMS)?;
    let p = node.params();
    if p.get_or("use_sim_time", false)? {
        tracing::warn!("use_sim_time is ignored: sim_node is the source of /clock");
    }
    let world_name: String = p.get_or("world", "push".to_string())?;
    let world = SimWorld::parse(&world_name).with_context(|| {
        format!("parameter world: `{world_name}` is not a world; use push or car")
    })?;
    let mode_name: String = p.get_or("mode", "realtime".to_string())?;
    let mode = Mode::parse(&mode_name).with_context(|| {
        format!("parameter mode: `{mode_name}` is not a mode; use realtime or lockstep")
    })?;
    let rate: f64 = p.get_or("rate", 1.0)?;
    if !(rate.is_finite() && rate > 0.0) {
        bail!("parameter rate: the real-time factor must be a positive number, got {rate}");
    }
    let scenario_path: String = p.get_or("scenario", String::new())?;
    let qos_name: String = p.get_or("pose_qos", "sensor_data".to_string())?;
    let pose_qos: QosProfile = match qos_name.as_str() {
        "sensor_data" => qos::sensor_data(),
        // Deep history: a lock-step burst of poses must not overwrite unacknowledged ones.
        "reliable" | "default" => QosProfile {
            history: History::KeepLast { depth: 10_000 },
            ..qos::default_profile()
        },
        other => bail!("parameter pose_qos: `{other}` is not a QoS; use sensor_data or reliable"),
    };
    let mut cfg = EngineConfig {
        mode,
        pose_rate: p.get_or("pose_rate", 100.0)?,
        cmd_timeout: p.get_or("cmd_timeout", 0.5)?,
        lockstep_period: p.get_or("lockstep_period", 0.02)?,
        seed: 0,
    };
    let seed: Option<u64> = p.get("seed")?;
    let mut engine = match world {
        SimWorld::Push => {
            let s = if scenario_path.is_empty() {
                PushScenario::free()
            } else {
                PushScenario::from_file(&scenario_path)
                    .with_context(|| format!("parameter scenario: {scenario_path}"))?
            };
            cfg.seed = seed.unwrap_or(s.seed);
            SimEngine::push(&s, cfg)?
        }
        SimWorld::Car => {
            let s = if scenario_path.is_empty() {
                CarScenario::floor()
            } else {
                CarScenario::from_file(&scenario_path)
                    .with_context(|| format!("parameter scenario: {scenario_path}"))?
            };
            cfg.seed = seed.unwrap_or(s.seed);
            SimEngine::car(&s, cfg)?
        }
    };

    let pubs = Publishers {
        world,
        pose: node.create_publisher(world.pose_topic(), pose_qos.clone())?,
        odom: match world {
            SimWorld::Car => Some(node.create_publisher(m::CAR_ODOM_TOPIC, pose_qos.clone())?),
            SimWorld::Push => None,
        },
        clock: node.create_publisher(m::CLOCK_TOPIC, qos::clock())?,
        // tf2's broadcaster QoS: reliable, keep last 100
        tf: node.create_publisher(
            m::TF_TOPIC,
            QosProfile {
                history: History::KeepLast { depth: 100 },
                ..qos::default_profile()
            },
        )?,
    };
    // Fixed frames, once: latched (transient local), so late subscribers get them as well.
    let tf_static = node.create_publisher::<TFMessage>(m::TF_STATIC_TOPIC, qos::latched())?;
    let car_params = engine.car_params().cloned().unwrap_or_default();
    tf_static.publish(m::tf_static_msg(world, engine.time_ns(), &car_params))?;
    // Commands: reliable with a deep queue, so a burst of actions is not lost (a best-effort
    // publisher still matches).
    let cmd_qos = QosProfile {
        history: History::KeepLast { depth: 1_000 },
        ..qos::default_profile()
    };
    let mut commands = match world {
        SimWorld::Push => Commands::Push(node.create_subscription(m::PUSH_ACTION_TOPIC, cmd_qos)?),
        SimWorld::Car => Commands::Car(node.create_subscription(m::CAR_CMD_TOPIC, cmd_qos)?),
    };
    let mut waits = WaitSet::new()?;
    match &mut commands {
        Commands::Push(s) => waits.add(s)?,
        Commands::Car(s) => waits.add(s)?,
    };
    tracing::info!(
        node = %node.fully_qualified_name(),
        domain = node.domain_id(),
        "{} world, {}, poses on {} at {} Hz{}",
        world.name(),
        match mode {
            Mode::RealTime => format!("real time × {rate}"),
            Mode::LockStep => "lock-step".to_string(),
        },
        pubs.pose.topic(),
        engine.config().pose_rate,
        if scenario_path.is_empty() { String::new() } else { format!(", scenario {scenario_path}") }
    );

    let mut emits = Vec::new();
    engine.start(&mut emits);
    pubs.publish(&mut emits)?;
    // Real time: simulation time `t` is due at wall time `wall0 + (t - sim0) / rate`.
    let mut wall0 = Instant::now();
    let mut sim0 = engine.time_ns();
    let mut lag_warned = false;
    while !shutdown.requested() {
        take_commands(&commands, &mut engine, &mut emits)?;
        match mode {
            Mode::LockStep => {
                if engine.has_work() {
                    for _ in 0..LOCKSTEP_BATCH {
                        if !engine.advance(&mut emits)? {
                            break;
                        }
                        pubs.publish(&mut emits)?;
                    }
                } else {
                    waits.wait(MAX_WAIT)?;
                }
            }
            Mode::RealTime => {
                let due = |t: u64, wall0: Instant, sim0: u64| {
                    wall0 + Duration::from_secs_f64((t - sim0) as f64 * 1e-9 / rate)
                };
                let now = Instant::now();
                let mut next = due(engine.next_time_ns(), wall0, sim0);
                if now > next + MAX_LAG {
                    if !lag_warned {
                        tracing::warn!(
                            "the simulation cannot keep up with rate {rate}; running as fast as it can"
                        );
                        lag_warned = true;
                    }
                    wall0 = now;
                    sim0 = engine.time_ns();
                    next = due(engine.next_time_ns(), wall0, sim0);
                }
                // Catch up, but check commands and shutdown at least every MAX_WAIT.
                let work_until = Instant::now() + MAX_WAIT;
                while next <= Instant::now() && Instant::now() < work_until {
                    engine.advance(&mut emits)?;
                    pubs.publish(&mut emits)?;
                    next = due(engine.next_time_ns(), wall0, sim0);
                }
                let wait = next.saturating_duration_since(Instant::now()).min(MAX_WAIT);
                if !wait.is_zero() {
                    waits.wait(wait)?;
                }
            }
        }
    }
    tracing::info!(
        "stopped at simulation time {:.3} s",
        engine.time_ns() as f64 * 1e-9
    );
    Ok(())
}
