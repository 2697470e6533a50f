//! How the fleet loop applies a change and makes it durable: each command is applied to the fleet
//! with its undo record and the writes that store it; a gap's changes go to the state writer after
//! the tick's snapshot is published; the writer answers the clients once the batch is on disk, or
//! sends it back, and the loop takes it (and every later batch) back, newest first, and answers 503.

use super::command::{ChangeError, Command, NewRoad, Outcome, Reply, Request};
use super::durable::{Batch, FromWriter, ToWriter};
use super::fleet_loop::{Engine, PendingBatch, STORAGE_STALL};
use super::hook::{Arrival, Ownership};
use super::linking::LinkFactory;
use super::persist::{SavedState, SavedUav};
use super::store::Write;
use fleet::{Edit, EditError, Fleet, Undo, ValidScenario};
use std::time::Instant;
use uav::UavState;

/// A gap's applied changes, not yet sent to the writer.
#[derive(Default)]
pub struct Gap {
    undo: Vec<Undo>,
    writes: Vec<Write>,
    replies: Vec<(Reply, Outcome)>,
    /// A `Resume` the writer has not been sent yet (its queue was full).
    resume_owed: bool,
}

/// A change applied to the fleet: its outcome, what takes it back and what stores it.
pub struct AppliedChange {
    /// What the client is told.
    pub outcome: Outcome,
    /// What restores the fleet (None: nothing to restore, e.g. land and stop).
    pub undo: Option<Undo>,
    /// What the database must store.
    pub writes: Vec<Write>,
}

impl AppliedChange {
    fn new(outcome: Outcome, undo: Undo, writes: Vec<Write>) -> Self {
        Self { outcome, undo: Some(undo), writes }
    }

    fn urgent() -> Self {
        Self { outcome: Outcome::Done, undo: None, writes: Vec::new() }
    }
}

fn uav_record(fleet: &Fleet, id: &str) -> Vec<Write> {
    fleet.uav(id).map(|u| Write::Uav(SavedUav::of(u))).into_iter().collect()
}

impl Engine {
    /// Applies one queued request (unless its client withdrew it), keeping it for the writer.
    pub(crate) fn apply_request(&mut self, request: Request) {
        let Request { command, reply, audit, claim } = request;
        if !claim.take() {
            return;
        }
        if let Some(reason) = self.channels.storage.refusal() {
            let _ = reply.send(Err(ChangeError::NotDurable(reason)));
            return;
        }
        if let Err(e) = self.hook.admits(&command) {
            let _ = reply.send(Err(e));
            return;
        }
        let (status, detail) = (command.success_status(), command.describe());
        match self.apply(command) {
            Ok(applied) => {
                self.gap.undo.extend(applied.undo);
                self.gap.writes.extend(applied.writes);
                if let Some(mut record) = audit {
                    record.status = status;
                    record.outcome = "applied".into();
                    record.detail = detail;
                    self.gap.writes.push(Write::Audit(record));
                }
                self.gap.replies.push((reply, applied.outcome));
            }
            Err(e) => {
                let _ = reply.send(Err(e));
            }
        }
    }

