//! From recorded poses and commands to training data.
//!
//! [`build_trajectories`] turns time-stamped poses `(t, x, y, yaw)` and commands at other rates
//! into [`Trajectory`]s: split at gaps, yaw unwrapped, resampled to a fixed step when the
//! stamps jitter, and each pose given the command held over the interval that starts at it
//! (zero-order hold, never a command from the future; see [`CommandHold`]). Everything it
//! changes or drops is counted in a [`PipelineReport`].
//!
//! Real data as they come: a pose with a NaN or infinite value (a motion capture that lost the
//! body) and a pose whose stamp goes back (earlier than the last pose kept) are skipped, counted
//! and listed, and the trajectory is split there, so no transition spans the bad message; when
//! [`STAMP_RESET_RUN`] poses in a row go back (the clock was reset, or one pose was stamped in the
//! future), they start a new trajectory instead of being skipped. A command with a NaN or infinite
//! value is skipped (the previous command stays held).
//! [`PipelineConfig::strict`] refuses such input instead.
//!
//! [`savgol`] smooths and differentiates on (possibly irregular) stamps; [`car_states`] turns a
//! trajectory into the car state `(x, y, ψ, vx, vy, ω)` with body-frame velocities as in Kohler
//! et al. [`windows`], [`split_trajectories`], [`split_windows_overlapping`], [`gather`] and
//! [`Normalizer`] make k-step training batches.

use crate::conventions::unwrap_angles;
use thiserror::Error;

/// Errors of the data pipeline. Each names the problem and what to do about it.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DataError {
    /// No poses at all.
    #[error(
        "no poses: the input has no pose messages; check the pose topic name (e.g. /car/pose or /push/block_pose)"
    )]
    NoPoses,
    /// Poses but no commands.
    #[error(
        "no commands: the input has {poses} poses but no command messages; record the command topic (e.g. /car/cmd or /push/action) as well"
    )]
    NoCommands {
        /// Number of poses seen.
        poses: usize,
    },
    /// A NaN or infinite value (only with [`PipelineConfig::strict`]; otherwise such messages
    /// are skipped).
    #[error(
        "non-finite value in {field} at t = {t_ns} ns ({value}); remove or repair that message \
         (`dynlab bag repair --drop-nonfinite`), or leave out --strict to skip such messages"
    )]
    NonFinite {
        /// Which field (`pose.x`, `command[1]`, …).
        field: String,
        /// Stamp of the message \[ns\].
        t_ns: i64,
        /// The offending value.
        value: f64,
    },
    /// A pose stamped before the pose received before it (only with [`PipelineConfig::strict`];
    /// otherwise such poses are skipped).
    #[error(
        "pose stamps go back: the pose at t = {t_ns} ns comes after one at t = {previous_ns} ns; \
         fix the stamps, or leave out --strict to skip such poses and split the trajectory there"
    )]
    OutOfOrder {
        /// Stamp of the pose that goes back \[ns\].
        t_ns: i64,
        /// Stamp of the pose before it \[ns\].
        previous_ns: i64,
    },
    /// Every pose was skipped.
    #[error(
        "no usable poses: all {poses} poses were skipped ({non_finite} with NaN or infinite \
         values, {out_of_order} with stamps going back); check the pose source"
    )]
    NoUsablePoses {
        /// Poses given.
        poses: usize,
        /// Of which non-finite.
        non_finite: usize,
        /// Of which out of order.
        out_of_order: usize,
    },
    /// Commands of different lengths.
    #[error(
        "command at t = {t_ns} ns has {got} values, earlier commands have {expected}; all commands must have the same dimension"
    )]
    CommandDimension {
        /// Stamp \[ns\].
        t_ns: i64,
        /// Dimension of the first command.
        expected: usize,
        /// Dimension of this one.
        got: usize,
    },
    /// Every pose came before the first command.
    #[error(
        "no pose has a command held at its stamp: the first command is at t = {first_command_ns} ns, the last pose at t = {last_pose_ns} ns; record commands from the start"
    )]
    NoPoseWithCommand {
        /// First command stamp \[ns\].
        first_command_ns: i64,
        /// Last pose stamp \[ns\].
        last_pose_ns: i64,
    },
    /// Not enough poses for the requested windows.
    #[error(
        "too little data: need at least {needed} poses per trajectory for a window of {k} steps; the longest trajectory has {longest} ({trajectories} trajectories); record longer runs or lower the number of steps"
    )]
    TooLittleData {
        /// Poses needed per trajectory (`k + 1`, more with filters).
        needed: usize,
        /// Window length in steps.
        k: usize,
        /// Longest trajectory available.
        longest: usize,
        /// Number of trajectories.
        trajectories: usize,
    },
    /// A setting out of range.
    #[error("invalid setting {name} = {value}: {hint}")]
    InvalidSetting {
        /// Setting name.
        name: &'static str,
        /// Given value.
        value: String,
        /// What is allowed.
        hint: &'static str,
    },
}

/// A measured planar pose.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseSample {
    /// Stamp \[ns\].
    pub t_ns: i64,
    /// Position x \[m\].
    pub x: f64,
    /// Position y \[m\].
    pub y: f64,
    /// Heading \[rad\] (any branch; unwrapped by the pipeline).
    pub yaw: f64,
}

/// A command (car `(δ, d)`, push `(p, φ, ℓ)`) with its stamp.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CommandSample {
    /// Stamp \[ns\].
    pub t_ns: i64,
    /// Command values.
    pub u: Vec<f64>,
}

/// Which command a pose gets: the one held over the interval from this pose to the next.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandHold {
    /// The latest command stamped at or before the pose (strict zero-order hold at the pose
    /// stamp; for streams of commands such as the car's `/car/cmd`).
    AtPose,
    /// The latest command stamped before the *next* pose: for event commands issued just after
    /// the pose they start from (a push published 1 ms after the block pose). Never uses a command
    /// stamped at or after the end of the interval. The last pose of a trajectory gets the command
    /// held at its own stamp (it starts no transition).
    BeforeNextPose,
}

/// Resampling of jittery stamps to a fixed step.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Resample {
    /// Keep the measured stamps.
    Off,
    /// Resample a trajectory to its median step when some interval deviates from the median by
    /// more than `max_jitter` (relative).
    Auto {
        /// Largest tolerated relative deviation of an interval from the median (e.g. 0.1).
        max_jitter: f64,
    },
    /// Always resample to this step \[ns\].
    Fixed {
        /// Step \[ns\].
        dt_ns: i64,
    },
}

