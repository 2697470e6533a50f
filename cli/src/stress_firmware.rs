//! `airroads stress --link firmware --cf2 PATH`: random faulty flights of the real Crazyflie
//! firmware on cfsim's physics, judged on the physics' ground truth (issue: fly the real firmware).
//!
//! Each case flies 2–3 Crazyflies with random starts and goals on the lab road of
//! `scenarios/lab3.json` (with its allowances η_p, η_v), each through its own firmware process, and
//! draws its faults: packet loss of 0–30 % per Crazyflie, motion-capture noise, and with some chance
//! each a motion-capture gap of up to 200 ms, a wind gust, a firmware killed or frozen in flight, or
//! a link lost for 3 s (the firmware's commander watchdog locks it and it falls). A case violates
//! if the true distance between two airborne Crazyflies falls below D_c or one comes closer than
//! D_s to a wall; the faulted Crazyflie is a lost UAV to the others.

use flights::say;

mod faults;

use crate::cli::StressArgs;
use crate::stress_cmd::each_seed;
use anyhow::Context as _;
use cfsim::sitl::SitlFaults;
use faults::{Fault, inject};
use fleet::{RunMetrics, RunOptions, Scenario, ScenarioUav, run_scenario_on_truth};
use flights::firmware_fleet::FirmwareFleet;
use flights::{crazyflie_links, real_time_ticks};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::process::ExitCode;
use uav::Vec2;

/// The lab road, its parameters and allowances.
const LAB: &str = include_str!("../../scenarios/lab3.json");
/// Above this height a Crazyflie is in the air and has margins (m).
const AIRBORNE_M: f64 = 0.3;
/// Flight time limit of a case (s).
const CASE_T_MAX_S: f64 = 30.0;

/// One case: the scenario and its faults.
#[derive(Debug, Clone)]
struct Case {
    scenario: Scenario,
    link_loss: Vec<f64>,
    faults: Vec<Fault>,
}

/// Case `seed`: 2–3 Crazyflies on the lab road, random faults.
fn case(seed: u64) -> anyhow::Result<Case> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut scenario: Scenario = serde_json::from_str(LAB).context("scenarios/lab3.json")?;
    scenario.name = format!("firmware-stress-{seed}");
    scenario.params.t_max = CASE_T_MAX_S;
    let road = roads::Road::new(roads::RoadLayout::new(scenario.segments.clone())).context("the lab road")?;
    let line = road.centerline();
    let count = rng.random_range(2..=3usize);
    for _attempt in 0..1000 {
        let point = |rng: &mut StdRng| {
            let s = rng.random_range(0.05..0.95) * line.length();
            let (c, d) = (line.point_at(s), line.tangent_at(s));
            let p = c + Vec2::new(-d.y, d.x) * rng.random_range(-0.35..0.35);
            [p.x, p.y]
        };
        let uavs: Vec<ScenarioUav> = (0..count)
            .map(|k| ScenarioUav {
                id: format!("cf{}", k + 1),
                start: point(&mut rng),
                goal: point(&mut rng),
                link: None,
            })
            .collect();
        let distance = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
        let far_apart = |f: fn(&ScenarioUav) -> [f64; 2]| {
            uavs.iter().enumerate().all(|(i, a)| uavs[i + 1..].iter().all(|b| distance(f(a), f(b)) > 0.6))
        };
        let long = uavs.iter().all(|u| distance(u.goal, u.start) > 1.0);
        if !(far_apart(|u| u.start) && far_apart(|u| u.goal) && long) {
            continue;
        }
        scenario.uavs = uavs;
        if scenario.validate().is_ok() {
            let link_loss = (0..count).map(|_| rng.random_range(0.0..0.3)).collect();
            return Ok(Case { faults: faults::draw(&mut rng, count), scenario, link_loss });
        }
    }
    anyhow::bail!("no valid case for seed {seed}")
}

/// One finished case.
struct CaseResult {
    seed: u64,
    uavs: usize,
    faults: Vec<Fault>,
    metrics: Option<RunMetrics>,
    /// How the firmware kept time: the lowest motor command rate (per s) of a Crazyflie no fault
    /// downed, over the flight (500 on an idle machine), and the motor watchdog's cuts.
    timing: Option<(f64, u64)>,
    error: Option<String>,
}

