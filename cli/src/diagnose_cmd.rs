//! `dynlab diagnose`: which physical effect of the library explains a model's residual on a bag
//! (a thin adapter over `dynlab_diagnose::diagnosis`).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use dynlab_diagnose::diagnosis::{DiagnoseConfig, diagnose, diagnosis_page};
use dynlab_learn::dynamics::data::SavGol;
use dynlab_learn::dynamics::physics::PhysicsModel;
use dynlab_learn::{load_bags_with, load_model, pipeline_notes};

/// `dynlab diagnose …`
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Model directory (from `dynlab train`; any kind).
    #[arg(long)]
    model: PathBuf,
    /// Bag(s) with the measurements (of the model's robot).
    #[arg(long = "bag", required = true, num_args = 1.., value_name = "BAG")]
    bags: Vec<PathBuf>,
    /// Output directory for diagnosis.json and diagnosis.html.
    #[arg(long, default_value = "out/diagnosis")]
    out: PathBuf,
    /// Open-loop steps k of the scored error (default: car 50, pushing 3).
    #[arg(long)]
    steps: Option<usize>,
    /// Seed of the split, subsamples and bootstrap.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Candidate effects, comma-separated (default: the world's whole library).
    #[arg(long, value_delimiter = ',')]
    effects: Option<Vec<String>>,
    /// Smallest held-out error reduction that counts (fraction).
    #[arg(long, default_value_t = 0.05)]
    min_reduction: f64,
    #[command(flatten)]
    source: crate::source_args::SourceArgs,
}

pub fn run(args: DiagnoseArgs) -> anyhow::Result<()> {
    let (model, _meta) = load_model(&args.model, None, None)
        .with_context(|| format!("loading the model {}", args.model.display()))?;
    let opts = args.source.options()?;
    let mut data = load_bags_with(
        &args.bags,
        Some(model.world()),
        &opts,
        &SavGol::default(),
        None,
    )?
    .data;
    // a car model steps a fixed dt: poses at another rate are resampled to it (as compare does)
    if model.world() == dynlab_learn::World::Car
        && (data.pose_dt_s - model.dt()).abs() > 0.01 * model.dt()
    {
        println!(
            "data: poses every {:.2} ms; the model steps {:.2} ms: resampled to the model's step",
            data.pose_dt_s * 1e3,
            model.dt() * 1e3
        );
        data = load_bags_with(
            &args.bags,
            Some(model.world()),
            &opts,
            &SavGol::default(),
            Some(model.dt()),
        )?
        .data;
    }
    crate::source_args::warn_about_data(&data);
    let effects = match &args.effects {
        Some(names) => {
            let n: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
            Some(PhysicsModel::parse_effects(&n)?)
        }
        None => None,
    };
    let cfg = DiagnoseConfig {
        steps: args.steps,
        seed: args.seed,
        effects,
        min_reduction: args.min_reduction,
        ..DiagnoseConfig::default()
    };
    let d = diagnose(&model, &data, &cfg)?;
    print!("{}", d.table());
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let json = args.out.join("diagnosis.json");
    let mut value = d.to_json();
    if let Some(obj) = value.as_object_mut() {
        // how the data were read: pose source, a damaged bag's recovery, skipped poses
        let notes: Vec<Vec<String>> = data.reports.iter().map(pipeline_notes).collect();
        obj.insert("data_notes".into(), serde_json::to_value(notes)?);
    }
    std::fs::write(&json, serde_json::to_string_pretty(&value)? + "\n")
        .with_context(|| format!("writing {}", json.display()))?;
    let html = args.out.join("diagnosis.html");
    std::fs::write(&html, diagnosis_page(&d))
        .with_context(|| format!("writing {}", html.display()))?;
    println!("report: {} and {}", json.display(), html.display());
    Ok(())
}
