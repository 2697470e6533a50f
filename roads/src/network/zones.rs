//! The conflict zones of a network (docs/traffic.md, "Junctions and merges"): every cell where three
//! or more passages meet (a junction polygon, or a road segment another road's end attaches to).
//! A UAV crosses a zone as a *movement*: in through one of its arms (passages), out through another.
//! Two movements *cross* when their lanes through the zone (the straight line from the middle of the
//! entry's gate to the middle of the exit's, [`GateRule`]: to the right of the middle on two-way
//! roads) come closer than D_c; they *merge* when they leave through the same arm from different
//! ones. Movements from the same arm never conflict (they follow each other in their lane).

use super::{GateRule, Network};
use crate::lanes::segment_distance;

/// A movement through a zone: the arm it comes in by and the arm it leaves by, as indices into
/// [`ConflictZone::arms`]; the index `arms.len()` stands for "inside" (a way that starts or ends in
/// the zone).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Movement {
    /// The arm it enters by.
    pub entry: usize,
    /// The arm it leaves by.
    pub exit: usize,
}

/// How two movements through a zone conflict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Conflict {
    /// They may use the zone together.
    None,
    /// Their lanes cross (or pass closer than D_c).
    Cross,
    /// They leave by the same arm from different ones.
    Merge,
}

/// One conflict zone: a cell with its arms and the conflicts between its movements.
#[derive(Debug, Clone, PartialEq)]
pub struct ConflictZone {
    /// The cell.
    pub cell: usize,
    /// The neighbour cell behind each arm (its passages' order).
    pub arms: Vec<usize>,
    /// `conflicts[index(a) * m + index(b)]`, m = (arms + 1)², for movements a and b.
    conflicts: Vec<Conflict>,
}

impl ConflictZone {
    /// The arm leading to neighbour `cell`, or "inside" ([`Movement`]) for None or a cell that is
    /// not a neighbour.
    pub fn arm(&self, cell: Option<usize>) -> usize {
        cell.and_then(|c| self.arms.iter().position(|&a| a == c)).unwrap_or(self.arms.len())
    }

    /// How movements `a` and `b` conflict.
    pub fn conflict(&self, a: Movement, b: Movement) -> Conflict {
        let m = (self.arms.len() + 1) * (self.arms.len() + 1);
        self.conflicts[self.index(a) * m + self.index(b)]
    }

    fn index(&self, m: Movement) -> usize {
        let n = self.arms.len() + 1;
        m.entry.min(n - 1) * n + m.exit.min(n - 1)
    }
}

/// How two movements of a zone conflict, given their lanes (None for a way that starts or ends
/// inside: it conflicts with every movement from another arm).
fn conflict_of(
    a: Movement,
    b: Movement,
    lane_a: Option<(uav::Vec2, uav::Vec2)>,
    lane_b: Option<(uav::Vec2, uav::Vec2)>,
    d_c: f64,
) -> Conflict {
    if a.entry == b.entry {
        return Conflict::None;
    }
    if a.exit == b.exit {
        return Conflict::Merge;
    }
    match (lane_a, lane_b) {
        (Some((p, q)), Some((x, y))) if segment_distance(&p, &q, &x, &y) >= d_c => Conflict::None,
        _ => Conflict::Cross,
    }
}