/// Settings of [`build_trajectories`]. Every field has a documented default.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct PipelineConfig {
    /// A larger interval between consecutive poses splits the trajectory \[ns\]. `None` (default):
    /// 5 × the median pose interval.
    pub max_gap_ns: Option<i64>,
    /// Command association (default [`CommandHold::AtPose`]).
    pub hold: CommandHold,
    /// Commands older than this at the pose stamp count as missing \[ns\] (default `None`: a
    /// command is held until the next one).
    pub max_command_age_ns: Option<i64>,
    /// Trajectories with fewer poses (after dropping poses without command) are dropped and
    /// counted (default 2).
    pub min_poses: usize,
    /// Resampling (default `Auto { max_jitter: 0.1 }`).
    pub resample: Resample,
    /// Refuse non-finite poses and commands and poses whose stamp goes back, with an error
    /// naming the message (default `false`: skip them, count them and split the trajectory at
    /// each skipped pose).
    pub strict: bool,
    /// Estimate the poses' noise ([`PipelineReport::pose_std`]; default `true`): for poses
    /// streamed along a motion, not for poses a push apart.
    pub estimate_noise: bool,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            max_gap_ns: None,
            hold: CommandHold::AtPose,
            max_command_age_ns: None,
            min_poses: 2,
            resample: Resample::Auto { max_jitter: 0.1 },
            strict: false,
            estimate_noise: true,
        }
    }
}

/// A gap that split a trajectory.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Gap {
    /// Stamp of the last pose before the gap \[ns\].
    pub from_ns: i64,
    /// Stamp of the first pose after it \[ns\].
    pub to_ns: i64,
}

/// Why a pose was skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SkipReason {
    /// A NaN or infinite x, y or yaw.
    NonFinite,
    /// Its stamp is before the last pose kept.
    OutOfOrder,
}

/// A pose [`build_trajectories`] skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SkippedPose {
    /// Its stamp \[ns\].
    pub t_ns: i64,
    /// Why.
    pub reason: SkipReason,
}

/// What [`build_trajectories`] did to the data.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PipelineReport {
    /// Poses given.
    pub poses_in: usize,
    /// Commands given.
    pub commands_in: usize,
    /// Poses dropped because another pose had the same stamp.
    pub duplicate_stamps: usize,
    /// Poses skipped for a NaN or infinite value.
    pub non_finite_poses: usize,
    /// Poses skipped because their stamp goes back.
    pub out_of_order_poses: usize,
    /// Every skipped pose, in input order.
    pub skipped: Vec<SkippedPose>,
    /// Trajectory splits at skipped poses and stamp resets (a run of skipped poses splits once;
    /// none at the start or end of the data).
    pub splits_at_skipped: usize,
    /// Stamps where the pose stamps went back and stayed back ([`STAMP_RESET_RUN`] poses in a
    /// row behind the last kept pose, in order among themselves: a clock reset, or a pose stamped
    /// in the future before them). Each starts a new trajectory; its poses are not skipped.
    pub stamp_resets: Vec<i64>,
    /// Commands skipped for a NaN or infinite value.
    pub non_finite_commands: usize,
    /// Notes about where the samples came from, set by the loader (pose source, a damaged bag's
    /// recovery); empty from [`build_trajectories`].
    pub source_notes: Vec<String>,
    /// The gap threshold used \[ns\].
    pub max_gap_ns: i64,
    /// Gaps that split trajectories.
    pub gaps: Vec<Gap>,
    /// Poses dropped because no command was held yet (or the held one was too old).
    pub poses_without_command: usize,
    /// Trajectories dropped as shorter than `min_poses`, and their poses.
    pub short_trajectories_dropped: usize,
    /// Poses in the dropped short trajectories.
    pub short_trajectory_poses: usize,
    /// Median pose interval over the input \[s\].
    pub median_dt_s: f64,
    /// Largest relative deviation of an interval from its trajectory's median.
    pub max_jitter: f64,
    /// Trajectories resampled to a fixed step.
    pub resampled_trajectories: usize,
    /// Trajectories produced.
    pub trajectories: usize,
    /// Poses in the produced trajectories.
    pub poses_out: usize,
    /// Standard deviations of the poses' noise about a smooth path (`x`, `y` \[m\], yaw
    /// \[rad\]), estimated from the poses as given (before resampling); `None` with too few
    /// poses or without [`PipelineConfig::estimate_noise`].
    #[serde(default)]
    pub pose_std: Option<[f64; 3]>,
    /// The Savitzky–Golay settings car states were estimated with (set by the loader of car
    /// data).
    #[serde(default)]
    pub savgol: Option<SavGol>,
}

/// One uninterrupted run of poses, each with the command held from it to the next pose.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Trajectory {
    /// Stamps \[ns\] (equidistant if resampled).
    pub t_ns: Vec<i64>,
    /// Poses `[x, y, yaw]` with yaw unwrapped (continuous).
    pub pose: Vec<[f64; 3]>,
    /// Commands, `len × dim_u`, row `i` held over `[t_i, t_{i+1})`.
    pub u: Vec<f64>,
    /// Command dimension.
    pub dim_u: usize,
    /// Median step \[s\].
    pub dt: f64,
    /// Whether the trajectory was resampled to a fixed step.
    pub resampled: bool,
}

impl Trajectory {
    /// Number of poses.
    pub fn len(&self) -> usize {
        self.pose.len()
    }
    /// Whether there are no poses.
    pub fn is_empty(&self) -> bool {
        self.pose.is_empty()
    }
    /// Stamps in seconds relative to the first pose.
    pub fn times_s(&self) -> Vec<f64> {
        let t0 = self.t_ns.first().copied().unwrap_or(0);
        self.t_ns.iter().map(|t| (t - t0) as f64 * 1e-9).collect()
    }
}

fn median_i64(v: &mut [i64]) -> i64 {
    if v.is_empty() {
        return 0;
    }
    v.sort_unstable();
    v[v.len() / 2]
}

/// The finite commands (all of one dimension, returned) — a non-finite one is an error when
/// `strict`, otherwise skipped and counted.
fn check_commands<'a>(
    commands: &'a [CommandSample],
    strict: bool,
    rep: &mut PipelineReport,
) -> Result<(usize, Vec<&'a CommandSample>), DataError> {
    let dim = commands.first().map(|c| c.u.len()).unwrap_or(0);
    let mut kept = Vec::with_capacity(commands.len());
    for c in commands {
        if c.u.len() != dim {
            return Err(DataError::CommandDimension {
                t_ns: c.t_ns,
                expected: dim,
                got: c.u.len(),
            });
        }
        match c.u.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            Some((i, v)) if strict => {
                return Err(DataError::NonFinite {
                    field: format!("command[{i}]"),
                    t_ns: c.t_ns,
                    value: *v,
                });
            }
            Some(_) => rep.non_finite_commands += 1,
            None => kept.push(c),
        }
    }
    Ok((dim, kept))
}

/// Poses in a row, in order among themselves but all behind the last pose kept, that count as a
/// reset of the stamps (a new trajectory starts with them) rather than as poses to skip.
pub const STAMP_RESET_RUN: usize = 5;

