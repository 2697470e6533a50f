//! A simulated Crazyflie 2.1 that speaks CRTP over UDP (one packet per datagram), for tests and
//! demos without hardware.
//!
//! [`SimCrazyflie::spawn`] binds a UDP socket and runs the simulated firmware on the current
//! tokio runtime: platform versions, log and param TOCs (v2) with log blocks streaming at their
//! period, memory (no memories), link echo, the supervisor (state bitfield, arming, auto-arming or
//! not), the Kalman estimator's variances, the low-level and high-level commanders with the
//! firmware's setpoint watchdog, external position and emergency stop. The vehicle is a point
//! mass behind a position/velocity controller with bounded acceleration.
//! [`SimHandle`] exposes the ground truth and switches link faults ([`Faults`]) at run time.
//!
//! The second simulator is physics only, for the real firmware: [`sitl`] serves N
//! [`quadrotor::Quadrotor`]s (a rigid-body model of the Crazyflie 2.1) to the firmware's
//! software-in-the-loop build (`cf2`), feeding it IMU, barometer and pose, taking its motor PWM
//! and relaying everything else between it and a CRTP client.
//!
//! ```no_run
//! # async fn demo() -> std::io::Result<()> {
//! use cfsim::{SimConfig, SimCrazyflie};
//! let sim = SimCrazyflie::spawn("127.0.0.1:0".parse().unwrap(), SimConfig::default())?;
//! println!("connect to {}", sim.uri());
//! # Ok(()) }
//! ```

pub mod commands;
pub mod crtp;
pub mod dynamics;
pub mod estimator;
pub mod faults;
pub mod firmware;
pub mod flight;
pub mod log;
pub mod logvars;
pub mod param;
pub mod planner;
pub mod quadrotor;
pub mod server;
pub mod services;
pub mod sitl;
pub mod supervisor;
pub mod toc;

pub use faults::Faults;
pub use flight::FlightMode;
pub use server::{LinkStats, SimConfig, SimCrazyflie, SimHandle, Truth};
pub use sitl::{SitlConfig, SitlFaults, SitlHandle};
