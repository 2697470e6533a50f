//! Which [`Link`] a UAV gets: the in-process simulator (`sim`, the default) or a Crazyflie relay for
//! a URI (`radio://…`, `udp://…`), whose session task runs on the server's tokio runtime. Crazyflie
//! links register where their motion-capture poses go ([`MocapRoutes`]).

use crazyflie::{CrazyflieLink, RelayConfig};
use links::{Link, SIM_LINK, SimLink};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};
use tokio::sync::mpsc;
use uav::UavState;

/// UAV id → where its motion-capture positions go (its Crazyflie session).
#[derive(Clone, Default)]
pub struct MocapRoutes(Arc<Mutex<HashMap<String, mpsc::Sender<[f32; 3]>>>>);

impl MocapRoutes {
    /// Forwards a position to UAV `id`'s Crazyflie; false when it has none (or its queue is full,
    /// which drops this pose: a newer one follows).
    pub fn forward(&self, id: &str, position: [f32; 3]) -> bool {
        let mut routes = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        match routes.get(id).map(|tx| tx.try_send(position)) {
            Some(Ok(())) => true,
            Some(Err(mpsc::error::TrySendError::Closed(_))) => {
                routes.remove(id);
                false
            }
            _ => false,
        }
    }

    fn insert(&self, id: &str, tx: mpsc::Sender<[f32; 3]>) {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).insert(id.to_string(), tx);
    }
}

/// UAV id → a handle that sends its Crazyflie an emergency stop without the fleet loop.
#[derive(Clone, Default)]
pub struct StopRoutes(Arc<Mutex<HashMap<String, crazyflie::StopHandle>>>);

impl StopRoutes {
    /// Sends every Crazyflie an emergency stop straight to its radio session (forgetting links that
    /// are gone); returns how many were sent one.
    pub fn stop_all(&self) -> usize {
        let mut routes = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        routes.retain(|_, handle| handle.stop());
        routes.len()
    }

    fn insert(&self, id: &str, handle: crazyflie::StopHandle) {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).insert(id.to_string(), handle);
    }
}

/// Makes the link of each UAV.
#[derive(Clone)]
pub struct LinkFactory {
    runtime: tokio::runtime::Handle,
    /// How Crazyflies are flown (altitude, take-off, log period; `dt` is set per fleet).
    pub relay: RelayConfig,
    /// Motion-capture routes of the Crazyflie links made so far.
    pub mocap: MocapRoutes,
    /// Emergency-stop handles of the Crazyflie links made so far.
    pub stops: StopRoutes,
}

impl LinkFactory {
    /// A factory whose Crazyflie sessions run on `runtime`.
    pub fn new(runtime: tokio::runtime::Handle, relay: RelayConfig) -> Self {
        Self { runtime, relay, mocap: MocapRoutes::default(), stops: StopRoutes::default() }
    }

    /// The link of UAV `id`: `link` None or `sim` simulates it in-process from `state`; a URI
    /// starts a Crazyflie session (already checked with [`links::check_link`]).
    pub fn make(&self, id: &str, link: Option<&str>, state: UavState, dt: f64) -> Box<dyn Link> {
        match link {
            None | Some(SIM_LINK) => Box::new(SimLink::new(state, dt)),
            Some(uri) => {
                let config = RelayConfig { dt, ..self.relay };
                let link = CrazyflieLink::spawn(&self.runtime, uri, config);
                self.mocap.insert(id, link.external_position_sender());
                self.stops.insert(id, link.stop_handle());
                Box::new(link)
            }
        }
    }
}
