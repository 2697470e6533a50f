//! Which walls a UAV enforces, and their rows: rule R2 `walls` (default), R3 `halfplanes`, R1 `paper`
//! (docs/safety.md §5, amended by §10.1).

use crate::barrier::{
    Clearance, MIN_DISTANCE_M, Row, RowKind, braking_margin, held_for, line_row, vertex_row,
};
use roads::network::Network;
use roads::{Boundary, Road, Wall};
use uav::{Params, Vec2};

/// Barrier value B (m/s) below which every row is present: walls and neighbours are searched within
/// R = D + (‖v‖ + B)²/(2δ), since b ≤ B implies √(2δ(dist − D)) ≤ B + ‖v‖.
///
/// The first design (docs/safety.md §5) used R = D_s + ‖v‖²/(2δ) + 1 m. That keeps new rows inside the
/// safe set (b > 0) but lets a fast neighbour appear with b ≈ 1, when its row already demands near-full
/// braking: a jump that made the QP infeasible in crowded runs. With B = 5 m/s a row appears while
/// ζb³ ≥ 6 m/s² keeps it mild, and since |ḃ| ≤ ~20 m/s² unconstrained, b ≥ 4 when it first counts
/// (dt = 0.05 s).
pub const ACTIVATION_BARRIER: f64 = 5.0;

/// The activation radius (m) of a barrier with safe distance `d` for closing speed bound `speed` and
/// braking capability `delta` (see [`ACTIVATION_BARRIER`]).
pub fn activation_radius(d: f64, speed: f64, delta: f64) -> f64 {
    d + (speed + ACTIVATION_BARRIER).powi(2) / (2.0 * delta)
}

/// Rule choosing the road barriers of a UAV.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RoadRule {
    /// R2 (recommended): every finite wall and end cap within the activation radius; line barrier in the
    /// wall's slab (from whichever side the UAV is on), end-point barrier beyond its ends.
    #[default]
    Walls,
    /// R3: the infinite lines of the current segment plus the neighbours' lines that bound it.
    Halfplanes,
    /// R1, the paper's: the two infinite lines of the current segment, unsigned distance. Leaves the
    /// road at convex corners (E5, E6): for comparison only.
    Paper,
}

impl RoadRule {
    /// The CLI/JSON name.
    pub fn name(&self) -> &'static str {
        match self {
            RoadRule::Walls => "walls",
            RoadRule::Halfplanes => "halfplanes",
            RoadRule::Paper => "paper",
        }
    }
}

impl std::str::FromStr for RoadRule {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "walls" => Ok(RoadRule::Walls),
            "halfplanes" => Ok(RoadRule::Halfplanes),
            "paper" => Ok(RoadRule::Paper),
            other => Err(format!("unknown road rule `{other}` (expected walls, halfplanes or paper)")),
        }
    }
}

/// Appends the road rows of a UAV at `p`, `v` in segment `segment` (from its [`roads::SegmentTracker`]).
pub fn road_rows(
    road: &Road,
    rule: RoadRule,
    p: Vec2,
    v: Vec2,
    segment: usize,
    params: &Params,
    out: &mut Vec<Row>,
) {
    let wall = Clearance::one(params.d_s, params);
    let radius = activation_radius(wall.boundary(), v.norm() + wall.eta_v, params.delta);
    let walls = road.walls();
    let line = |k: usize, n: Vec2, s: f64| wall_row(s, n, v, params, k);
    match rule {
        RoadRule::Walls => {
            walls_rows(road, p, v, segment, radius, None, params, out);
        }
        RoadRule::Halfplanes => {
            for &k in road.halfplane_walls(segment) {
                let s = walls[k].signed_distance(&p);
                if s <= radius {
                    out.push(line(k, walls[k].n_in, s));
                }
            }
        }
        RoadRule::Paper => {
            for k in road.segment_walls(segment) {
                let s = walls[k].signed_distance(&p);
                // Unsigned distance ‖O_kij‖ and Ô_kij = ±n̂_in (paper eq. 8, before erratum E5).
                let n = if s >= 0.0 { walls[k].n_in } else { -walls[k].n_in };
                if s.abs() <= radius {
                    out.push(line(k, n, s.abs()));
                }
            }
        }
    }
}

/// Appends the road rows of a UAV at `p`, `v` in cell `cell` of a network: the walls rule (R2),
/// the only one defined on a network (docs/safety.md §5.1).
pub fn network_rows(net: &Network, p: Vec2, v: Vec2, cell: usize, params: &Params, out: &mut Vec<Row>) {
    walls_rows_and_margin(net, p, v, cell, params, None, out);
}

/// What rule R2's pass over the walls saw around a UAV inside the road.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallsSeen {
    /// The radius of the walls' query: every wall within it of the UAV was looked at.
    pub reach: f64,
    /// The smallest squared distance from the UAV to a wall looked at (to its nearest point).
    pub nearest_d2: f64,
    /// The smallest [`wall_braking_margin`] of a wall looked at.
    pub margin: f64,
}

/// Appends the rows of rule R2 (`walls`, as [`road_rows`] with [`RoadRule::Walls`] and
/// [`network_rows`]) of a UAV at `p`, `v` in segment or cell `segment`; with `reach` given, looks at
/// least at every wall within `reach` too (the same rows) and returns what it saw when the UAV is in
/// the road (None outside or without `reach`): a run's road margin and boundary distance in the same
/// pass over the walls.
pub fn walls_rows_and_margin<B: Boundary>(
    road: &B,
    p: Vec2,
    v: Vec2,
    segment: usize,
    params: &Params,
    reach: Option<f64>,
    out: &mut Vec<Row>,
) -> Option<WallsSeen> {
    let wall = Clearance::one(params.d_s, params);
    let radius = activation_radius(wall.boundary(), v.norm() + wall.eta_v, params.delta);
    walls_rows(road, p, v, segment, radius, reach, params, out)
}