/// Below this motor command rate (per s) a firmware process did not keep real time: the machine
/// starved it (a real Crazyflie's microcontroller never is).
const LATE_FIRMWARE_RATE: f64 = 400.0;

impl CaseResult {
    /// Ground truth kept D_c between airborne Crazyflies and D_s from the walls.
    fn safe(&self, d_c: f64, d_s: f64) -> bool {
        self.metrics
            .as_ref()
            .is_none_or(|m| m.min_separation_m.is_none_or(|s| s >= d_c) && m.min_wall_distance_m >= d_s)
    }

    /// Crazyflies no fault downed / those of them that arrived.
    fn arrivals(&self) -> (usize, usize) {
        let downed: Vec<usize> = self.faults.iter().filter_map(Fault::downs).collect();
        let Some(m) = &self.metrics else { return (self.uavs - downed.len(), 0) };
        let flying = (0..self.uavs).filter(|k| !downed.contains(k));
        let arrived = flying
            .clone()
            .filter(|k| m.arrival_time_s.get(&format!("cf{}", k + 1)).is_some_and(Option::is_some));
        (flying.count(), arrived.count())
    }
}

/// Flies case `seed` in real time.
fn fly(args: &StressArgs, cf2: &Path, runtime: &tokio::runtime::Handle, seed: u64) -> CaseResult {
    let mut result =
        CaseResult { seed, uavs: 0, faults: Vec::new(), metrics: None, timing: None, error: None };
    let mut scenario = None;
    let flown = case(seed).and_then(|case| {
        result.uavs = case.scenario.uavs.len();
        result.faults = case.faults.clone();
        scenario = Some(case.scenario.clone());
        fly_case(args, cf2, runtime, &case)
    });
    match flown {
        Ok((metrics, timing)) => (result.metrics, result.timing) = (Some(metrics), Some(timing)),
        Err(e) => result.error = Some(format!("{e:#}")),
    }
    if let Some(scenario) = scenario {
        save(args, &result, &scenario);
    }
    result
}

/// With `--save-failing DIR`, writes the scenario of a violating case (firmware-stress-SEED.json)
/// and of one in which a Crazyflie no fault downed did not arrive (…-unfinished.json), to fly
/// again with `airroads run --link firmware` (without the faults, which the line lists), beside
/// its trajectory with the true states; removes the trajectory of any other case.
fn save(args: &StressArgs, result: &CaseResult, scenario: &Scenario) {
    let Some(dir) = save_dir(args) else { return };
    let lab = scenario.params;
    let (flying, arrived) = result.arrivals();
    let trajectory = dir.join(format!("{}.csv", scenario.name));
    let name = if !result.safe(lab.d_c, lab.d_s) {
        format!("firmware-stress-{}.json", result.seed)
    } else if arrived < flying {
        format!("firmware-stress-{}-unfinished.json", result.seed)
    } else {
        let _ = std::fs::remove_file(trajectory);
        return;
    };
    let path = dir.join(name);
    let written = std::fs::create_dir_all(dir)
        .and_then(|()| std::fs::write(&path, serde_json::to_string_pretty(scenario).unwrap_or_default()));
    if let Err(e) = written {
        eprintln!("warning: {}: {e}", path.display());
    }
}

/// Where `--save-failing` (or `--save-unfinished`) keeps the cases worth flying again.
fn save_dir(args: &StressArgs) -> Option<&std::path::PathBuf> {
    args.save_failing.as_ref().or(args.save_unfinished.as_ref())
}

/// With `--save-failing DIR`, the case's trajectory (with the true states) goes to
/// DIR/NAME.csv; `save` keeps it only for a violating or unfinished case.
fn trajectory_file(args: &StressArgs, name: &str) -> anyhow::Result<Option<Box<dyn std::io::Write>>> {
    let Some(dir) = save_dir(args) else { return Ok(None) };
    std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
    let path = dir.join(format!("{name}.csv"));
    let file = std::fs::File::create(&path).with_context(|| path.display().to_string())?;
    Ok(Some(Box::new(std::io::BufWriter::new(file))))
}

