//! Headless flights of a scenario through real links, for `airroads run --link cfsim|firmware`,
//! `airroads stress --link firmware` and `airroads bench firmware`: simulated Crazyflies in their
//! own tasks ([`cfsim_fleet`]), real firmware processes on cfsim's physics ([`firmware_fleet`]),
//! the relay's links to them and the real-time tick; also the scenario file reader and the run
//! summary every command prints.

/// Prints a line to stdout, ignoring write errors: a closed pipe (`airroads run … | head`) must not
/// panic the program, and the exit status and any `--out` file do not depend on stdout.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

pub mod cfsim_fleet;
pub mod firmware_fleet;
mod real_links;
mod scenario_file;

pub use real_links::{crazyflie_links, real_time_ticks, run_on_cfsim, run_on_firmware};
pub use scenario_file::{load_scenario, load_scenario_with, print_summary};
