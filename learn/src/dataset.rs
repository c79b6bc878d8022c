//! From bags (or raw samples) to model-state trajectories: the topic contract, world inference,
//! the pose source (a `PoseStamped` or `Odometry` topic, or a tf frame pair), the data pipeline of
//! `dynlab-dynamics`, and the bag hashes a model file records.
//!
//! Real data as they come: poses with NaN or infinite values and poses whose stamp goes back are
//! skipped and the trajectory split there (unless [`LoadOptions::strict`]); a damaged bag is read
//! as far as the recovering reader gets, and what was recovered against what the bag declares is
//! in the report's [`PipelineReport::source_notes`] (see [`data_warnings`]).

use std::path::{Path, PathBuf};

use dynlab_bag::Bag;
use dynlab_dynamics::data::{
    CommandHold, CommandSample, PipelineConfig, PipelineReport, PoseSample, SavGol, SkipReason,
    StateTrajectory, Trajectory, build_trajectories,
};
use dynlab_msgs::ackermann_msgs::AckermannDriveStamped;
use dynlab_msgs::dynlab_msgs::PushAction;
use dynlab_msgs::geometry_msgs::PoseStamped;
use dynlab_msgs::nav_msgs::Odometry;
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

/// A tf frame pair: the pose of `child` in `parent`, read from a bag's `/tf` and `/tf_static`
/// (written `PARENT:CHILD` on the command line, e.g. `world:car`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TfFrames {
    /// The fixed frame the poses are expressed in (`world`, `table`, `map`, `odom`).
    pub parent: String,
    /// The moving body's frame (`car`, `block`, `base_link`).
    pub child: String,
}

impl TfFrames {
    /// Parses `PARENT:CHILD` (frame names without spaces; a leading `/` is dropped, as tf2 does).
    pub fn parse(text: &str) -> Result<Self, LearnError> {
        let bad = || {
            LearnError::setting(
                "pose-tf",
                text,
                "write the frame pair as PARENT:CHILD, e.g. world:car or table:block",
            )
        };
        let (p, c) = text.split_once(':').ok_or_else(bad)?;
        let clean = |f: &str| f.trim().trim_start_matches('/').to_string();
        let (parent, child) = (clean(p), clean(c));
        let ok = |f: &str| !f.is_empty() && !f.contains(char::is_whitespace) && !f.contains(':');
        if !ok(&parent) || !ok(&child) || parent == child {
            return Err(bad());
        }
        Ok(TfFrames { parent, child })
    }
}

impl std::fmt::Display for TfFrames {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.parent, self.child)
    }
}

/// How bags are read: topic names, where the poses come from, and how bad messages are handled.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadOptions {
    /// Pose and command topics. The pose topic may carry `geometry_msgs/msg/PoseStamped`,
    /// `nav_msgs/msg/Odometry` or `geometry_msgs/msg/PoseWithCovarianceStamped` (their
    /// `pose.pose`) or `geometry_msgs/msg/TransformStamped` (a motion-capture bridge's
    /// `transform`); the type is read from the bag.
    pub topics: Topics,
    /// Read the poses from tf instead of a pose topic (default `None`).
    pub pose_tf: Option<TfFrames>,
    /// Refuse NaN or infinite values and pose stamps that go back instead of skipping them
    /// (default `false`).
    pub strict: bool,
}

impl From<&Topics> for LoadOptions {
    fn from(topics: &Topics) -> Self {
        LoadOptions {
            topics: topics.clone(),
            ..Default::default()
        }
    }
}