fn fly_case(
    args: &StressArgs,
    cf2: &Path,
    runtime: &tokio::runtime::Handle,
    case: &Case,
) -> anyhow::Result<(RunMetrics, (f64, u64))> {
    let mut scenario = case.scenario.clone().validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut firmware = FirmwareFleet::start(&mut scenario, cf2)?;
    let dt = scenario.params.dt;
    let policies = args.flight.policies(scenario.params.delta).map_err(anyhow::Error::msg)?;
    let options = RunOptions {
        config: args.flight.fleet_config(),
        policy: args.flight.policy.clone(),
        trajectory: trajectory_file(args, case.scenario.name.as_str())?,
        paths: false,
    };
    let mut make_link = crazyflie_links(runtime, dt);
    let mut wait_tick = real_time_ticks(dt);
    let (mut flight_s, mut pending, mut undo) = (0.0, case.faults.clone(), Vec::new());
    let mut first_packets = None;
    let mut truth = || {
        let states = firmware.truth(AIRBORNE_M);
        // Flight time counts from the first tick with every Crazyflie in the air.
        if states.is_some() {
            if flight_s == 0.0 {
                first_packets = Some(firmware.motor_packets());
                // Packet loss from take-off on (connecting through it is not what is tested).
                for (i, loss) in case.link_loss.iter().enumerate() {
                    let faults = firmware.physics.faults(i).unwrap_or_default();
                    firmware.physics.set_faults(i, SitlFaults { link_loss: *loss, ..faults });
                }
            }
            inject(&mut firmware, &mut pending, &mut undo, flight_s);
            flight_s += dt;
        }
        states
    };
    let outcome =
        run_scenario_on_truth(&scenario, options, policies, &mut make_link, &mut wait_tick, &mut truth)
            .context("flying the firmware")?;
    let downed: Vec<usize> = case.faults.iter().filter_map(Fault::downs).collect();
    let slowest = first_packets.map_or(0.0, |first| {
        let rates = firmware.motor_rates_since(&first).into_iter().enumerate();
        rates.filter(|(i, _)| !downed.contains(i)).map(|(_, r)| r).fold(f64::INFINITY, f64::min)
    });
    Ok((outcome.metrics, (slowest, firmware.motor_cuts())))
}

/// Runs the subcommand with `--link firmware`.
pub fn main(args: &StressArgs, cf2: &Path) -> ExitCode {
    if let Err(msg) = args.flight.policies(2.0) {
        eprintln!("error: {msg}");
        return ExitCode::from(2);
    }
    let runtime = match tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    // Real time, one flight at a time by default: two at once on this 2-core machine starved the
    // ground station and violated (BENCHMARKS.md), which tests the machine, not the flight.
    let results = each_seed(args, args.jobs.unwrap_or(1), |seed| {
        let result = fly(args, cf2, runtime.handle(), seed);
        say!("{}", line(&result));
        result
    });
    report(args, &results)
}

/// A case's line: seed, faults, margins, arrivals.
fn line(r: &CaseResult) -> String {
    let faults: Vec<String> = r.faults.iter().map(|f| format!("{f:?}")).collect();
    match (&r.metrics, &r.error) {
        (Some(m), _) => {
            let (flying, arrived) = r.arrivals();
            let (rate, cuts) = r.timing.unwrap_or_default();
            format!(
                "  seed {:>4}: {} UAVs, separation {:.3} m, wall {:.3} m, arrived {arrived}/{flying}, \
                 firmware >= {rate:.0} motor commands/s, {cuts} watchdog cuts{}; {}",
                r.seed,
                r.uavs,
                m.min_separation_m.unwrap_or(f64::INFINITY),
                m.min_wall_distance_m,
                if rate < LATE_FIRMWARE_RATE { " (LATE)" } else { "" },
                faults.join(", ")
            )
        }
        (None, e) => format!("  seed {:>4}: not flown: {}", r.seed, e.as_deref().unwrap_or("?")),
    }
}

