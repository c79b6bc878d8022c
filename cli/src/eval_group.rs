//! `dynlab eval …`: closed-loop evaluations (`push`: MPPI pushing episodes).

use clap::Subcommand;

use crate::eval_push_cmd;

/// `dynlab eval <what>`
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Closed-loop MPPI pushing episodes against the simulator (Tu & Lin's Table I).
    Push(eval_push_cmd::EvalPushArgs),
}

/// Runs one `dynlab eval` command.
pub fn run(cmd: EvalCommand) -> anyhow::Result<()> {
    match cmd {
        EvalCommand::Push(args) => eval_push_cmd::run(args),
    }
}