/// The braking margin `dist − min(ḋist, 0)²/(2δ)` of finite wall `w` for a UAV at `p`, `v`, given the
/// wall's point nearest to `p` and its parameter along the wall (`w.nearest(&p)`), as rule R2
/// enforces the wall: its line distance in its slab (from either side), its end points as points.
#[inline]
pub fn wall_braking_margin(w: &Wall, nearest: (Vec2, f64), p: Vec2, v: Vec2, delta: f64) -> f64 {
    let (c, t) = nearest;
    let (dist, rate) = if t > 0.0 && t < 1.0 {
        let d = w.signed_distance(&p);
        (d.abs(), d.signum() * w.n_in.dot(&v))
    } else {
        let e: Vec2 = p - c;
        let n = e.norm();
        (n, if n > 0.0 { e.dot(&v) / n } else { 0.0 })
    };
    braking_margin(dist, rate, delta)
}

/// Rule R2: for a UAV inside the road, the barrier of each finite wall on the distance to that wall
/// (a line barrier in its slab, an end-point barrier beyond its ends); for a UAV outside the road, the
/// signed line barriers of the nearest walls to bring it back.
///
/// In the slab the distance is taken from whichever side the UAV is on. Past the inner vertex V of a
/// bend sharper than 90°, a UAV still in the road can stand behind the next wall's line with its foot
/// inside that wall. The first fix of docs/safety.md §10.1 dropped the wall there (its *signed* barrier
/// is negative), which left V unguarded: a UAV sliding along the first wall towards V met V's end-point
/// barrier only when its foot left the slab, already at b ≈ 0 (stress seed 225, rl: S = 0.088 m < D_s).
/// The unsigned distance is the true distance to that wall, so it is positive and C¹-continuous with
/// V's end-point barrier where the foot reaches V.
///
/// With `reach` given, also looks at every wall within it and returns, inside the road, what it saw
/// of the walls it looked at (None otherwise).
#[allow(clippy::too_many_arguments)] // The rows' inputs, and the margin's reach.
fn walls_rows<B: Boundary>(
    road: &B,
    p: Vec2,
    v: Vec2,
    segment: usize,
    radius: f64,
    reach: Option<f64>,
    params: &Params,
    out: &mut Vec<Row>,
) -> Option<WallsSeen> {
    let walls = road.wall_list();
    if !road.inside_in(segment, &p) {
        let nearest = (walls[road.nearest_wall_to(&p)].nearest(&p).0 - p).norm();
        for (k, w) in walls.iter().enumerate() {
            if (w.nearest(&p).0 - p).norm() <= nearest + 0.5 {
                out.push(wall_row(w.signed_distance(&p), w.n_in, v, params, k));
            }
        }
        return None;
    }
    // The index (or the tracked segment's list) gives a superset of the walls within the radius, in
    // index order: the same rows, in the same order, as a loop over every wall.
    let mut seen = [Vec2::zeros(); 16];
    let mut n_seen = 0;
    let query = reach.map_or(radius, |reach| radius.max(reach));
    let mut seen_walls = WallsSeen { reach: query, nearest_d2: f64::INFINITY, margin: f64::INFINITY };
    // A larger query gives the same rows (the same walls within `radius`, in the same order).
    for k in road.walls_within(segment, &p, query) {
        let w = &walls[k];
        let (c, t) = w.nearest(&p);
        let d2 = (c - p).norm_squared();
        if reach.is_some() {
            seen_walls.nearest_d2 = seen_walls.nearest_d2.min(d2);
            seen_walls.margin = seen_walls.margin.min(wall_braking_margin(w, (c, t), p, v, params.delta));
        }
        if d2.sqrt() > radius {
            continue;
        }
        if t > 0.0 && t < 1.0 {
            // The distance to the finite wall, from whichever side the UAV is on (see the doc above).
            let s = w.signed_distance(&p);
            let n = if s >= 0.0 { w.n_in } else { -w.n_in };
            out.push(wall_row(s.abs(), n, v, params, k));
        } else if !seen[..n_seen].contains(&c) {
            // A vertex shared by two walls gets one end-point barrier, not two.
            if n_seen < seen.len() {
                seen[n_seen] = c;
                n_seen += 1;
            }
            // The row keeps b ≥ 0 with a class-K function that lets a UAV pass V at speed (§10.5).
            out.push(corner_row(p, v, c, params, k));
        }
    }
    reach.map(|_| seen_walls)
}

/// The line row of wall `k` at signed distance `s` along normal `n`, held for one tick (§4.4).
fn wall_row(s: f64, n: Vec2, v: Vec2, params: &Params, k: usize) -> Row {
    let (delta, d_s, rate) = (params.delta, Clearance::one(params.d_s, params), n.dot(&v));
    let row = line_row(s, rate, n, delta, d_s, params.zeta, RowKind::Road(k));
    held_for(row, s - d_s.boundary(), rate, 0.0, delta, params.dt, d_s.eta_v)
}

/// The end-point row of road vertex `c` (wall `k`), held for one tick (§4.4, §10.5).
fn corner_row(p: Vec2, v: Vec2, c: Vec2, params: &Params, k: usize) -> Row {
    let (delta, d_s) = (params.delta, Clearance::one(params.d_s, params));
    let row = vertex_row(p, v, c, delta, d_s, params.zeta, RowKind::Road(k));
    let n = (p - c).norm().max(MIN_DISTANCE_M);
    let rate = (p - c).dot(&v) / n;
    let bend = (v.norm_squared() - rate * rate).max(0.0) / n;
    held_for(row, n - d_s.boundary(), rate, bend, delta, params.dt, d_s.eta_v)
}
