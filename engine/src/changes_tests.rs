//! Tests of the loop's change path with a writer played by the test: land first, the cap per gap,
//! withdrawn and refused changes, and a batch the disk refused taken back with every later one.

use super::*;
use crate::command::{Claim, Command, Outcome, Request};
use crate::durable::StorageStatus;
use crate::fleet_loop::{LoopChannels, LoopClock, MAX_COMMANDS_PER_TICK, RoadView};
use crate::snapshot::Snapshot;
use crate::stats::LoopMetrics;
use links::LinkPhase;
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot, watch};
use uav::Vec2;

struct Rig {
    engine: Engine,
    commands: mpsc::Sender<Request>,
    urgent: mpsc::UnboundedSender<Request>,
    writer: mpsc::Receiver<ToWriter>,
    written: std::sync::mpsc::Sender<FromWriter>,
    storage: Arc<StorageStatus>,
    _runtime: tokio::runtime::Runtime,
}

fn rig(max_uavs: usize) -> Rig {
    let runtime = tokio::runtime::Builder::new_current_thread().build().unwrap();
    let scenario = crate::demo_scenario().unwrap();
    let policies = policies::PolicyRegistry::with_pd(scenario.params.delta);
    let config = fleet::FleetConfig { params: scenario.params, ..Default::default() };
    let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
    let factory = LinkFactory::new(runtime.handle().clone(), crazyflie::RelayConfig::default());
    load_scenario(&mut fleet, &scenario, "pd", &factory).unwrap();
    let (commands, requests) = mpsc::channel(1024);
    let (urgent, urgent_requests) = mpsc::unbounded_channel();
    let (writer_tx, writer) = mpsc::channel(1024);
    let (written, written_rx) = std::sync::mpsc::channel();
    let storage = Arc::new(StorageStatus::default());
    let channels = LoopChannels {
        requests,
        urgent: urgent_requests,
        snapshots: watch::channel(Arc::new(Snapshot::of(&fleet, 0, 0.0, 0))).0,
        metrics: watch::channel(Arc::new(LoopMetrics::default())).0,
        road: watch::channel(Arc::new(RoadView::of(fleet.airspace(), &fleet.config.params, 0, 0))).0,
        writer: writer_tx,
        written: written_rx,
        storage: storage.clone(),
        clock: Arc::new(LoopClock::default()),
    };
    let engine = Engine::new(fleet, "pd".into(), factory, channels, max_uavs);
    Rig { engine, commands, urgent, writer, written, storage, _runtime: runtime }
}

type Answer = oneshot::Receiver<Result<Outcome, ChangeError>>;

fn queue(rig: &Rig, command: Command) -> (Answer, Arc<Claim>) {
    let (reply, answer) = oneshot::channel();
    let request = Request::new(command, reply);
    let claim = request.claim.clone();
    rig.commands.try_send(request).unwrap();
    (answer, claim)
}

fn ids(rig: &Rig) -> Vec<String> {
    rig.engine.fleet.uavs().iter().map(|u| u.id.clone()).collect()
}

fn add(id: &str, x: f64, y: f64) -> Command {
    Command::AddUav { id: id.into(), position: Vec2::new(x, y), policy: None, goal: None, link: None }
}

/// The next batch the loop sent to the writer.
fn batch(rig: &mut Rig) -> Batch {
    loop {
        match rig.writer.try_recv().expect("a batch for the writer") {
            ToWriter::Batch(b) => return b,
            _ => continue,
        }
    }
}

#[test]
fn land_goes_out_at_once_and_changes_are_capped_per_gap() {
    let mut rig = rig(1000);
    let first = rig.engine.fleet.uavs()[0].id.clone();
    let goal = rig.engine.fleet.uavs()[1].state.p;
    let answers: Vec<Answer> =
        (0..100).map(|_| queue(&rig, Command::SetGoal(first.clone(), Some(goal))).0).collect();
    let (reply, mut landed) = oneshot::channel();
    rig.urgent.send(Request::new(Command::Land(Some(first.clone())), reply)).unwrap();
    rig.engine.apply_urgent();
    assert_eq!(landed.try_recv().unwrap(), Ok(Outcome::Done), "the land request was applied");
    assert_eq!(rig.engine.fleet.uavs()[0].link.phase(), LinkPhase::Landing);
    assert!(rig.engine.apply_commands());
    rig.engine.send_gap();
    let b = batch(&mut rig);
    assert_eq!(b.replies.len(), MAX_COMMANDS_PER_TICK, "the rest wait for the next gap");
    drop(answers);
}

