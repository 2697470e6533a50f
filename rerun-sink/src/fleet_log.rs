//! The fleet as one batch (`world/fleet`), for fleets above `--rerun-batch-above` UAVs: one
//! `Points2D` and one `Arrows2D` per tick for every UAV, so the sink's work and the recording's
//! chunk count per tick do not grow with the number of entities. The UAVs' ids are the points'
//! labels, logged again only when the roster (the ids in snapshot order) changes: Rerun joins them
//! to later positions by instance index.

use super::logger::{color, xy};
use engine::snapshot::Snapshot;
use rerun::{Arrows2D, Clear, Color, Points2D, RecordingStream, RecordingStreamResult};

/// Entity of the fleet's positions (labels: the UAVs' ids).
pub const FLEET_ENTITY: &str = "world/fleet";
/// Entity of the fleet's velocities.
pub const FLEET_VELOCITY_ENTITY: &str = "world/fleet/velocity";

/// What the batch remembers between ticks, and its buffers (reused: no allocation per tick once
/// the fleet's size is reached).
#[derive(Default)]
pub(super) struct FleetLog {
    /// The ids the labels were last logged for, in snapshot order.
    roster: Vec<String>,
    /// `world/fleet` holds data (to clear when the fleet falls back under the threshold).
    logged: bool,
    positions: Vec<[f32; 2]>,
    velocities: Vec<[f32; 2]>,
    colors: Vec<Color>,
}

impl FleetLog {
    /// Logs every UAV of `snapshot` as one batch; points have radius `radius` (m).
    pub(super) fn log(
        &mut self,
        rec: &RecordingStream,
        snapshot: &Snapshot,
        radius: f32,
    ) -> RecordingStreamResult<()> {
        let uavs = &snapshot.uavs;
        self.positions.clear();
        self.positions.extend(uavs.iter().map(|u| xy(u.p)));
        self.velocities.clear();
        self.velocities.extend(uavs.iter().map(|u| xy(u.v)));
        self.colors.clear();
        self.colors.extend(uavs.iter().map(|u| color(u.status)));
        let same_roster =
            self.roster.len() == uavs.len() && self.roster.iter().zip(uavs).all(|(id, u)| **id == *u.id);
        let mut points = Points2D::update_fields()
            .with_positions(self.positions.iter().copied())
            .with_colors(self.colors.iter().copied());
        if !same_roster || !self.logged {
            self.roster.clear();
            self.roster.extend(uavs.iter().map(|u| u.id.to_string()));
            // Thousands of labels would cover the view: they show on hover and in the selection panel.
            points = points
                .with_labels(self.roster.iter().map(String::as_str))
                .with_show_labels(false)
                .with_radii([radius]);
        }
        rec.log(FLEET_ENTITY, &points)?;
        let arrows = Arrows2D::from_vectors(self.velocities.iter().copied())
            .with_origins(self.positions.iter().copied());
        rec.log(FLEET_VELOCITY_ENTITY, &arrows)?;
        self.logged = true;
        Ok(())
    }

    /// Clears the batch (the fleet is logged per UAV again).
    pub(super) fn clear(&mut self, rec: &RecordingStream) -> RecordingStreamResult<()> {
        if self.logged {
            rec.log(FLEET_ENTITY, &Clear::recursive())?;
            self.logged = false;
            self.roster.clear();
        }
        Ok(())
    }
}
