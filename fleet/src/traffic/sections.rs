//! Single-file sections: the parts of a road where opposite UAVs cannot pass each other (or only
//! slowly), found once per road from its clearance profile, with the hold points where UAVs wait
//! for their turn on either side ([`crate::traffic`] reserves them through [`crate::traffic::zones`]).

use roads::{Navigator, PROFILE_STEP_M, Road, RoutePosition};

/// Distance (m) from a single-file section's end at which UAVs wait for their turn.
pub const HOLD_M: f64 = 1.0;

/// A grant is kept until its UAV is this far (m) beyond the section's far end.
pub const EXIT_M: f64 = 0.5;

/// A part of the road's centre line, [start, end] in arc length, where two opposite UAVs do not
/// fit side by side, with the hold points where UAVs wait for their turn on either side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section {
    /// Arc length where it starts.
    pub start: f64,
    /// Arc length where it ends.
    pub end: f64,
    /// Where UAVs coming from its start wait: [`HOLD_M`] before the nearest place (within r_s) wide
    /// enough for a waiting UAV beside the lane of those leaving.
    pub hold_before: f64,
    /// Where UAVs coming from its end wait.
    pub hold_after: f64,
    /// Opposite UAVs can pass each other everywhere in it (slowly, in their lanes): it is tight, not
    /// single file.
    pub passable: bool,
}

impl Section {
    /// True when arc length `s` is nearer the end a UAV from `entry` leaves by than the one it came in.
    pub fn exit_side(&self, entry: usize, s: f64) -> bool {
        let middle = (self.start + self.end) / 2.0;
        if entry == 0 { s >= middle } else { s <= middle }
    }
}

/// The single-file sections of `road` for `nav`'s parameters: maximal runs of profile samples where
/// the lanes are not roomy (single file, or tight), merged when the two-way gap between them is too
/// short to wait in, and kept only where there are places to wait on both sides: on a road that is
/// narrow end to end nobody could wait for a turn, so traffic keeps to its lanes there (or to the
/// middle, passing slowly under the filter) and the deadlock rule sorts out meetings.
pub fn sections(road: &Road, nav: &Navigator) -> Vec<Section> {
    let length = road.centerline().length();
    let mut out: Vec<Section> = Vec::new();
    let samples = road.profile().len();
    let s = |k: usize| (k as f64 * PROFILE_STEP_M).min(length);
    let mut k = 0;
    while k < samples {
        if nav.roomy_at(s(k)) {
            k += 1;
            continue;
        }
        let first = k;
        while k < samples && !nav.roomy_at(s(k)) {
            k += 1;
        }
        let (start, end) = (s(first), s(k - 1));
        let passable = (first..k).all(|j| nav.two_way_at(s(j)));
        match out.last_mut() {
            Some(last) if start - last.end < 2.0 * HOLD_M + nav.d_c => {
                last.end = end;
                last.passable &= passable;
            }
            _ => out.push(Section { start, end, hold_before: start, hold_after: end, passable }),
        }
    }
    out.into_iter()
        .filter_map(|mut z| {
            z.hold_before = wide_place(nav, z.start, -1.0, length)? - HOLD_M;
            z.hold_after = wide_place(nav, z.end, 1.0, length)? + HOLD_M;
            Some(z)
        })
        .collect()
}

/// The nearest arc length from `s` towards `direction` (at most r_s away, on the road) where each
/// side of the road has room for a lane and a UAV waiting beside it: D_s + margin + D_c/2 + gap + D_c.
fn wide_place(nav: &Navigator, s: f64, direction: f64, length: f64) -> Option<f64> {
    let room = nav.d_s + roads::CLEARANCE_MARGIN_M + nav.d_c / 2.0 + roads::LANE_GAP_MARGIN_M + nav.d_c;
    let steps = (nav.r_s / PROFILE_STEP_M).ceil() as usize;
    (0..=steps)
        .map(|k| s + direction * k as f64 * PROFILE_STEP_M)
        .take_while(|x| (0.0..=length).contains(x))
        .find(|&x| {
            let (right, left) = nav.road.profile().at(x);
            right.min(left) >= room
        })
}

/// The section a UAV at `pos` must cross next (or is in), with its entry (0: from its start, going
/// towards increasing arc length; 1: from its end), when it is within `approach` of it.
pub(crate) fn next_section(
    sections: &[Section],
    pos: &RoutePosition,
    approach: f64,
) -> Option<(usize, usize)> {
    let (lo, hi) = (pos.s.min(pos.goal_s), pos.s.max(pos.goal_s));
    if pos.direction() > 0.0 {
        let z = sections.partition_point(|z| z.end + EXIT_M < pos.s);
        let zone = sections.get(z)?;
        (zone.start <= hi && zone.start - pos.s <= approach).then_some((z, 0))
    } else {
        let z = sections.partition_point(|z| z.start - EXIT_M <= pos.s).checked_sub(1)?;
        let zone = sections[z];
        (zone.end >= lo && pos.s - zone.end <= approach).then_some((z, 1))
    }
}
