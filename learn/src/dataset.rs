//! From bags (or raw samples) to model-state trajectories: the topic contract, world inference,
//! the data pipeline of `dynlab-dynamics`, and the bag hashes a model file records.

use std::path::{Path, PathBuf};

use dynlab_bag::Bag;
use dynlab_dynamics::data::{
    CommandHold, CommandSample, PipelineConfig, PipelineReport, PoseSample, SavGol,
    StateTrajectory, build_trajectories,
};
use dynlab_msgs::ackermann_msgs::AckermannDriveStamped;
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::PoseStamped;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::{LearnError, World};

/// Topic names to read (defaults: the topic contract of the world).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Topics {
    /// Pose topic (`geometry_msgs/msg/PoseStamped`); default `/push/block_pose` or `/car/pose`.
    pub pose: Option<String>,
    /// Command topic (`dynlab_msgs/msg/PushAction` or `ackermann_msgs/msg/AckermannDriveStamped`);
    /// default `/push/action` or `/car/cmd`.
    pub cmd: Option<String>,
}

impl Topics {
    /// The pose topic for `world`.
    pub fn pose_topic(&self, world: World) -> String {
        self.pose
            .clone()
            .unwrap_or_else(|| world.default_pose_topic().to_string())
    }
    /// The command topic for `world`.
    pub fn cmd_topic(&self, world: World) -> String {
        self.cmd
            .clone()
            .unwrap_or_else(|| world.default_cmd_topic().to_string())
    }
}

/// A bag a model was trained on: its path and the SHA-256 of its MCAP file(s).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BagSource {
    /// Path as given.
    pub path: String,
    /// Lower-case hex SHA-256 over the bag's `.mcap` files in name order (or the file itself).
    pub sha256: String,
}

/// Model-state trajectories of one world, ready for windows.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// The robot.
    pub world: World,
    /// Trajectories of model states (`dim_s` = 3 or 6) with the commands held over each step.
    pub trajectories: Vec<StateTrajectory>,
    /// Median pose interval \[s\] (pushing: time between pushes).
    pub pose_dt_s: f64,
    /// The bags the data came from.
    pub sources: Vec<BagSource>,
    /// What the pipeline did, per bag (or one entry for raw samples).
    pub reports: Vec<PipelineReport>,
}

impl Dataset {
    /// Number of transitions (state pairs) over all trajectories.
    pub fn transitions(&self) -> usize {
        self.trajectories
            .iter()
            .map(|t| t.len().saturating_sub(1))
            .sum()
    }

    /// Trajectory lengths (states).
    pub fn lengths(&self) -> Vec<usize> {
        self.trajectories.iter().map(|t| t.len()).collect()
    }

    /// Builds a data set from raw samples (poses and commands at any rates), as read from a bag.
    /// `sg` is used for the car's Savitzky–Golay velocities.
    pub fn from_samples(
        world: World,
        poses: &[PoseSample],
        commands: &[CommandSample],
        sg: &SavGol,
    ) -> Result<Self, LearnError> {
        let (trajectories, report, dt) = trajectories_of(world, poses, commands, sg)?;
        Ok(Self {
            world,
            trajectories,
            pose_dt_s: dt,
            sources: Vec::new(),
            reports: vec![report],
        })
    }
}

fn trajectories_of(
    world: World,
    poses: &[PoseSample],
    commands: &[CommandSample],
    sg: &SavGol,
) -> Result<(Vec<StateTrajectory>, PipelineReport, f64), LearnError> {
    sg.validate()?;
    let cfg = match world {
        // a push is published just after the pose it starts from, and held until the next pose
        World::Push => PipelineConfig {
            hold: CommandHold::BeforeNextPose,
            resample: dynlab_dynamics::data::Resample::Off,
            ..Default::default()
        },
        World::Car => PipelineConfig {
            hold: CommandHold::AtPose,
            min_poses: sg.window,
            ..Default::default()
        },
    };
    let (trajs, report) = build_trajectories(poses, commands, &cfg)?;
    let dt = report.median_dt_s;
    let states = match world {
        World::Push => trajs.iter().map(StateTrajectory::from_poses).collect(),
        World::Car => trajs
            .iter()
            .map(|t| StateTrajectory::car(t, sg))
            .collect::<Result<Vec<_>, _>>()?,
    };
    Ok((states, report, dt))
}

/// Infers the world of a bag from its topics (`/push/block_pose` → push, `/car/pose` → car).
pub fn infer_world(bag: &Bag) -> Result<World, LearnError> {
    if bag.topic(World::Push.default_pose_topic()).is_some() {
        Ok(World::Push)
    } else if bag.topic(World::Car.default_pose_topic()).is_some() {
        Ok(World::Car)
    } else {
        Err(LearnError::UnknownWorld {
            path: bag.path().to_path_buf(),
            topics: bag
                .topics()
                .iter()
                .map(|t| t.name.clone())
                .collect::<Vec<_>>()
                .join(", "),
        })
    }
}

