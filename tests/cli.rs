//! End-to-end tests of the `airroads` command line: exit codes, METRICS.json keys, error messages.

mod support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn airroads(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_airroads")).args(args).output().expect("the airroads binary runs")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("airroads-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn write_scenario(name: &str, json: &serde_json::Value) -> PathBuf {
    let path = scratch(name);
    std::fs::write(&path, serde_json::to_string_pretty(json).unwrap()).unwrap();
    path
}

fn lab3() -> serde_json::Value {
    let text = std::fs::read_to_string(repo().join("scenarios/lab3.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn shipped_lab_scenario_is_safe_and_writes_exactly_the_metrics_keys() {
    let out = scratch("lab3-metrics.json");
    let traj = scratch("lab3-trajectory.csv");
    let scenario = repo().join("scenarios/lab3.json");
    let run = airroads(&[
        "run",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--trajectory",
        traj.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert_eq!(run.status.code(), Some(0), "{stdout}{}", String::from_utf8_lossy(&run.stderr));
    assert!(stdout.contains("SAFE"));
    let metrics: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let mut keys: Vec<&str> = metrics.as_object().unwrap().keys().map(String::as_str).collect();
    keys.sort();
    assert_eq!(keys, support::METRICS_KEYS);
    let mut qp: Vec<&str> = metrics["qp"].as_object().unwrap().keys().map(String::as_str).collect();
    qp.sort();
    assert_eq!(qp, ["failures", "max_slack", "p50_us", "p99_us", "slack_used", "solves"]);
    assert_eq!(metrics["scenario"], "lab3");
    assert_eq!(metrics["safe"], true);
    assert_eq!(metrics["all_arrived"], true);
    assert!(metrics["min_collision_margin_m"].as_f64().unwrap() >= 0.3);
    assert!(metrics["min_road_margin_m"].as_f64().unwrap() >= 0.1);
    assert_eq!(metrics["arrival_time_s"].as_object().unwrap().len(), 3);
    let csv = std::fs::read_to_string(&traj).unwrap();
    assert!(csv.starts_with("t,id,x,y,vx,vy,"));
    assert_eq!(csv.lines().count(), 1 + 3 * metrics["ticks"].as_u64().unwrap() as usize);
}

/// The trajectory CSV of a run of a shipped scenario with extra flags (exit status checked to be 0).
fn shipped_run_trajectory(name: &str, extra: &[&str]) -> String {
    let traj = scratch(&format!("{name}-{}.csv", extra.join("-")));
    let scenario = repo().join(format!("scenarios/{name}.json"));
    let mut args = vec!["run", scenario.to_str().unwrap(), "--trajectory", traj.to_str().unwrap()];
    args.extend_from_slice(extra);
    let run = airroads(&args);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{name} {extra:?}: {stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("SAFE") && !stdout.contains("UNSAFE"), "{name} {extra:?}: {stdout}");
    std::fs::read_to_string(&traj).unwrap()
}

#[test]
fn rl_is_the_default_policy_and_pd_keeps_the_baseline_both_safe_on_the_shipped_scenarios() {
    for name in ["lab3", "snake10"] {
        let default = shipped_run_trajectory(name, &[]);
        assert_eq!(default, shipped_run_trajectory(name, &["--policy", "rl"]), "{name}: default is not rl");
        assert_ne!(default, shipped_run_trajectory(name, &["--policy", "pd"]), "{name}: pd flies like rl");
    }
}

#[test]
fn a_run_that_does_not_arrive_exits_1() {
    let mut s = lab3();
    s["params"]["t_max"] = serde_json::json!(1.0);
    let path = write_scenario("short.json", &s);
    let run = airroads(&["run", path.to_str().unwrap()]);
    assert_eq!(run.status.code(), Some(1));
}

#[test]
fn unknown_param_key_exits_2_naming_file_and_key() {
    let mut s = lab3();
    s["params"]["Dc"] = serde_json::json!(0.5);
    let path = write_scenario("unknown-key.json", &s);
    let run = airroads(&["run", path.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(err.contains("unknown-key.json") && err.contains("`Dc`"), "{err}");
}

#[test]
fn invalid_road_and_fleet_exit_2_naming_the_field() {
    let mut s = lab3();
    s["segments"][2][1][0] = serde_json::json!(3.9);
    let path = write_scenario("broken-join.json", &s);
    let err = String::from_utf8_lossy(&airroads(&["run", path.to_str().unwrap()]).stderr).to_string();
    assert!(err.contains("broken-join.json: segments[2]:") && err.contains("seamless_join"), "{err}");

    let cases = [
        ("start-outside.json", "start", serde_json::json!([0.4, 5.0]), "uavs[0].start", "outside the road"),
        ("start-wall.json", "start", serde_json::json!([0.4, -0.65]), "uavs[0].start", "from a wall"),
        ("goal-nan.json", "goal", serde_json::json!([1.0, null]), "goal-nan.json:", "invalid type"),
        ("close.json", "start", serde_json::json!([0.4, 0.1]), "uavs[1].start", "closer than D_c"),
    ];
    for (file, key, value, field, reason) in cases {
        let mut s = lab3();
        let index = if field == "uavs[1].start" { 1 } else { 0 };
        if field == "uavs[1].start" {
            s["uavs"][0]["start"] = serde_json::json!([0.4, -0.1]);
        }
        s["uavs"][index][key] = value;
        let path = write_scenario(file, &s);
        let run = airroads(&["run", path.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{file}: {err}");
        assert!(err.contains(file) && err.contains(field) && err.contains(reason), "{file}: {err}");
    }
}

#[test]
fn missing_file_and_bad_flags_exit_2() {
    assert_eq!(airroads(&["run", "/nonexistent/scenario.json"]).status.code(), Some(2));
    let scenario = repo().join("scenarios/lab3.json");
    assert_eq!(airroads(&["run", scenario.to_str().unwrap(), "--road-rule", "bogus"]).status.code(), Some(2));
    assert_eq!(airroads(&["run", scenario.to_str().unwrap(), "--policy", "nope"]).status.code(), Some(2));
}

#[test]
fn track_benchmark_rows_and_rl_regression_guard() {
    let run = airroads(&["track", "all", "--json"]);
    assert_eq!(run.status.code(), Some(0), "{}", String::from_utf8_lossy(&run.stderr));
    let rows: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 3 * 5);
    let keys = [
        "trajectory",
        "policy",
        "rmse_m",
        "rmse_x_m",
        "rmse_y_m",
        "infer_us_batch1",
        "infer_us_per_uav_batch1000",
    ];
    for row in rows {
        let mut got: Vec<&str> = row.as_object().unwrap().keys().map(String::as_str).collect();
        got.sort();
        let mut want = keys.to_vec();
        want.sort();
        assert_eq!(got, want);
    }
    // Regression guard of the shipped model (its manifest: 0.0090 / 0.0162 / 0.0322 m; BENCHMARKS.md).
    for (trajectory, limit) in [("ellipse", 0.012), ("figure8", 0.020), ("rectangle", 0.040)] {
        let rl = rows.iter().find(|r| r["trajectory"] == trajectory && r["policy"] == "rl").unwrap();
        let rmse = rl["rmse_m"].as_f64().unwrap();
        assert!(rmse <= limit, "{trajectory}: rl RMSE {rmse} m > {limit} m");
        // The fleet's PD (kp 1.5, kd 2) tracks far worse; the comparison must show it.
        let pd = rows.iter().find(|r| r["trajectory"] == trajectory && r["policy"] == "pd").unwrap();
        assert!(pd["rmse_m"].as_f64().unwrap() > rmse);
    }
}

#[test]
fn run_plot_draws_the_road_every_path_and_where_uavs_waited_into_an_svg() {
    // The narrow section: one side waits for the single-file section within the first 30 s.
    let text = std::fs::read_to_string(repo().join("scenarios/narrow16.json")).unwrap();
    let mut s: serde_json::Value = serde_json::from_str(&text).unwrap();
    s["params"]["t_max"] = serde_json::json!(30.0);
    let path = write_scenario("narrow-30s.json", &s);
    let svg_path = scratch("narrow.svg");
    let run =
        airroads(&["run", path.to_str().unwrap(), "--policy", "pd", "--plot", svg_path.to_str().unwrap()]);
    assert!(run.status.code().is_some_and(|c| c <= 1), "{}", String::from_utf8_lossy(&run.stderr));
    let svg = std::fs::read_to_string(&svg_path).expect("the plot is written");
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"), "an SVG document");
    assert!(svg.contains("narrow16: ") && svg.contains("arrived in"), "the title gives the arrivals");
    // Every UAV's path, labelled with its id at its start.
    for uav in s["uavs"].as_array().unwrap() {
        let id = uav["id"].as_str().unwrap();
        assert!(svg.contains(&format!("\n{id}\n</text>")), "{id} is labelled");
    }
    assert!(svg.matches("<polyline").count() >= 16, "a path per UAV");
    assert!(svg.contains("single_file "), "where the single-file rule held a UAV");
}

#[test]
fn run_plot_to_an_unwritable_place_fails_with_the_file_named() {
    let path = write_scenario("lab3-plot.json", &lab3());
    let run = airroads(&["run", path.to_str().unwrap(), "--plot", "/nonexistent/dir/p.svg"]);
    assert_eq!(run.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&run.stderr).contains("/nonexistent/dir/p.svg"));
}

#[test]
fn stress_reports_time_to_arrival_and_saves_unfinished_cases_with_save_failing() {
    let dir = scratch("stress-saved");
    let _ = std::fs::remove_dir_all(&dir);
    // Seeds 45–48 of `mixed`: 47 leaves 2 of its 30 UAVs short of their goals within 60 s when
    // measured (a congested two-way road; all home by 75 s). When a rule change lets it finish, the
    // assertion below says to pick other seeds.
    let run = airroads(&[
        "stress",
        "--family",
        "mixed",
        "--scenarios",
        "4",
        "--seed",
        "45",
        "--policy",
        "pd",
        "--save-failing",
        dir.to_str().unwrap(),
    ]);
    let out = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.code().is_some_and(|c| c <= 1), "{out}");
    let line = out.lines().find(|l| l.contains("time until all arrived")).expect("the arrival line");
    assert!(line.contains("p50") && line.contains("p99"), "{line}");
    // The cases listed as unfinished are exactly the ones saved as such.
    let listed: Vec<String> = out
        .lines()
        .skip_while(|l| !l.contains("not all arrived"))
        .skip(2)
        .take_while(|l| l.split_whitespace().count() == 5)
        .map(|l| format!("stress-{}-unfinished.json", l.split_whitespace().next().unwrap()))
        .collect();
    let mut saved: Vec<String> = std::fs::read_dir(&dir)
        .map(|d| d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    saved.retain(|f| f.ends_with("-unfinished.json"));
    saved.sort();
    let mut listed = listed;
    listed.sort();
    assert!(!listed.is_empty(), "no unfinished case among these seeds any more: pick others\n{out}");
    assert_eq!(saved, listed, "{out}");
    for f in &saved {
        let scenario = std::fs::read_to_string(dir.join(f)).unwrap();
        let rerun = airroads(&["run", dir.join(f).to_str().unwrap(), "--policy", "pd"]);
        assert_eq!(rerun.status.code(), Some(1), "{f} replays as unfinished: {scenario:.80}");
    }
}

/// `run --link firmware` needs the firmware binary: without one it says so and exits 2 before
/// anything runs.
#[test]
fn a_run_over_the_firmware_needs_its_binary() {
    let scenario = repo().join("scenarios/lab3.json");
    for extra in [&[][..], &["--cf2", "/nonexistent/cf2"][..]] {
        let run = airroads(&[&["run", scenario.to_str().unwrap(), "--link", "firmware"][..], extra].concat());
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains("--link firmware needs --cf2 PATH"), "{stderr}");
    }
}

#[test]
fn run_flies_the_depot_network_through_its_junctions_and_plots_every_cell() {
    let out = scratch("depot-metrics.json");
    let svg_path = scratch("depot.svg");
    let scenario = repo().join("scenarios/depot.json");
    let args = [
        "run",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--plot",
        svg_path.to_str().unwrap(),
    ];
    let run = airroads(&args);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert_eq!(run.status.code(), Some(0), "{stdout}{}", String::from_utf8_lossy(&run.stderr));
    let metrics: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!((metrics["safe"].as_bool(), metrics["all_arrived"].as_bool()), (Some(true), Some(true)));
    assert_eq!(metrics["arrival_time_s"].as_object().unwrap().len(), 16);
    assert!(metrics["min_road_margin_m"].as_f64().unwrap() >= 0.1);
    // Every cell drawn: the roads' segments and the junctions.
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&scenario).unwrap()).unwrap();
    let cells: usize =
        s["roads"].as_array().unwrap().iter().map(|r| r["segments"].as_array().unwrap().len()).sum::<usize>()
            + s["junctions"].as_array().unwrap().len();
    let svg = std::fs::read_to_string(&svg_path).expect("the plot is written");
    assert!(
        svg.matches("<polygon").count() >= cells,
        "{} polygons for {cells} cells",
        svg.matches("<polygon").count()
    );
}

#[test]
fn a_broken_network_exits_2_naming_the_road_segment_and_rule() {
    let text = std::fs::read_to_string(repo().join("scenarios/depot.json")).unwrap();
    let mut s: serde_json::Value = serde_json::from_str(&text).unwrap();
    // The trunk's first segment no longer meets the depot junction's side.
    s["roads"][0]["segments"][0][1][0] = serde_json::json!(2.3);
    let path = write_scenario("depot-broken.json", &s);
    let run = airroads(&["run", path.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(err.contains("depot-broken.json") && err.contains("roads[0].segments[0]"), "{err}");
    // The server flies networks but divides only one road into regions: `--region` says so.
    let data = scratch("depot-serve");
    let serve = airroads(&[
        "serve",
        "--addr",
        "127.0.0.1:0",
        "--data-dir",
        data.to_str().unwrap(),
        "--zenoh-insecure",
        "--scenario",
        repo().join("scenarios/depot.json").to_str().unwrap(),
        "--region",
        "west",
    ]);
    let err = String::from_utf8_lossy(&serve.stderr);
    assert_eq!(serve.status.code(), Some(2), "{err}");
    assert!(err.contains("--region") && err.contains("network"), "{err}");
}

#[test]
fn bench_scale_writes_every_measured_tick_with_its_stages_and_names_a_file_it_cannot_write() {
    let csv = scratch("tick-times.csv");
    let run = airroads(&[
        "bench",
        "scale",
        "--uavs",
        "300",
        "--ticks",
        "4",
        "--policy",
        "pd",
        "--tick-times",
        csv.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let stages = ["states", "navigation", "neighbours", "policies", "rows", "filter", "send", "metrics"];
    let header: Vec<String> = ["uavs", "tick", "tick_us"]
        .iter()
        .map(|s| s.to_string())
        .chain(stages.iter().map(|s| format!("{s}_us")))
        .collect();
    assert_eq!(lines.next().unwrap(), header.join(","));
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 4, "one row per measured tick");
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), 3 + stages.len());
        assert_eq!((row[0], row[1]), (300.0, (i + 1) as f64));
        assert!(row.iter().all(|x| x.is_finite() && *x >= 0.0), "{row:?}");
        // The tick's time covers its stages (each rounded to 0.1 µs).
        let stages_sum: f64 = row[3..].iter().sum();
        assert!(row[2] + 0.1 * stages.len() as f64 >= stages_sum, "{row:?}");
    }
    let missing = scratch("no-such-dir").join("t.csv");
    let bad = airroads(&[
        "bench",
        "scale",
        "--uavs",
        "300",
        "--ticks",
        "1",
        "--tick-times",
        missing.to_str().unwrap(),
    ]);
    assert_eq!(bad.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(stderr.contains("--tick-times") && stderr.contains("t.csv"), "{stderr}");
}
