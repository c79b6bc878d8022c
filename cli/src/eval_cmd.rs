//! `dynlab eval-model`: one-step and k-step errors per state dimension (RMSE, MAE), the
//! training-loss metric, and TVE for the car, as a table or JSON.

use std::path::PathBuf;

use clap::Args;
use dynlab_learn::dynamics::data::SavGol;
use dynlab_learn::{Topics, evaluate, load_bags, load_model};

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
    /// Pose topic (default from the model's world).
    #[arg(long)]
    pose_topic: Option<String>,
    /// Command topic (default from the model's world).
    #[arg(long, alias = "action-topic")]
    cmd_topic: Option<String>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let (model, _meta) = load_model(&args.model, None, None)?;
    let topics = Topics {
        pose: args.pose_topic.clone(),
        cmd: args.cmd_topic.clone(),
    };
    let data = load_bags(&args.bags, Some(model.world()), &topics, &SavGol::default())?;
    let report = evaluate(&model, &data, args.steps, args.segment)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}
