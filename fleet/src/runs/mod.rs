//! Headless runs and what they measure: a scenario flown to its end ([`run`]), the random stress
//! scenarios ([`stress`], [`families`]), the trunk road and the city grid of `bench scale` ([`trunk`],
//! [`city`]), the paths `run --plot` draws ([`paths`]), the metrics and margins of a run
//! ([`metrics`], [`totals`], [`margins`], [`histogram`]), and a road flown by one fleet per region ([`split`]).

pub mod city;
pub mod families;
pub(crate) mod histogram;
pub(crate) mod margins;
pub(crate) mod metrics;
pub(crate) mod networks;
pub mod paths;
pub(crate) mod run;
pub mod split;
pub mod stress;
pub(crate) mod totals;
pub mod trunk;