/// The poses to use, in input order, each with whether the trajectory must split before it
/// (a skipped pose came between it and the previous kept one). Non-finite poses and poses whose
/// stamp goes back are skipped (errors when `strict`), repeated stamps dropped; a run of
/// [`STAMP_RESET_RUN`] poses behind the last kept one starts a new trajectory instead.
fn screen_poses(
    poses: &[PoseSample],
    strict: bool,
    rep: &mut PipelineReport,
) -> Result<(Vec<PoseSample>, Vec<bool>), DataError> {
    let mut kept: Vec<PoseSample> = Vec::with_capacity(poses.len());
    let mut split_before = Vec::with_capacity(poses.len());
    let mut pending = false;
    // poses behind the last kept one, in order among themselves
    let mut behind: Vec<PoseSample> = Vec::new();
    for p in poses {
        let bad = [("pose.x", p.x), ("pose.y", p.y), ("pose.yaw", p.yaw)]
            .into_iter()
            .find(|(_, v)| !v.is_finite());
        let reason = if let Some((field, value)) = bad {
            if strict {
                return Err(DataError::NonFinite {
                    field: field.into(),
                    t_ns: p.t_ns,
                    value,
                });
            }
            rep.non_finite_poses += 1;
            Some(SkipReason::NonFinite)
        } else if let Some(last) = kept.last()
            && p.t_ns < last.t_ns
        {
            if strict {
                return Err(DataError::OutOfOrder {
                    t_ns: p.t_ns,
                    previous_ns: last.t_ns,
                });
            }
            match behind.last() {
                Some(b) if b.t_ns == p.t_ns => {
                    rep.duplicate_stamps += 1;
                    continue;
                }
                Some(b) if b.t_ns < p.t_ns => behind.push(*p),
                _ => {
                    behind.clear();
                    behind.push(*p);
                }
            }
            rep.out_of_order_poses += 1;
            Some(SkipReason::OutOfOrder)
        } else {
            None
        };
        if behind.len() == STAMP_RESET_RUN {
            // The stamps went back and stay back (a clock reset, or one pose stamped in the
            // future before): the run is not skipped but starts a new trajectory.
            let run: Vec<i64> = behind.iter().map(|b| b.t_ns).collect();
            rep.out_of_order_poses -= STAMP_RESET_RUN;
            rep.skipped
                .retain(|s| !(s.reason == SkipReason::OutOfOrder && run.contains(&s.t_ns)));
            rep.stamp_resets.push(run[0]);
            rep.splits_at_skipped += 1;
            for (i, b) in behind.drain(..).enumerate() {
                split_before.push(i == 0);
                kept.push(b);
            }
            pending = false;
            continue;
        }
        if let Some(reason) = reason {
            rep.skipped.push(SkippedPose {
                t_ns: p.t_ns,
                reason,
            });
            pending = true;
            continue;
        }
        if kept.last().is_some_and(|last| last.t_ns == p.t_ns) {
            rep.duplicate_stamps += 1;
            continue;
        }
        behind.clear();
        let split = pending && !kept.is_empty();
        if split {
            rep.splits_at_skipped += 1;
        }
        split_before.push(split);
        kept.push(*p);
        pending = false;
    }
    if kept.is_empty() {
        return Err(DataError::NoUsablePoses {
            poses: poses.len(),
            non_finite: rep.non_finite_poses,
            out_of_order: rep.out_of_order_poses,
        });
    }
    Ok((kept, split_before))
}

/// Index of the latest command with stamp `< t` (`strict`) or `≤ t`.
fn latest_command(cmd_t: &[i64], t: i64, strict: bool) -> Option<usize> {
    let k = if strict {
        cmd_t.partition_point(|&c| c < t)
    } else {
        cmd_t.partition_point(|&c| c <= t)
    };
    k.checked_sub(1)
}

/// Builds trajectories from poses and commands; see the module docs.
pub fn build_trajectories(
    poses: &[PoseSample],
    commands: &[CommandSample],
    cfg: &PipelineConfig,
) -> Result<(Vec<Trajectory>, PipelineReport), DataError> {
    if poses.is_empty() {
        return Err(DataError::NoPoses);
    }
    if commands.is_empty() {
        return Err(DataError::NoCommands { poses: poses.len() });
    }
    if cfg.min_poses < 1 {
        return Err(DataError::InvalidSetting {
            name: "min_poses",
            value: cfg.min_poses.to_string(),
            hint: "must be at least 1",
        });
    }
    if let Some(g) = cfg.max_gap_ns
        && g <= 0
    {
        return Err(DataError::InvalidSetting {
            name: "max_gap_ns",
            value: g.to_string(),
            hint: "must be positive (or unset for 5 × the median interval)",
        });
    }
    let mut rep = PipelineReport {
        poses_in: poses.len(),
        commands_in: commands.len(),
        ..Default::default()
    };
    let (dim_u, mut cs) = check_commands(commands, cfg.strict, &mut rep)?;
    if cs.is_empty() {
        return Err(DataError::NoCommands { poses: poses.len() });
    }
    let (ps, split_before) = screen_poses(poses, cfg.strict, &mut rep)?;
    cs.sort_by_key(|c| c.t_ns);
    let cmd_t: Vec<i64> = cs.iter().map(|c| c.t_ns).collect();

    let mut dts: Vec<i64> = ps
        .windows(2)
        .zip(&split_before[1..])
        .filter(|(_, split)| !**split)
        .map(|(w, _)| w[1].t_ns - w[0].t_ns)
        .collect();
    let med = median_i64(&mut dts);
    rep.median_dt_s = med as f64 * 1e-9;
    let max_gap = cfg.max_gap_ns.unwrap_or((5 * med).max(1));
    rep.max_gap_ns = max_gap;

    // split at gaps and at skipped poses
    let mut pieces: Vec<Vec<PoseSample>> = vec![Vec::new()];
    for (i, p) in ps.iter().enumerate() {
        if split_before[i] {
            pieces.push(Vec::new());
        } else if i > 0 && p.t_ns - ps[i - 1].t_ns > max_gap {
            rep.gaps.push(Gap {
                from_ns: ps[i - 1].t_ns,
                to_ns: p.t_ns,
            });
            pieces.push(Vec::new());
        }
        if let Some(last) = pieces.last_mut() {
            last.push(*p);
        }
    }

    let mut out = Vec::new();
    let mut noise = NoiseResiduals::default();
    for piece in pieces {
        let mut t: Vec<i64> = piece.iter().map(|p| p.t_ns).collect();
        let mut yaw: Vec<f64> = piece.iter().map(|p| p.yaw).collect();
        unwrap_angles(&mut yaw);
        let mut pose: Vec<[f64; 3]> = piece
            .iter()
            .zip(&yaw)
            .map(|(p, &w)| [p.x, p.y, w])
            .collect();
        let mut d: Vec<i64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let med_i = median_i64(&mut d);
        let jitter = if med_i > 0 {
            t.windows(2)
                .map(|w| ((w[1] - w[0] - med_i) as f64 / med_i as f64).abs())
                .fold(0.0, f64::max)
        } else {
            0.0
        };
        rep.max_jitter = rep.max_jitter.max(jitter);
        let step = match cfg.resample {
            Resample::Off => None,
            Resample::Auto { max_jitter } => (jitter > max_jitter && med_i > 0).then_some(med_i),
            Resample::Fixed { dt_ns } => (dt_ns > 0).then_some(dt_ns),
        };
        noise.add(&t, &pose);
        let mut resampled = false;
        if let Some(step) = step
            && t.len() >= 2
        {
            let (nt, np) = resample_linear(&t, &pose, step);
            t = nt;
            pose = np;
            resampled = true;
            rep.resampled_trajectories += 1;
        }
        // command association
        let mut keep_t = Vec::new();
        let mut keep_pose = Vec::new();
        let mut u = Vec::new();
        for i in 0..t.len() {
            let idx = match cfg.hold {
                CommandHold::AtPose => latest_command(&cmd_t, t[i], false),
                CommandHold::BeforeNextPose => match t.get(i + 1) {
                    Some(&tn) => latest_command(&cmd_t, tn, true),
                    None => latest_command(&cmd_t, t[i], false),
                },
            };
            let idx = idx.filter(|&k| match cfg.max_command_age_ns {
                Some(age) => t[i] - cmd_t[k] <= age,
                None => true,
            });
            match idx {
                Some(k) => {
                    keep_t.push(t[i]);
                    keep_pose.push(pose[i]);
                    u.extend_from_slice(&cs[k].u);
                }
                None => rep.poses_without_command += 1,
            }
        }
        if keep_t.len() < cfg.min_poses.max(1) {
            if !keep_t.is_empty() {
                rep.short_trajectories_dropped += 1;
                rep.short_trajectory_poses += keep_t.len();
            }
            continue;
        }
        let mut d: Vec<i64> = keep_t.windows(2).map(|w| w[1] - w[0]).collect();
        let dt = median_i64(&mut d) as f64 * 1e-9;
        out.push(Trajectory {
            t_ns: keep_t,
            pose: keep_pose,
            u,
            dim_u,
            dt,
            resampled,
        });
    }
    if out.is_empty() && rep.poses_without_command > 0 && rep.short_trajectories_dropped == 0 {
        return Err(DataError::NoPoseWithCommand {
            first_command_ns: cmd_t[0],
            last_pose_ns: ps.last().map(|p| p.t_ns).unwrap_or(0),
        });
    }
    rep.trajectories = out.len();
    rep.poses_out = out.iter().map(|t| t.len()).sum();
    rep.pose_std = cfg.estimate_noise.then(|| noise.std()).flatten();
    Ok((out, rep))
}

