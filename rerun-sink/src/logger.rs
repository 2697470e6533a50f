//! What the Rerun sink logs for each snapshot (entities and series listed in `rerun_sink`), and
//! what it remembers between snapshots: the road version, each UAV's trail, the sink's counters.
//! Above `batch_above` UAVs the fleet is one batch (`rerun_fleet`) and only the selected UAVs get
//! their own entities.

use super::fleet_log::FleetLog;
use super::{SinkStats, TICK_TIMELINE, TIME_TIMELINE, TRAIL_EVERY_TICKS, TRAIL_POINTS};
use engine::fleet_loop::RoadView;
use engine::snapshot::{ReservationSnapshot, Snapshot, UavSnapshot, UavStatus};
use engine::stats::LoopMetrics;
use rerun::{
    Arrows2D, Clear, Color, EntityPath, EntityPathPart, LineStrip2D, LineStrips2D, Points2D, Radius,
    RecordingStream, RecordingStreamResult, Scalars, Transform3D,
};
use std::collections::{HashMap, HashSet, VecDeque};

/// Entity paths and trail of one UAV.
struct UavLog {
    root: EntityPath,
    trail: EntityPath,
    velocity: EntityPath,
    target: EntityPath,
    goal: EntityPath,
    barrier: EntityPath,
    slack: EntityPath,
    points: VecDeque<[f32; 2]>,
    trail_tick: Option<u64>,
    had_goal: bool,
    seen_tick: u64,
}

fn path(parts: &[&str]) -> EntityPath {
    EntityPath::new(parts.iter().map(|p| EntityPathPart::new(*p)).collect())
}

impl UavLog {
    fn new(id: &str) -> Self {
        let below = |leaf| path(&["world", "uavs", id, leaf]);
        Self {
            root: path(&["world", "uavs", id]),
            trail: below("trail"),
            velocity: below("velocity"),
            target: below("target"),
            goal: below("goal"),
            barrier: path(&["barrier", id]),
            slack: path(&["slack", id]),
            points: VecDeque::with_capacity(TRAIL_POINTS),
            trail_tick: None,
            had_goal: false,
            seen_tick: 0,
        }
    }
}

/// What the sink remembers between snapshots.
#[derive(Default)]
pub(super) struct Logger {
    /// Above this many UAVs the fleet is logged as one batch.
    batch_above: usize,
    fleet: FleetLog,
    road_version: Option<u64>,
    last_tick: Option<u64>,
    /// Reservations were logged and must be cleared when the road has none any more.
    had_reservations: bool,
    uavs: HashMap<String, UavLog>,
    pub(super) stats: SinkStats,
}

/// A position or vector as Rerun takes it.
pub(super) fn xy(v: [f64; 2]) -> [f32; 2] {
    [v[0] as f32, v[1] as f32]
}

/// A UAV's colour by status (as in the dashboard's legend).
pub(super) fn color(status: UavStatus) -> Color {
    match status {
        UavStatus::Flying => Color::from_rgb(60, 200, 90),
        UavStatus::Arrived => Color::from_rgb(70, 140, 255),
        UavStatus::Braking => Color::from_rgb(255, 170, 40),
        UavStatus::Failed => Color::from_rgb(230, 40, 40),
        UavStatus::Stale => Color::from_rgb(150, 150, 150),
        UavStatus::Lost => Color::from_rgb(176, 23, 155),
        UavStatus::Connecting => Color::from_rgb(185, 194, 204),
        UavStatus::TakingOff => Color::from_rgb(127, 200, 160),
        UavStatus::Landing => Color::from_rgb(143, 179, 232),
        UavStatus::Landed => Color::from_rgb(91, 101, 112),
        UavStatus::Stopped => Color::from_rgb(59, 13, 13),
        UavStatus::Stopping => Color::from_rgb(150, 30, 30),
        UavStatus::Waiting => Color::from_rgb(240, 210, 40),
    }
}

/// A single-file section's colour: grey while free, green while admitting from its start, blue
/// from its end.
fn reservation_color(r: &ReservationSnapshot) -> Color {
    match r.open_from {
        None => Color::from_rgb(150, 150, 150),
        Some("start") => Color::from_rgb(60, 200, 90),
        Some(_) => Color::from_rgb(70, 140, 255),
    }
}

