//! `model_server --ros-args -p model:=DIR [-p steps:=10] [-r /car/pose:=/mocap/car] …`: a
//! learned model run live against the robot's measurements, for Foxglove or PlotJuggler to
//! overlay prediction and measurement.
//!
//! Subscribes to the measurement and command topics of the model's world (car: `/car/pose`
//! `PoseStamped` + `/car/cmd` `AckermannDriveStamped`; pushing: `/push/block_pose` +
//! `/push/action`), all remappable, and publishes:
//!
//! | topic | type | what |
//! |---|---|---|
//! | `/model/prediction` | `geometry_msgs/msg/PoseStamped` | the one-step prediction, stamped at the predicted time, in the measurement's frame |
//! | `/model/predicted_path` | `nav_msgs/msg/Path` | the k-step prediction with the command held, poses stamped `t + j·dt` |
//! | `/model/error` | `nav_msgs/msg/Odometry` | measured − predicted for the pose the earlier prediction was for: `pose.position.x/y` = x, y error (m), `pose.orientation` = the heading error as a yaw quaternion, `twist.linear.x/y`, `twist.angular.z` = vx, vy, ω error (car); `child_frame_id` = `model_error` |
//!
//! The computation is `dynlab_diagnose::compare::online::OnlinePredictor` (no DDS in it):
//! `dynlab compare --online FILE` replays a bag through the same code. The car's velocities are
//! estimated causally by the Savitzky–Golay fit of the offline pipeline over the last 15 poses.
//! Stale or NaN input is skipped with a warning (rate-limited), never a crash.
//!
//! A model with effects that have a state (`motor_lag`'s filtered throttle `d_f`,
//! `steering_lag`'s wheel angle `delta_w`) gets them from the command stream it receives, as
//! the offline tools rebuild them from a bag: settled at the first command, then advanced one
//! model step per pose under the command held; a pose gap restarts them.
//!
//! Parameters: `model` (model directory, required), `steps` (10), `max_command_age` (s, 0.5),
//! `pose_qos` (`sensor_data` | `reliable`, default `sensor_data`: matches both kinds of
//! publisher).

use std::time::Duration;

use anyhow::{Context, bail};
use dynlab_diagnose::compare::online::{OnlineConfig, OnlinePredictor, PoseOutcome};
use dynlab_learn::{World, load_model};
use dynlab_msgs::ackermann_msgs::AckermannDriveStamped;
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::{Pose, PoseStamped, Quaternion};
use dynlab_msgs::nav_msgs::{Odometry, Path};
use dynlab_msgs::std_msgs::Header;
use dynlab_nodes::{Started, start_node};
use dynlab_ros::{Publisher, QosProfile, WaitSet, qos};

const POLL: Duration = Duration::from_millis(20);

struct Outputs {
    prediction: Publisher<PoseStamped>,
    path: Publisher<Path>,
    error: Publisher<Odometry>,
}

fn stamped(t_ns: i64, frame: &str, s: &[f64]) -> PoseStamped {
    PoseStamped {
        header: Header::new(Time::from_nanos(t_ns), frame),
        pose: Pose::planar(s[0], s[1], s[2]),
    }
}

