//! `airroads`: ground control for UAV fleets in air roads. Subcommands: `serve` (the server), `run` (a scenario, headless),
//! `stress` (random scenarios), `bench` (filter timing), `track` (tracking benchmark of a policy).

mod certs_cmd;
mod cli;
mod plot;
mod run_cmd;
mod serve_cmd;
mod stress_cmd;
mod stress_firmware;
mod track;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    match cli.command {
        cli::Command::Run(args) => run_cmd::main(args),
        cli::Command::Stress(args) => stress_cmd::main(args),
        cli::Command::Bench(args) => bench::main(args),
        cli::Command::Track(args) => track::main(args),
        cli::Command::Serve(args) => serve_cmd::main(args),
        cli::Command::Health(args) => serve_cmd::health(&args.url),
        cli::Command::Certs(args) => certs_cmd::main(&args),
    }
}
