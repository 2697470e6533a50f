//! `airroads`: ground control for UAV fleets in air roads. Subcommands: `serve` (the server), `run` (a scenario, headless),
//! `stress` (random scenarios), `bench` (filter timing), `track` (tracking benchmark of a policy).

/// Prints a line to stdout, ignoring write errors: a closed pipe (`airroads run … | head`) must not
/// panic the program, and the exit status and any `--out` file do not depend on stdout.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

mod bench;
mod bench_crazyflie;
mod bench_durability;
mod bench_firmware;
mod bench_fleet;
mod bench_regions;
mod bench_scale;
mod bench_server;
mod bench_solver;
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