/// Linear interpolation of poses (yaw already unwrapped) onto `t0 + k·step` up to the last stamp.
fn resample_linear(t: &[i64], pose: &[[f64; 3]], step: i64) -> (Vec<i64>, Vec<[f64; 3]>) {
    let (t0, t1) = (t[0], t[t.len() - 1]);
    let mut nt = Vec::new();
    let mut np = Vec::new();
    let mut j = 0;
    let mut tk = t0;
    while tk <= t1 {
        while j + 1 < t.len() - 1 && t[j + 1] < tk {
            j += 1;
        }
        let (ta, tb) = (t[j], t[j + 1]);
        let a = if tb > ta {
            (tk - ta) as f64 / (tb - ta) as f64
        } else {
            0.0
        };
        let a = a.clamp(0.0, 1.0);
        let p = [0, 1, 2].map(|c| pose[j][c] + a * (pose[j + 1][c] - pose[j][c]));
        nt.push(tk);
        np.push(p);
        tk += step;
    }
    (nt, np)
}

/// Savitzky–Golay settings: a least-squares polynomial of degree `order` over `window` samples.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SavGol {
    /// Samples per window (odd, > `order`; default 15: ≈ 60 ms at 240 Hz): the position's
    /// (x, y), and the yaw's unless `yaw_window` is set.
    pub window: usize,
    /// Polynomial degree (default 3).
    pub order: usize,
    /// Samples per window for the yaw (odd, > `order`; default: `window`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub yaw_window: Option<usize>,
    /// Whether the car's loader chooses the windows for the poses' noise and the motion
    /// ([`SavGol::adapted`]); the settings it records are the ones it took.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub adaptive: bool,
}

impl Default for SavGol {
    fn default() -> Self {
        Self {
            window: 15,
            order: 3,
            yaw_window: None,
            adaptive: false,
        }
    }
}

impl std::fmt::Display for SavGol {
    /// `Savitzky–Golay fits of degree 3 over 27 poses (x, y) and 15 (yaw)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Savitzky–Golay fits of degree {} over {} poses (x, y) and {} (yaw)",
            self.order,
            self.window,
            self.yaw_window.unwrap_or(self.window)
        )
    }
}

/// [`SavGol::adapted`] tries windows from the given one in steps of this many samples…
const WIDEN_STEP: usize = 6;
/// … up to this many times the given one.
const WIDEN_MAX: usize = 3;

impl SavGol {
    /// The default windows, widened where that gives the velocities a smaller error
    /// ([`SavGol::adapted`]).
    pub fn adaptive() -> Self {
        Self {
            adaptive: true,
            ..Self::default()
        }
    }

    /// The samples one estimate of every component needs: the longer of the two windows.
    pub fn span(&self) -> usize {
        self.window.max(self.yaw_window.unwrap_or(self.window))
    }

    /// The settings for pose component `c` (0 x, 1 y, 2 yaw), with the window shortened to
    /// the largest odd one of at most `n` samples (never below `order + 2`).
    pub fn for_component(&self, c: usize, n: usize) -> SavGol {
        let w = match c {
            2 => self.yaw_window.unwrap_or(self.window),
            _ => self.window,
        };
        let fit = if n.is_multiple_of(2) {
            n.saturating_sub(1)
        } else {
            n
        };
        SavGol {
            window: w.min(fit).max((self.order + 2) | 1),
            yaw_window: None,
            adaptive: false,
            ..*self
        }
    }

