//! `racer --ros-args -p model:=DIR [-p track:=FILE -p optimizer:=sqp|gd …]`: receding-horizon
//! racing over a learned car model (the `dynlab_control::racing` library), as a ROS 2 node.
//!
//! Subscribes to `/car/pose` (`geometry_msgs/PoseStamped`, any rate), estimates the state
//! `[x, y, ψ, vx, vy, ω]` causally from the poses (Savitzky–Golay over the latest poses, as the
//! training pipeline does), re-solves the trajectory optimisation every control period from the
//! newest estimate with the previous solution shifted as warm start, and publishes the first
//! input on `/car/cmd` (`ackermann_msgs/AckermannDriveStamped`: `steering_angle` = δ,
//! `acceleration` = throttle).
//!
//! Parameters: `model` (model directory, required), `track` (track JSON;
//! default `launch_scripts/tracks/default.json`), `optimizer` (`sqp`), `settings` (TOML with
//! RacerSettings fields, optional), `horizon` (20), `hold` (model steps per control step, 5:
//! 20 Hz with a 100 Hz model), `delay` (command delay \[s\], default 0.03 = three model
//! steps, with the solve budget enough for real time: the command computed from the pose stamped `t` is published when the clock reaches
//! `t + delay`, and the optimiser starts from the state predicted at that time under the
//! commands already sent; 0 publishes at once and assumes no delay; see
//! `dynlab_nodes::racer`), `solve_budget` (wall-clock seconds per solve, default 0.015, or the
//! settings file's `solve_budget`; 0: none): when it runs out the optimiser stops and the best
//! plan found is sent (RacerSettings::solve_budget; the periodic log counts these solves),
//! `reference_speed` (m/s, default the settings' 2.0; can be changed
//! while the node runs: `ros2 param set /racer reference_speed 2.5`), `use_sim_time` (follow
//! `/clock`; recommended with `sim_node`), `stale_timeout` (s, default 0.2: twenty pose periods
//! at 100 Hz). The other parameters are read-only.
//!
//! Stale poses: when no pose has arrived for `stale_timeout` seconds of the node's own steady
//! clock (not ROS time: with `use_sim_time` a stopped simulator stops `/clock` too), the racer
//! logs one WARN, forgets its plan and publishes zero throttle with the last steering angle
//! every control period (`dynlab_nodes::racer::held_input` says why not centred). When poses
//! arrive again it logs one INFO, restarts its state estimate from fresh poses only (no
//! velocity from across the gap; a restarted simulator's stamps from 0 are taken as a new
//! clock) and its warm start, and races again with the first command solved from them.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use dynlab_control::racing::{Optimizer, Racer, RacerSettings};
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_nodes::racer::{HoldEvent, Planned, RaceClock, StaleHold};
use dynlab_nodes::{Started, start_node};
use dynlab_ros::qos::{self, History, QosProfile};
use dynlab_ros::{ParamDescriptor, ParamValue, WaitSet};
use dynlab_sim::{CarInput, Track};
use dynlab_simbridge::messages as m;

const POLL: Duration = Duration::from_millis(2);
/// Default wall-clock budget of a solve \[s\]: the 30 ms command delay less room for the pose's
/// way in, the one iteration a budget can be overrun by, and the command's way out.
const DEFAULT_BUDGET: f64 = 0.015;

