//! A scenario file read and validated with errors that name the file, and the run summary.

use fleet::{RunMetrics, Scenario, ScenarioError, ValidScenario};
use std::path::Path;

/// Reads and validates a scenario file; the error names the file, the field (or line) and the reason.
pub fn load_scenario(path: &Path) -> Result<ValidScenario, String> {
    load_scenario_with(path, &links::LinkRules::default())
}

/// [`load_scenario`] with the links `rules` allow (e.g. the server's `--allow-link-host`).
pub fn load_scenario_with(path: &Path, rules: &links::LinkRules) -> Result<ValidScenario, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let located = |e: ScenarioError| match e {
        ScenarioError::Parse { line, column, message } => {
            format!("{}:{line}:{column}: {message}", path.display())
        }
        ScenarioError::Invalid { field, reason } => format!("{}: {field}: {reason}", path.display()),
    };
    Scenario::from_json(&text).and_then(|s| s.validate_with(rules)).map_err(located)
}

/// Prints the short human summary of a run.
pub fn print_summary(m: &RunMetrics, policy_fallbacks: u64, stalls: &[fleet::Stall]) {
    let arrived = m.arrival_time_s.values().filter(|t| t.is_some()).count();
    let fmt = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.3} m"));
    say!("scenario {}: {} ticks, {:.2} s simulated", m.scenario, m.ticks, m.sim_time_s);
    say!("  arrived          {arrived}/{}", m.arrival_time_s.len());
    say!("  stalls           {:.1} UAV-s in total, longest {:.1} s", m.stall_s, m.max_stall_s);
    say!("  longest wait     {:.1} s for a turn at a conflict zone", m.max_wait_s);
    for s in stalls.iter().filter(|s| s.duration_s > 2.0).take(5) {
        say!(
            "                   {} {:.1} s from t = {:.1} s at [{:.2}, {:.2}]",
            s.id,
            s.duration_s,
            s.start_s,
            s.at[0],
            s.at[1]
        );
    }
    say!(
        "  collision margin {} (min S_kd), separation {}",
        fmt(m.min_collision_margin_m),
        fmt(m.min_separation_m)
    );
    say!(
        "  road margin      {:.3} m (min S_kij), wall distance {:.3} m",
        m.min_road_margin_m,
        m.min_wall_distance_m
    );
    say!("  outside road     {} UAV-ticks", m.steps_outside_road);
    say!(
        "  qp               {} solves, {} with slack, max slack {:.3e}, {} failures, p50 {:.1} µs, p99 {:.1} µs",
        m.qp.solves,
        m.qp.slack_used,
        m.qp.max_slack,
        m.qp.failures,
        m.qp.p50_us,
        m.qp.p99_us
    );
    if policy_fallbacks > 0 {
        say!("  policy fallbacks {policy_fallbacks} UAV-ticks braked on a non-finite policy output");
    }
    say!("  {}", if m.safe { "SAFE" } else { "UNSAFE" });
}
