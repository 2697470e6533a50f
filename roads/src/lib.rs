//! Air-road layouts: the JSON format, validation with precise errors, and the geometry the
//! safety filter and navigation need (finite walls with end caps, point-in-road, centre line),
//! plus navigation (Algorithm 1 and its road-aware `route` variant, `docs/safety.md` §5, §7), and the
//! layout's optional regions (named segment ranges that partition the road).
//!
//! Conventions (paper labels): segment i = `[p1, p2, p3, p4]`; walls (barrier lines) p2→p1 (j = 21)
//! and p4→p3 (j = 43); passable edges p2–p4 (entry) and p1–p3 (exit); cyclic polygon order
//! p1, p2, p4, p3; seamless joins `p1(i) = p2(i+1)`, `p3(i) = p4(i+1)`.
//!
//! This crate knows nothing of UAV dynamics, barriers or solvers.

mod airspace;
mod airspace_layout;
mod boundary;
mod centerline;
mod geometry;
mod index;
#[cfg(test)]
mod index_tests;
mod lanes;
mod layout;
mod nav;
pub mod network;
mod network_nav;
mod regions;
#[cfg(test)]
mod regions_tests;
mod road;
pub mod schema;
mod traffic_nav;
mod validate;

pub use airspace::Airspace;
pub use airspace_layout::AirspaceLayout;
pub use boundary::Boundary;
pub use centerline::CenterLine;
pub use geometry::{Quad, Wall, WallKind, nearest_on_segment, segments_intersect};
pub use index::{NearWalls, SEGMENT_NEAR_M};
pub use lanes::{ClearanceProfile, PROFILE_STEP_M, segment_distance};
pub use layout::RoadLayout;
pub use nav::{NavMode, NavState, Navigator, Restriction, RoutePosition};
pub use network_nav::NetworkNavigator;
pub use regions::{MAX_REGION_NAME, Region};
pub use road::{Road, SegmentTracker};
pub use traffic_nav::{CLEARANCE_MARGIN_M, LANE_GAP_MARGIN_M, MIN_CLEARANCE_MARGIN_M};
pub use validate::{MAX_COORDINATE_M, MAX_SEGMENTS, RoadError, RoadRule};