#[test]
fn a_batch_the_disk_refused_is_taken_back_with_every_later_one() {
    let mut rig = rig(1000);
    let before = ids(&rig);
    let (mut added, _) = queue(&rig, add("x", 13.0, 16.0));
    rig.engine.apply_commands();
    rig.engine.send_gap();
    let first = batch(&mut rig);
    assert!(ids(&rig).contains(&"x".to_string()));
    // A later change that builds on the first, sent before the writer answered.
    let (mut goal, _) = queue(&rig, Command::SetGoal("x".into(), Some(Vec2::new(10.0, 17.0))));
    rig.engine.apply_commands();
    rig.engine.send_gap();
    let second = batch(&mut rig);
    // The writer refuses the first: both are taken back, the writer is told to resume.
    let reason = "database or disk is full".to_string();
    rig.written
        .send(FromWriter::Failed { seq: first.seq, replies: first.replies, reason: reason.clone() })
        .unwrap();
    rig.written.send(FromWriter::Failed { seq: second.seq, replies: second.replies, reason }).unwrap();
    rig.engine.read_writer();
    assert_eq!(ids(&rig), before, "nothing of the refused changes flies");
    assert!(matches!(rig.writer.try_recv(), Ok(ToWriter::Resume)));
    // Answered once the next snapshot shows the fleet without them.
    assert!(added.try_recv().is_err(), "not before the snapshot");
    rig.engine.answer_held();
    assert!(matches!(added.try_recv().unwrap(), Err(ChangeError::NotDurable(r)) if r.contains("full")));
    assert!(matches!(goal.try_recv().unwrap(), Err(ChangeError::NotDurable(_))));
    assert!(rig.engine.pending.is_empty());
}

#[test]
fn a_committed_batch_releases_its_undo_records() {
    let mut rig = rig(1000);
    let removed = rig.engine.fleet.uavs()[0].id.clone();
    let (_answer, _) = queue(&rig, Command::RemoveUav(removed.clone()));
    rig.engine.apply_commands();
    rig.engine.send_gap();
    let b = batch(&mut rig);
    assert_eq!(rig.engine.pending.len(), 1);
    assert_eq!(rig.engine.pending[0].undo.iter().map(fleet::Undo::kept_uavs).sum::<usize>(), 1);
    rig.written.send(FromWriter::Committed(b.seq)).unwrap();
    rig.engine.read_writer();
    assert!(rig.engine.pending.is_empty());
    assert!(!ids(&rig).contains(&removed));
}

#[test]
fn withdrawn_degraded_and_oversized_changes_change_nothing() {
    let mut rig = rig(1000);
    let before = ids(&rig);
    let (mut withdrawn, claim) = queue(&rig, add("w", 13.0, 16.0));
    assert!(claim.withdraw());
    rig.engine.apply_commands();
    assert!(withdrawn.try_recv().is_err(), "a withdrawn change gets no answer from the loop");
    rig.storage.degrade("disk full".into());
    let (mut refused, _) = queue(&rig, add("d", 13.0, 16.0));
    rig.engine.apply_commands();
    assert!(matches!(refused.try_recv().unwrap(), Err(ChangeError::NotDurable(r)) if r == "disk full"));
    assert_eq!(ids(&rig), before);

    let mut full = self::rig(before.len());
    let (mut answer, _) = queue(&full, add("f", 13.0, 16.0));
    full.engine.apply_commands();
    let wanted = before.len() + 1;
    assert_eq!(answer.try_recv().unwrap(), Err(ChangeError::FleetFull { wanted, max: before.len() }));
    full.engine.send_gap();
    assert!(full.writer.try_recv().is_err(), "nothing to write");
}