impl Network {
    /// The conflict zones: every cell with three or more passages, with the conflicts of its
    /// movements through the gates of `rule`; movements closer than `d_c` cross.
    pub fn conflict_zones(&self, rule: GateRule, d_c: f64) -> Vec<ConflictZone> {
        (0..self.cells.len())
            .filter(|&c| self.passages[c].len() >= 3)
            .map(|cell| {
                let arms: Vec<usize> = self.passages[cell].iter().map(|p| p.other).collect();
                let n = arms.len() + 1;
                let movements: Vec<Movement> =
                    (0..n * n).map(|k| Movement { entry: k / n, exit: k % n }).collect();
                let lane = |m: &Movement| {
                    let (from, into) = (*arms.get(m.entry)?, *arms.get(m.exit)?);
                    let (entry, _) = self.gate(from, cell, rule);
                    let (exit, _) = self.gate(cell, into, rule);
                    Some(((entry.left + entry.right) / 2.0, (exit.left + exit.right) / 2.0))
                };
                let lanes: Vec<_> = movements.iter().map(lane).collect();
                let conflicts = movements
                    .iter()
                    .zip(&lanes)
                    .flat_map(|(a, la)| {
                        movements.iter().zip(&lanes).map(move |(b, lb)| conflict_of(*a, *b, *la, *lb, d_c))
                    })
                    .collect();
                ConflictZone { cell, arms, conflicts }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::{CellKind, Junction, NetworkLayout, NetworkRoad};

    /// A 4-way crossing: a 4 m square junction at the origin with a 4 m wide road on each side.
    fn crossing() -> Network {
        let road = |name: &str, segments: Vec<[[f64; 2]; 4]>| NetworkRoad {
            name: name.into(),
            segments,
            one_way: false,
            speed_limit: None,
        };
        // Each road runs away from the junction: p2, p4 on the junction's edge.
        let layout = NetworkLayout {
            roads: vec![
                road("east", vec![[[8.0, -2.0], [2.0, -2.0], [8.0, 2.0], [2.0, 2.0]]]),
                road("west", vec![[[-8.0, 2.0], [-2.0, 2.0], [-8.0, -2.0], [-2.0, -2.0]]]),
                road("north", vec![[[2.0, 8.0], [2.0, 2.0], [-2.0, 8.0], [-2.0, 2.0]]]),
                road("south", vec![[[-2.0, -8.0], [-2.0, -2.0], [2.0, -8.0], [2.0, -2.0]]]),
            ],
            junctions: vec![Junction {
                name: "x".into(),
                polygon: vec![[-2.0, -2.0], [2.0, -2.0], [2.0, 2.0], [-2.0, 2.0]],
            }],
            regions: None,
        };
        Network::new(layout, 0.6).expect("a valid crossing")
    }

    #[test]
    fn a_crossing_lets_opposite_straights_pass_together_and_stops_left_turns_across_them() {
        let net = crossing();
        let rule = GateRule { clearance: 0.2, keep_right: Some(0.2) };
        let zones = net.conflict_zones(rule, 0.3);
        assert_eq!(zones.len(), 1, "one zone: the junction");
        let z = &zones[0];
        let arm = |name: &str| {
            let road = net.layout.roads.iter().position(|r| r.name == name).expect("a road of the test");
            z.arms
                .iter()
                .position(|&c| matches!(net.cells[c].kind, CellKind::Segment { road: r, .. } if r == road))
                .expect("an arm per road")
        };
        let (e, w, n, s) = (arm("east"), arm("west"), arm("north"), arm("south"));
        let go = |entry, exit| Movement { entry, exit };
        // East to west and west to east keep right: their lanes are D_c apart.
        assert_eq!(z.conflict(go(e, w), go(w, e)), Conflict::None);
        // South to north crosses both.
        assert_eq!(z.conflict(go(e, w), go(s, n)), Conflict::Cross);
        assert_eq!(z.conflict(go(s, n), go(w, e)), Conflict::Cross);
        // A left turn (from the east, heading west, into the south) crosses the opposite straight.
        assert_eq!(z.conflict(go(e, s), go(w, e)), Conflict::Cross);
        // Right turns from opposite arms do not meet.
        assert_eq!(z.conflict(go(e, n), go(w, s)), Conflict::None);
        // Two arms into one: a merge; one arm into two: none.
        assert_eq!(z.conflict(go(e, w), go(n, w)), Conflict::Merge);
        assert_eq!(z.conflict(go(e, w), go(e, s)), Conflict::None);
        // A way that ends inside conflicts with every other arm's movement.
        let inside = z.arm(None);
        assert_eq!(z.conflict(go(e, inside), go(w, e)), Conflict::Cross);
        // Symmetric.
        for a in 0..25 {
            for b in 0..25 {
                let (ma, mb) = (go(a / 5, a % 5), go(b / 5, b % 5));
                assert_eq!(z.conflict(ma, mb), z.conflict(mb, ma), "{ma:?} {mb:?}");
            }
        }
    }
}
