//! What the walls rule of the safety filter needs of a road, a chain ([`crate::Road`]) or a
//! network ([`crate::network::Network`]) alike: its walls, membership, and the walls near a point.

use crate::geometry::Wall;
use uav::Vec2;

/// A road's boundary as the walls rule reads it (docs/safety.md §5, §5.1).
pub trait Boundary {
    /// Every wall.
    fn wall_list(&self) -> &[Wall];
    /// True when `x` is in the road.
    fn inside(&self, x: &Vec2) -> bool;
    /// [`Boundary::inside`] for a point believed to be in segment or cell `hint` (the same answer).
    fn inside_in(&self, _hint: usize, x: &Vec2) -> bool {
        self.inside(x)
    }
    /// The index of a wall nearest to `x`.
    fn nearest_wall_to(&self, x: &Vec2) -> usize;
    /// Every wall within `radius` of `x` (and perhaps a few more), in index order; `hint` is the
    /// segment or cell the UAV is tracked in.
    fn walls_within(&self, hint: usize, x: &Vec2, radius: f64) -> impl Iterator<Item = usize> + '_;
    /// The distance (m) from `x` to the nearest wall, negative outside; `hint` as for
    /// [`Boundary::walls_within`].
    fn signed_distance_in(&self, hint: usize, x: &Vec2) -> f64;
}

impl Boundary for crate::Road {
    fn wall_list(&self) -> &[Wall] {
        self.walls()
    }

    fn inside(&self, x: &Vec2) -> bool {
        self.contains(x)
    }

    fn inside_in(&self, hint: usize, x: &Vec2) -> bool {
        self.contains_in(hint, x)
    }

    fn nearest_wall_to(&self, x: &Vec2) -> usize {
        self.nearest_wall(x)
    }

    fn walls_within(&self, hint: usize, x: &Vec2, radius: f64) -> impl Iterator<Item = usize> + '_ {
        self.walls_near_in(hint, x, radius)
    }

    fn signed_distance_in(&self, hint: usize, x: &Vec2) -> f64 {
        self.boundary_distance_in(hint, x)
    }
}

impl Boundary for crate::network::Network {
    fn wall_list(&self) -> &[Wall] {
        Self::wall_list(self)
    }

    fn inside(&self, x: &Vec2) -> bool {
        self.contains(x)
    }

    fn inside_in(&self, hint: usize, x: &Vec2) -> bool {
        self.contains_in(hint, x)
    }

    fn nearest_wall_to(&self, x: &Vec2) -> usize {
        self.nearest_wall(x)
    }

    fn walls_within(&self, hint: usize, x: &Vec2, radius: f64) -> impl Iterator<Item = usize> + '_ {
        self.walls_near_in(hint, x, radius)
    }

    fn signed_distance_in(&self, hint: usize, x: &Vec2) -> f64 {
        let d = self.boundary_distance_in(hint, x);
        if self.contains_in(hint, x) { d } else { -d }
    }
}
