//! How the fleet navigates and filters ([`FleetConfig`]) and how a pair's collision barrier is
//! shared ([`CollisionShare`]).

use roads::NavMode;
use safety::{FilterSettings, RoadRule};
use uav::Params;

/// How the collision barrier b_kd of a pair is shared between its two UAVs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CollisionShare {
    /// Each UAV k enforces its share δ_k/(δ_k+δ_d) of every pair row (paper eq. 14, 15;
    /// docs/safety.md §2).
    Split,
    /// UAVs are filtered one after another within a tick. A UAV enforces the whole relative row
    /// `−p̂ᵀ(u_k − u_d) ≤ rhs` against every neighbour d already filtered (its u_d is known) and its
    /// share against the others. Each pair is then enforced exactly by its later UAV, whose row is at
    /// least as loose as its share because the earlier one met its own share; so every QP is at least
    /// as feasible as with `Split`, and a platoon can brake together (with `Split` every member may
    /// only decelerate by about ζb³/2 towards its follower: docs/safety.md §10.3).
    #[default]
    Sequential,
}

impl CollisionShare {
    /// The CLI/JSON name.
    pub fn name(&self) -> &'static str {
        match self {
            CollisionShare::Split => "split",
            CollisionShare::Sequential => "sequential",
        }
    }
}

impl std::str::FromStr for CollisionShare {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "split" => Ok(CollisionShare::Split),
            "sequential" => Ok(CollisionShare::Sequential),
            other => Err(format!("unknown collision share `{other}` (expected split or sequential)")),
        }
    }
}

/// How the fleet navigates and filters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FleetConfig {
    /// Parameters (dt, δ, r_s, D_s, D_c, ζ, ε).
    pub params: Params,
    /// Which walls each UAV enforces.
    pub road_rule: RoadRule,
    /// How temporary targets are chosen.
    pub nav: NavMode,
    /// QP weights and objective.
    pub filter: FilterSettings,
    /// How pair rows are shared.
    pub share: CollisionShare,
    /// A UAV whose link gives no fresh state for this long (s) is lost ([`crate::tick::lost`]).
    pub stale_after: f64,
    /// How long (s) a lost UAV may keep moving: the Crazyflie's setpoint watchdog cuts its motors
    /// 2 s after the last setpoint, so its reach stops growing after that.
    pub lost_reach_horizon: f64,
    /// On a network with `traffic` navigation: a UAV coming to a conflict zone takes another way
    /// when that costs at least this many seconds less than its own, counting the queues measured
    /// ahead ([`crate::traffic::congestion`]); None: every UAV keeps the fastest way by travel time.
    pub reroute_margin_s: Option<f64>,
    /// The rows stage also measures each UAV's smallest collision margin to a neighbour in the air
    /// ([`crate::Fleet::tick_margins`]), which the server's snapshot shows per UAV; headless runs
    /// need only the smallest over the pairs and leave it off.
    pub uav_collision_margins: bool,
}

impl Default for FleetConfig {
    fn default() -> Self {
        Self {
            params: Params::default(),
            road_rule: RoadRule::default(),
            nav: NavMode::default(),
            filter: FilterSettings::default(),
            share: CollisionShare::default(),
            stale_after: 0.3,
            lost_reach_horizon: 2.0,
            reroute_margin_s: Some(crate::traffic::congestion::REROUTE_MARGIN_S),
            uav_collision_margins: false,
        }
    }
}