/// The label beside a single-file section: who it admits, how many are in and how many wait.
fn reservation_label(r: &ReservationSnapshot) -> String {
    let open = r.open_from.map_or("free".to_string(), |end| format!("from {end}"));
    format!("single file: {open}, {} in, {} waiting", r.admitted, r.waiting)
}

impl Logger {
    /// A logger that batches fleets of more than `batch_above` UAVs.
    pub(super) fn new(batch_above: usize) -> Self {
        Self { batch_above, ..Self::default() }
    }

    /// True when `snapshot` is logged as one batch.
    pub(super) fn batched(&self, snapshot: &Snapshot) -> bool {
        snapshot.uavs.len() > self.batch_above
    }

    /// Logs the road again with the next snapshot (a new viewer has not seen it).
    pub(super) fn forget_road(&mut self) {
        self.road_version = None;
    }

    /// Logs one snapshot (and the road when it changed) on the tick timeline; in a batched fleet
    /// only the UAVs in `selection` get their own entities.
    pub(super) fn log(
        &mut self,
        rec: &RecordingStream,
        snapshot: &Snapshot,
        road: &RoadView,
        metrics: &LoopMetrics,
        selection: &HashSet<String>,
    ) {
        if self.last_tick == Some(snapshot.tick) {
            return; // The first snapshot after a (re)connection may be one already logged.
        }
        if let Some(last) = self.last_tick {
            self.stats.skipped += snapshot.tick.saturating_sub(last + 1);
        }
        self.last_tick = Some(snapshot.tick);
        match self.log_snapshot(rec, snapshot, road, metrics, selection) {
            Ok(()) => self.stats.logged += 1,
            Err(e) => {
                if self.stats.errors == 0 {
                    tracing::warn!("rerun: logging tick {}: {e}", snapshot.tick);
                }
                self.stats.errors += 1;
            }
        }
    }

    fn log_snapshot(
        &mut self,
        rec: &RecordingStream,
        snapshot: &Snapshot,
        road: &RoadView,
        metrics: &LoopMetrics,
        selection: &HashSet<String>,
    ) -> RecordingStreamResult<()> {
        rec.set_time_sequence(TICK_TIMELINE, i64::try_from(snapshot.tick).unwrap_or(i64::MAX));
        rec.set_duration_secs(TIME_TIMELINE, snapshot.time);
        if self.road_version != Some(road.version) {
            // Rerun's 2D view draws y downwards; flipping `world` shows the road as on a map.
            rec.log_static("world", &Transform3D::from_scale([1.0, -1.0, 1.0]))?;
            log_road(rec, road)?;
            self.road_version = Some(road.version);
        }
        let radius = (snapshot.d_c / 2.0) as f32;
        let batched = self.batched(snapshot);
        if batched {
            self.fleet.log(rec, snapshot, radius)?;
        } else {
            self.fleet.clear(rec)?;
        }
        for u in &snapshot.uavs {
            if batched && !selection.contains(&*u.id) {
                continue; // Cleared below if it had its own entities.
            }
            if !self.uavs.contains_key(&*u.id) {
                self.uavs.insert(u.id.to_string(), UavLog::new(&u.id));
            }
            if let Some(log) = self.uavs.get_mut(&*u.id) {
                log_uav(rec, log, u, snapshot.tick, radius)?;
            }
        }
        let gone: Vec<String> = self
            .uavs
            .iter()
            .filter(|(_, l)| l.seen_tick != snapshot.tick)
            .map(|(id, _)| id.clone())
            .collect();
        for id in gone {
            if let Some(log) = self.uavs.remove(&id) {
                rec.log(log.root, &Clear::recursive())?;
                rec.log(log.barrier, &Clear::flat())?;
                rec.log(log.slack, &Clear::flat())?;
            }
        }
        if !snapshot.reservations.is_empty() {
            let r = &snapshot.reservations;
            let strips = r.iter().map(|z| LineStrip2D::from_iter(z.path.iter().map(|p| xy(*p))));
            let strips = LineStrips2D::new(strips)
                .with_colors(r.iter().map(reservation_color))
                .with_labels(r.iter().map(reservation_label))
                .with_radii([Radius::new_ui_points(4.0)]);
            rec.log("world/road/reservations", &strips)?;
            self.had_reservations = true;
        } else if self.had_reservations {
            rec.log("world/road/reservations", &Clear::flat())?;
            self.had_reservations = false;
        }
        if let Some(m) = snapshot.min_collision_margin_m {
            rec.log("margins/collision", &Scalars::single(m))?;
        }
        if let Some(m) = snapshot.min_road_margin_m {
            rec.log("margins/road", &Scalars::single(m))?;
        }
        if metrics.ticks > 0 {
            rec.log("tick_us/p50", &Scalars::single(metrics.tick.p50_us))?;
            rec.log("tick_us/p99", &Scalars::single(metrics.tick.p99_us))?;
        }
        Ok(())
    }
}

