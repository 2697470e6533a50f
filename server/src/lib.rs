//! The airroads server library: `airroads serve` (fleet loop, REST API, WebSocket stream,
//! persistence). The binary adds the command line and the headless subcommands.

pub mod cfsim_fleet;
pub mod firmware_fleet;
pub mod serve;