fn publish(
    out: &Outputs,
    o: &PoseOutcome,
    frame: &str,
    dt_ns: i64,
    world: World,
) -> anyhow::Result<()> {
    if let Some(p) = &o.prediction {
        out.prediction.publish(stamped(p.t_ns, frame, &p.next))?;
        out.path.publish(Path {
            header: Header::new(Time::from_nanos(p.from_ns), frame),
            poses: p
                .path
                .iter()
                .enumerate()
                .map(|(j, s)| stamped(p.from_ns + (j as i64 + 1) * dt_ns, frame, s))
                .collect(),
        })?;
    }
    if let Some(e) = &o.error {
        let mut m = Odometry {
            header: Header::new(Time::from_nanos(e.t_ns), frame),
            child_frame_id: "model_error".into(),
            ..Default::default()
        };
        m.pose.pose.position.x = e.error[0];
        m.pose.pose.position.y = e.error[1];
        m.pose.pose.orientation = Quaternion::from_yaw(e.error[2]);
        if world == World::Car {
            m.twist.twist.linear.x = e.error[3];
            m.twist.twist.linear.y = e.error[4];
            m.twist.twist.angular.z = e.error[5];
        }
        out.error.publish(m)?;
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let known = [
        "model",
        "steps",
        "max_command_age",
        "pose_qos",
        "use_sim_time",
    ];
    let Started { mut node, shutdown } = start_node("model_server", &known)?;
    let p = node.params();
    let model_dir: String = p.get_or("model", String::new())?;
    if model_dir.is_empty() {
        bail!("parameter model: give the model directory (-p model:=out/car_rk4)");
    }
    let steps: i64 = p.get_or("steps", 10)?;
    if steps < 1 {
        bail!("parameter steps: predict at least 1 step, got {steps}");
    }
    let max_age: f64 = p.get_or("max_command_age", 0.5)?;
    let qos_name: String = p.get_or("pose_qos", "sensor_data".to_string())?;
    let pose_qos: QosProfile = match qos_name.as_str() {
        "sensor_data" => qos::sensor_data(),
        "reliable" | "default" => qos::default_profile(),
        other => bail!("parameter pose_qos: `{other}` is not a QoS; use sensor_data or reliable"),
    };
    let (model, meta) = load_model(std::path::Path::new(&model_dir), None, None)
        .with_context(|| format!("parameter model: loading {model_dir}"))?;
    let world = model.world();
    if model.dim_extra() > 0 {
        tracing::info!(
            "effect states {:?} kept from {}",
            model.extra_state_names(),
            world.default_cmd_topic()
        );
    }
    let fit = meta.state_fit();
    if world == World::Car && fit != Default::default() {
        tracing::info!("car velocities from {fit}, as in the model's training data");
    }
    let mut predictor = OnlinePredictor::new(
        model,
        OnlineConfig {
            steps: steps as usize,
            max_command_age_s: max_age,
            savgol: fit,
            ..Default::default()
        },
    )?;
    let dt_ns = predictor.dt_ns();
    let out = Outputs {
        prediction: node.create_publisher("/model/prediction", qos::default_profile())?,
        path: node.create_publisher("/model/predicted_path", qos::default_profile())?,
        error: node.create_publisher("/model/error", qos::default_profile())?,
    };
    let mut poses =
        node.create_subscription::<PoseStamped>(world.default_pose_topic(), pose_qos)?;
    let mut waits = WaitSet::new()?;
    waits.add(&mut poses)?;
    enum Cmds {
        Car(dynlab_ros::Subscription<AckermannDriveStamped>),
        Push(dynlab_ros::Subscription<PushAction>),
    }
    let mut cmds = match world {
        World::Car => {
            Cmds::Car(node.create_subscription(world.default_cmd_topic(), qos::default_profile())?)
        }
        World::Push => {
            Cmds::Push(node.create_subscription(world.default_cmd_topic(), qos::default_profile())?)
        }
    };
    match &mut cmds {
        Cmds::Car(s) => waits.add(s)?,
        Cmds::Push(s) => waits.add(s)?,
    };
    tracing::info!(
        "{} model {model_dir}: {} + {} → /model/prediction, /model/predicted_path, /model/error",
        world,
        poses.topic(),
        match &cmds {
            Cmds::Car(s) => s.topic().to_string(),
            Cmds::Push(s) => s.topic().to_string(),
        }
    );
    let mut warnings = 0u64;
    let mut warn = |w: &str| {
        warnings += 1;
        // the first ten, then every thousandth: a stream of bad input must not flood the log
        if warnings <= 10 || warnings.is_multiple_of(1000) {
            tracing::warn!("{w} ({warnings} warnings so far)");
        }
    };
    while !shutdown.requested() {
        waits.wait(POLL)?;
        // commands first: a pose is predicted with every command stamped at or before it
        loop {
            let c = match &cmds {
                Cmds::Car(s) => s.take()?.map(|m| {
                    (
                        m.header.stamp.to_nanos(),
                        vec![
                            f64::from(m.drive.steering_angle),
                            f64::from(m.drive.acceleration),
                        ],
                    )
                }),
                Cmds::Push(s) => s.take()?.map(|m| {
                    (
                        m.header.stamp.to_nanos(),
                        vec![m.location, m.angle, m.length],
                    )
                }),
            };
            let Some((t, u)) = c else { break };
            if let Some(w) = predictor.on_command(t, u) {
                warn(&w);
            }
        }
        while let Some(m) = poses.take()? {
            let (x, y, yaw) = m.pose.planar_xy_yaw();
            let o = predictor.on_pose(m.header.stamp.to_nanos(), x, y, yaw);
            if let Some(w) = &o.warning {
                warn(w);
            }
            publish(&out, &o, &m.header.frame_id, dt_ns, world)?;
        }
    }
    Ok(())
}