fn log_uav(
    rec: &RecordingStream,
    log: &mut UavLog,
    u: &UavSnapshot,
    tick: u64,
    radius: f32,
) -> RecordingStreamResult<()> {
    log.seen_tick = tick;
    let p = xy(u.p);
    let point = Points2D::new([p]).with_labels([&*u.id]).with_colors([color(u.status)]);
    rec.log(log.root.clone(), &point.with_radii([radius]))?;
    rec.log(log.velocity.clone(), &Arrows2D::from_vectors([xy(u.v)]).with_origins([p]))?;
    rec.log(log.target.clone(), &Points2D::new([xy(u.target)]).with_radii([Radius::new_ui_points(3.0)]))?;
    match u.goal {
        Some(goal) => {
            let goal = Points2D::new([xy(goal)]).with_colors([Color::from_rgb(255, 255, 255)]);
            rec.log(log.goal.clone(), &goal.with_radii([Radius::new_ui_points(5.0)]))?;
        }
        None if log.had_goal => rec.log(log.goal.clone(), &Clear::flat())?,
        None => {}
    }
    log.had_goal = u.goal.is_some();
    if log.trail_tick.is_none_or(|t| tick >= t + TRAIL_EVERY_TICKS) {
        if log.points.len() == TRAIL_POINTS {
            log.points.pop_front();
        }
        log.points.push_back(p);
        log.trail_tick = Some(tick);
        let strip = LineStrip2D::from_iter(log.points.iter().copied());
        rec.log(log.trail.clone(), &LineStrips2D::new([strip]).with_radii([Radius::new_ui_points(1.0)]))?;
    }
    if let Some(b) = u.min_barrier {
        rec.log(log.barrier.clone(), &Scalars::single(b))?;
    }
    rec.log(log.slack.clone(), &Scalars::single(u.slack))
}

/// Logs the road: its walls, a chain road's centre line, a network's cells as closed outlines
/// (`world/road/cells`; cleared on a chain road, which has no centre line on a network).
fn log_road(rec: &RecordingStream, road: &RoadView) -> RecordingStreamResult<()> {
    let walls = road.walls.iter().map(|[a, b]| LineStrip2D::from_iter([xy(*a), xy(*b)]));
    let walls = LineStrips2D::new(walls).with_colors([Color::from_rgb(220, 220, 220)]);
    rec.log("world/road/walls", &walls.with_radii([Radius::new_ui_points(1.5)]))?;
    if road.centerline.is_empty() {
        rec.log("world/road/centerline", &Clear::flat())?;
    } else {
        let centre = LineStrip2D::from_iter(road.centerline.iter().map(|p| xy(*p)));
        let centre = LineStrips2D::new([centre]).with_colors([Color::from_rgb(200, 180, 60)]);
        rec.log("world/road/centerline", &centre.with_radii([Radius::new_ui_points(0.5)]))?;
    }
    if road.cells.is_empty() {
        return rec.log("world/road/cells", &Clear::flat());
    }
    let outlines = road.cells.iter().map(|c| {
        let closed = c.polygon.iter().chain(c.polygon.first()).map(|p| xy(*p));
        LineStrip2D::from_iter(closed)
    });
    let labels = road.cells.iter().map(|c| match c.segment {
        Some(k) => format!("{}[{k}]", c.name),
        None => c.name.clone(),
    });
    let cells = LineStrips2D::new(outlines)
        .with_colors([Color::from_rgb(110, 130, 160)])
        .with_radii([Radius::new_ui_points(0.5)])
        .with_labels(labels)
        .with_show_labels(false);
    rec.log("world/road/cells", &cells)
}
