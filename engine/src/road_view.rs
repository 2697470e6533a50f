//! The road as published to readers (`GET /api/road/geometry`, the dashboard, Rerun): the layout
//! as put, its walls, a chain road's centre line and a network's cells.

use roads::network::{CellKind, Network};
use roads::{Airspace, AirspaceLayout, Road};
use serde::Serialize;
use uav::Params;

/// The road as published to readers: the layout plus its drawable geometry.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
#[schemars(rename = "RoadGeometry")]
pub struct RoadView {
    /// Increases with every change.
    pub version: u64,
    /// The layout (`PUT /api/road` format): a chain layout, or a network layout.
    pub layout: AirspaceLayout,
    /// Every finite wall (barrier lines and end caps; a network's edges no other cell shares) as
    /// `[[x1, y1], [x2, y2]]`.
    pub walls: Vec<[[f64; 2]; 2]>,
    /// The centre line as a polyline (a chain road's; empty on a network).
    pub centerline: Vec<[f64; 2]>,
    /// A network's cells (its roads' segments, then its junctions); absent for a chain road.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cells: Vec<CellView>,
    /// The narrowest passage a network may have with the fleet's parameters now (m): 2·D_s + D_c
    /// and margins (`PUT /api/road` refuses a narrower one, rule `narrow_passage`).
    pub min_passage_m: f64,
    /// The tick boundary at which this version was put in place (the instant the loop had
    /// scheduled for that gap, ms since the Unix epoch).
    pub since_ms: u64,
}

/// What a cell of a network is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CellKindView {
    /// A segment of a road.
    Segment,
    /// A junction.
    Junction,
}

/// One convex cell of a network, for drawing.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct CellView {
    /// A road's segment or a junction.
    pub kind: CellKindView,
    /// The name of its road (a segment) or its own (a junction).
    pub name: String,
    /// Its index among its road's segments (absent for a junction).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub segment: Option<usize>,
    /// Its vertices `[x, y]` in cyclic order (a segment's p1, p2, p4, p3).
    pub polygon: Vec<[f64; 2]>,
}

fn xy(v: &uav::Vec2) -> [f64; 2] {
    [v.x, v.y]
}

impl RoadView {
    /// The view of what a fleet flies with `params`, a road or a network, at `version`, put in
    /// place at `since_ms`.
    pub fn of(airspace: &Airspace, params: &Params, version: u64, since_ms: u64) -> Self {
        let mut view = match airspace {
            Airspace::Road(road) => Self::of_road(road, version, since_ms),
            Airspace::Network(net) => Self::of_network(net, version, since_ms),
        };
        view.min_passage_m = fleet::min_passage_m(params);
        view
    }

    fn of_road(road: &Road, version: u64, since_ms: u64) -> Self {
        Self {
            version,
            layout: road.layout().clone().into(),
            walls: road.walls().iter().map(|w| [xy(&w.a), xy(&w.b)]).collect(),
            centerline: road.centerline().points().iter().map(xy).collect(),
            cells: Vec::new(),
            min_passage_m: 0.0,
            since_ms,
        }
    }

    fn of_network(net: &Network, version: u64, since_ms: u64) -> Self {
        let layout = net.layout();
        let cells = net
            .cells()
            .iter()
            .map(|cell| {
                let (kind, name, segment) = match cell.kind {
                    CellKind::Segment { road, segment } => {
                        (CellKindView::Segment, layout.roads[road].name.clone(), Some(segment))
                    }
                    CellKind::Junction { junction } => {
                        (CellKindView::Junction, layout.junctions[junction].name.clone(), None)
                    }
                };
                CellView { kind, name, segment, polygon: cell.vertices.iter().map(xy).collect() }
            })
            .collect();
        Self {
            version,
            layout: layout.clone().into(),
            walls: net.walls().map(|(a, b, _)| [xy(&a), xy(&b)]).collect(),
            centerline: Vec::new(),
            cells,
            min_passage_m: 0.0,
            since_ms,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roads::RoadLayout;
    use roads::network::NetworkLayout;

    #[test]
    fn a_network_shows_its_cells_and_walls_and_a_chain_keeps_its_keys() {
        let chain = RoadLayout::straight(0.0, 10.0, 4.0, 2);
        let params = Params::default();
        let view = RoadView::of(&Airspace::Road(Road::new(chain.clone()).unwrap()), &params, 3, 7);
        let json = serde_json::to_value(&view).unwrap();
        assert_eq!(json["layout"], serde_json::to_value(&chain).unwrap());
        assert!(json.get("cells").is_none(), "{json}");
        assert!(!view.centerline.is_empty());
        let net = Network::new(NetworkLayout::from(&chain), 1.0).unwrap();
        let view = RoadView::of(&Airspace::Network(net), &params, 4, 8);
        assert_eq!(view.min_passage_m, fleet::min_passage_m(&params));
        assert_eq!(view.cells.len(), 2);
        assert_eq!((view.cells[1].name.as_str(), view.cells[1].segment), ("road", Some(1)));
        assert_eq!(view.cells[0].polygon.len(), 4);
        // Two segments end to end: 2 long sides each and the two end caps.
        assert_eq!(view.walls.len(), 6);
        assert!(view.centerline.is_empty());
        let json = serde_json::to_value(&view).unwrap();
        assert_eq!(json["layout"]["roads"][0]["name"], "road");
        assert_eq!(json["cells"][0]["kind"], "segment");
    }
}