fn report(args: &StressArgs, results: &[CaseResult]) -> ExitCode {
    let lab = serde_json::from_str::<Scenario>(LAB).map(|s| s.params).unwrap_or_default();
    let (d_c, d_s) = (lab.d_c, lab.d_s);
    let flown: Vec<&CaseResult> = results.iter().filter(|r| r.metrics.is_some()).collect();
    let violations: Vec<&&CaseResult> = flown.iter().filter(|r| !r.safe(d_c, d_s)).collect();
    let min = |f: fn(&RunMetrics) -> f64| {
        flown.iter().filter_map(|r| r.metrics.as_ref()).map(f).fold(f64::INFINITY, f64::min)
    };
    let count = |f: fn(&Fault) -> bool| flown.iter().flat_map(|r| &r.faults).filter(|x| f(x)).count();
    say!(
        "stress --link firmware: {} of {} faulty flights flown (seeds {}..{}), policy {}, eta_p {} m, eta_v {} m/s",
        flown.len(),
        results.len(),
        args.seed,
        args.seed.wrapping_add(args.scenarios),
        args.flight.policy,
        lab.eta_p,
        lab.eta_v
    );
    say!(
        "  faults           mocap gaps {}, gusts {}, firmware killed {}, frozen {}, locked {}; packet loss 0-30 % everywhere",
        count(|f| matches!(f, Fault::PoseGap { .. })),
        count(|f| matches!(f, Fault::Gust { .. })),
        count(|f| matches!(f, Fault::Kill { .. })),
        count(|f| matches!(f, Fault::Freeze { .. })),
        count(|f| matches!(f, Fault::Lock { .. }))
    );
    say!(
        "  ground truth     min separation {:.3} m (D_c {d_c}), min wall distance {:.3} m (D_s {d_s})",
        min(|m| m.min_separation_m.unwrap_or(f64::INFINITY)),
        min(|m| m.min_wall_distance_m)
    );
    let downing = |r: &&&CaseResult| r.faults.iter().any(|f| f.downs().is_some());
    let (with, without): (Vec<&&CaseResult>, Vec<&&CaseResult>) = flown.iter().partition(downing);
    let sum = |cases: &[&&CaseResult]| {
        cases.iter().map(|r| r.arrivals()).fold((0, 0), |(a, b), (c, d)| (a + c, b + d))
    };
    let ((flying_with, arrived_with), (flying_without, arrived_without)) = (sum(&with), sum(&without));
    let (flying, arrived) = (flying_with + flying_without, arrived_with + arrived_without);
    say!(
        "  arrivals         {arrived}/{flying} of the Crazyflies no fault downed, in {CASE_T_MAX_S} s: \
         {arrived_without}/{flying_without} in the {} flights where none was downed, \
         {arrived_with}/{flying_with} in the {} where one was (its reach disk blocks the road)",
        without.len(),
        with.len()
    );
    let late = flown.iter().filter(|r| r.timing.is_some_and(|(rate, _)| rate < LATE_FIRMWARE_RATE)).count();
    say!(
        "  timing           {late} flights with a firmware under {LATE_FIRMWARE_RATE} motor commands/s (the machine starved it)"
    );
    let not_flown = results.len() - flown.len();
    say!("  violations       {} ({not_flown} not flown)", violations.len());
    for r in &violations {
        say!("{}", line(r));
    }
    if violations.is_empty() && not_flown == 0 { ExitCode::SUCCESS } else { ExitCode::from(1) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cases_are_valid_spread_out_and_the_same_for_a_seed() {
        for seed in 0..200 {
            let case = case(seed).unwrap();
            assert!(case.scenario.validate().is_ok(), "seed {seed}");
            assert!((2..=3).contains(&case.scenario.uavs.len()));
            assert_eq!(case.link_loss.len(), case.scenario.uavs.len());
            assert!(case.link_loss.iter().all(|l| (0.0..0.3).contains(l)));
            let uavs = &case.scenario.uavs;
            for (i, a) in uavs.iter().enumerate() {
                for b in &uavs[i + 1..] {
                    let d = (a.start[0] - b.start[0]).hypot(a.start[1] - b.start[1]);
                    assert!(d > 0.6, "seed {seed}: starts {d} m apart");
                }
            }
            // The allowances of the real Crazyflie are flown.
            assert_eq!((case.scenario.params.eta_p, case.scenario.params.eta_v), (0.07, 0.5));
            assert_eq!(format!("{:?}", case.faults), format!("{:?}", super::case(seed).unwrap().faults));
        }
    }
}