    /// The windows that give the car's velocities the smallest error, for car trajectories on
    /// an equidistant step with white pose noise of `pose_std` (σ of x, y \[m\] and the yaw
    /// \[rad\]). A wider window leaves less noise in a slope and bends it more where the motion
    /// changes within the window; the error is the sum of both. For each window `w` tried (from
    /// `window` in steps of 6 samples, to three times `window`), the noise follows from the
    /// filter's weights (`σ² ‖c_w‖²`), and the bend from the data: the mean square difference
    /// between the slopes of `w` and of `window`, less the part of it the noise gives
    /// (`σ² ‖c_w − c_window‖²`). The position's window minimises the error of `vx` and `vy`
    /// (body frame), each relative to its spread, the yaw's that of `ω`. The given window's own
    /// bend is taken as none: where it bends too, the choice errs wide. Only samples a window of
    /// every width fits centred on count. Without trajectories long enough, or without noise,
    /// the settings stay.
    pub fn adapted(&self, trajs: &[Trajectory], pose_std: [f64; 3]) -> SavGol {
        let fixed = SavGol {
            adaptive: false,
            ..*self
        };
        let w0 = [self.window, self.yaw_window.unwrap_or(self.window)];
        let widest = w0.map(|w| WIDEN_MAX * w);
        let long: Vec<&Trajectory> = trajs
            .iter()
            .filter(|t| t.len() >= widest[0].max(widest[1]) && t.dt > 0.0)
            .collect();
        let sigma = [
            ((pose_std[0].powi(2) + pose_std[1].powi(2)) / 2.0).sqrt(),
            pose_std[2],
        ];
        let Some(dt) = long.first().map(|t| t.dt) else {
            return fixed;
        };
        // per trajectory: its stamps, its pose columns and the yaw of the `w0` fit
        let mut prepared = Vec::with_capacity(long.len());
        for t in &long {
            let times = t.times_s();
            let cols: [Vec<f64>; 3] = [0, 1, 2].map(|c| t.pose.iter().map(|p| p[c]).collect());
            let yaw = SavGol {
                window: w0[1],
                ..fixed
            };
            let Ok((psi, _)) = savgol(&times, &cols[2], &yaw.for_component(0, t.len())) else {
                return fixed;
            };
            prepared.push((times, cols, psi));
        }
        // the slopes of pose component `c` of a prepared trajectory from fits of `w` samples
        let slopes =
            |(times, cols, _): &(Vec<f64>, [Vec<f64>; 3], Vec<f64>), c: usize, w: usize| {
                let sg = SavGol { window: w, ..fixed };
                savgol(times, &cols[c], &sg.for_component(0, times.len())).map(|(_, d)| d)
            };
        let mut chosen = w0;
        for g in 0..2 {
            if sigma[g] <= 0.0 {
                continue;
            }
            let tried: Vec<usize> = (w0[g]..=widest[g]).step_by(WIDEN_STEP).collect();
            let c0 = derivative_weights(w0[g], self.order, dt);
            // per window: the mean square slope difference to `w0` of each velocity component
            let mut msd = vec![[0.0; 2]; tried.len()];
            // the reference slopes' mean and mean square, for their spread
            let mut mean = [0.0; 2];
            let mut sq = [0.0; 2];
            let mut n = 0.0;
            for p in &prepared {
                let psi = &p.2;
                let inner = widest[g] / 2..psi.len() - widest[g] / 2;
                // the components' slopes of window w: (vx, vy) or (ω)
                let velocities = |w: usize| -> Option<Vec<[f64; 2]>> {
                    if g == 0 {
                        let xd = slopes(p, 0, w).ok()?;
                        let yd = slopes(p, 1, w).ok()?;
                        Some(
                            inner
                                .clone()
                                .map(|i| {
                                    let (s, c) = psi[i].sin_cos();
                                    [c * xd[i] + s * yd[i], -s * xd[i] + c * yd[i]]
                                })
                                .collect(),
                        )
                    } else {
                        let wd = slopes(p, 2, w).ok()?;
                        Some(inner.clone().map(|i| [wd[i], 0.0]).collect())
                    }
                };
                let Some(reference) = velocities(w0[g]) else {
                    return fixed;
                };
                for v in &reference {
                    for c in 0..2 {
                        mean[c] += v[c];
                        sq[c] += v[c] * v[c];
                    }
                }
                n += reference.len() as f64;
                for (k, &w) in tried.iter().enumerate().skip(1) {
                    let Some(vs) = velocities(w) else {
                        return fixed;
                    };
                    for (v, r) in vs.iter().zip(&reference) {
                        for c in 0..2 {
                            msd[k][c] += (v[c] - r[c]).powi(2);
                        }
                    }
                }
            }
            if n < 2.0 {
                return fixed;
            }
            let var0 = sigma[g].powi(2) * norm2(&c0);
            // each component's spread net of its noise (at least the noise, for a weight)
            let weight = [0, 1].map(|c| {
                let v = sq[c] / n - (mean[c] / n).powi(2);
                1.0 / (v - var0).max(var0)
            });
            let components = if g == 0 { 2 } else { 1 };
            let error = |k: usize| {
                let cw = derivative_weights(tried[k], self.order, dt);
                let noise = sigma[g].powi(2) * norm2(&cw);
                let noise_diff = sigma[g].powi(2) * norm2(&centred_difference(&cw, &c0));
                (0..components)
                    .map(|c| weight[c] * ((msd[k][c] / n - noise_diff).max(0.0) + noise))
                    .sum::<f64>()
            };
            let best = (0..tried.len())
                .min_by(|&a, &b| error(a).total_cmp(&error(b)))
                .unwrap_or(0);
            chosen[g] = tried[best];
        }
        SavGol {
            window: chosen[0],
            yaw_window: (chosen[1] != chosen[0]).then_some(chosen[1]),
            ..fixed
        }
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), DataError> {
        if let Some(w) = self.yaw_window {
            SavGol {
                window: w,
                yaw_window: None,
                ..*self
            }
            .validate()?;
        }
        if self.window.is_multiple_of(2) || self.window < 3 {
            return Err(DataError::InvalidSetting {
                name: "savgol.window",
                value: self.window.to_string(),
                hint: "must be odd and at least 3",
            });
        }
        if self.order + 1 >= self.window || self.order == 0 {
            return Err(DataError::InvalidSetting {
                name: "savgol.order",
                value: self.order.to_string(),
                hint: "must be at least 1 and smaller than window − 1",
            });
        }
        Ok(())
    }
}

/// Least squares `min ‖A c − b‖` by modified Gram–Schmidt QR; `a` is `m × k` row-major.
fn lstsq(a: &[f64], m: usize, k: usize, b: &[f64]) -> Option<Vec<f64>> {
    let mut q: Vec<Vec<f64>> = (0..k)
        .map(|j| (0..m).map(|i| a[i * k + j]).collect())
        .collect();
    let mut r = vec![0.0; k * k];
    for j in 0..k {
        for p in 0..j {
            let d: f64 = (0..m).map(|i| q[p][i] * q[j][i]).sum();
            r[p * k + j] = d;
            for i in 0..m {
                q[j][i] -= d * q[p][i];
            }
        }
        let nrm = q[j].iter().map(|x| x * x).sum::<f64>().sqrt();
        if nrm < 1e-12 {
            return None;
        }
        r[j * k + j] = nrm;
        q[j].iter_mut().for_each(|x| *x /= nrm);
    }
    let qtb: Vec<f64> = (0..k)
        .map(|j| (0..m).map(|i| q[j][i] * b[i]).sum())
        .collect();
    let mut c = vec![0.0; k];
    for j in (0..k).rev() {
        let s: f64 = (j + 1..k).map(|p| r[j * k + p] * c[p]).sum();
        c[j] = (qtb[j] - s) / r[j * k + j];
    }
    Some(c)
}

