//! The HTTP side of `airroads serve`: the REST API ([`routes`]: one table; [`handlers`], the road's
//! in [`road`]; typed
//! [`answers`]), the WebSocket stream ([`ws`], [`binary`]), the request guard, the token check and
//! the audit log ([`guard`], [`auth`], [`audit`]), the error bodies ([`error`]), the accept loop
//! ([`listener`]), the dashboard's files ([`web`]) and the HTTP side of the regions (forwarding,
//! merged reads, deployments: [`federate`], [`deploy`]). It reaches the fleet loop only through
//! [`engine::EngineHandle`] (in [`state::AppState`]); `airroads-server` wires it to the engine.

pub mod answers;
pub mod audit;
pub mod auth;
pub mod binary;
pub mod client;
pub mod deploy;
pub mod error;
pub mod federate;
mod federate_merge;
pub mod guard;
mod handlers;
pub mod listener;
pub mod openapi;
mod request;
pub mod road;
pub mod road_follow;
pub mod routes;
pub mod state;
pub mod web;
pub mod ws;
