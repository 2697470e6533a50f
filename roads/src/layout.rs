//! The road layout JSON format: `{"segments": [[p1, p2, p3, p4], ...]}`, vertices `[x, y]` in metres,
//! optionally with `"regions": [{"name", "segments": [first, last]}, ...]`.

use crate::regions::Region;
use serde::{Deserialize, Deserializer, Serialize};
use uav::Vec2;

/// A road layout as users write it: a chain of convex quadrilateral segments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RoadLayout {
    /// Segment i as `[p1, p2, p3, p4]`, each vertex `[x, y]` in metres.
    #[schemars(with = "crate::schema::Segments")]
    pub segments: Vec<[[f64; 2]; 4]>,
    /// Named ranges of segments that cover every segment exactly once; None (absent from the JSON)
    /// when the layout is not divided into regions.
    #[serde(default, skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    #[schemars(with = "crate::schema::Regions")]
    #[schemars(
        description = "optional: named inclusive segment ranges that cover every segment exactly once (the partition the regional servers will use); absent when the road is not divided"
    )]
    pub regions: Option<Vec<Region>>,
}

/// `regions` when the key is there: a list (`null` is refused; an absent key is None by default).
fn present<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<Region>>, D::Error> {
    Vec::deserialize(d).map(Some)
}

impl RoadLayout {
    /// A layout of `segments` without regions.
    pub fn new(segments: Vec<[[f64; 2]; 4]>) -> Self {
        Self { segments, regions: None }
    }

    /// A road along a centre polyline with mitre joints (each joint edge bisects its bend);
    /// `widths[k]` is the road's width measured perpendicular to the pieces at polyline vertex k.
    /// The result still has to pass [`crate::Road::new`] (sharp bends on short pieces are not convex).
    pub fn from_centerline(points: &[[f64; 2]], widths: &[f64]) -> Self {
        let c: Vec<Vec2> = points.iter().map(|p| Vec2::new(p[0], p[1])).collect();
        let left_normal = |k: usize| {
            let d = (c[k + 1] - c[k]).normalize();
            Vec2::new(-d.y, d.x)
        };
        let pieces = c.len().saturating_sub(1);
        // Offset of the left vertex at each polyline vertex (the right one is its mirror).
        let offsets: Vec<Vec2> = (0..c.len())
            .map(|k| {
                let half = widths[k] / 2.0;
                let n = match (k.checked_sub(1), k < pieces) {
                    (Some(prev), true) => {
                        let (a, b) = (left_normal(prev), left_normal(k));
                        let bis = (a + b).normalize();
                        return bis * (half / bis.dot(&b));
                    }
                    (Some(prev), false) => left_normal(prev),
                    (None, _) => left_normal(k),
                };
                n * half
            })
            .collect();
        let arr = |v: Vec2| [v.x, v.y];
        let segments = (0..pieces)
            .map(|i| {
                let (r0, r1) = (c[i] - offsets[i], c[i + 1] - offsets[i + 1]);
                let (l0, l1) = (c[i] + offsets[i], c[i + 1] + offsets[i + 1]);
                [arr(r1), arr(r0), arr(l1), arr(l0)]
            })
            .collect();
        Self::new(segments)
    }

    /// A straight road along +x from `x0` to `x1` (`count` equal segments), `width` wide, centred on y = 0.
    pub fn straight(x0: f64, x1: f64, width: f64, count: usize) -> Self {
        let h = width / 2.0;
        let step = (x1 - x0) / count as f64;
        let segments = (0..count)
            .map(|i| {
                let a = x0 + step * i as f64;
                let b = a + step;
                // p1, p2 on the right wall (y = -h), p3, p4 on the left wall (y = +h); entry p2-p4 at x = a.
                [[b, -h], [a, -h], [b, h], [a, h]]
            })
            .collect();
        Self::new(segments)
    }
}
