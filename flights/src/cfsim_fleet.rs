//! Simulated Crazyflies for a scenario (`airroads serve --cfsim N`, `airroads run --link cfsim`):
//! one `cfsim` per UAV, in this process, standing on the ground at the UAV's start, and the UAV's
//! link pointed at it, so the fleet flies it through the real CRTP path over UDP.

use anyhow::Context as _;
use cfsim::{SimConfig, SimCrazyflie, SimHandle};
use fleet::ValidScenario;
use std::net::{Ipv4Addr, SocketAddr};

/// Starts simulated Crazyflies for the first `n` UAVs of `scenario` on UDP ports from `first_port`
/// up (0: any free ports) and sets those UAVs' links to them. Needs a tokio runtime.
pub fn spawn(scenario: &mut ValidScenario, n: usize, first_port: u16) -> anyhow::Result<Vec<SimHandle>> {
    let mut sims = Vec::with_capacity(n);
    for (i, uav) in scenario.uavs.iter_mut().take(n).enumerate() {
        let port = if first_port == 0 {
            0
        } else {
            u16::try_from(i)
                .ok()
                .and_then(|i| first_port.checked_add(i))
                .context("--cfsim: out of UDP ports")?
        };
        let config = SimConfig {
            initial_position: [uav.start.x, uav.start.y, 0.0],
            // The fleet commands up to δ; the simulated controller may use a little more to track.
            max_accel: 1.2 * scenario.params.delta,
            ..SimConfig::default()
        };
        let bind = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
        let sim =
            SimCrazyflie::spawn(bind, config).with_context(|| format!("simulated Crazyflie on {bind}"))?;
        uav.link = Some(sim.uri());
        sims.push(sim);
    }
    Ok(sims)
}
