//! Parts of logs: `--window START..END` and the enable (torque-on) column end a log's usable
//! part, the same on every command (servo_core::record::part::cut after the log is read).

use serde_json::Value;
use servo_core::sim::{PlantSim, SensorConfig, Sensors};
use servo_core::{Plant, PlantParams};
use std::fmt::Write as _;
use std::path::Path;

const DT_S: f64 = 1e-3;

/// An open-loop voltage sweep of `plant` for `seconds`, the drive switched off at `off_s`: from
/// then on the controller's command is still logged as u, but the plant gets 0 V and coasts.
/// Writes `time_s,u_V,theta_l_rad,drv_on` to `full` and, cut by hand, the rows before the drive
/// went off (servo's own columns) to `cut`.
fn drive_off_log(plant: &Plant, seconds: f64, off_s: f64, seed: u64, full: &Path, cut: &Path) {
    let mut sim = PlantSim::new(plant, DT_S).unwrap();
    let mut sensors = Sensors::new(SensorConfig {
        seed,
        ..SensorConfig::default()
    });
    let mut a = String::from("time_s,u_V,theta_l_rad,drv_on\n");
    let mut b = String::from("time_s,u_V,theta_l_rad\n");
    let n = (seconds / DT_S).round() as usize;
    let rate = 0.21 + 0.02 * (seed % 5) as f64;
    for k in 0..n {
        let t = k as f64 * DT_S;
        let u = 7.0
            * (std::f64::consts::TAU * rate * t).sin().signum()
            * (0.4 + 0.6 * ((t * 0.7).sin()).abs());
        let on = t < off_s - 0.5 * DT_S;
        let m = sensors.measure(sim.state());
        let row = format!("{t:.6},{u:.6},{:.10}", m.theta_l_rad);
        writeln!(a, "{row},{}", u8::from(on)).unwrap();
        if on {
            writeln!(b, "{row}").unwrap();
        }
        sim.step(if on { u } else { 0.0 });
    }
    std::fs::write(full, a).unwrap();
    std::fs::write(cut, b).unwrap();
}

fn identify(args: &[&str]) -> Value {
    let mut all = vec!["identify"];
    all.extend_from_slice(args);
    all.push("--json");
    let (ok, out, err) = servo_e2e::servo(&all);
    assert!(ok, "servo {all:?} failed: {err}");
    serde_json::from_str(&out).unwrap()
}

fn value(v: &Value, key: &str) -> f64 {
    v[key]["value"]
        .as_f64()
        .unwrap_or_else(|| panic!("no {key} in {v:#}"))
}

#[test]
fn a_drive_switched_off_ends_the_log_for_identify() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let cols = "time=time_s,u=u_V,theta_l=theta_l_rad";
    let with_enable = format!("{cols},enable=drv_on");
    // Two made-up motors (other inertia and friction than the default), other seeds and off times.
    for (seed, j, b, tau, off_s) in [
        (3u64, 7.0e-7, 1.0e-6, 9.0e-3, 9.0),
        (11, 9.5e-7, 2.0e-6, 5.0e-3, 12.5),
    ] {
        let p = PlantParams {
            j_eq: Some(j),
            b_eq: Some(b),
            tau_sf: Some(tau),
            ..PlantParams::TABLE2
        };
        let plant = Plant::from_params(p).unwrap();
        let full = dir.path().join(format!("full{seed}.csv"));
        let cut = dir.path().join(format!("cut{seed}.csv"));
        drive_off_log(&plant, 20.0, off_s, seed, &full, &cut);
        let (f, c) = (full.to_str().unwrap(), cut.to_str().unwrap());
        let by_hand = identify(&[c]);
        let by_enable = identify(&[f, "--columns", &with_enable]);
        let last_on = format!("..{}", off_s - 0.5 * DT_S);
        let by_window = identify(&[f, "--columns", cols, "--window", &last_on]);
        let naive = identify(&[f, "--columns", cols]);
        for key in ["j_eq_kg_m2", "b_eq_n_m_s_rad", "tau_sf_n_m"] {
            let want = value(&by_hand, key);
            for (how, v) in [("enable column", &by_enable), ("--window", &by_window)] {
                let got = value(v, key);
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs(),
                    "seed {seed} {key}: {how} {got:e} vs the log cut by hand {want:e}"
                );
            }
        }
        // The naive identification on the whole log (the coasting part with the logged
        // command) is visibly different: the cut matters.
        let rel = |key: &str| (value(&naive, key) / value(&by_hand, key) - 1.0).abs();
        let worst = rel("j_eq_kg_m2").max(rel("b_eq_n_m_s_rad"));
        eprintln!(
            "seed {seed}: by hand J {:.4e} B {:.4e}; naive J {:.4e} B {:.4e} (worst {:.1} %)",
            value(&by_hand, "j_eq_kg_m2"),
            value(&by_hand, "b_eq_n_m_s_rad"),
            value(&naive, "j_eq_kg_m2"),
            value(&naive, "b_eq_n_m_s_rad"),
            100.0 * worst
        );
        assert!(
            worst > 0.05,
            "seed {seed}: the naive estimate is as good ({worst})"
        );
        // The part used, in --json and in the text.
        let part = &by_enable["log_parts"][0];
        assert!(
            (part["drive_off_at_s"].as_f64().unwrap() - off_s).abs() < 1e-9,
            "{part}"
        );
        let n_on = (off_s / DT_S).round() as u64;
        assert_eq!(part["samples"].as_u64(), Some(n_on), "{part}");
        assert_eq!(part["log_samples"].as_u64(), Some(20_000), "{part}");
        assert_eq!(
            by_window["log_parts"][0]["window"],
            Value::from(last_on.as_str())
        );
        let (ok, text, err) = servo_e2e::servo(&["identify", f, "--columns", &with_enable]);
        assert!(ok, "{err}");
        assert!(
            text.contains(&format!("{n_on} of 20000 samples"))
                && text.contains(&format!("the drive was off from {off_s} s")),
            "{text}"
        );
    }
}

