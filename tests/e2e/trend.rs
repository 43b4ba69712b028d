//! `servo trend` on a simulated fleet (issue #31): three actuators of a made-up gearmotor, a
//! short open-loop log a week for 20 weeks each; one with a gear play growing linearly, one with
//! its Coulomb friction rising, one steady. The command must name the two changing parameters
//! with the right actuators and slopes, say the steady one is steady, forecast the limit
//! crossings, skip a corrupt log, and fit only the new logs on a second run.

use servo_core::effects::Effect;
use servo_core::sim::excitation::{simulate_open_loop, RandomSteps, ZeroRamps};
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use std::path::Path;

/// Logs a week apart from this date.
const START: (i64, u32, u32) = (2026, 1, 5);
const WEEKS: usize = 20;
/// Seconds of each log (short: the test fits 65 logs).
const LOG_S: f64 = 4.0;

/// Gear play of arm-1 [rad] in week k: 0.010 rad, +0.001 rad a week.
fn gap_rad(k: usize) -> f64 {
    0.010 + 0.001 * k as f64
}
/// Coulomb friction of arm-2 [N m] in week k: 0.010 N m, +0.0004 N m a week.
fn tau_sf_n_m(k: usize) -> f64 {
    0.010 + 0.0004 * k as f64
}

/// A made-up gearmotor (not Table 2's): another torque constant, resistance, ratio, inertia.
fn motor(tau_sf: f64) -> PlantParams {
    PlantParams {
        k_t: 9.0e-3,
        k_e: 9.0e-3,
        r_a: 3.1,
        n: 16.0,
        j_eq: Some(8.0e-7),
        b_eq: Some(1.2e-6),
        tau_sf: Some(tau_sf),
        ..PlantParams::TABLE2
    }
}

fn date_name(week: usize) -> String {
    // Days from 1970-01-01 of START, plus a week per log, back to a civil date.
    let (y, m, d) = START;
    let days = servo_cli::trend::when::days_from_civil(y, m, d) + 7 * week as i64;
    let (y, m, d) = servo_cli::trend::when::civil_from_days(days);
    format!("{y:04}{m:02}{d:02}.csv")
}

/// The log of `actuator` in week `week`.
fn write_log(dir: &Path, actuator: &str, week: usize) {
    let (tau_sf, gap) = match actuator {
        "arm-1" => (0.011, Some(gap_rad(week))),
        "arm-2" => (tau_sf_n_m(week), None),
        _ => (0.011, None),
    };
    let mut plant = Plant::from_params(motor(tau_sf)).unwrap();
    if let Some(g) = gap {
        plant
            .effects
            .insert(Effect::parse(&format!("backlash:gap={g}")).unwrap());
    }
    let seed = 1000 * week as u64 + actuator.len() as u64 + actuator.as_bytes()[4] as u64;
    let u = RandomSteps {
        ramps: Some(ZeroRamps {
            probability: 0.3,
            min_v: 3.0,
            span_v: 3.0,
        }),
        ..RandomSteps::new(seed)
    }
    .voltages((LOG_S / 1e-3) as usize, 1e-3);
    let rec = simulate_open_loop(
        &plant,
        SensorConfig {
            seed,
            ..SensorConfig::default()
        },
        1e-3,
        &u,
        actuator,
    )
    .unwrap();
    let d = dir.join(actuator);
    std::fs::create_dir_all(&d).unwrap();
    servo_cli::io::write_csv(&d.join(date_name(week)), &rec).unwrap();
}

/// The model the fleet is fitted with: the made-up motor, a gear play to size, the Coulomb
/// limit in its [limits] table.
fn write_model(path: &Path) {
    let mut m = servo_cli::model_file::ModelFile {
        params: motor(0.011),
        ..Default::default()
    };
    m.effects
        .insert(Effect::parse("backlash:gap=0.01").unwrap());
    m.limits.insert("tau_sf".into(), 0.02);
    m.save(path).unwrap();
}

fn change<'a>(
    v: &'a serde_json::Value,
    actuator: &str,
    parameter: &str,
) -> Option<&'a serde_json::Value> {
    v["changes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["actuator"] == actuator && c["parameter"] == parameter)
}

