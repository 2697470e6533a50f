//! The airroads server as a library: [`serve::Server::start`] wires the fleet loop (the `engine`
//! crate), the regions (`regions`) and the HTTP side (`api`), and [`serve::serve`] runs it on a bound
//! listener. The `airroads` command (`cli/`) adds the command line; tests start it in-process.

pub mod serve;