/// The design matrix of a local polynomial of `k` coefficients over the stamps `t` (row-major
/// into `a`, `t.len() × k`), in `τ = (t − centre)/scale` with `scale` half the stamps' span,
/// which it returns; `None` (and `scale` 1) when the stamps do not span any time.
fn local_design(t: &[f64], centre: f64, k: usize, a: &mut [f64]) -> Option<f64> {
    let span = (t[t.len() - 1] - t[0]) / 2.0;
    let scale = if span > 0.0 { span } else { 1.0 };
    for (r, &tr) in t.iter().enumerate() {
        let tau = (tr - centre) / scale;
        let mut p = 1.0;
        for c in 0..k {
            a[r * k + c] = p;
            p *= tau;
        }
    }
    (span > 0.0).then_some(scale)
}

/// The derivative weights `c` at the centre of a Savitzky–Golay window of `window` samples and
/// degree `order` on the step `dt` (the slope is `Σ c_j y_j`; white noise of σ gives it a noise
/// of `σ · ‖c‖`), reversed. The filter is linear and alike at every interior sample, so the
/// slopes it gives a unit impulse, at the samples whose window holds it, are those weights;
/// empty for settings [`savgol`] refuses.
fn derivative_weights(window: usize, order: usize, dt: f64) -> Vec<f64> {
    let n = 2 * window + 1;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let mut impulse = vec![0.0; n];
    impulse[window] = 1.0;
    let sg = SavGol {
        window,
        order,
        ..SavGol::default()
    };
    let h = window / 2;
    savgol(&t, &impulse, &sg).map_or(Vec::new(), |(_, slope)| {
        slope[window - h..=window + h].to_vec()
    })
}

fn norm2(c: &[f64]) -> f64 {
    c.iter().map(|v| v * v).sum()
}

/// `a − b` for centred weights, the shorter `b` padded with zeros on both sides.
fn centred_difference(a: &[f64], b: &[f64]) -> Vec<f64> {
    let off = a.len().saturating_sub(b.len()) / 2;
    a.iter()
        .enumerate()
        .map(|(i, v)| v - i.checked_sub(off).and_then(|j| b.get(j)).unwrap_or(&0.0))
        .collect()
}

/// Savitzky–Golay smoothing and first derivative of `y(t)` on arbitrary increasing stamps `t`
/// \[s\]: at each sample, a polynomial of degree `order` is fitted by least squares to the
/// `window` samples centred on it (in `t`, so irregular stamps are handled exactly), and its value
/// and slope at that sample's stamp are returned. On equidistant stamps this is the classic
/// filter.
///
/// Edges: within half a window of either end, the window is shifted to stay inside the data
/// (the first/last `window` samples) and the polynomial is evaluated off-centre at the sample's
/// stamp, as scipy's `savgol_filter(mode="interp")` does. Edge values are therefore noisier than
/// interior ones.
pub fn savgol(t: &[f64], y: &[f64], sg: &SavGol) -> Result<(Vec<f64>, Vec<f64>), DataError> {
    sg.validate()?;
    let n = t.len();
    if n < sg.window {
        return Err(DataError::TooLittleData {
            needed: sg.window,
            k: 0,
            longest: n,
            trajectories: 1,
        });
    }
    let h = sg.window / 2;
    let k = sg.order + 1;
    let mut val = vec![0.0; n];
    let mut der = vec![0.0; n];
    let mut a = vec![0.0; sg.window * k];
    for i in 0..n {
        let lo = i.saturating_sub(h).min(n - sg.window);
        let scale = local_design(&t[lo..lo + sg.window], t[i], k, &mut a).unwrap_or(1.0);
        let c =
            lstsq(&a, sg.window, k, &y[lo..lo + sg.window]).ok_or(DataError::InvalidSetting {
                name: "stamps",
                value: format!("{}", t[i]),
                hint: "repeated stamps inside a Savitzky–Golay window; deduplicate the poses",
            })?;
        val[i] = c[0];
        der[i] = c[1] / scale;
    }
    Ok((val, der))
}

/// The noise of a trajectory set's poses about a smooth path, and the Savitzky–Golay settings
/// their car states were estimated with: what [`car_state_noise`] needs to draw the noise of
/// those states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseNoise {
    /// Standard deviations of `x`, `y` \[m\] and the yaw \[rad\] ([`PipelineReport::pose_std`]).
    pub std: [f64; 3],
    /// The settings the states were smoothed with.
    pub savgol: SavGol,
}

/// Samples of the local fits [`NoiseResiduals`] standardises residuals with, and their degree.
const NOISE_FIT: SavGol = SavGol {
    window: 9,
    order: 3,
    yaw_window: None,
    adaptive: false,
};

/// Smallest number of residuals [`NoiseResiduals::std`] estimates from.
const MIN_NOISE_SAMPLES: usize = 50;

/// The poses' residuals about local cubic fits on their own stamps, standardised by their
/// leverage (`r/√(1 − h)`, which has the noise's variance for white noise about a path the
/// cubic follows): from these [`NoiseResiduals::std`] estimates the noise. Taken before any
/// resampling, whose interpolation averages neighbouring poses and hides part of the noise
/// from anything that looks from one pose to the next, but not from a velocity estimated over
/// a window of them.
#[derive(Default)]
struct NoiseResiduals([Vec<f64>; 3]);

impl NoiseResiduals {
    /// Adds the residuals of one run of poses at stamps `t` \[ns\].
    fn add(&mut self, t: &[i64], pose: &[[f64; 3]]) {
        let (w, k) = (NOISE_FIT.window, NOISE_FIT.order + 1);
        let h = w / 2;
        if t.len() < w {
            return;
        }
        let ts: Vec<f64> = t.iter().map(|&v| (v - t[0]) as f64 * 1e-9).collect();
        let mut a = vec![0.0; w * k];
        let mut unit = vec![0.0; w];
        unit[h] = 1.0;
        for i in h..t.len() - h {
            let lo = i - h;
            if local_design(&ts[lo..lo + w], ts[i], k, &mut a).is_none() {
                continue;
            }
            // the fit's weights of the centre's fitted value: the hat matrix is symmetric, so
            // they are the fit of the centre's unit vector, evaluated at every sample
            let Some(c) = lstsq(&a, w, k, &unit) else {
                continue;
            };
            let g: Vec<f64> = (0..w)
                .map(|r| (0..k).map(|j| a[r * k + j] * c[j]).sum())
                .collect();
            // the leverage of the centre sample: its own weight in its fitted value
            let lev = g[h];
            if lev.is_nan() || lev >= 1.0 - 1e-9 {
                continue;
            }
            for (c, out) in self.0.iter_mut().enumerate() {
                let fit: f64 = (0..w).map(|r| g[r] * pose[lo + r][c]).sum();
                let z = (pose[i][c] - fit) / (1.0 - lev).sqrt();
                if z.is_finite() {
                    out.push(z);
                }
            }
        }
    }

