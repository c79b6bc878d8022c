//! The dynlab offline command line: collect, train, compare, diagnose, eval, bag info.
//!
//! Each command group lives in its own module (`bag_cmd` for `dynlab bag …`) and is a thin
//! adapter over a library crate.

mod bag_cmd;
mod collect_cmd;
mod compare_cmd;
mod diagnose_cmd;
mod eval_cmd;
mod eval_group;
mod eval_push_cmd;
mod eval_race_cmd;
mod source_args;
mod train_cmd;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Learned robot dynamics you can trust, explain and control with: the offline tools.
#[derive(Debug, Parser)]
#[command(name = "dynlab", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Inspect, export and import rosbag2 (MCAP) bags.
    Bag(bag_cmd::BagArgs),
    /// Train a dynamics model (residual, NeuralODE, physics, hybrid) from bags.
    Train(train_cmd::TrainArgs),
    /// Evaluate a model on a bag: one-step and k-step errors per dimension, TVE for the car.
    EvalModel(eval_cmd::EvalArgs),
    /// Hold a model against bags: errors per dimension, over time, against their causes,
    /// residual correlations, worst segments; report.json and index.html (--baseline: side by side).
    Compare(compare_cmd::CompareArgs),
    /// Collect simulated data into a bag, headless and far faster than real time.
    Collect(collect_cmd::CollectArgs),
    /// Which physical effect is missing: fit each effect of the library to a model's residual on
    /// a bag, score it on held-out data, rank (diagnosis.json, diagnosis.html).
    Diagnose(diagnose_cmd::DiagnoseArgs),
    /// Closed-loop evaluations: `eval push` (MPPI pushing episodes), `eval race` (racing laps).
    #[command(subcommand)]
    Eval(eval_group::EvalCommand),
}

fn main() -> ExitCode {
    restore_default_sigpipe();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bag(args) => bag_cmd::run(args),
        Command::Train(args) => train_cmd::run(args),
        Command::EvalModel(args) => eval_cmd::run(args),
        Command::Collect(args) => collect_cmd::run(args),
        Command::Compare(args) => compare_cmd::run(args),
        Command::Diagnose(args) => diagnose_cmd::run(args),
        Command::Eval(cmd) => eval_group::run(cmd),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", error_chain(&err));
            ExitCode::FAILURE
        }
    }
}

/// Lets a closed output pipe (`dynlab bag info B | head`) end the program quietly, as it ends
/// other command-line tools, instead of a panic in `println!`: Rust ignores SIGPIPE by default.
fn restore_default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in `main`, before any thread exists; SIG_DFL is a valid action.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The error and its causes joined by `: `, leaving out a cause whose text the message before it
/// already contains (library errors often quote their source).
fn error_chain(err: &anyhow::Error) -> String {
    let mut out = String::new();
    let mut previous = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if previous.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
        previous = text;
    }
    out
}
