//! `mppi_pusher --ros-args -p model:=DIR [-p samples:=1000 …]`: pushes the block to the goal with
//! MPPI over a learned (or physics) model.
//!
//! Subscribes `/push/block_pose` and `/push/goal` (`geometry_msgs/PoseStamped`), publishes
//! `/push/action` (`dynlab_msgs/PushAction`). One action per push: after sending one it waits
//! for a pose stamped `push_wait` later (the push has run and settled), then plans again from
//! that pose. It stops at the goal (resumes on a new goal) and holds off while the pose is stale.
//! The logic is `dynlab_nodes::mppi_pusher`, the controller `dynlab_control::mppi`.
//!
//! | name | default | meaning |
//! |---|---|---|
//! | `model` | required | model directory (`dynlab train --out`) of a pushing model |
//! | `mppi` | none | TOML file with `MppiConfig` keys; the parameters below override it |
//! | `samples`, `horizon`, `lambda`, `seed`, `threads` | `MppiConfig` defaults | K, T, λ, noise seed, rollout threads |
//! | `goal_tolerance` | 0.02 | goal reached within this xy distance (m) ... |
//! | `angle_tolerance` | 0.1 | ... and this heading error (rad) |
//! | `stale_timeout` | 1.0 | no action while the last pose arrived longer ago than this (s, the node's steady clock, also with `use_sim_time`); one WARN on going stale, one INFO when poses return |
//! | `push_wait` | 1.8 | after a push, wait for a pose stamped this much later (s, pose time) |
//! | `obstacle` | none | `"cx,cy,sx,sy[,angle]"`: an obstacle box (m, rad) to avoid, e.g. Tu & Lin's `"0.6,0.2,0.1,0.5"` |
//! | `block_size` | `"0.1,0.1"` | block side lengths (m) for the collision test |
//! | `goal` | none | `"x,y,θ"`: a goal to start with (m, rad); `/push/goal` replaces it |
//!
//! `goal`, `goal_tolerance`, `angle_tolerance` and `lambda` can be changed while the node runs
//! (`ros2 param set /mppi_pusher goal_tolerance 0.05`); the others are read-only.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use dynlab_control::mppi::{Mppi, MppiConfig, PushTask, Rect};
use dynlab_learn::{World, load_model};
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_nodes::mppi_pusher::{Decision, PusherLogic, PusherSettings, parse_goal};
use dynlab_nodes::stale::PoseEvent;
use dynlab_nodes::{Started, start_node};
use dynlab_ros::{ParamChange, ParamDescriptor, ParamValue, WaitSet, qos};
use dynlab_sim::PushAction;
use dynlab_simbridge::messages as m;

const POLL: Duration = Duration::from_millis(10);
const GOAL_TOPIC: &str = "/push/goal";

fn floats(key: &str, text: &str, n: &[usize]) -> anyhow::Result<Vec<f64>> {
    let v: Result<Vec<f64>, _> = text.split(',').map(|s| s.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if n.contains(&v.len()) && v.iter().all(|x| x.is_finite()) => Ok(v),
        _ => bail!("parameter {key}: `{text}` must be {n:?} comma-separated finite numbers"),
    }
}

fn planar(msg: &PoseStamped) -> ([f64; 3], f64) {
    let (x, y, yaw) = msg.pose.planar_xy_yaw();
    ([x, y, yaw], msg.header.stamp.to_nanos() as f64 * 1e-9)
}

