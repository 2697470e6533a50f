//! `airroads run --plot FILE.svg`: the road, every UAV's path from start to goal, where each one
//! stalled and where a traffic rule held it back (like Fig. 2 of the paper), drawn with plotters.

use fleet::paths::UavPath;
use fleet::{Stall, traffic::WaitReason};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use roads::{Airspace, Boundary};
use std::path::Path;

/// Width of the picture (px); the height follows the road's aspect ratio.
const WIDTH_PX: u32 = 1200;

/// Stalls shorter than this (s) are not marked.
const MARK_STALL_S: f64 = 2.0;

/// Waits shorter than this (s) are not marked.
const MARK_WAIT_S: f64 = 2.0;

/// Draws the run into an SVG file at `path`.
pub fn draw(
    path: &Path,
    road: &Airspace,
    paths: &[UavPath],
    stalls: &[Stall],
    title: &str,
) -> anyhow::Result<()> {
    let (lo, hi) = extent(road, paths);
    let margin = 0.05 * (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1.0);
    let (x0, x1, y0, y1) = (lo[0] - margin, hi[0] + margin, lo[1] - margin, hi[1] + margin);
    let height = ((WIDTH_PX as f64) * (y1 - y0) / (x1 - x0)).round().clamp(200.0, 4000.0) as u32;
    let root = SVGBackend::new(path, (WIDTH_PX, height + 30)).into_drawing_area();
    root.fill(&WHITE)?;
    let (header, body) = root.split_vertically(30);
    header.draw(&Text::new(title.to_string(), (8, 8), ("sans-serif", 16).into_font()))?;
    // Metres on both axes at the same scale: y grows upwards, as on a map.
    let area: DrawingArea<_, Cartesian2d<RangedCoordf64, RangedCoordf64>> =
        body.apply_coord_spec(Cartesian2d::new(x0..x1, y0..y1, (0..WIDTH_PX as i32, height as i32..0)));
    draw_road(&area, road)?;
    for (k, p) in paths.iter().enumerate() {
        draw_path(&area, p, Palette99::pick(k).to_rgba())?;
    }
    for s in stalls.iter().filter(|s| s.duration_s >= MARK_STALL_S) {
        let at = (s.at[0], s.at[1]);
        let radius = (4.0 + 2.0 * s.duration_s.sqrt()).min(20.0) as i32;
        area.draw(&Circle::new(at, radius, RED.stroke_width(2)))?;
        let label = format!("{} stalled {:.1} s", s.id, s.duration_s);
        area.draw(
            &(EmptyElement::at(at) + Text::new(label, (radius + 2, -6), ("sans-serif", 11).into_font())),
        )?;
    }
    root.present()?;
    Ok(())
}

/// The bounding box of the road and of every path.
fn extent(road: &Airspace, paths: &[UavPath]) -> ([f64; 2], [f64; 2]) {
    let road_points = road.wall_list().iter().flat_map(|w| [[w.a.x, w.a.y], [w.b.x, w.b.y]]);
    let path_points = paths.iter().flat_map(|p| p.points.iter().copied());
    road_points
        .chain(path_points)
        .filter(|p| p[0].is_finite() && p[1].is_finite())
        .fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), p| {
            ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
        })
}

type Area<'a> = DrawingArea<SVGBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn draw_road(area: &Area, airspace: &Airspace) -> anyhow::Result<()> {
    let surface = RGBColor(235, 238, 242);
    let outlines: Vec<Vec<(f64, f64)>> = match airspace {
        // p2 → p1 along one barrier line, p3 → p4 back along the other: each quad's outline.
        Airspace::Road(road) => road
            .quads()
            .iter()
            .map(|q| [1, 0, 2, 3].iter().map(|&i| (q.p[i].x, q.p[i].y)).collect())
            .collect(),
        Airspace::Network(net) => {
            net.cells().iter().map(|c| c.vertices.iter().map(|v| (v.x, v.y)).collect()).collect()
        }
    };
    for outline in outlines {
        area.draw(&Polygon::new(outline, surface.filled()))?;
    }
    for w in airspace.wall_list() {
        area.draw(&PathElement::new(vec![(w.a.x, w.a.y), (w.b.x, w.b.y)], BLACK.stroke_width(2)))?;
    }
    let Some(road) = airspace.road() else { return Ok(()) };
    let line = road.centerline();
    let steps = (line.length() / 0.25).ceil().max(1.0) as usize;
    let centre: Vec<(f64, f64)> = (0..=steps)
        .map(|k| line.point_at(line.length() * k as f64 / steps as f64))
        .map(|p| (p.x, p.y))
        .collect();
    area.draw(&PathElement::new(centre, RGBColor(200, 180, 60).stroke_width(1)))?;
    Ok(())
}

fn draw_path(area: &Area, path: &UavPath, colour: RGBAColor) -> anyhow::Result<()> {
    let points: Vec<(f64, f64)> = path.points.iter().map(|p| (p[0], p[1])).collect();
    area.draw(&PathElement::new(points.clone(), colour.stroke_width(2)))?;
    if let Some(&start) = points.first() {
        area.draw(&Circle::new(start, 4, colour.filled()))?;
        let label = Text::new(path.id.clone(), (5, -12), ("sans-serif", 10).into_font());
        area.draw(&(EmptyElement::at(start) + label))?;
    }
    if let Some(goal) = path.goal {
        area.draw(&Cross::new((goal[0], goal[1]), 5, colour.stroke_width(2)))?;
    }
    for w in path.waits.iter().filter(|w| w.duration_s >= MARK_WAIT_S) {
        let at = (w.at[0], w.at[1]);
        let fill = match w.reason {
            WaitReason::SingleFile => RGBColor(230, 198, 25),
            WaitReason::DeadlockBackoff => RGBColor(230, 120, 25),
            WaitReason::Junction => RGBColor(40, 150, 220),
            WaitReason::Merge => RGBColor(140, 90, 210),
        };
        // A square where the wait began, labelled with its reason and length.
        let label = format!("{} {:.1} s", w.reason.name(), w.duration_s);
        let mark = EmptyElement::at(at)
            + Rectangle::new([(-4, -4), (4, 4)], fill.filled())
            + Text::new(label, (6, 2), ("sans-serif", 9).into_font());
        area.draw(&mark)?;
    }
    Ok(())
}