    /// The noise's standard deviation per `x`, `y`, yaw: 1.4826 × the median absolute
    /// standardised residual (robust to the few residuals at a jump of the path); `None` with
    /// fewer than [`MIN_NOISE_SAMPLES`] of them.
    fn std(mut self) -> Option<[f64; 3]> {
        let mut out = [0.0; 3];
        for (o, z) in out.iter_mut().zip(self.0.iter_mut()) {
            if z.len() < MIN_NOISE_SAMPLES {
                return None;
            }
            let mut dev: Vec<f64> = z.iter().map(|v| v.abs()).collect();
            *o = 1.4826 * median_f64(&mut dev);
        }
        Some(out)
    }
}

fn median_f64(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Car states `s` (`len × 6`, as [`car_states`] gives them, on the equidistant step `dt`) with
/// one draw of pose noise of `noise` passed through the same estimation: white noise on `x`,
/// `y`, yaw (`normal` draws standard normals), smoothed and differentiated with
/// `noise.savgol` over the whole trajectory, added to the pose and to the
/// world-frame velocity, which is rotated into the body frame by the noisy yaw. The noise of
/// the states the data already hold has this structure to first order: estimated states plus a
/// second draw hold twice their noise.
pub fn car_state_noise(
    s: &[f64],
    dt: f64,
    noise: &PoseNoise,
    normal: &mut dyn FnMut() -> f64,
) -> Result<Vec<f64>, DataError> {
    let n = s.len() / 6;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let mut smoothed = Vec::with_capacity(3);
    for c in 0..3 {
        let w: Vec<f64> = (0..n).map(|_| noise.std[c] * normal()).collect();
        smoothed.push(savgol(&t, &w, &noise.savgol.for_component(c, n))?);
    }
    let mut out = s.to_vec();
    for i in 0..n {
        let r = &mut out[i * 6..(i + 1) * 6];
        let (sn, cs) = r[2].sin_cos();
        let xd = cs * r[3] - sn * r[4] + smoothed[0].1[i];
        let yd = sn * r[3] + cs * r[4] + smoothed[1].1[i];
        r[0] += smoothed[0].0[i];
        r[1] += smoothed[1].0[i];
        r[2] += smoothed[2].0[i];
        r[5] += smoothed[2].1[i];
        let (sn, cs) = r[2].sin_cos();
        r[3] = cs * xd + sn * yd;
        r[4] = -sn * xd + cs * yd;
    }
    Ok(out)
}

/// Car states `[x, y, ψ, vx, vy, ω]` along a trajectory (Kohler et al.): x, y and the unwrapped
/// yaw are smoothed with [`savgol`], their time derivatives come from the same fits, and the
/// world velocity is rotated into the body frame: `vx = cos ψ·ẋ + sin ψ·ẏ`,
/// `vy = −sin ψ·ẋ + cos ψ·ẏ`, `ω = ψ̇`. The pose in the state is the smoothed pose (ψ unwrapped).
/// x and y take `sg.window`, the yaw `sg.yaw_window` (if set); a window longer than the
/// trajectory is shortened to it.
pub fn car_states(traj: &Trajectory, sg: &SavGol) -> Result<Vec<[f64; 6]>, DataError> {
    let t = traj.times_s();
    let col = |c: usize| traj.pose.iter().map(|p| p[c]).collect::<Vec<_>>();
    let n = t.len();
    let (x, xd) = savgol(&t, &col(0), &sg.for_component(0, n))?;
    let (y, yd) = savgol(&t, &col(1), &sg.for_component(1, n))?;
    let (psi, psid) = savgol(&t, &col(2), &sg.for_component(2, n))?;
    Ok((0..t.len())
        .map(|i| {
            let (s, c) = psi[i].sin_cos();
            [
                x[i],
                y[i],
                psi[i],
                c * xd[i] + s * yd[i],
                -s * xd[i] + c * yd[i],
                psid[i],
            ]
        })
        .collect())
}

/// A trajectory of model states with the commands held from each state to the next: what
/// training windows index.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StateTrajectory {
    /// States, `len × dim_s`.
    pub s: Vec<f64>,
    /// Commands, `len × dim_u`.
    pub u: Vec<f64>,
    /// State dimension.
    pub dim_s: usize,
    /// Command dimension.
    pub dim_u: usize,
    /// Model step \[s\].
    pub dt: f64,
}

impl StateTrajectory {
    /// Number of states.
    pub fn len(&self) -> usize {
        self.s.len() / self.dim_s.max(1)
    }
    /// Whether it has no states.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Pushing: the poses themselves are the states.
    pub fn from_poses(traj: &Trajectory) -> Self {
        Self {
            s: traj.pose.iter().flatten().copied().collect(),
            u: traj.u.clone(),
            dim_s: 3,
            dim_u: traj.dim_u,
            dt: traj.dt,
        }
    }
    /// Car: states from [`car_states`].
    pub fn car(traj: &Trajectory, sg: &SavGol) -> Result<Self, DataError> {
        let s = car_states(traj, sg)?;
        Ok(Self {
            s: s.iter().flatten().copied().collect(),
            u: traj.u.clone(),
            dim_s: 6,
            dim_u: traj.dim_u,
            dt: traj.dt,
        })
    }
}

/// A k-step training window: states `start … start + k` and commands `start … start + k − 1` of
/// one trajectory.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Window {
    /// Trajectory index.
    pub trajectory: usize,
    /// First state index.
    pub start: usize,
}

/// All k-step windows inside trajectories of the given lengths (never crossing a boundary).
/// Errors with [`DataError::TooLittleData`] when no trajectory has `k + 1` states.
pub fn windows(lengths: &[usize], k: usize) -> Result<Vec<Window>, DataError> {
    if k == 0 {
        return Err(DataError::InvalidSetting {
            name: "steps",
            value: "0".into(),
            hint: "a window needs at least 1 step",
        });
    }
    let mut w = Vec::new();
    for (ti, &len) in lengths.iter().enumerate() {
        if len > k {
            w.extend((0..len - k).map(|start| Window {
                trajectory: ti,
                start,
            }));
        }
    }
    if w.is_empty() {
        return Err(DataError::TooLittleData {
            needed: k + 1,
            k,
            longest: lengths.iter().copied().max().unwrap_or(0),
            trajectories: lengths.len(),
        });
    }
    Ok(w)
}

/// A k-step batch: initial states, commands and the measured states after each step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WindowBatch {
    /// Windows in the batch.
    pub n: usize,
    /// Steps per window.
    pub k: usize,
    /// Initial states, `n × dim_s`.
    pub s0: Vec<f64>,
    /// Commands, `k × n × dim_u` (step-major, so step `j` is one contiguous batch).
    pub u: Vec<f64>,
    /// Measured states after each step, `k × n × dim_s` (step-major).
    pub target: Vec<f64>,
}