fn main() -> anyhow::Result<()> {
    let known = [
        "model",
        "mppi",
        "samples",
        "horizon",
        "lambda",
        "seed",
        "threads",
        "goal_tolerance",
        "angle_tolerance",
        "stale_timeout",
        "push_wait",
        "obstacle",
        "block_size",
        "goal",
        "use_sim_time",
    ];
    let Started { mut node, shutdown } = start_node("mppi_pusher", &known)?;
    let p = node.params();
    let model_dir: String = p.get_or("model", String::new())?;
    if model_dir.is_empty() {
        bail!("parameter model: required; pass -p model:=DIR (a pushing model from dynlab train)");
    }
    let (model, _) = load_model(&PathBuf::from(&model_dir), None, Some(World::Push))
        .with_context(|| format!("parameter model: {model_dir}"))?;
    let mppi_file: String = p.get_or("mppi", String::new())?;
    let mut cfg: MppiConfig = if mppi_file.is_empty() {
        MppiConfig::default()
    } else {
        let text = std::fs::read_to_string(&mppi_file)
            .with_context(|| format!("parameter mppi: cannot read {mppi_file}"))?;
        toml::from_str(&text)
            .map_err(|e| anyhow::anyhow!("parameter mppi: {mppi_file}: {}", e.to_string().trim()))?
    };
    if let Some(v) = p.get::<i64>("samples")? {
        cfg.samples = usize::try_from(v).context("parameter samples: must be ≥ 2")?;
    }
    if let Some(v) = p.get::<i64>("horizon")? {
        cfg.horizon = usize::try_from(v).context("parameter horizon: must be ≥ 1")?;
    }
    if let Some(v) = p.get::<f64>("lambda")? {
        cfg.lambda = v;
    }
    if let Some(v) = p.get::<i64>("seed")? {
        cfg.seed = u64::try_from(v).context("parameter seed: must be ≥ 0")?;
    }
    if let Some(v) = p.get::<i64>("threads")? {
        cfg.threads = usize::try_from(v).context("parameter threads: must be ≥ 1")?;
    }
    cfg.validate()?;
    let settings = PusherSettings {
        goal_tolerance: p.get_or("goal_tolerance", 0.02)?,
        angle_tolerance: p.get_or("angle_tolerance", 0.1)?,
        stale_timeout: p.get_or("stale_timeout", 1.0)?,
        push_wait: p.get_or("push_wait", 1.8)?,
    };
    let block: String = p.get_or("block_size", "0.1,0.1".to_string())?;
    let block = floats("block_size", &block, &[2])?;
    let obstacle: String = p.get_or("obstacle", String::new())?;
    let goal0: String = p.get_or("goal", String::new())?;
    let mut task = PushTask::free([0.0; 3], [0.5 * block[0], 0.5 * block[1]]);
    if !obstacle.is_empty() {
        let o = floats("obstacle", &obstacle, &[4, 5])?;
        let m_ = cfg.obstacle_margin;
        task.obstacles.push(Rect::new(
            [o[0], o[1]],
            o.get(4).copied().unwrap_or(0.0),
            [0.5 * o[2] + m_, 0.5 * o[3] + m_],
        ));
    }
    let mut mppi = Mppi::new(cfg, task)?;

    let poses = node.create_subscription::<PoseStamped>(m::BLOCK_POSE_TOPIC, qos::sensor_data())?;
    let goals = node.create_subscription::<PoseStamped>(GOAL_TOPIC, qos::default_profile())?;
    let actions = node.create_publisher(m::PUSH_ACTION_TOPIC, qos::default_profile())?;
    let mut poses = poses;
    let mut goals = goals;
    let mut waits = WaitSet::new()?;
    waits.add(&mut poses)?;
    waits.add(&mut goals)?;
    tracing::info!(
        node = %node.fully_qualified_name(),
        "MPPI over {} model {model_dir}: K = {}, T = {}, λ = {}",
        model.kind().name(),
        mppi.config().samples,
        mppi.config().horizon,
        mppi.config().lambda
    );
    let wall0 = Instant::now();
    let mut logic = PusherLogic::new(settings)?;
    if !goal0.is_empty() {
        let g = floats("goal", &goal0, &[3])?;
        logic.on_goal([g[0], g[1], g[2]]);
        mppi.set_goal([g[0], g[1], g[2]])?;
    }
    declare_runtime_parameters(&node, logic.settings(), mppi.config(), &goal0)?;
    let mut last = Decision::Idle;
    let mut pushes = 0u64;
    while !shutdown.requested() {
        waits.wait(POLL)?;
        for change in node.poll_parameter_changes() {
            apply_parameter(&change, &mut logic, &mut mppi)?;
        }
        let now = wall0.elapsed().as_secs_f64();
        while let Some(g) = goals.take()? {
            let (goal, _) = planar(&g);
            if goal.iter().all(|v| v.is_finite()) {
                tracing::info!("goal ({:.3}, {:.3}, {:.3})", goal[0], goal[1], goal[2]);
                logic.on_goal(goal);
                mppi.set_goal(goal)?;
                mppi.reset();
                let text = format!("{},{},{}", goal[0], goal[1], goal[2]);
                node.set_parameter("goal", ParamValue::String(text))?;
            } else {
                tracing::warn!("goal with a non-finite field ignored");
            }
        }
        if let Some(msg) = poses.take_latest()? {
            let (pose, stamp) = planar(&msg);
            match logic.on_pose(pose, stamp, now) {
                Some(PoseEvent::Resumed { gap, restarted }) => {
                    tracing::info!(
                        "block pose back after {gap:.2} s{}: pushing again (MPPI warm start reset)",
                        if restarted {
                            " with its clock restarted"
                        } else {
                            ""
                        }
                    );
                    mppi.reset();
                }
                Some(PoseEvent::Restarted { from, to }) => {
                    tracing::info!(
                        "block pose stamps went back from {from:.3} s to {to:.3} s: a new run (MPPI warm start reset)"
                    );
                    mppi.reset();
                }
                _ => {}
            }
        }
        if let Some(PoseEvent::Stale { silent }) = logic.check(now) {
            tracing::warn!(
                "no block pose for {silent:.2} s: holding off (no push) until it returns"
            );
        }
        let d = logic.decide(now);
        match d {
            Decision::Push(pose) => {
                let out = mppi.step(&model, pose)?;
                let a = PushAction::new(out.action[0], out.action[1], out.action[2]).clamped();
                let stamp = (msg_stamp_ns(&logic)).unwrap_or(0);
                actions.publish(m::push_action_msg(stamp, a))?;
                logic.pushed();
                pushes += 1;
                tracing::info!(
                    "push {pushes} from ({:.3}, {:.3}, {:.3}): p = {:.3}, φ = {:.3}, ℓ = {:.3} (best cost {:.4})",
                    pose[0],
                    pose[1],
                    pose[2],
                    a.location,
                    a.angle,
                    a.length,
                    out.cost_min
                );
            }
            Decision::AtGoal if last != Decision::AtGoal => {
                tracing::info!("goal reached after {pushes} pushes");
            }
            _ => {}
        }
        if !matches!(d, Decision::Push(_)) {
            last = d;
        } else {
            last = Decision::Waiting;
        }
    }
    Ok(())
}

