//! `dynlab eval-model`: one-step and k-step errors per state dimension (RMSE, MAE), the
//! training-loss metric, and TVE for the car, as a table or JSON.

use std::path::PathBuf;

use clap::Args;
use dynlab_learn::{evaluate, load_bags_with, load_model};

/// `dynlab eval-model …`
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Model directory (from `dynlab train`).
    #[arg(long)]
    model: PathBuf,
    /// Bag(s) to evaluate on (of the model's robot).
    #[arg(long = "bag", required = true, num_args = 1.., value_name = "BAG")]
    bags: Vec<PathBuf>,
    /// Open-loop steps of the k-step errors.
    #[arg(long, default_value_t = 5)]
    steps: usize,
    /// Car: length of the TVE segments (s) (Kohler et al.: 3 s).
    #[arg(long, default_value_t = 3.0)]
    segment: f64,
    #[command(flatten)]
    source: crate::source_args::SourceArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let (model, _meta) = load_model(&args.model, None, None)?;
    let opts = args.source.options()?;
    let data = load_bags_with(
        &args.bags,
        Some(model.world()),
        &opts,
        &args.source.savgol(),
        None,
    )?
    .data;
    crate::source_args::warn_about_data(&data);
    let report = evaluate(&model, &data, args.steps, args.segment)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}