/// Gathers windows into a step-major batch (each step's samples contiguous, ready for one
/// batched model call per step).
pub fn gather(trajs: &[StateTrajectory], ws: &[Window], k: usize) -> WindowBatch {
    let n = ws.len();
    let (ds, du) = trajs.first().map(|t| (t.dim_s, t.dim_u)).unwrap_or((0, 0));
    let mut b = WindowBatch {
        n,
        k,
        s0: Vec::with_capacity(n * ds),
        u: vec![0.0; k * n * du],
        target: vec![0.0; k * n * ds],
    };
    for (i, w) in ws.iter().enumerate() {
        let t = &trajs[w.trajectory];
        b.s0.extend_from_slice(&t.s[w.start * ds..(w.start + 1) * ds]);
        for j in 0..k {
            let src_u = &t.u[(w.start + j) * du..(w.start + j + 1) * du];
            b.u[(j * n + i) * du..(j * n + i + 1) * du].copy_from_slice(src_u);
            let src_s = &t.s[(w.start + j + 1) * ds..(w.start + j + 2) * ds];
            b.target[(j * n + i) * ds..(j * n + i + 1) * ds].copy_from_slice(src_s);
        }
    }
    b
}

/// SplitMix64 (Steele, Lea & Flood 2014): a tiny seeded generator with the same stream on
/// every platform, used for reproducible splits and shuffles.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform integer in `0..n` (`n > 0`), by rejection (no modulo bias).
    pub fn below(&mut self, n: u64) -> u64 {
        let zone = u64::MAX - u64::MAX % n;
        loop {
            let x = self.next_u64();
            if x < zone {
                return x % n;
            }
        }
    }
    /// Fisher–Yates shuffle.
    pub fn shuffle<T>(&mut self, v: &mut [T]) {
        for i in (1..v.len()).rev() {
            let j = self.below(i as u64 + 1) as usize;
            v.swap(i, j);
        }
    }
}

/// A train/validation split.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Split<T> {
    /// Training items.
    pub train: Vec<T>,
    /// Validation items.
    pub validation: Vec<T>,
}

fn check_fraction(f: f64) -> Result<(), DataError> {
    if !(f > 0.0 && f < 1.0) {
        return Err(DataError::InvalidSetting {
            name: "validation_fraction",
            value: f.to_string(),
            hint: "must be strictly between 0 and 1 (e.g. 0.2)",
        });
    }
    Ok(())
}

/// Splits trajectory indices `0..n` by whole trajectories (seeded): `round(n·fraction)`
/// validation trajectories, at least one each side. Windows of a validation trajectory never
/// overlap training data.
pub fn split_trajectories(
    n: usize,
    validation_fraction: f64,
    seed: u64,
) -> Result<Split<usize>, DataError> {
    check_fraction(validation_fraction)?;
    if n < 2 {
        return Err(DataError::InvalidSetting {
            name: "trajectories",
            value: n.to_string(),
            hint: "a split by whole trajectories needs at least 2 trajectories; record more runs or split the bag at gaps",
        });
    }
    let mut idx: Vec<usize> = (0..n).collect();
    SplitMix64::new(seed).shuffle(&mut idx);
    let nv = ((n as f64 * validation_fraction).round() as usize).clamp(1, n - 1);
    let mut validation = idx[..nv].to_vec();
    let mut train = idx[nv..].to_vec();
    validation.sort_unstable();
    train.sort_unstable();
    Ok(Split { train, validation })
}

/// The split of Tu & Lin for comparison: all windows shuffled (seeded) and cut 80/20 (or
/// `validation_fraction`), so validation windows overlap training windows and share
/// trajectories (leakage; use [`split_trajectories`] for honest numbers).
pub fn split_windows_overlapping(
    ws: &[Window],
    validation_fraction: f64,
    seed: u64,
) -> Result<Split<Window>, DataError> {
    check_fraction(validation_fraction)?;
    let mut v = ws.to_vec();
    SplitMix64::new(seed).shuffle(&mut v);
    let nv = (v.len() as f64 * validation_fraction).round() as usize;
    let validation = v[..nv].to_vec();
    let train = v[nv..].to_vec();
    Ok(Split { train, validation })
}

/// Per-dimension normalisation statistics `x̃ = (x − mean) / std`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Normalizer {
    /// Mean per dimension.
    pub mean: Vec<f64>,
    /// Standard deviation per dimension (1 for constant dimensions).
    pub std: Vec<f64>,
    /// Dimensions whose spread was below `min_std` (their std is set to 1, so they are only
    /// centred; report them: a constant input carries no information).
    pub constant_dims: Vec<usize>,
}

impl Normalizer {
    /// Statistics of `rows` (row-major, width `dim`). A dimension with standard deviation below
    /// `min_std` (absolute, e.g. 1e-8) gets std 1 and is listed in `constant_dims`.
    pub fn fit(rows: &[f64], dim: usize, min_std: f64) -> Result<Self, DataError> {
        if dim == 0 || rows.len() < dim || !rows.len().is_multiple_of(dim) {
            return Err(DataError::TooLittleData {
                needed: 1,
                k: 0,
                longest: rows.len() / dim.max(1),
                trajectories: 0,
            });
        }
        let n = (rows.len() / dim) as f64;
        let mut mean = vec![0.0; dim];
        for r in rows.chunks_exact(dim) {
            for (m, x) in mean.iter_mut().zip(r) {
                *m += x;
            }
        }
        mean.iter_mut().for_each(|m| *m /= n);
        let mut var = vec![0.0; dim];
        for r in rows.chunks_exact(dim) {
            for ((v, x), m) in var.iter_mut().zip(r).zip(&mean) {
                *v += (x - m) * (x - m);
            }
        }
        let mut std = Vec::with_capacity(dim);
        let mut constant_dims = Vec::new();
        for (d, v) in var.iter().enumerate() {
            let s = (v / n).sqrt();
            if s.is_nan() || s < min_std || !s.is_finite() {
                std.push(1.0);
                constant_dims.push(d);
            } else {
                std.push(s);
            }
        }
        Ok(Self {
            mean,
            std,
            constant_dims,
        })
    }
    /// Normalises rows in place.
    pub fn normalize(&self, rows: &mut [f64]) {
        let d = self.mean.len();
        for r in rows.chunks_exact_mut(d) {
            for ((x, m), s) in r.iter_mut().zip(&self.mean).zip(&self.std) {
                *x = (*x - m) / s;
            }
        }
    }
    /// Undoes [`Normalizer::normalize`] in place.
    pub fn denormalize(&self, rows: &mut [f64]) {
        let d = self.mean.len();
        for r in rows.chunks_exact_mut(d) {
            for ((x, m), s) in r.iter_mut().zip(&self.mean).zip(&self.std) {
                *x = *x * s + m;
            }
        }
    }
}
