//! `airroads`: ground control for UAV fleets in air roads. Subcommands: `run` (a scenario, headless),
//! `stress` (random scenarios), `bench` (filter timing).

mod bench;
mod cli;
mod run_cmd;
mod stress_cmd;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    match cli.command {
        cli::Command::Run(args) => run_cmd::main(args),
        cli::Command::Stress(args) => stress_cmd::main(args),
        cli::Command::Bench(args) => bench::main(args),
    }
}