/// Days from the first log (START) to an ISO date.
fn days_after_start(date: &str) -> f64 {
    let p: Vec<&str> = date.split('-').collect();
    let d = servo_cli::trend::when::days_from_civil(
        p[0].parse().unwrap(),
        p[1].parse().unwrap(),
        p[2].parse().unwrap(),
    );
    (d - servo_cli::trend::when::days_from_civil(START.0, START.1, START.2)) as f64
}

#[test]
fn a_fleet_s_wear_is_found_forecast_and_cached() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let fleet = tmp.path().join("fleet");
    for a in ["arm-1", "arm-2", "arm-3"] {
        for k in 0..WEEKS {
            write_log(&fleet, a, k);
        }
    }
    // A corrupt log among them.
    std::fs::write(
        fleet.join("arm-3").join("20260301.csv"),
        b"\x00\x01garbage,\nnot a log",
    )
    .unwrap();
    let model = tmp.path().join("fleet.toml");
    write_model(&model);
    let cache = tmp.path().join("cache");
    let report = tmp.path().join("trend.html");
    let args = |json: bool| -> Vec<String> {
        let mut v: Vec<String> = [
            "trend",
            fleet.to_str().unwrap(),
            "--model",
            model.to_str().unwrap(),
            "--time-from",
            "name:%Y%m%d",
            "--limit",
            "backlash.gap=0.04",
            "--cache",
            cache.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        if json {
            v.push("--json".into());
        }
        v
    };
    let started = std::time::Instant::now();
    let a: Vec<String> = args(true);
    let refs: Vec<&str> = a.iter().map(String::as_str).collect();
    let (ok, out, err) = servo_e2e::servo(&refs);
    assert!(ok, "servo trend failed: {err}");
    eprintln!(
        "first run {:.1} s; stderr: {err}",
        started.elapsed().as_secs_f64()
    );
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["schema"], "servo.trend/1");
    for c in v["changes"].as_array().unwrap() {
        eprintln!("change: {}", c["words"]);
    }
    for act in v["actuators"].as_array().unwrap() {
        for p in act["parameters"].as_array().unwrap() {
            eprintln!(
                "{} {} {} slope/day {} ci {}",
                act["actuator"], p["parameter"], p["verdict"], p["slope_per_day"], p["slope_ci"]
            );
        }
    }
    // The corrupt log is reported and skipped; the 60 good ones fitted.
    assert_eq!(v["cache"]["new"], 60, "{}", v["cache"]);
    assert_eq!(v["cache"]["failed"], 1, "{}", v["cache"]);
    assert_eq!(v["cache"]["hits"], 0, "{}", v["cache"]);
    let failed = v["failed"].as_array().unwrap();
    assert!(
        failed.len() == 1 && failed[0]["log"].as_str().unwrap().ends_with("20260301.csv"),
        "{failed:?}"
    );
    // The gear play of arm-1: +0.001 rad a week.
    let gap = change(&v, "arm-1", "backlash.gap")
        .unwrap_or_else(|| panic!("no gap change: {}", v["changes"]));
    let slope = gap["slope_per_day"].as_f64().unwrap() * 7.0;
    assert!(
        (slope / 0.001 - 1.0).abs() < 0.25,
        "gap slope {slope} rad/week, true 0.001"
    );
    // The limit 0.04 rad is reached in week 30 (true line), 11 weeks after the last log (week
    // 19): the forecast within 20 % of that lead time.
    let when = days_after_start(gap["forecast_limit_date"].as_str().unwrap());
    let lead = (when - 7.0 * 19.0) / 7.0;
    assert!(
        (lead / 11.0 - 1.0).abs() < 0.20,
        "gap limit forecast {lead} weeks after the last log, true 11"
    );
    // The Coulomb friction of arm-2: +0.0004 N m a week; its limit 0.02 N m (model file) in
    // week 25, 6 weeks after the last log.
    let tau = change(&v, "arm-2", "tau_sf")
        .unwrap_or_else(|| panic!("no tau_sf change: {}", v["changes"]));
    let slope = tau["slope_per_day"].as_f64().unwrap() * 7.0;
    assert!(
        (slope / 0.0004 - 1.0).abs() < 0.25,
        "tau_sf slope {slope} N m/week, true 0.0004"
    );
    let when = days_after_start(tau["forecast_limit_date"].as_str().unwrap());
    let lead = (when - 7.0 * 19.0) / 7.0;
    assert!(
        (lead / 6.0 - 1.0).abs() < 0.20,
        "tau_sf limit forecast {lead} weeks after the last log, true 6"
    );
    // Only those two change; arm-3 is steady in every parameter, and says so.
    let names: Vec<String> = v["changes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            format!(
                "{}:{}",
                c["actuator"].as_str().unwrap(),
                c["parameter"].as_str().unwrap()
            )
        })
        .collect();
    assert_eq!(names.len(), 2, "changes: {names:?}");
    let arm3 = v["actuators"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["actuator"] == "arm-3")
        .unwrap();
    assert_eq!(arm3["logs"].as_array().unwrap().len(), WEEKS);
    for p in arm3["parameters"].as_array().unwrap() {
        assert_eq!(p["verdict"], "steady", "arm-3 {}", p);
    }
    let html = std::fs::read_to_string(&report).unwrap();
    assert!(
        html.contains("<svg") && html.contains("arm-1"),
        "the report has its charts"
    );

    // Five new logs: the second run fits only those five (and the corrupt log fails again).
    for k in WEEKS..WEEKS + 5 {
        write_log(&fleet, "arm-3", k);
    }
    let a: Vec<String> = args(false);
    let refs: Vec<&str> = a.iter().map(String::as_str).collect();
    let (ok, text, err) = servo_e2e::servo(&refs);
    assert!(ok, "second run failed: {err}");
    eprintln!("{text}");
    assert!(
        text.contains("60 from the cache, 5 fitted, 1 failed"),
        "second run counts: {text}"
    );
    assert!(
        text.contains("skipped ") && text.contains("20260301.csv"),
        "{text}"
    );
    assert!(
        text.contains("CHANGE: the total play") && text.contains("arm-1 grew from"),
        "{text}"
    );
    assert!(
        text.contains("steady: ") && text.contains(" of arm-3"),
        "{text}"
    );
}

