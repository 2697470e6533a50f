//! The safety filter of airroads (`docs/safety.md` §1–§6, §10): control barrier functions for
//! road walls (b_kij, signed, finite walls with end-point barriers) and neighbours (b_kd, decentralised
//! share δ_k/(δ_k+δ_d)), turned into affine rows `aᵀu ≤ c`, and the per-UAV QP
//! `min ½‖u_q‖² + Σ(ρ r + ½P r²)` with one slack per row and ‖u‖ ≤ δ as a second-order cone, solved
//! exactly by an active-set method in R² with a KKT certificate (`exact`) or with Clarabel (`qp`).
//!
//! The rows against neighbours (`neighbour_rows`): shared collision rows, and a lost or grounded-in-
//! the-air neighbour's reach disk kept alone.
//!
//! Synchronous and allocation-free in steady state; knows nothing of fleets, policies or I/O.

pub mod barrier;
pub mod exact;
mod filter;
mod neighbour_rows;
pub mod paper;
mod qp;
mod road_rows;

pub use barrier::{Row, RowKind};
pub use exact::{ExactError, ExactSolver, KktResidual, kkt_residual};
pub use filter::{FilterOutcome, FilterSettings, Objective, SafetyFilter, Solver};
pub use neighbour_rows::{
    Neighbour, ReachDisk, WATCHDOG_HOLD_S, flown_reach_disk, neighbour_rows, obstacle_row, point_disk,
    reach_disk,
};
pub use qp::{CLARABEL_TOL, ConstraintRow, QpSolution, QpSolver};
pub use road_rows::{
    ACTIVATION_BARRIER, RoadRule, WallsSeen, activation_radius, network_rows, road_rows, wall_braking_margin,
    walls_rows_and_margin,
};