    /// Applies one command to the fleet; on an error nothing changed.
    pub fn apply(&mut self, command: Command) -> Result<AppliedChange, ChangeError> {
        let dt = self.fleet.config.params.dt;
        Ok(match command {
            Command::SetRoad(new) => self.replace_road(*new)?,
            Command::FollowRoad(new) => self.replace_road(*new)?,
            Command::CheckRoad(road) => {
                self.fleet.check_road(&*road)?;
                AppliedChange::urgent()
            }
            Command::AddUav { id, position, policy, goal, link } => {
                let count = self.fleet.uavs().len();
                if count >= self.max_uavs {
                    return Err(ChangeError::FleetFull { wanted: count + 1, max: self.max_uavs });
                }
                let state = UavState::at_rest(position);
                let policy = policy.unwrap_or_else(|| self.default_policy.clone());
                // Checked before the link exists: a refused UAV never starts a radio session.
                self.fleet.check_new(&id, &policy, &state, goal)?;
                let link = self.links.make(&id, link.as_deref(), state, dt);
                let add = Edit::Add { id: id.clone(), policy, link, state, goal };
                let undo = self.fleet.apply(add)?.undo;
                self.hook.ownership(Ownership::Opened { id: &id, how: "added" });
                AppliedChange::new(Outcome::Done, undo, uav_record(&self.fleet, &id))
            }
            Command::Land(Some(id)) => {
                self.fleet.land(&id)?;
                AppliedChange::urgent()
            }
            Command::Land(None) => {
                self.fleet.land_all();
                AppliedChange::urgent()
            }
            Command::EmergencyStop => {
                self.fleet.emergency_stop_all();
                AppliedChange::urgent()
            }
            Command::RemoveUav(id) => {
                let undo = self.fleet.apply(Edit::Remove(id.clone()))?.undo;
                self.hook.ownership(Ownership::Closed { id: &id, how: "removed" });
                AppliedChange::new(Outcome::Done, undo, vec![Write::RemoveUav(id)])
            }
            Command::SetGoal(id, goal) => {
                let undo = self.fleet.apply(Edit::SetGoal(id.clone(), goal))?.undo;
                AppliedChange::new(Outcome::Done, undo, uav_record(&self.fleet, &id))
            }
            Command::SetPolicy(id, policy) => {
                let undo = self.fleet.apply(Edit::SetPolicy(id.clone(), policy))?.undo;
                AppliedChange::new(Outcome::Done, undo, uav_record(&self.fleet, &id))
            }
            Command::LoadScenario(scenario) => {
                if scenario.uavs.len() > self.max_uavs {
                    return Err(ChangeError::FleetFull { wanted: scenario.uavs.len(), max: self.max_uavs });
                }
                let policy = self.default_policy.clone();
                let undo = load_scenario(&mut self.fleet, &scenario, &policy, &self.links)?;
                self.hook.ownership(Ownership::ClosedAll);
                for u in self.fleet.uavs() {
                    self.hook.ownership(Ownership::Opened { id: &u.id, how: "added" });
                }
                self.road_changed();
                let writes = vec![Write::Replace(SavedState::of(&self.fleet))];
                AppliedChange::new(Outcome::ScenarioLoaded { tick: self.ticks }, undo, writes)
            }
            Command::Pause(paused) => {
                let undo = self.fleet.apply(Edit::Pause(paused))?.undo;
                AppliedChange::new(Outcome::Done, undo, vec![Write::Paused(paused)])
            }
            Command::Adopt(arrival) => {
                self.add_arrival(*arrival)?;
                // Neither undone nor saved: only a region server adopts, and a region server never
                // resumes saved state (its region's owner or mirror is the record: `handle::start`
                // resumes nothing when a hook is plugged in), so a failed write must not take it back.
                AppliedChange::urgent()
            }
        })
    }

    /// Replaces the road or network if every UAV in the air is safe on it; goals it no longer
    /// holds are cleared. A network validated for parameters that needed narrower passages than the
    /// fleet's now (a scenario changed them meanwhile) is refused.
    fn replace_road(&mut self, new: NewRoad) -> Result<AppliedChange, ChangeError> {
        let needed = fleet::min_passage_m(&self.fleet.config.params);
        if new.road.network().is_some() && new.checked_passage_m < needed {
            let reason = format!(
                "the network was checked for passages {:.3} m wide, the fleet's parameters now need {needed:.3} m: put it again",
                new.checked_passage_m
            );
            return Err(EditError::Unsafe { field: "roads".into(), reason }.into());
        }
        let layout = new.road.layout();
        let fleet::Applied { undo, cleared_goals } = self.fleet.apply(Edit::ReplaceRoad(new.road))?;
        self.road_changed();
        let mut writes = vec![Write::Road(layout)];
        for id in &cleared_goals {
            writes.extend(uav_record(&self.fleet, id));
        }
        Ok(AppliedChange::new(Outcome::RoadReplaced { cleared_goals }, undo, writes))
    }

    /// Adds a UAV another server gave this one, where it is (its last owner flew it safely there);
    /// its link only if this server may open it, its goal only if this road has room for it, its
    /// policy only if loaded here (else the default).
    fn add_arrival(&mut self, arrival: Arrival) -> Result<(), ChangeError> {
        let Arrival { id, state, goal, policy, link, airborne } = arrival;
        if let Some(Err(reason)) = link.as_deref().map(|l| links::check_link_with(l, &self.link_rules)) {
            return Err(EditError::Unsafe { field: "link".into(), reason }.into());
        }
        if self.fleet.uav(&id).is_some() {
            return Err(EditError::DuplicateId(id).into());
        }
        let policy =
            if self.fleet.policy_names().any(|n| n == policy) { policy } else { self.default_policy.clone() };
        let goal = goal.filter(|g| self.fleet.check_goal(*g, "goal").is_ok());
        let link = self.links.make(&id, link.as_deref(), state, self.fleet.config.params.dt);
        let added = self.fleet.add(id, policy, link, state, goal);
        if airborne {
            // A Crazyflie's new link connects first: meanwhile it is avoided as lost.
            added.mark_airborne();
        }
        Ok(())
    }