fn stamp_or_log(stamp_ns: i64, log_ns: u64) -> i64 {
    if stamp_ns != 0 {
        stamp_ns
    } else {
        i64::try_from(log_ns).unwrap_or(i64::MAX)
    }
}

/// Reads poses and commands of `world` from one bag.
pub fn read_samples(
    bag: &Bag,
    world: World,
    topics: &Topics,
) -> Result<(Vec<PoseSample>, Vec<CommandSample>), LearnError> {
    let bag_err = |source| LearnError::Bag {
        path: bag.path().to_path_buf(),
        source,
    };
    let pose_topic = topics.pose_topic(world);
    let cmd_topic = topics.cmd_topic(world);
    bag.require_topics(&[&pose_topic, &cmd_topic])
        .map_err(bag_err)?;
    let poses: Vec<PoseSample> = bag
        .read::<PoseStamped>(&pose_topic)
        .map_err(bag_err)?
        .into_iter()
        .map(|m| {
            let (x, y, yaw) = m.msg.pose.planar_xy_yaw();
            PoseSample {
                t_ns: stamp_or_log(m.msg.header.stamp.to_nanos(), m.log_time_ns),
                x,
                y,
                yaw,
            }
        })
        .collect();
    let commands: Vec<CommandSample> = match world {
        World::Push => bag
            .read::<PushAction>(&cmd_topic)
            .map_err(bag_err)?
            .into_iter()
            .map(|m| CommandSample {
                t_ns: stamp_or_log(m.msg.header.stamp.to_nanos(), m.log_time_ns),
                u: vec![m.msg.location, m.msg.angle, m.msg.length],
            })
            .collect(),
        World::Car => bag
            .read::<AckermannDriveStamped>(&cmd_topic)
            .map_err(bag_err)?
            .into_iter()
            .map(|m| CommandSample {
                t_ns: stamp_or_log(m.msg.header.stamp.to_nanos(), m.log_time_ns),
                u: vec![
                    f64::from(m.msg.drive.steering_angle),
                    f64::from(m.msg.drive.acceleration),
                ],
            })
            .collect(),
    };
    Ok((poses, commands))
}

/// SHA-256 of a bag: over its `.mcap` files in name order (a bag directory) or of the file.
pub fn bag_sha256(path: &Path) -> Result<String, LearnError> {
    let io = |p: &Path| {
        let p = p.to_path_buf();
        move |source| LearnError::Io { path: p, source }
    };
    let mut files: Vec<PathBuf> = if path.is_dir() {
        std::fs::read_dir(path)
            .map_err(io(path))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            .collect()
    } else {
        vec![path.to_path_buf()]
    };
    files.sort();
    let mut h = Sha256::new();
    for f in &files {
        h.update(std::fs::read(f).map_err(io(f))?);
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// Loads one or more bags of the same world. `world = None` infers it from the first bag's
/// topics; every bag must then be of that world.
pub fn load_bags(
    paths: &[PathBuf],
    world: Option<World>,
    topics: &Topics,
    sg: &SavGol,
) -> Result<Dataset, LearnError> {
    if paths.is_empty() {
        return Err(LearnError::setting(
            "bag",
            "(none)",
            "give at least one bag (--bag PATH)",
        ));
    }
    let mut world = world;
    let mut ds: Option<Dataset> = None;
    for path in paths {
        let bag = Bag::open(path).map_err(|source| LearnError::Bag {
            path: path.clone(),
            source,
        })?;
        let w = match world {
            Some(w) => w,
            None => {
                let w = infer_world(&bag)?;
                world = Some(w);
                w
            }
        };
        let (poses, commands) = read_samples(&bag, w, topics)?;
        let (trajs, report, dt) = trajectories_of(w, &poses, &commands, sg)?;
        let source = BagSource {
            path: path.display().to_string(),
            sha256: bag_sha256(path)?,
        };
        match &mut ds {
            None => {
                ds = Some(Dataset {
                    world: w,
                    trajectories: trajs,
                    pose_dt_s: dt,
                    sources: vec![source],
                    reports: vec![report],
                })
            }
            Some(d) => {
                if w == World::Car && (dt - d.pose_dt_s).abs() > 0.1 * d.pose_dt_s {
                    return Err(LearnError::setting(
                        "bag",
                        path.display(),
                        format!(
                            "its pose interval {dt:.4} s differs from the first bag's {:.4} s; train on bags recorded at the same rate",
                            d.pose_dt_s
                        ),
                    ));
                }
                d.trajectories.extend(trajs);
                d.sources.push(source);
                d.reports.push(report);
            }
        }
    }
    ds.ok_or_else(|| LearnError::setting("bag", "(none)", "give at least one bag"))
}
