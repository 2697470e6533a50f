//! Crazyflie 2.1 relay: CRTP transports (Crazyradio through crazyflie-link, UDP to simulators) and
//! [`CrazyflieLink`], the fleet's [`links::Link`] to one Crazyflie.

pub mod confirm;
pub mod machine;
mod prepare;
mod relay;
mod session;
pub mod transport;
pub mod udp;

pub use prepare::CONTROLLER_PARAM;
pub use relay::{Controller, CrazyflieLink, RelayConfig, Sample, Setpoint, Shared, StopHandle, Urgent};
pub use session::STATE_VARIABLES;
