//! Synthetic bags from known dynamics (the physics models of `dynlab-dynamics`), written with
//! `dynlab_bag::BagWriter` under the topic contract.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use dynlab_bag::{BagWriter, QosProfile, WriterOptions};
use dynlab_dynamics::data::SplitMix64;
use dynlab_dynamics::ode::{Solver, integrate};
use dynlab_dynamics::physics::PhysicsModel;
use dynlab_msgs::ackermann_msgs::{AckermannDrive, AckermannDriveStamped};
use dynlab_msgs::builtin_interfaces::Time;
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::{Pose, PoseStamped};
use dynlab_msgs::std_msgs::Header;

pub fn uniform(rng: &mut SplitMix64, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

fn pose_msg(t_ns: i64, frame: &str, x: f64, y: f64, yaw: f64) -> PoseStamped {
    PoseStamped {
        header: Header::new(Time::from_nanos(t_ns), frame),
        pose: Pose::planar(x, y, yaw),
    }
}

/// Pushing data from the quasi-static pusher–slider: `trajs` trajectories of `pushes` random
/// pushes, 2 s apart, trajectories 60 s apart (the layout of the Tu & Lin bag).
pub fn push_bag(dir: &Path, trajs: usize, pushes: usize, seed: u64) -> PathBuf {
    let path = dir.join(format!("push_{trajs}_{pushes}_{seed}"));
    let model = PhysicsModel::pushing(&[]).unwrap();
    let mut w = BagWriter::create(&path, WriterOptions::default()).unwrap();
    let tp = w
        .add_typed_topic::<PoseStamped>("/push/block_pose", &[QosProfile::default_profile()])
        .unwrap();
    let ta = w
        .add_typed_topic::<PushAction>("/push/action", &[QosProfile::default_profile()])
        .unwrap();
    let mut rng = SplitMix64::new(seed);
    let solver = Solver::Rk4 { substeps: 4 };
    for tr in 0..trajs {
        let t0 = 1_000_000_000i64 + tr as i64 * 60_000_000_000;
        let mut s = [
            uniform(&mut rng, 0.3, 0.5),
            uniform(&mut rng, -0.1, 0.1),
            uniform(&mut rng, -1.0, 1.0),
        ];
        for i in 0..=pushes {
            let t = t0 + i as i64 * 2_000_000_000;
            w.write(tp, t as u64, &pose_msg(t, "table", s[0], s[1], s[2]))
                .unwrap();
            if i == pushes {
                break;
            }
            let u = [
                uniform(&mut rng, -1.0, 1.0),
                uniform(&mut rng, -1.2, 1.2),
                uniform(&mut rng, 0.2, 1.0),
            ];
            let ta_t = t + 1_000_000;
            let msg = PushAction {
                header: Header::new(Time::from_nanos(ta_t), "table"),
                location: u[0],
                angle: u[1],
                length: u[2],
            };
            w.write(ta, ta_t as u64, &msg).unwrap();
            let mut next = [0.0; 3];
            integrate(&model, &solver, 1, &s, &u, 1.0, &mut next);
            s = next;
        }
    }
    w.finish().unwrap();
    path
}

/// Car data from the dynamic bicycle: `runs` runs of `seconds` at `rate_hz`, piecewise constant
/// random commands changing every 0.4 s, runs 10 s apart (so they split into trajectories).
pub fn car_bag(dir: &Path, runs: usize, seconds: f64, rate_hz: f64, seed: u64) -> PathBuf {
    car_bag_from(
        dir,
        &PhysicsModel::car(&[]).unwrap(),
        runs,
        seconds,
        rate_hz,
        seed,
    )
}

/// As [`car_bag`] from any car physics model; its effect states (`d_f`, `delta_w`) start settled
/// at the first command of a run and are carried by the integration.
pub fn car_bag_from(
    dir: &Path,
    model: &PhysicsModel,
    runs: usize,
    seconds: f64,
    rate_hz: f64,
    seed: u64,
) -> PathBuf {
    car_bag_delayed(dir, model, runs, seconds, rate_hz, seed, 0)
}

/// As [`car_bag_from`], with the steering command reaching the car `delay` samples after it is
/// logged (a transport delay; before a run's first command, that command).
pub fn car_bag_delayed(
    dir: &Path,
    model: &PhysicsModel,
    runs: usize,
    seconds: f64,
    rate_hz: f64,
    seed: u64,
    delay: usize,
) -> PathBuf {
    let names: Vec<&str> = model.effects().iter().map(|e| e.name()).collect();
    let path = dir.join(format!("car_{runs}_{seed}_{delay}_{}", names.join("_")));
    let mut w = BagWriter::create(&path, WriterOptions::default()).unwrap();
    let tp = w
        .add_typed_topic::<PoseStamped>("/car/pose", &[QosProfile::default_profile()])
        .unwrap();
    let tc = w
        .add_typed_topic::<AckermannDriveStamped>("/car/cmd", &[QosProfile::default_profile()])
        .unwrap();
    let mut rng = SplitMix64::new(seed);
    let dt = 1.0 / rate_hz;
    let steps = (seconds * rate_hz) as usize;
    let solver = Solver::Rk4 { substeps: 4 };
    for run in 0..runs {
        let t0 = 1_000_000_000i64 + (run as f64 * (seconds + 10.0) * 1e9) as i64;
        let mut s = vec![0.0, 0.0, uniform(&mut rng, -3.0, 3.0), 1.0, 0.0, 0.0];
        let mut u = [0.0, 0.3];
        let mut steering = Vec::with_capacity(steps + 1);
        for i in 0..=steps {
            let t = t0 + (i as f64 * dt * 1e9) as i64;
            if i % ((0.4 * rate_hz) as usize).max(1) == 0 {
                u = [uniform(&mut rng, -0.3, 0.3), uniform(&mut rng, 0.1, 0.6)];
            }
            if i == 0 {
                let uf = [f64::from(u[0] as f32), f64::from(u[1] as f32)];
                s.extend(model.settled_effect_states(&uf));
            }
            w.write(tp, t as u64, &pose_msg(t, "world", s[0], s[1], s[2]))
                .unwrap();
            let cmd = AckermannDriveStamped {
                header: Header::new(Time::from_nanos(t), "base_link"),
                drive: AckermannDrive {
                    steering_angle: u[0] as f32,
                    acceleration: u[1] as f32,
                    ..Default::default()
                },
            };
            w.write(tc, t as u64, &cmd).unwrap();
            // commands go through f32 on the wire: integrate with the same values
            let mut uf = [f64::from(u[0] as f32), f64::from(u[1] as f32)];
            steering.push(uf[0]);
            uf[0] = steering[i.saturating_sub(delay)];
            let mut next = vec![0.0; s.len()];
            integrate(model, &solver, 1, &s, &uf, dt, &mut next);
            s = next;
        }
    }
    w.finish().unwrap();
    path
}
