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
//! 20 Hz with a 100 Hz model), `use_sim_time` (follow `/clock`; recommended with `sim_node`).

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use dynlab_control::racing::{CarStateEstimator, Optimizer, Racer, RacerSettings};
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_nodes::{Started, start_node};
use dynlab_ros::{WaitSet, qos};
use dynlab_sim::{CarInput, Track};
use dynlab_simbridge::messages as m;

const POLL: Duration = Duration::from_millis(2);

fn main() -> anyhow::Result<()> {
    let known = [
        "model",
        "track",
        "optimizer",
        "settings",
        "horizon",
        "hold",
        "use_sim_time",
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
    let (model, _) = dynlab_learn::load_model(std::path::Path::new(&model_dir), None, None)
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
    let mut racer = Racer::new(&model, &track, settings)?;
    let period_ns = (racer.period() * 1e9).round() as i64;
    tracing::info!(
        "racing {} ({:.2} m) with {} ({:?}, n = {}, {:.0} Hz)",
        track_path,
        track.length(),
        model_dir,
        settings.optimizer,
        settings.horizon,
        1e9 / period_ns as f64
    );
    let clock = node.clock()?;
    let mut poses =
        node.create_subscription::<PoseStamped>(m::CAR_POSE_TOPIC, qos::sensor_data())?;
    let publisher = node.create_publisher(m::CAR_CMD_TOPIC, qos::default_profile())?;
    let mut waits = WaitSet::new()?;
    waits.add(&mut poses)?;
    let mut est = CarStateEstimator::default();
    let mut state = None;
    let mut next: Option<i64> = None;
    let mut solves = 0u64;
    let mut worst = 0.0f64;
    while !shutdown.requested() {
        waits.wait(POLL)?;
        while let Some(msg) = poses.take()? {
            let t = f64::from(msg.header.stamp.sec) + 1e-9 * f64::from(msg.header.stamp.nanosec);
            let (x, y, psi) = msg.pose.planar_xy_yaw();
            if let Some(s) = est.push(t, [x, y, psi]) {
                state = Some(s);
            }
        }
        let Some(s) = state else { continue };
        let now = clock.now_ns()?;
        if next.is_some_and(|n| now < n) {
            continue;
        }
        let t0 = Instant::now();
        let r = racer.step(s)?;
        let dt = t0.elapsed().as_secs_f64();
        worst = worst.max(dt);
        solves += 1;
        publisher.publish(m::car_cmd_msg(
            now.max(0) as u64,
            CarInput::new(r.input[0], r.input[1]),
        ))?;
        if solves.is_multiple_of(100) {
            tracing::info!(
                "{solves} solves, last {:.1} ms ({}), worst {:.1} ms",
                1e3 * dt,
                r.status,
                1e3 * worst
            );
        }
        next = Some(match next {
            Some(n) => (n + period_ns).max(now),
            None => now + period_ns,
        });
    }
    Ok(())
}