impl LoadOptions {
    /// Where the poses come from, for messages: `/car/pose` or `tf world → car`.
    pub fn pose_source(&self, world: World) -> String {
        match &self.pose_tf {
            Some(f) => format!("tf {} → {}", f.parent, f.child),
            None => self.topics.pose_topic(world),
        }
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
    trajectories_with_stamps(world, poses, commands, sg, None, false)
        .map(|(s, r, dt, _)| (s, r, dt))
}

#[allow(clippy::type_complexity)]
fn trajectories_with_stamps(
    world: World,
    poses: &[PoseSample],
    commands: &[CommandSample],
    sg: &SavGol,
    step_ns: Option<i64>,
    strict: bool,
) -> Result<(Vec<StateTrajectory>, PipelineReport, f64, Vec<Vec<i64>>), LearnError> {
    sg.validate()?;
    let cfg = match world {
        // a push is published just after the pose it starts from, and held until the next pose
        World::Push => PipelineConfig {
            hold: CommandHold::BeforeNextPose,
            resample: dynlab_dynamics::data::Resample::Off,
            estimate_noise: false,
            strict,
            ..Default::default()
        },
        World::Car => PipelineConfig {
            hold: CommandHold::AtPose,
            min_poses: sg.window,
            resample: match step_ns {
                Some(dt_ns) => dynlab_dynamics::data::Resample::Fixed { dt_ns },
                None => PipelineConfig::default().resample,
            },
            strict,
            ..Default::default()
        },
    };
    let (mut trajs, mut report) = build_trajectories(poses, commands, &cfg)?;
    // the car's smoothing: as given, or chosen for the poses' noise
    let sg = &match report.pose_std {
        Some(std) if sg.adaptive && world == World::Car => sg.adapted(&trajs, std),
        _ => *sg,
    };
    if world == World::Car {
        report.savgol = Some(*sg);
    }
    if world == World::Push {
        let mut cmd_t: Vec<i64> = commands.iter().map(|c| c.t_ns).collect();
        cmd_t.sort_unstable();
        trajs = trajs
            .iter()
            .map(|t| one_state_per_push(t, &cmd_t))
            .collect();
    }
    // resampled to a fixed step: that is the step of the data now
    let dt = match (world, step_ns) {
        (World::Car, Some(ns)) => ns as f64 * 1e-9,
        (World::Push, _) => median_interval_s(&trajs).unwrap_or(report.median_dt_s),
        _ => report.median_dt_s,
    };
    let states = match world {
        World::Push => trajs.iter().map(StateTrajectory::from_poses).collect(),
        World::Car => trajs
            .iter()
            .map(|t| StateTrajectory::car(t, sg))
            .collect::<Result<Vec<_>, _>>()?,
    };
    let stamps = trajs.iter().map(|t| t.t_ns.clone()).collect();
    Ok((states, report, dt, stamps))
}

/// One state per push: a pushing model steps one whole push, so a pushing trajectory keeps
/// the pose each push starts from (the last pose at or before its `/push/action` message, as
/// [`CommandHold::BeforeNextPose`] assigns commands) and its last pose (the settled pose after
/// the last push); the poses in between (a block pose streamed at 10 Hz during a push) are
/// dropped. Data with one pose per push (each push published after the pose it starts from)
/// keep every pose and load exactly as before.
pub fn one_state_per_push(traj: &Trajectory, cmd_t: &[i64]) -> Trajectory {
    let n = traj.t_ns.len();
    let mut keep = vec![false; n];
    if n > 0 {
        keep[0] = true;
        keep[n - 1] = true;
    }
    for &c in cmd_t {
        let k = traj.t_ns.partition_point(|&t| t <= c);
        if k > 0 && k < n {
            keep[k - 1] = true;
        }
    }
    let du = traj.dim_u;
    let idx: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
    let t_ns: Vec<i64> = idx.iter().map(|&i| traj.t_ns[i]).collect();
    let mut gaps: Vec<i64> = t_ns.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_unstable();
    let dt = gaps
        .get(gaps.len() / 2)
        .map_or(traj.dt, |&g| g as f64 * 1e-9);
    Trajectory {
        pose: idx.iter().map(|&i| traj.pose[i]).collect(),
        u: idx
            .iter()
            .flat_map(|&i| traj.u[i * du..(i + 1) * du].iter().copied())
            .collect(),
        t_ns,
        dim_u: du,
        dt,
        resampled: traj.resampled,
    }
}

/// Median interval between consecutive states over all trajectories \[s\].
fn median_interval_s(trajs: &[Trajectory]) -> Option<f64> {
    let mut gaps: Vec<i64> = trajs
        .iter()
        .flat_map(|t| t.t_ns.windows(2).map(|w| w[1] - w[0]))
        .collect();
    gaps.sort_unstable();
    gaps.get(gaps.len() / 2).map(|&g| g as f64 * 1e-9)
}

/// Infers the world of a bag from its topics (`/push/block_pose` → push, `/car/pose` → car;
/// without either, from the command topic: `/push/action` → push, `/car/cmd` → car).
pub fn infer_world(bag: &Bag) -> Result<World, LearnError> {
    if bag.topic(World::Push.default_pose_topic()).is_some() {
        Ok(World::Push)
    } else if bag.topic(World::Car.default_pose_topic()).is_some() {
        Ok(World::Car)
    } else if bag.topic(World::Push.default_cmd_topic()).is_some() {
        Ok(World::Push)
    } else if bag.topic(World::Car.default_cmd_topic()).is_some() {
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

/// Reads poses and commands of `world` from one bag (poses from the pose topic, any supported
/// type).
pub fn read_samples(
    bag: &Bag,
    world: World,
    topics: &Topics,
) -> Result<(Vec<PoseSample>, Vec<CommandSample>), LearnError> {
    read_samples_with(bag, world, &LoadOptions::from(topics)).map(|(p, c, _)| (p, c))
}

fn planar_sample(
    stamp_ns: i64,
    log_ns: u64,
    pose: &dynlab_msgs::geometry_msgs::Pose,
) -> PoseSample {
    let (x, y, yaw) = pose.planar_xy_yaw();
    PoseSample {
        t_ns: stamp_or_log(stamp_ns, log_ns),
        x,
        y,
        yaw,
    }
}

/// The poses of one bag from the source `opts` names, in recording order, with notes saying
/// where they came from.
fn read_poses(
    bag: &Bag,
    world: World,
    opts: &LoadOptions,
) -> Result<(Vec<PoseSample>, Vec<String>), LearnError> {
    let bag_err = |source| LearnError::Bag {
        path: bag.path().to_path_buf(),
        source,
    };
    if let Some(frames) = &opts.pose_tf {
        let series =
            dynlab_bag::tf::lookup_series(bag, &frames.parent, &frames.child).map_err(|e| {
                LearnError::setting(
                    "pose-tf",
                    frames,
                    format!("in bag {}: {e}", bag.path().display()),
                )
            })?;
        let mut notes = vec![format!(
            "poses from tf {} → {} (chain {}; stamps of {}): {} transforms",
            frames.parent,
            frames.child,
            series.chain.join(" → "),
            series.driving_link,
            series.samples.len()
        )];
        if series.skipped_before_chain > 0 {
            notes.push(format!(
                "{} transforms before every link of the chain was known skipped",
                series.skipped_before_chain
            ));
        }
        notes.extend(series.notes);
        let poses = series
            .samples
            .iter()
            .map(|s| planar_sample(s.t_ns, s.log_time_ns, &s.transform.as_pose()))
            .collect();
        return Ok((poses, notes));
    }
    let pose_topic = opts.topics.pose_topic(world);
    bag.require_topics(&[&pose_topic]).map_err(bag_err)?;
    let type_name = bag
        .topic(&pose_topic)
        .map(|t| t.type_name.clone())
        .unwrap_or_default();
    use dynlab_msgs::RosMessage;
    use dynlab_msgs::geometry_msgs::{PoseWithCovarianceStamped, TransformStamped};
    // Every supported type: its name, the field the pose is read from, and the reader.
    type Reader = fn(&Bag, &str) -> Result<Vec<PoseSample>, dynlab_bag::BagError>;
    fn poses_of<T: RosMessage>(
        bag: &Bag,
        topic: &str,
        pose: impl Fn(&T) -> (i64, dynlab_msgs::geometry_msgs::Pose),
    ) -> Result<Vec<PoseSample>, dynlab_bag::BagError> {
        Ok(bag
            .read::<T>(topic)?
            .into_iter()
            .map(|m| {
                let (stamp, p) = pose(&m.msg);
                planar_sample(stamp, m.log_time_ns, &p)
            })
            .collect())
    }
    let readers: [(&str, &str, Reader); 4] = [
        (PoseStamped::TYPE_NAME, "pose", |b, t| {
            poses_of::<PoseStamped>(b, t, |m| (m.header.stamp.to_nanos(), m.pose))
        }),
        (Odometry::TYPE_NAME, "pose.pose", |b, t| {
            poses_of::<Odometry>(b, t, |m| (m.header.stamp.to_nanos(), m.pose.pose))
        }),
        (PoseWithCovarianceStamped::TYPE_NAME, "pose.pose", |b, t| {
            poses_of::<PoseWithCovarianceStamped>(b, t, |m| {
                (m.header.stamp.to_nanos(), m.pose.pose)
            })
        }),
        (TransformStamped::TYPE_NAME, "transform", |b, t| {
            poses_of::<TransformStamped>(b, t, |m| {
                (m.header.stamp.to_nanos(), m.transform.as_pose())
            })
        }),
    ];
    let Some(&(name, field, read)) = readers.iter().find(|(n, _, _)| *n == type_name) else {
        let names: Vec<&str> = readers.iter().map(|(n, _, _)| *n).collect();
        return Err(LearnError::setting(
            "pose-topic",
            &pose_topic,
            format!(
                "in bag {} it carries {type_name}; poses are read from topics of type {}, or from \
                 tf (--pose-tf PARENT:CHILD)",
                bag.path().display(),
                names.join(", ")
            ),
        ));
    };
    let poses = read(bag, &pose_topic).map_err(bag_err)?;
    let notes = if name == PoseStamped::TYPE_NAME {
        Vec::new()
    } else {
        vec![format!("poses from {pose_topic} ({name}: {field})")]
    };
    Ok((poses, notes))
}

/// Poses and commands read from one bag, with notes on where they came from.
pub type SourcedSamples = (Vec<PoseSample>, Vec<CommandSample>, Vec<String>);

/// Reads poses (from the source `opts` names) and commands of `world` from one bag, with notes
/// on where the poses came from and, for a damaged bag, what was recovered.
pub fn read_samples_with(
    bag: &Bag,
    world: World,
    opts: &LoadOptions,
) -> Result<SourcedSamples, LearnError> {
    let bag_err = |source| LearnError::Bag {
        path: bag.path().to_path_buf(),
        source,
    };
    let cmd_topic = opts.topics.cmd_topic(world);
    // the pose source first: a bag of the other robot is named by its missing pose topic
    let (poses, mut notes) = read_poses(bag, world, opts)?;
    bag.require_topics(&[&cmd_topic]).map_err(bag_err)?;
    if let Some(r) = bag.recovery() {
        notes.insert(
            0,
            format!(
                "damaged bag: {}; the data were used as far as they were readable (`dynlab bag info` says where reading stopped, `dynlab bag repair` rewrites it)",
                r.summary()
            ),
        );
    }
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
    Ok((poses, commands, notes))
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
    load_bags_timed(paths, world, topics, sg).map(|t| t.data)
}

/// Where each state of a [`Dataset`] was measured: the bag stamps behind every trajectory, so
/// that errors can be reported against bag time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Stamps {
    /// Per trajectory, the stamp of each state \[ns\] (header stamps, or log times where a
    /// header stamp is zero; equidistant where the pipeline resampled).
    pub t_ns: Vec<Vec<i64>>,
    /// Per trajectory, the index of the bag (in [`Dataset::sources`]) it came from.
    pub bag: Vec<usize>,
    /// Per bag, the stamp of its first pose \[ns\]: the origin of "seconds from bag start".
    pub bag_start_ns: Vec<i64>,
}

impl Stamps {
    /// Seconds from the start of its bag of state `i` of trajectory `traj` (0 when out of range).
    pub fn seconds_from_bag_start(&self, traj: usize, i: usize) -> f64 {
        let (Some(t), Some(&b)) = (
            self.t_ns.get(traj).and_then(|t| t.get(i)),
            self.bag.get(traj),
        ) else {
            return 0.0;
        };
        let t0 = self.bag_start_ns.get(b).copied().unwrap_or(*t);
        (*t - t0) as f64 * 1e-9
    }
}

/// A [`Dataset`] with the bag stamps of its states.
#[derive(Clone, Debug, PartialEq)]
pub struct TimedDataset {
    /// The data set (as [`load_bags`] returns it).
    pub data: Dataset,
    /// Stamps of every state, parallel to `data.trajectories`.
    pub stamps: Stamps,
}

impl TimedDataset {
    /// Builds a timed data set from raw samples (poses and commands at any rates, in any
    /// order), as [`Dataset::from_samples`] does, keeping the stamps (one "bag": index 0, whose
    /// start is the first pose).
    pub fn from_samples(
        world: World,
        poses: &[PoseSample],
        commands: &[CommandSample],
        sg: &SavGol,
    ) -> Result<Self, LearnError> {
        let (trajectories, report, dt, t_ns) =
            trajectories_with_stamps(world, poses, commands, sg, None, false)?;
        let n = t_ns.len();
        Ok(Self {
            data: Dataset {
                world,
                trajectories,
                pose_dt_s: dt,
                sources: Vec::new(),
                reports: vec![report],
            },
            stamps: Stamps {
                t_ns,
                bag: vec![0; n],
                bag_start_ns: vec![poses.iter().map(|p| p.t_ns).min().unwrap_or(0)],
            },
        })
    }
}

/// [`load_bags`], keeping the bag stamp of every state (for error-over-time plots and for
/// naming the worst segments of a bag by their time).
pub fn load_bags_timed(
    paths: &[PathBuf],
    world: Option<World>,
    topics: &Topics,
    sg: &SavGol,
) -> Result<TimedDataset, LearnError> {
    load_bags_timed_at(paths, world, topics, sg, None)
}

/// [`load_bags_timed`], with the car's poses resampled (linear interpolation, yaw unwrapped) to
/// a fixed step of `step_s` seconds when given — to hold a model trained at 100 Hz against a
/// motion capture at 240 Hz, say. Pushing data are never resampled (one state per pose).
pub fn load_bags_timed_at(
    paths: &[PathBuf],
    world: Option<World>,
    topics: &Topics,
    sg: &SavGol,
    step_s: Option<f64>,
) -> Result<TimedDataset, LearnError> {
    load_bags_with(paths, world, &LoadOptions::from(topics), sg, step_s)
}

/// [`load_bags_timed_at`] with every reading option: the pose source (a `PoseStamped` or
/// `Odometry` topic, or a tf frame pair) and strictness.
pub fn load_bags_with(
    paths: &[PathBuf],
    world: Option<World>,
    opts: &LoadOptions,
    sg: &SavGol,
    step_s: Option<f64>,
) -> Result<TimedDataset, LearnError> {
    let topics = &opts.topics;
    let step_ns = match step_s {
        Some(s) if s.is_finite() && s > 0.0 => Some((s * 1e9).round() as i64),
        Some(s) => {
            return Err(LearnError::setting(
                "step",
                s,
                "a positive number of seconds",
            ));
        }
        None => None,
    };
    if paths.is_empty() {
        return Err(LearnError::setting(
            "bag",
            "(none)",
            "give at least one bag (--bag PATH)",
        ));
    }
    let mut world = world;
    let mut ds: Option<Dataset> = None;
    let mut stamps = Stamps::default();
    for (bi, path) in paths.iter().enumerate() {
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
        let (poses, commands, notes) = read_samples_with(&bag, w, opts)?;
        let (trajs, mut report, dt, t_ns) =
            trajectories_with_stamps(w, &poses, &commands, sg, step_ns, opts.strict)
                .map_err(|e| in_bag(e, path, &opts.pose_source(w), &topics.cmd_topic(w)))?;
        report.source_notes = notes;
        if trajs.is_empty() {
            return Err(LearnError::setting(
                "bag",
                path.display(),
                format!(
                    "too little data: no trajectory is long enough: {} poses from {} in {} pieces shorter than {} poses each; record longer uninterrupted runs",
                    report.poses_in,
                    opts.pose_source(w),
                    report.short_trajectories_dropped,
                    match w {
                        World::Car => sg.window,
                        World::Push => 2,
                    }
                ),
            ));
        }
        stamps
            .bag_start_ns
            .push(poses.iter().map(|p| p.t_ns).min().unwrap_or(0));
        stamps.bag.extend(std::iter::repeat_n(bi, t_ns.len()));
        stamps.t_ns.extend(t_ns);
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
    let data = ds.ok_or_else(|| LearnError::setting("bag", "(none)", "give at least one bag"))?;
    Ok(TimedDataset { data, stamps })
}

/// Names the bag and topics in a pipeline error about missing poses or commands.
fn in_bag(e: LearnError, path: &Path, pose_topic: &str, cmd_topic: &str) -> LearnError {
    use dynlab_dynamics::data::DataError;
    match e {
        LearnError::Data(DataError::NoPoses) => LearnError::setting(
            "bag",
            path.display(),
            format!(
                "no poses: {pose_topic} has no messages; record the robot's poses on it or name the pose source (--pose-topic, --pose-tf)"
            ),
        ),
        LearnError::Data(DataError::NoCommands { poses }) => LearnError::setting(
            "bag",
            path.display(),
            format!(
                "no commands: topic {cmd_topic} has no messages ({poses} poses on {pose_topic}); record the commands sent to the robot on it or name the command topic (--cmd-topic / --action-topic)"
            ),
        ),
        other => other,
    }
}

/// How the car's velocities were estimated, where not with the default smoothing (chosen for
/// the poses' noise, or as given): the windows and the noise estimated.
pub fn smoothing_note(report: &PipelineReport) -> Option<String> {
    let sg = report.savgol.filter(|s| *s != SavGol::default())?;
    let noise = match report.pose_std {
        Some([x, y, yaw]) => format!(
            " (the poses' noise: σ {:.2} mm, {:.2} mm, {:.4} rad)",
            x * 1e3,
            y * 1e3,
            yaw
        ),
        None => String::new(),
    };
    Some(format!(
        "car velocities from {sg}{noise}; --savgol-window sets them"
    ))
}

/// What the data pipeline did to one bag, in sentences for a person: commands held at pose
/// stamps, gaps that split trajectories, resampling, dropped poses.
pub fn pipeline_notes(report: &PipelineReport) -> Vec<String> {
    let mut notes = report.source_notes.clone();
    let rate = if report.median_dt_s > 0.0 {
        1.0 / report.median_dt_s
    } else {
        0.0
    };
    notes.push(format!(
        "{} poses (median interval {:.2} ms, {:.1} Hz) and {} commands; each pose gets the latest command at or before it (zero-order hold)",
        report.poses_in,
        report.median_dt_s * 1e3,
        rate,
        report.commands_in
    ));
    if !report.skipped.is_empty() {
        let first = |reason| {
            report
                .skipped
                .iter()
                .find(|s| s.reason == reason)
                .map(|s| format!(" (first at {:.3} s)", s.t_ns as f64 * 1e-9))
                .unwrap_or_default()
        };
        let mut parts = Vec::new();
        if report.non_finite_poses > 0 {
            parts.push(format!(
                "{} poses with NaN or infinite values{}",
                report.non_finite_poses,
                first(SkipReason::NonFinite)
            ));
        }
        if report.out_of_order_poses > 0 {
            parts.push(format!(
                "{} poses whose stamp goes back{}",
                report.out_of_order_poses,
                first(SkipReason::OutOfOrder)
            ));
        }
        notes.push(format!(
            "skipped {}; the data are split there ({} split(s)); --strict refuses such data instead",
            parts.join(" and "),
            report.splits_at_skipped
        ));
    }
    if !report.stamp_resets.is_empty() {
        notes.push(format!(
            "the pose stamps went back and stayed back {} time(s) (first at {:.3} s: a clock reset, or a pose stamped in the future before): a new trajectory starts at each",
            report.stamp_resets.len(),
            report.stamp_resets[0] as f64 * 1e-9
        ));
    }
    if report.non_finite_commands > 0 {
        notes.push(format!(
            "{} commands with NaN or infinite values skipped (the command before stays held)",
            report.non_finite_commands
        ));
    }
    if report.duplicate_stamps > 0 {
        notes.push(format!(
            "{} poses with a repeated stamp dropped",
            report.duplicate_stamps
        ));
    }
    if !report.gaps.is_empty() {
        let list: Vec<String> = report
            .gaps
            .iter()
            .take(5)
            .map(|g| {
                format!(
                    "{:.3} s → {:.3} s ({:.3} s without poses)",
                    g.from_ns as f64 * 1e-9,
                    g.to_ns as f64 * 1e-9,
                    (g.to_ns - g.from_ns) as f64 * 1e-9
                )
            })
            .collect();
        notes.push(format!(
            "{} gap(s) longer than {:.3} s split the data into separate trajectories: {}{}",
            report.gaps.len(),
            report.max_gap_ns as f64 * 1e-9,
            list.join(", "),
            if report.gaps.len() > 5 { ", …" } else { "" }
        ));
    }
    if report.resampled_trajectories > 0 {
        notes.push(format!(
            "{} trajectories resampled (linear interpolation) to their median step: stamps jittered by up to {:.0} %",
            report.resampled_trajectories,
            report.max_jitter * 100.0
        ));
    }
    if report.poses_without_command > 0 {
        notes.push(format!(
            "{} poses before the first command (or without a recent one) dropped",
            report.poses_without_command
        ));
    }
    if report.short_trajectories_dropped > 0 {
        notes.push(format!(
            "{} pieces too short to use dropped ({} poses)",
            report.short_trajectories_dropped, report.short_trajectory_poses
        ));
    }
    notes.extend(smoothing_note(report));
    notes.push(format!(
        "{} trajectories, {} poses used",
        report.trajectories, report.poses_out
    ));
    notes
}

/// What a person must be told about how the data were read, one line per bag and issue, for the
/// terminal: a damaged bag's recovery, skipped poses and commands. Empty for clean data.
pub fn data_warnings(data: &Dataset) -> Vec<String> {
    let mut out = Vec::new();
    for (i, r) in data.reports.iter().enumerate() {
        let bag = data
            .sources
            .get(i)
            .map(|s| format!("{}: ", s.path))
            .unwrap_or_default();
        for n in &r.source_notes {
            if n.starts_with("damaged bag") {
                out.push(format!("{bag}{n}"));
            }
        }
        if !r.skipped.is_empty() || r.non_finite_commands > 0 || !r.stamp_resets.is_empty() {
            out.extend(
                pipeline_notes(r)
                    .into_iter()
                    .filter(|n| {
                        n.starts_with("skipped")
                            || n.contains("commands with NaN")
                            || n.starts_with("the pose stamps went back")
                    })
                    .map(|n| format!("{bag}{n}")),
            );
        }
    }
    out
}

/// Warnings about too little excitation: a command that never changes, or (car) a robot that
/// hardly moves. Each names what to record. Empty when the data vary enough.
pub fn excitation_warnings(data: &Dataset) -> Vec<String> {
    let mut out = Vec::new();
    let du = data.world.action_dim();
    let names = data.world.action_names();
    let mut n = 0usize;
    let mut sum = vec![0.0; du];
    let mut sq = vec![0.0; du];
    for t in &data.trajectories {
        for row in t.u.chunks_exact(t.dim_u.max(1)) {
            if row.len() != du {
                continue;
            }
            n += 1;
            for d in 0..du {
                sum[d] += row[d];
                sq[d] += row[d] * row[d];
            }
        }
    }
    if n == 0 {
        return vec!["no commands at all: record the command topic".into()];
    }
    for d in 0..du {
        let mean = sum[d] / n as f64;
        let var = (sq[d] / n as f64 - mean * mean).max(0.0);
        if var.sqrt() < 1e-6 * mean.abs().max(1e-3) {
            out.push(format!(
                "command {} is constant ({mean:.4}) over all {n} samples: the data say nothing about its effect; record runs that vary it",
                names.get(d).copied().unwrap_or("?")
            ));
        }
    }
    if data.world == World::Car {
        let (mut moving, mut total) = (0usize, 0usize);
        for t in &data.trajectories {
            for s in t.s.chunks_exact(6) {
                total += 1;
                if s[3].hypot(s[4]) > 0.05 {
                    moving += 1;
                }
            }
        }
        if total > 0 && (moving as f64) < 0.1 * total as f64 {
            out.push(format!(
                "the car moves faster than 0.05 m/s in only {moving} of {total} states: record driving, not standing still"
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A car driving a circle, seen by a 240 Hz motion capture with ±20 % stamp jitter, commands
    /// at 37 Hz not aligned with the poses, and a 0.5 s gap in the poses.
    fn mocap() -> (Vec<PoseSample>, Vec<CommandSample>) {
        let dt = 1e9 / 240.0;
        let mut poses = Vec::new();
        for i in 0..1200i64 {
            let jitter = ((i * 7919) % 41 - 20) as f64 / 100.0;
            let t = (i as f64 * dt + jitter * dt) as i64 + 3_000_000;
            if (2.0e9..2.5e9).contains(&(t as f64)) {
                continue; // the gap
            }
            let a = t as f64 * 1e-9;
            poses.push(PoseSample {
                t_ns: t,
                x: a.cos(),
                y: a.sin(),
                yaw: a + std::f64::consts::FRAC_PI_2,
            });
        }
        let commands = (0..200i64)
            .map(|i| CommandSample {
                t_ns: i * 27_027_027,
                u: vec![0.1, 0.3 + 0.001 * i as f64],
            })
            .collect();
        (poses, commands)
    }

    #[test]
    fn mocap_rate_jitter_and_a_gap_split_resample_and_say_so() {
        let (poses, commands) = mocap();
        let d =
            TimedDataset::from_samples(World::Car, &poses, &commands, &SavGol::default()).unwrap();
        // split at the gap into two trajectories, each resampled to the median step (the median
        // of intervals jittered by ±20 % is within 10 % of the nominal 1/240 s)
        assert_eq!(d.data.trajectories.len(), 2);
        assert!(
            (d.data.pose_dt_s - 1.0 / 240.0).abs() < 0.1 / 240.0,
            "{}",
            d.data.pose_dt_s
        );
        let r = &d.data.reports[0];
        assert_eq!(r.gaps.len(), 1);
        assert!(r.gaps[0].from_ns < 2_000_000_000 && r.gaps[0].to_ns >= 2_500_000_000);
        assert_eq!(r.resampled_trajectories, 2);
        // stamps: one per state, equidistant after resampling, on both sides of the gap
        for (t, tr) in d.stamps.t_ns.iter().zip(&d.data.trajectories) {
            assert_eq!(t.len(), tr.len());
            let step = t[1] - t[0];
            assert!(t.windows(2).all(|w| w[1] - w[0] == step));
        }
        assert!(*d.stamps.t_ns[0].last().unwrap() < 2_000_000_000);
        assert!(d.stamps.t_ns[1][0] >= 2_500_000_000);
        assert_eq!(d.stamps.bag_start_ns, vec![poses[0].t_ns]);
        // the speed estimated from 240 Hz poses is the circle's 1 m/s
        let s = &d.data.trajectories[1].s;
        let mid = d.data.trajectories[1].len() / 2;
        assert!((s[mid * 6 + 3] - 1.0).abs() < 0.01, "vx {}", s[mid * 6 + 3]);
        assert!(
            (s[mid * 6 + 5] - 1.0).abs() < 0.01,
            "omega {}",
            s[mid * 6 + 5]
        );
        // the commands are held: each state's command is the latest at or before its stamp
        let u = &d.data.trajectories[1].u;
        let t = d.stamps.t_ns[1][mid];
        let k = (t / 27_027_027) as f64;
        assert!((u[mid * 2 + 1] - (0.3 + 0.001 * k)).abs() < 1e-12);
        // and the notes say all of it
        let notes = pipeline_notes(r).join("\n");
        assert!(notes.contains("1 gap(s)"), "{notes}");
        assert!(notes.contains("resampled"), "{notes}");
        assert!(notes.contains("zero-order hold"), "{notes}");
        assert!(notes.contains("Hz) and 200 commands"), "{notes}");
        assert!(
            excitation_warnings(&d.data)
                .iter()
                .any(|w| w.contains("delta is constant"))
        );
    }

    #[test]
    fn tf_frame_pairs_parse_or_say_how_to_write_them() {
        let f = TfFrames::parse("world:car").unwrap();
        assert_eq!((f.parent.as_str(), f.child.as_str()), ("world", "car"));
        let f = TfFrames::parse("/map:base_link").unwrap();
        assert_eq!(f.to_string(), "map:base_link");
        for bad in ["world", "world:", ":car", "car:car", "a:b:c", "wor ld:car"] {
            let e = TfFrames::parse(bad).unwrap_err().to_string();
            assert!(e.contains("PARENT:CHILD"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_car_standing_still_is_too_little_excitation() {
        let poses: Vec<PoseSample> = (0..100)
            .map(|i| PoseSample {
                t_ns: i * 10_000_000,
                x: 0.0,
                y: 0.0,
                yaw: 0.0,
            })
            .collect();
        let commands = vec![CommandSample {
            t_ns: 0,
            u: vec![0.0, 0.0],
        }];
        let d = Dataset::from_samples(World::Car, &poses, &commands, &SavGol::default()).unwrap();
        let w = excitation_warnings(&d).join("\n");
        assert!(w.contains("standing still"), "{w}");
        assert!(w.contains("command d is constant"), "{w}");
    }
}
