//! `explorer [--ros-args -p world:=car -p scenario:=FILE -p use_sim_time:=true …]`: the
//! exploration driver — the simulated operator that pushes the block or drives the car while
//! data is recorded over DDS, with the same policies as `dynlab collect`.
//!
//! - `world:=push`: publishes one `/push/action` every `push_period` (uniform over the action
//!   space, as Tu & Lin), `pushes` times (0: until stopped).
//! - `world:=car`: reads the car's state from `/car/odom` (the simulator's ground truth) and
//!   publishes `/car/cmd` at `control_rate`: smooth random steering and throttle with
//!   aggressive phases that break traction, steering home near the floor edges.
//!
//! Parameters: `world` (`push`), `scenario` (the simulator's scenario file: floor, track and car
//! limits), `explore` (TOML with PushExplorer / CarExplorer fields), `seed` (0), `pushes` (0),
//! `subscribers` (1: wait until this many subscriptions — `sim_node`, a recorder — have matched
//! the command topic before the first command, so none is lost), `use_sim_time` (follow
//! `/clock`; recommended with `sim_node`). Messages come from
//! `dynlab_simbridge::messages`, as in `dynlab collect`.

use std::time::Duration;

use anyhow::Context;
use dynlab_msgs::nav_msgs::Odometry;
use dynlab_nodes::{Started, start_node};
use dynlab_ros::{Shutdown, WaitSet, qos};
use dynlab_sim::{CarExplorer, CarScenario, CarState, PushExplorer, PushScenario, SimRng};
use dynlab_simbridge::messages::{self as m, SimWorld};

const POLL: Duration = Duration::from_millis(5);

fn load_explorer<T: serde::de::DeserializeOwned + Default>(path: &str) -> anyhow::Result<T> {
    if path.is_empty() {
        return Ok(T::default());
    }
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("parameter explore: cannot read {path}"))?;
    toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("parameter explore: {path}: {}", e.to_string().trim()))
}

/// Waits until `ready` (discovery has matched the subscribers), then a little longer for the
/// match to complete on both sides; `false` when shutdown was requested first.
fn wait_for(shutdown: &Shutdown, ready: impl Fn() -> bool, topic: &str) -> bool {
    tracing::info!("waiting for subscribers on {topic}");
    while !ready() {
        if shutdown.requested() {
            return false;
        }
        std::thread::sleep(POLL);
    }
    std::thread::sleep(Duration::from_millis(200));
    !shutdown.requested()
}

fn main() -> anyhow::Result<()> {
    let known = [
        "world",
        "scenario",
        "explore",
        "seed",
        "pushes",
        "subscribers",
        "use_sim_time",
    ];
    let Started { mut node, shutdown } = start_node("explorer", &known)?;
    let p = node.params();
    let world_name: String = p.get_or("world", "push".to_string())?;
    let world = SimWorld::parse(&world_name).with_context(|| {
        format!("parameter world: `{world_name}` is not a world; use push or car")
    })?;
    let scenario: String = p.get_or("scenario", String::new())?;
    let explore: String = p.get_or("explore", String::new())?;
    let seed: u64 = p.get_or("seed", 0)?;
    let pushes: u64 = p.get_or("pushes", 0)?;
    let subscribers: usize = p.get_or("subscribers", 1)?;
    let mut rng = SimRng::new(seed);
    let clock = node.clock()?;
    if clock.is_sim() {
        tracing::info!("waiting for /clock");
        while !clock.is_valid()? {
            if shutdown.requested() {
                return Ok(());
            }
            std::thread::sleep(POLL);
        }
    }
    let now = || -> anyhow::Result<u64> { Ok(clock.now_ns()?.max(0) as u64) };

    match world {
        SimWorld::Push => {
            let s = if scenario.is_empty() {
                PushScenario::free()
            } else {
                PushScenario::from_file(&scenario)
                    .with_context(|| format!("parameter scenario: {scenario}"))?
            };
            let explorer: PushExplorer = load_explorer(&explore)?;
            explorer.validate(&s)?;
            let publisher = node.create_publisher(m::PUSH_ACTION_TOPIC, qos::default_profile())?;
            if !wait_for(
                &shutdown,
                || publisher.subscription_count() >= subscribers,
                publisher.topic(),
            ) {
                return Ok(());
            }
            let period = (explorer.push_period * 1e9).round() as u64;
            let mut next = now()?;
            let mut sent = 0u64;
            while !shutdown.requested() && (pushes == 0 || sent < pushes) {
                let t = now()?;
                if t >= next {
                    let a = explorer.sample_action(&mut rng);
                    publisher.publish(m::push_action_msg(t, a))?;
                    tracing::info!(
                        "push {}: p = {:.3}, φ = {:.3}, ℓ = {:.3}",
                        sent + 1,
                        a.location,
                        a.angle,
                        a.length
                    );
                    sent += 1;
                    next = t + period;
                }
                std::thread::sleep(POLL);
            }
        }
        SimWorld::Car => {
            let s = if scenario.is_empty() {
                CarScenario::floor()
            } else {
                CarScenario::from_file(&scenario)
                    .with_context(|| format!("parameter scenario: {scenario}"))?
            };
            let explorer: CarExplorer = load_explorer(&explore)?;
            explorer.validate()?;
            let mut driver = explorer.driver(&s);
            let publisher = node.create_publisher(m::CAR_CMD_TOPIC, qos::default_profile())?;
            if !wait_for(
                &shutdown,
                || publisher.subscription_count() >= subscribers,
                publisher.topic(),
            ) {
                return Ok(());
            }
            let mut odom =
                node.create_subscription::<Odometry>(m::CAR_ODOM_TOPIC, qos::sensor_data())?;
            let mut waits = WaitSet::new()?;
            waits.add(&mut odom)?;
            let period = (1e9 / explorer.control_rate).round() as u64;
            let dt = 1.0 / explorer.control_rate;
            let mut state: Option<CarState> = None;
            let mut next = now()?;
            while !shutdown.requested() {
                waits.wait(POLL)?;
                if let Some(o) = odom.take_latest()? {
                    let (x, y, psi) = o.pose.pose.planar_xy_yaw();
                    state = Some(CarState {
                        x,
                        y,
                        psi,
                        vx: o.twist.twist.linear.x,
                        vy: o.twist.twist.linear.y,
                        omega: o.twist.twist.angular.z,
                    });
                }
                let t = now()?;
                if let Some(st) = &state
                    && t >= next
                {
                    let u = driver.command(st, dt, &mut rng);
                    publisher.publish(m::car_cmd_msg(t, u))?;
                    next = (next + period).max(t);
                }
            }
        }
    }
    Ok(())
}
