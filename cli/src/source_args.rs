//! The options every offline tool that reads robot data shares: where the poses come from
//! (a `PoseStamped` or `Odometry` topic, or a tf frame pair), the command topic, and `--strict`.

use clap::Args;
use dynlab_learn::dynamics::data::SavGol;
use dynlab_learn::{Dataset, LoadOptions, TfFrames, Topics, data_warnings, smoothing_note};

/// Pose source, command topic and strictness.
#[derive(Debug, Clone, Args)]
pub struct SourceArgs {
    /// Pose topic: PoseStamped, Odometry, PoseWithCovarianceStamped or TransformStamped (the
    /// type is read from the bag) (default /push/block_pose or /car/pose).
    #[arg(long, conflicts_with = "pose_tf")]
    pub pose_topic: Option<String>,
    /// Poses from tf instead: the pose of CHILD in PARENT from /tf and /tf_static, composing
    /// intermediate frames, e.g. world:car or table:block.
    #[arg(long, value_name = "PARENT:CHILD")]
    pub pose_tf: Option<String>,
    /// Command topic (default /push/action or /car/cmd).
    #[arg(long, alias = "action-topic")]
    pub cmd_topic: Option<String>,
    /// Refuse poses or commands with NaN or infinite values and pose stamps that go back (by
    /// default they are skipped, counted, and the trajectory is split there).
    #[arg(long)]
    pub strict: bool,
    /// Car velocities from Savitzky–Golay fits over this many poses (odd; default: 15 to 45,
    /// the window estimated to give the velocities the smallest error for the poses' noise).
    #[arg(long, value_name = "POSES")]
    pub savgol_window: Option<usize>,
    /// The fits' polynomial degree.
    #[arg(long, default_value_t = 3, value_name = "DEGREE")]
    pub savgol_order: usize,
}

impl SourceArgs {
    /// The loader options these arguments ask for.
    pub fn options(&self) -> anyhow::Result<LoadOptions> {
        Ok(LoadOptions {
            topics: Topics {
                pose: self.pose_topic.clone(),
                cmd: self.cmd_topic.clone(),
            },
            pose_tf: self.pose_tf.as_deref().map(TfFrames::parse).transpose()?,
            strict: self.strict,
        })
    }

    /// The car's smoothing: the window given, or one chosen for the poses' noise.
    pub fn savgol(&self) -> SavGol {
        match self.savgol_window {
            Some(window) => SavGol {
                window,
                order: self.savgol_order,
                ..SavGol::default()
            },
            None => SavGol {
                order: self.savgol_order,
                ..SavGol::adaptive()
            },
        }
    }

    /// The command-line flags that give these settings again (where not the defaults).
    pub fn savgol_flags(&self) -> Vec<String> {
        let mut flags = Vec::new();
        if let Some(w) = self.savgol_window {
            flags.extend(["--savgol-window".to_string(), w.to_string()]);
        }
        if self.savgol_order != SavGol::default().order {
            flags.extend(["--savgol-order".to_string(), self.savgol_order.to_string()]);
        }
        flags
    }

    /// Whether the pose source was named (so the world's default pose topic is not expected).
    pub fn names_pose_source(&self) -> bool {
        self.pose_topic.is_some() || self.pose_tf.is_some()
    }
}

/// Prints what must not go unnoticed about how the data were read — a damaged bag's recovery,
/// skipped poses — as warnings on standard error, and, as notes, car velocities estimated with
/// other than the default smoothing.
pub fn warn_about_data(data: &Dataset) {
    for w in data_warnings(data) {
        eprintln!("warning: {w}");
    }
    for (source, report) in data.sources.iter().zip(&data.reports) {
        if let Some(note) = smoothing_note(report) {
            eprintln!("note: {}: {note}", source.path);
        }
    }
}