fn main() -> anyhow::Result<()> {
    let known = [
        "model",
        "track",
        "optimizer",
        "settings",
        "horizon",
        "hold",
        "delay",
        "reference_speed",
        "use_sim_time",
        "stale_timeout",
        "solve_budget",
    ];
    let Started { mut node, shutdown } = start_node("racer", &known)?;
    let p = node.params();
    let model_dir: String = p.get_or("model", String::new())?;
    if model_dir.is_empty() {
        bail!("parameter model is required: -p model:=DIR (a car model from `dynlab train`)");
    }
    let track_path: String = p.get_or("track", "launch_scripts/tracks/default.json".to_string())?;
    let optimizer: String = p.get_or("optimizer", "sqp".to_string())?;
    let settings_path: String = p.get_or("settings", String::new())?;
    let horizon: i64 = p.get_or("horizon", 20)?;
    let hold: i64 = p.get_or("hold", 5)?;
    let delay: f64 = p.get_or("delay", 0.03)?;
    let stale_timeout: f64 = p.get_or("stale_timeout", 0.2)?;
    let (model, meta) = dynlab_learn::load_model(std::path::Path::new(&model_dir), None, None)
        .with_context(|| format!("parameter model: {model_dir}"))?;
    let track =
        Track::from_file(&track_path).with_context(|| format!("parameter track: {track_path}"))?;
    let mut settings: RacerSettings = if settings_path.is_empty() {
        RacerSettings::default()
    } else {
        toml::from_str(&std::fs::read_to_string(&settings_path)?)
            .with_context(|| format!("parameter settings: {settings_path}"))?
    };
    settings.optimizer = optimizer
        .parse::<Optimizer>()
        .with_context(|| "parameter optimizer")?;
    settings.horizon = usize::try_from(horizon).context("parameter horizon must be ≥ 1")?;
    settings.hold = usize::try_from(hold).context("parameter hold must be ≥ 1")?;
    settings.reference_speed = p.get_or("reference_speed", settings.reference_speed)?;
    let budget: f64 = p.get_or(
        "solve_budget",
        if settings.solve_budget.is_finite() {
            settings.solve_budget
        } else {
            DEFAULT_BUDGET
        },
    )?;
    if budget.is_nan() || budget < 0.0 {
        bail!(
            "parameter solve_budget: {budget} s; give a wall-clock budget per solve in seconds \
             (e.g. {DEFAULT_BUDGET}; 0: none)"
        );
    }
    settings.solve_budget = if budget > 0.0 { budget } else { f64::INFINITY };
    let racer = Racer::new(&model, &track, settings)?;
    let dt = dynlab_control::racing::CarDynamics::dt(&model);
    let delay_steps = (delay / dt).round();
    if !(delay.is_finite() && delay >= 0.0 && (delay_steps * dt - delay).abs() < 1e-9) {
        bail!(
            "parameter delay: {delay} s is not a whole number (≥ 0) of model steps of {dt} s; use e.g. 0.03"
        );
    }
    let fit = meta.state_fit();
    if fit != Default::default() {
        tracing::info!("car velocities from {fit}, as in the model's training data");
    }
    let mut rc = RaceClock::new(racer, &model, delay_steps as usize)?.with_state_fit(fit);
    let mut hold = StaleHold::new(stale_timeout, rc.period())?;
    let steady0 = Instant::now();
    tracing::info!(
        "racing {} ({:.2} m) with {} ({:?}, n = {}, {:.0} Hz, command delay {:.0} ms, solve budget {})",
        track_path,
        track.length(),
        model_dir,
        settings.optimizer,
        settings.horizon,
        1.0 / rc.period(),
        1e3 * rc.delay(),
        if settings.solve_budget.is_finite() {
            format!("{:.1} ms", 1e3 * settings.solve_budget)
        } else {
            "none".into()
        }
    );
    node.declare_parameter(
        "reference_speed",
        ParamValue::Double(settings.reference_speed),
        ParamDescriptor::dynamic(
            "reference speed along the centre line [m/s]; a change applies from the next solve",
        )
        .range(0.01, 50.0),
    )?;
    let clock = node.clock()?;
    // best effort as the publisher, but deep: poses that arrive during a long solve are kept
    let pose_qos = QosProfile {
        history: History::KeepLast { depth: 100 },
        ..qos::sensor_data()
    };
    let mut poses = node.create_subscription::<PoseStamped>(m::CAR_POSE_TOPIC, pose_qos)?;
    let publisher = node.create_publisher(m::CAR_CMD_TOPIC, qos::default_profile())?;
    let mut waits = WaitSet::new()?;
    waits.add(&mut poses)?;
    // planned commands waiting for their time, and whether their due time was checked yet
    let mut pending: VecDeque<(Planned, bool)> = VecDeque::new();
    let mut solves = 0u64;
    let tick = dt;
    let mut last_stamp: Option<f64> = None;
    let mut missed = 0u64;
    let mut worst = 0.0f64;
    let mut budget_hits = 0u64;
    // every solve's wall-clock time [s], for the summary at shutdown (20 Hz: 0.3 MB an hour)
    let mut solve_times: Vec<f32> = Vec::new();
    let limits = settings.limits;
    while !shutdown.requested() {
        waits.wait(POLL)?;
        for change in node.poll_parameter_changes() {
            if let ("reference_speed", ParamValue::Double(v)) =
                (change.name.as_str(), &change.value)
            {
                let new = RacerSettings {
                    reference_speed: *v,
                    ..*rc.racer().settings()
                };
                match Racer::new(&model, &track, new) {
                    Ok(r) => {
                        rc.replace_racer(r);
                        tracing::info!("reference speed {v} m/s from the next solve");
                    }
                    Err(e) => tracing::warn!("reference speed {v} m/s not applied: {e}"),
                }
            }
        }
        while let Some(msg) = poses.take()? {
            let t = f64::from(msg.header.stamp.sec) + 1e-9 * f64::from(msg.header.stamp.nanosec);
            let event = hold.on_pose(steady0.elapsed().as_secs_f64(), t);
            match event {
                Some(HoldEvent::Resumed { gap, restarted }) => tracing::info!(
                    "poses back after {gap:.2} s{}: state estimate restarted, racing again after a \
                     full window of fresh poses",
                    if restarted {
                        " with their clock restarted"
                    } else {
                        ""
                    }
                ),
                Some(HoldEvent::Restarted { from, to }) => tracing::info!(
                    "pose stamps went back from {from:.3} s to {to:.3} s: state estimate \
                     restarted on the new clock"
                ),
                _ => {}
            }
            if event.is_some() {
                rc.restart();
                pending.clear();
                last_stamp = None;
            }
            let (x, y, psi) = msg.pose.planar_xy_yaw();
            if let Some(l) = last_stamp
                && t > l + 1.5 * tick
            {
                missed += ((t - l) / tick).round() as u64 - 1;
            }
            last_stamp = Some(last_stamp.map_or(t, |l: f64| l.max(t)));
            rc.on_pose(t, [x, y, psi]);
        }
        let now = clock.now_ns()?;
        let now_s = now as f64 * 1e-9;
        let steady = steady0.elapsed().as_secs_f64();
        if let Some(HoldEvent::Stale { silent }) = hold.check(steady) {
            tracing::warn!(
                "no pose for {silent:.2} s (stale_timeout {stale_timeout} s): holding zero \
                 throttle with the last steering angle until poses return"
            );
            rc.restart();
            pending.clear();
            last_stamp = None;
        }
        if let Some(u) = hold.due(steady) {
            publisher.publish(m::car_cmd_msg(now.max(0) as u64, CarInput::new(u[0], u[1])))?;
        }
        while let Some((p, checked)) = pending.front_mut() {
            let first = !*checked;
            *checked = true;
            if !rc.due(p, now_s, first) {
                break;
            }
            // shrink a hair towards zero so the f32 message stays inside the limits
            let u = p.step.input;
            let u = limits.clamp([u[0] * (1.0 - 1e-6), u[1] * (1.0 - 1e-6)]);
            publisher.publish(m::car_cmd_msg(now.max(0) as u64, CarInput::new(u[0], u[1])))?;
            hold.published(u);
            pending.pop_front();
        }
        // schedule solves on pose stamps (the clock only releases commands): each solve starts
        // from the pose of its own control instant, as in the headless loop
        let Some(stamp) = last_stamp else { continue };
        let t0 = Instant::now();
        let Some(planned) = rc.plan(stamp)? else {
            continue;
        };
        let dt = t0.elapsed().as_secs_f64();
        worst = worst.max(dt);
        solve_times.push(dt as f32);
        solves += 1;
        budget_hits += u64::from(planned.step.deadline);
        if solves.is_multiple_of(100) {
            tracing::info!(
                "{solves} solves, last {:.1} ms ({}), worst {:.1} ms, {budget_hits} stopped at the \
                 solve budget, {} late commands, {} poses missed",
                1e3 * dt,
                planned.step.status,
                1e3 * worst,
                rc.overruns(),
                missed
            );
        }
        pending.push_back((planned, false));
    }
    let quantile = |q: f64| {
        let mut v = solve_times.clone();
        v.sort_by(f32::total_cmp);
        v.get(((q * v.len() as f64).ceil() as usize).saturating_sub(1))
            .map_or(0.0, |&x| 1e3 * f64::from(x))
    };
    tracing::info!(
        "racing summary: {solves} solves, solve p50 {:.1} ms, p99 {:.1} ms, worst {:.1} ms, \
         {budget_hits} stopped at the solve budget, {} late commands, {missed} poses missed",
        quantile(0.5),
        quantile(0.99),
        1e3 * worst,
        rc.overruns(),
    );
    Ok(())
}