    /// Hands the gap's changes to the writer (after the tick published them). If the writer cannot
    /// take them, they are taken back and their clients told after the next snapshot.
    pub(crate) fn send_gap(&mut self) {
        if self.gap.resume_owed {
            self.gap.resume_owed = self.channels.writer.try_send(ToWriter::Resume).is_err();
        }
        if self.gap.replies.is_empty() {
            return;
        }
        let undo = std::mem::take(&mut self.gap.undo);
        self.next_seq += 1;
        let seq = self.next_seq;
        let batch = Batch {
            seq,
            writes: std::mem::take(&mut self.gap.writes),
            replies: std::mem::take(&mut self.gap.replies),
        };
        match self.channels.writer.try_send(ToWriter::Batch(batch)) {
            Ok(()) => self.pending.push_back(PendingBatch { seq, undo, sent: Instant::now() }),
            Err(e) => {
                let reason = "the state writer is not keeping up".to_string();
                self.channels.storage.degrade(reason.clone());
                self.take_back(undo);
                if let ToWriter::Batch(batch) = e.into_inner() {
                    self.refuse(batch.replies, &reason);
                }
            }
        }
    }

    /// Reads the writer's answers: confirmed batches are final; a failed one is taken back with
    /// every later batch. Also marks the storage degraded when it stops answering.
    pub(crate) fn read_writer(&mut self) {
        while let Ok(answer) = self.channels.written.try_recv() {
            match answer {
                FromWriter::Committed(seq) => {
                    while self.pending.front().is_some_and(|p| p.seq <= seq) {
                        // Dropping the undo records closes the links of removed UAVs.
                        self.pending.pop_front();
                    }
                }
                FromWriter::Failed { seq, replies, reason } => {
                    if self.pending.iter().any(|p| p.seq == seq) {
                        while self.pending.back().is_some_and(|p| p.seq >= seq) {
                            if let Some(p) = self.pending.pop_back() {
                                self.take_back(p.undo);
                            }
                        }
                        self.gap.resume_owed = self.channels.writer.try_send(ToWriter::Resume).is_err();
                    }
                    self.refuse(replies, &reason);
                }
            }
        }
        if self.pending.front().is_some_and(|p| p.sent.elapsed() > STORAGE_STALL) {
            self.channels
                .storage
                .degrade(format!("the disk has not confirmed a write for {} s", STORAGE_STALL.as_secs()));
        }
    }

    fn refuse(&mut self, replies: Vec<(Reply, Outcome)>, reason: &str) {
        for (reply, _) in replies {
            self.after_publish.push((reply, Err(ChangeError::NotDurable(reason.to_string()))));
        }
    }

    /// Undoes a batch's changes, newest first.
    fn take_back(&mut self, undo: Vec<Undo>) {
        for record in undo.into_iter().rev() {
            let road = matches!(record, Undo::Road { .. } | Undo::Fleet { .. });
            self.fleet.undo(record);
            if road {
                self.road_changed();
            }
        }
    }
}

/// Replaces road, parameters and UAVs of `fleet` by those of `scenario`, every UAV flying `policy`;
/// returns what restores the old fleet.
pub fn load_scenario(
    fleet: &mut Fleet,
    scenario: &ValidScenario,
    policy: &str,
    links: &LinkFactory,
) -> Result<Undo, EditError> {
    // Checked before anything changes; the scenario's starts and goals were validated with it.
    if !fleet.policy_names().any(|n| n == policy) {
        return Err(EditError::UnknownPolicy(format!("policy `{policy}` is not loaded")));
    }
    let undo = fleet.apply(Edit::Reset(scenario.params, scenario.road.clone()))?.undo;
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        let link = links.make(&u.id, u.link.as_deref(), state, scenario.params.dt);
        fleet.add(u.id.clone(), policy.to_string(), link, state, Some(u.goal));
    }
    Ok(undo)
}

#[cfg(test)]
#[path = "changes_tests.rs"]
mod tests;