/// A hook that refuses every change, as a region's standby does.
struct Refusing;

impl crate::hook::LoopHook for Refusing {
    fn admits(&self, _: &Command) -> Result<(), ChangeError> {
        Err(ChangeError::Standby("west".into()))
    }
}

#[test]
fn a_change_the_hook_refuses_is_answered_with_its_reason_and_changes_nothing() {
    let mut rig = rig(1000);
    let before = ids(&rig);
    rig.engine.set_hook(Box::new(Refusing));
    let (mut added, _) = queue(&rig, add("x", 13.0, 16.0));
    rig.engine.apply_commands();
    assert_eq!(added.try_recv().unwrap(), Err(ChangeError::Standby("west".into())));
    assert_eq!(ids(&rig), before);
    rig.engine.send_gap();
    assert!(rig.writer.try_recv().is_err(), "nothing to write");
}

#[test]
fn a_uav_from_another_server_gets_only_a_link_this_server_may_open() {
    use crate::hook::{Arrival, LoopEdits};
    let mut rig = rig(1000);
    let arrival = |link: &str| Arrival {
        id: "far".into(),
        state: uav::UavState::at_rest(Vec2::new(13.0, 16.0)),
        goal: None,
        policy: "pd".into(),
        link: Some(link.into()),
        airborne: true,
    };
    // A simulator on another host: refused by default, as over REST, and allowed by the rules.
    assert!(!LoopEdits::adopt(&mut rig.engine, arrival("udp://10.0.0.5:19850")));
    assert!(!ids(&rig).contains(&"far".to_string()));
    rig.engine.set_link_rules(Arc::new(links::LinkRules { udp_hosts: vec!["10.0.0.5".parse().unwrap()] }));
    assert!(LoopEdits::adopt(&mut rig.engine, arrival("udp://10.0.0.5:19850")));
    assert!(ids(&rig).contains(&"far".to_string()));
    // Adopted, it is neither undone nor written (a region server never resumes saved state).
    rig.engine.send_gap();
    assert!(rig.writer.try_recv().is_err(), "an adoption is not saved");
}

#[test]
fn a_network_is_flown_stored_and_published_unless_checked_for_narrower_passages() {
    use crate::command::NewRoad;
    use roads::network::{Network, NetworkLayout};
    let mut rig = rig(1000);
    let chain = rig.engine.fleet.road().expect("the demo flies a road").layout().clone();
    let needed = fleet::min_passage_m(&rig.engine.fleet.config.params);
    // The demo road's own geometry as a network of one road: every UAV is safe on it.
    let network = Network::new(NetworkLayout::from(&chain), needed).unwrap();
    let cells = network.cells().len();
    let version = rig.engine.road_version;
    // Checked for narrower passages than the fleet's parameters need now: refused, nothing changed.
    let stale = NewRoad { road: network.clone().into(), checked_passage_m: needed / 2.0 };
    let refused = rig.engine.apply(Command::SetRoad(Box::new(stale))).err().expect("refused");
    assert!(
        matches!(&refused, ChangeError::Edit(fleet::EditError::Unsafe { field, .. }) if field == "roads"),
        "{refused}"
    );
    assert!(rig.engine.fleet.road().is_some());
    assert_eq!(rig.engine.road_version, version);
    let new = NewRoad { road: network.into(), checked_passage_m: needed };
    let applied = rig.engine.apply(Command::SetRoad(Box::new(new))).unwrap();
    assert!(rig.engine.fleet.airspace().network().is_some());
    assert!(
        matches!(&applied.writes[0], Write::Road(roads::AirspaceLayout::Network(n)) if n.roads[0].segments == chain.segments)
    );
    let view = rig.engine.channels.road.borrow().clone();
    assert_eq!((view.version, view.cells.len()), (version + 1, cells));
    assert!(view.centerline.is_empty() && !view.walls.is_empty());
    // Its undo record puts the chain road back.
    rig.engine.fleet.undo(applied.undo.unwrap());
    assert_eq!(rig.engine.fleet.road().map(|r| r.layout().clone()), Some(chain));
}
