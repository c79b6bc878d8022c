//! `dynlab compare`: a model (and optionally a baseline) held against bags — errors per
//! dimension, over time, against their causes, over position, residual correlations, worst
//! segments — as a terminal summary, `DIR/report.json` and `DIR/index.html`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use dynlab_diagnose::compare::{CompareConfig, compare_with_baseline, html};
use dynlab_learn::{LoadOptions, load_bags_with, load_model};

/// `dynlab compare …`
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Model directory (from `dynlab train`).
    #[arg(long)]
    model: PathBuf,
    /// Bag(s) to compare on (of the model's robot; any recorder, any rates).
    #[arg(long = "bag", required = true, num_args = 1.., value_name = "BAG")]
    bags: Vec<PathBuf>,
    /// Output directory for report.json and index.html.
    #[arg(long)]
    out: PathBuf,
    /// A second model to compare against, side by side with the error change.
    #[arg(long)]
    baseline: Option<PathBuf>,
    /// Open-loop steps of the k-step errors.
    #[arg(long, default_value_t = 5)]
    steps: usize,
    /// Car: length of the TVE segments (s).
    #[arg(long, default_value_t = 3.0)]
    segment: f64,
    /// Largest lag of the residual correlations (steps).
    #[arg(long, default_value_t = 20)]
    max_lag: usize,
    /// Worst segments to list.
    #[arg(long, default_value_t = 10)]
    worst: usize,
    #[command(flatten)]
    source: crate::source_args::SourceArgs,
    /// Also replay the bag(s) through the live predictor of the `model_server` node and write its
    /// predictions, one JSON object per pose, to this file (what the node publishes on the same
    /// data).
    #[arg(long, value_name = "FILE")]
    online: Option<PathBuf>,
    /// Steps of the online predicted path (the node's `steps`).
    #[arg(long, default_value_t = 10)]
    online_steps: usize,
}

fn write_online(
    args: &CompareArgs,
    model: &dynlab_learn::Model,
    fit: dynlab_learn::dynamics::data::SavGol,
    opts: &LoadOptions,
) -> anyhow::Result<()> {
    use dynlab_diagnose::compare::online::{OnlineConfig, OnlinePredictor, replay};
    use std::io::Write as _;
    let Some(path) = &args.online else {
        return Ok(());
    };
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    for b in &args.bags {
        let bag = dynlab_bag::Bag::open(b)?;
        let (poses, cmds, _) = dynlab_learn::dataset::read_samples_with(&bag, model.world(), opts)?;
        let mut p = OnlinePredictor::new(
            model.clone(),
            OnlineConfig {
                steps: args.online_steps,
                savgol: fit,
                ..Default::default()
            },
        )?;
        for (t, o) in replay(&mut p, &poses, &cmds) {
            writeln!(
                f,
                "{}",
                serde_json::json!({"bag": b.display().to_string(), "pose_ns": t, "prediction": o.prediction, "error": o.error, "warning": o.warning})
            )?;
        }
    }
    f.flush()?;
    Ok(())
}

pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    let (model, meta) = load_model(&args.model, None, None)
        .with_context(|| format!("loading the model {}", args.model.display()))?;
    let baseline = match &args.baseline {
        Some(p) => Some(
            load_model(p, None, None)
                .with_context(|| format!("loading the baseline {}", p.display()))?
                .0,
        ),
        None => None,
    };
    let world = model.world();
    // a bag of the other robot: say so rather than "topic missing"
    if !args.source.names_pose_source() {
        for b in &args.bags {
            if let Ok(bag) = dynlab_bag::Bag::open(b)
                && let Ok(w) = dynlab_learn::dataset::infer_world(&bag)
                && w != world
                && bag.topic(world.default_pose_topic()).is_none()
            {
                bail!(
                    "the model {} is a {} model but {} holds {} data ({}); compare it on a bag of the same robot, or name the pose source with --pose-topic or --pose-tf",
                    args.model.display(),
                    world,
                    b.display(),
                    w,
                    w.default_pose_topic()
                );
            }
        }
    }
    let opts = args.source.options()?;
    let mut data = load_bags_with(&args.bags, Some(world), &opts, &args.source.savgol(), None)?;
    // a car model steps a fixed dt: poses at another rate (a 240 Hz motion capture) are
    // resampled to it
    if world == dynlab_learn::World::Car
        && (data.data.pose_dt_s - model.dt()).abs() > 0.01 * model.dt()
    {
        println!(
            "data: poses every {:.2} ms ({:.1} Hz); the model steps {:.2} ms: resampled to the model's step",
            data.data.pose_dt_s * 1e3,
            1.0 / data.data.pose_dt_s,
            model.dt() * 1e3
        );
        data = load_bags_with(
            &args.bags,
            Some(world),
            &opts,
            &args.source.savgol(),
            Some(model.dt()),
        )?;
    }
    crate::source_args::warn_about_data(&data.data);
    let cfg = CompareConfig {
        steps: args.steps,
        segment_s: args.segment,
        max_lag: args.max_lag,
        worst: args.worst,
        ..Default::default()
    };
    let label = args.model.display().to_string();
    let blabel = args
        .baseline
        .as_ref()
        .map(|p| p.display().to_string())
        .unwrap_or_default();
    let report = compare_with_baseline(
        (&label, &model),
        baseline.as_ref().map(|b| (blabel.as_str(), b)),
        &data,
        &cfg,
    )?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let json = args.out.join("report.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("writing {}", json.display()))?;
    let page = html::report(&report).write(&args.out)?;
    write_online(&args, &model, meta.state_fit(), &opts)?;
    print!("{}", report.summary());
    println!("report: {} and {}", page.display(), json.display());
    Ok(())
}