/// `path`'s CSV with two columns more: `unit_id` (the actuator, text) and `unix_time_s` (the
/// recording time, the same on every row).
fn add_columns(path: &Path, unit: &str, unix_s: i64) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if i == 0
            || !line
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit() || c == '-')
        {
            out.push_str(&format!("{line},unit_id,unix_time_s"));
        } else {
            out.push_str(&format!("{line},{unit},{unix_s}"));
        }
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

fn run_json(args: &[&str]) -> serde_json::Value {
    let (ok, out, err) = servo_e2e::servo(args);
    assert!(ok, "servo {args:?} failed: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

/// `--group-by FIELD` groups by a column's value (two units in one folder); the times come from
/// each log's own source: a CSV date column, an MCAP run's start, else the modification time,
/// each said in the log's `time_from`.
#[test]
fn trend_groups_by_a_field_and_takes_each_log_s_time_from_its_source() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let mixed = tmp.path().join("mixed");
    // 2 x 3 CSV logs, all in the folder `arm-3`, units A and B, dated a week apart.
    let t0 = 86_400 * servo_cli::trend::when::days_from_civil(2026, 1, 5);
    for k in 0..6 {
        write_log(&mixed, "arm-3", k);
        let p = mixed.join("arm-3").join(date_name(k));
        let unit = if k % 2 == 0 { "A" } else { "B" };
        add_columns(&p, unit, t0 + 7 * 86_400 * k as i64);
    }
    let model = tmp.path().join("fleet.toml");
    write_model(&model);
    let cache = tmp.path().join("cache");
    let (d, m, c) = (
        mixed.to_str().unwrap(),
        model.to_str().unwrap(),
        cache.to_str().unwrap(),
    );
    let v = run_json(&[
        "trend",
        d,
        "--model",
        m,
        "--cache",
        c,
        "--group-by",
        "unit_id",
        "--quiet",
        "--json",
    ]);
    let acts = v["actuators"].as_array().unwrap();
    let names: Vec<&str> = acts
        .iter()
        .map(|a| a["actuator"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["A", "B"], "{}", v["actuators"]);
    for a in acts {
        assert_eq!(a["logs"].as_array().unwrap().len(), 3, "{a}");
        for l in a["logs"].as_array().unwrap() {
            assert_eq!(l["time_from"], "column:unix_time_s", "{l}");
            // the date of the column, not the file's modification time (today)
            let t = l["time_unix_s"].as_f64().unwrap();
            assert!(
                (t0 as f64..(t0 + 6 * 7 * 86_400) as f64).contains(&t),
                "{l}"
            );
        }
    }
    // the same logs by folder (the default): one actuator, times still from the column
    let v = run_json(&["trend", d, "--model", m, "--cache", c, "--quiet", "--json"]);
    assert_eq!(v["actuators"].as_array().unwrap().len(), 1, "{v}");
    assert_eq!(v["cache"]["hits"], 6, "{}", v["cache"]);

    // An MCAP run dates itself; a CSV without a date column takes its modification time, and
    // the text says so.
    let other = tmp.path().join("other");
    std::fs::create_dir_all(&other).unwrap();
    let mcap = other.join("run.mcap");
    let (ok, _, err) = servo_e2e::servo(&[
        "run",
        "--voltage",
        "prbs:amp=4,bit=0.2",
        "--duration",
        "3",
        "--log",
        mcap.to_str().unwrap(),
        "--progress",
        "never",
    ]);
    assert!(ok, "{err}");
    write_log(&other, "arm-2", 0);
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    let lab = tmp.path().join("lab.toml");
    let (ok, out, err) = servo_e2e::servo(&["params"]);
    assert!(ok, "{err}");
    std::fs::write(&lab, out).unwrap();
    let v = run_json(&[
        "trend",
        other.to_str().unwrap(),
        "--model",
        lab.to_str().unwrap(),
        "--cache",
        c,
        "--group-by",
        "file",
        "--quiet",
        "--json",
    ]);
    let mut sources: Vec<(String, f64)> = v["actuators"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|a| a["logs"].as_array().unwrap().iter())
        .map(|l| {
            (
                l["time_from"].as_str().unwrap().to_string(),
                l["time_unix_s"].as_f64().unwrap(),
            )
        })
        .collect();
    sources.sort_by(|a, b| a.0.cmp(&b.0));
    assert_eq!(sources.len(), 2, "{v}");
    assert_eq!(sources[0].0, "mcap", "{sources:?}");
    assert_eq!(sources[1].0, "mtime", "{sources:?}");
    for (src, t) in &sources {
        assert!(
            (t - now).abs() < 600.0,
            "{src}: {t} is not about now ({now})"
        );
    }
}

/// A run killed halfway resumes from the cache: what was fitted before the kill is not fitted
/// again, and the rest is.
#[test]
fn an_interrupted_trend_resumes_from_the_cache() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let fleet = tmp.path().join("fleet");
    const N: usize = 12;
    for k in 0..N {
        write_log(&fleet, "arm-2", k);
    }
    let model = tmp.path().join("fleet.toml");
    write_model(&model);
    let cache = tmp.path().join("cache");
    let args = [
        "trend",
        fleet.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
        "--cache",
        cache.to_str().unwrap(),
        "--jobs",
        "1",
        "--quiet",
    ];
    let mut child = std::process::Command::new(servo_e2e::servo_bin())
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let entries = || {
        std::fs::read_dir(&cache)
            .map(|d| {
                d.filter_map(Result::ok)
                    .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
                    .count()
            })
            .unwrap_or(0)
    };
    let t = std::time::Instant::now();
    while entries() < 3 && t.elapsed().as_secs() < 300 {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
    let before = entries();
    assert!(
        (1..N).contains(&before),
        "{before} cache entries at the kill: not halfway"
    );
    let (ok, text, err) = servo_e2e::servo(&args);
    assert!(ok, "the resumed run failed: {err}");
    let want = format!("{before} from the cache, {} fitted, 0 failed", N - before);
    assert!(text.contains(&want), "expected `{want}`:\n{text}");
}