/// Offers the parameters that `ros2 param set` can change while the node runs (the others are
/// read-only: restart with `-p name:=value`).
fn declare_runtime_parameters(
    node: &dynlab_ros::Node,
    settings: &PusherSettings,
    cfg: &MppiConfig,
    goal: &str,
) -> anyhow::Result<()> {
    node.declare_parameter_checked(
        "goal",
        ParamValue::String(goal.to_owned()),
        ParamDescriptor::dynamic("goal \"x,y,θ\" (m, m, rad); a message on /push/goal replaces it")
            .constraints("three comma-separated finite numbers"),
        |v| match v {
            ParamValue::String(t) => parse_goal(t).map(|_| ()),
            _ => Ok(()),
        },
    )?;
    node.declare_parameter(
        "goal_tolerance",
        ParamValue::Double(settings.goal_tolerance),
        ParamDescriptor::dynamic("goal reached within this xy distance [m]").range(0.0, 10.0),
    )?;
    // No range for these two: a start value the node accepted (an angle tolerance above π to
    // ignore the heading, any λ that MppiConfig::validate accepts) must stay declarable.
    node.declare_parameter_checked(
        "angle_tolerance",
        ParamValue::Double(settings.angle_tolerance),
        ParamDescriptor::dynamic("... and this heading error [rad]; above π: heading ignored")
            .constraints("finite, ≥ 0"),
        |v| match v {
            ParamValue::Double(a) if !(a.is_finite() && *a >= 0.0) => {
                Err(format!("{a} is not a finite angle ≥ 0 rad"))
            }
            _ => Ok(()),
        },
    )?;
    node.declare_parameter_checked(
        "lambda",
        ParamValue::Double(cfg.lambda),
        ParamDescriptor::dynamic(
            "MPPI temperature λ; a change rebuilds the controller (warm start and noise stream restart from the seed)",
        )
        .constraints("finite, > 0"),
        |v| match v {
            ParamValue::Double(l) if !(l.is_finite() && *l > 0.0) => {
                Err(format!("{l} is not a finite temperature > 0"))
            }
            _ => Ok(()),
        },
    )?;
    Ok(())
}

/// Applies a parameter change accepted by the parameter services (already validated).
fn apply_parameter(
    c: &ParamChange,
    logic: &mut PusherLogic,
    mppi: &mut Mppi,
) -> anyhow::Result<()> {
    match (c.name.as_str(), &c.value) {
        ("goal", ParamValue::String(text)) => {
            let goal = parse_goal(text).map_err(anyhow::Error::msg)?;
            tracing::info!(
                "goal ({:.3}, {:.3}, {:.3}) from the goal parameter",
                goal[0],
                goal[1],
                goal[2]
            );
            logic.on_goal(goal);
            mppi.set_goal(goal)?;
            mppi.reset();
        }
        ("goal_tolerance", ParamValue::Double(v)) => logic.settings_mut().goal_tolerance = *v,
        ("angle_tolerance", ParamValue::Double(v)) => logic.settings_mut().angle_tolerance = *v,
        ("lambda", ParamValue::Double(v)) => {
            let cfg = MppiConfig {
                lambda: *v,
                ..mppi.config().clone()
            };
            *mppi = Mppi::new(cfg, mppi.task().clone())?;
        }
        _ => tracing::warn!("parameter {} = {} has no run-time effect", c.name, c.value),
    }
    Ok(())
}

/// The stamp of the latest pose (the action is stamped with the pose it was planned from).
fn msg_stamp_ns(logic: &PusherLogic) -> Option<u64> {
    logic
        .pose_stamp()
        .map(|s| (s * 1e9).round().max(0.0) as u64)
}
