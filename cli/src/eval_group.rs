//! `dynlab eval …`: closed-loop evaluations (`push`: MPPI pushing episodes; `race`: racing laps).

use clap::Subcommand;

use crate::{eval_push_cmd, eval_race_cmd};

/// `dynlab eval <what>`
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Closed-loop MPPI pushing episodes against the simulator (Tu & Lin's Table I).
    Push(eval_push_cmd::EvalPushArgs),
    /// Laps of the racing optimiser with the learned and the true model, side by side.
    Race(eval_race_cmd::RaceArgs),
}

/// Runs one `dynlab eval` command.
pub fn run(cmd: EvalCommand) -> anyhow::Result<()> {
    match cmd {
        EvalCommand::Push(args) => eval_push_cmd::run(args),
        EvalCommand::Race(args) => eval_race_cmd::run(args),
    }
}