#[test]
fn bad_windows_are_refused_with_the_flag_and_the_span() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let plant = Plant::lab();
    let full = dir.path().join("full.csv");
    let cut = dir.path().join("cut.csv");
    drive_off_log(&plant, 4.0, 3.0, 1, &full, &cut);
    let c = cut.to_str().unwrap();
    for (window, needle) in [
        ("30..40", "outside the log's span 0 .. 2.999 s"),
        ("..12", "outside the log's span 0 .. 2.999 s"),
        ("2..1", "reversed"),
        ("1.0001..1.0002", "leaves 0 sample(s)"),
        ("abc", "START..END"),
    ] {
        let (ok, _, err) = servo_e2e::servo(&["identify", c, "--window", window]);
        assert!(!ok, "--window {window} was accepted");
        assert!(
            err.contains("--window") && err.contains(needle),
            "--window {window}: {err}"
        );
    }
    // One window per log, or one for all: two for one log is a mismatch.
    let (ok, _, err) = servo_e2e::servo(&["identify", c, "--window", "0..1", "--window", "1..2"]);
    assert!(
        !ok && err.contains("--window given 2 times for 1 logs"),
        "{err}"
    );
    // The other commands that read logs take the same flag and refuse the same way.
    let model = dir.path().join("m.toml");
    let (ok, out, err) = servo_e2e::servo(&["params"]);
    assert!(ok, "{err}");
    std::fs::write(&model, out).unwrap();
    let m = model.to_str().unwrap();
    for cmd in [
        vec!["compare", c, "--model", m],
        vec!["diagnose", c, "--model", m],
        vec!["frf", c],
        vec!["export", c, "-o", "/nonexistent/x.mcap"],
    ] {
        let mut args = cmd.clone();
        args.extend(["--window", "30..40"]);
        let (ok, _, err) = servo_e2e::servo(&args);
        assert!(
            !ok && err.contains("--window 30..40") && err.contains("outside the log's span"),
            "{cmd:?}: {err}"
        );
    }
}

#[test]
fn export_writes_the_part_used() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.csv");
    let cut = dir.path().join("cut.csv");
    drive_off_log(&Plant::lab(), 3.0, 2.0, 5, &full, &cut);
    let out = dir.path().join("part.csv");
    let (ok, text, err) = servo_e2e::servo(&[
        "export",
        full.to_str().unwrap(),
        "--columns",
        "time=time_s,u=u_V,theta_l=theta_l_rad,enable=drv_on",
        "--window",
        "0.5..",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(text.contains("1500 of 3000 samples"), "{text}");
    let rows = std::fs::read_to_string(&out).unwrap();
    let times: Vec<f64> = rows
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(times.len(), 1500);
    assert!((times[0] - 0.5).abs() < 1e-9 && (times[1499] - 1.999).abs() < 1e-9);
}
