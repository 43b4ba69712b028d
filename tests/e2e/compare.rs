//! End-to-end tests of `servo compare`: simulated logs with a hidden effect, a model equal to the
//! truth, `servo run` logs replayed with the controller they ran (Tustin, derivative on the
//! measurement, back-calculation, feedforward), and the real closed-loop steps of
//! padova2021-jacopisky.

use serde_json::Value;
use servo_cli::gains_file::{GainsFile, PidSection};
use servo_cli::model_file::ModelFile;
use servo_core::{Plant, PlantParams};
use servo_e2e::{realdata_dir, servo};
use std::path::{Path, PathBuf};

use crate::util::{DT_S as DT, PID};

fn plant(tau_sf: Option<f64>) -> Plant {
    Plant::from_params(PlantParams {
        j_eq: Some(7.4e-7),
        b_eq: Some(7.0e-7),
        tau_sf,
        ..PlantParams::TABLE2
    })
    .unwrap()
}

/// A closed-loop run of `truth` with the PID over steps of several sizes (see
/// [`crate::util::simulate_pid_steps`]), written as servo CSV (time_s,u_V,theta_l_rad,ref_rad).
fn simulate_steps(truth: &Plant, path: &Path) {
    let steps_deg = [0.0, 30.0, 0.0, 90.0, -45.0, 0.0, 180.0, 20.0, -10.0, 0.0];
    crate::util::simulate_pid_steps(truth, path, &steps_deg, 1500, false);
}

fn gains_file(path: &Path) {
    crate::util::write_pid_gains(path);
}

fn run_json(args: &[&str]) -> Value {
    let (ok, out, err) = servo(args);
    assert!(ok, "servo {args:?} failed: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("bad JSON ({e}): {out}"))
}

fn regime<'a>(v: &'a Value, name: &str) -> &'a Value {
    v["regimes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["regime"] == name)
        .unwrap()
}

#[test]
fn hidden_coulomb_friction_is_located_and_added() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("steps.csv");
    let model = dir.path().join("model.toml");
    let gains = dir.path().join("gains.toml");
    let saved = dir.path().join("extended.toml");
    let svg = dir.path().join("cmp.svg");
    let tau_sf = 0.01;
    simulate_steps(&plant(Some(tau_sf)), &log);
    ModelFile::from_plant(&plant(None)).save(&model).unwrap();
    gains_file(&gains);
    let cols = "time=time_s,u=u_V,theta_l=theta_l_rad,ref=ref_rad";
    let g = gains.to_str().unwrap();
    let v = compare_json(
        &log,
        &model,
        &[
            "--gains",
            g,
            "--columns",
            cols,
            "--add",
            "coulomb",
            "--save",
            saved.to_str().unwrap(),
            "--plot",
            svg.to_str().unwrap(),
        ],
    );
    assert_eq!(v["mode"], "closed-loop", "{v}");
    assert_eq!(v["signal"], "theta_l");
    // The given gains are the ones that ran: the controller check passes.
    assert!(
        v["controller"]["check_fit_pct"].as_f64().unwrap() > 99.0,
        "{}",
        v["controller"]
    );
    let ladder = v["ladder"].as_array().unwrap();
    assert_eq!(ladder.len(), 2);
    let (before, after) = (
        ladder[0]["fit_pct"].as_f64().unwrap(),
        ladder[1]["fit_pct"].as_f64().unwrap(),
    );
    println!("fit without Coulomb {before:.2} %, after --add coulomb {after:.2} %");
    assert!(after > before + 1.0, "fit {before} -> {after}");
    assert!(ladder[1]["rmse"].as_f64().unwrap() < 0.7 * ladder[0]["rmse"].as_f64().unwrap());
    let fitted = v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["effect"] == "coulomb")
        .unwrap();
    let est = fitted["params"]["tau_sf"].as_f64().unwrap();
    assert!((est - tau_sf).abs() < 0.25 * tau_sf, "tau_sf {est}");
    // The final figures describe the extended model; the saved model has the effect.
    assert!((v["fit_pct"].as_f64().unwrap() - after).abs() < 1e-9);
    let back = ModelFile::load(&saved).unwrap().plant().unwrap();
    assert!((back.tau_sf() - est).abs() < 1e-12);
    let svg_text = std::fs::read_to_string(&svg).unwrap();
    assert!(svg_text.matches("<svg").count() >= 5, "stacked panels");
    for key in [
        "rmse",
        "signals",
        "regimes",
        "worst_windows",
        "whiteness",
        "findings",
    ] {
        assert!(!v[key].is_null(), "missing {key}");
    }

    // Where the model without friction fails: compare the base model alone.
    let v0 = compare_json(&log, &model, &["--gains", g, "--columns", cols]);
    let rev = regime(&v0, "reversal");
    let still = regime(&v0, "standstill");
    println!("base model: reversal {} / standstill {}", rev, still);
    let err = rev["error_share_pct"].as_f64().unwrap() + still["error_share_pct"].as_f64().unwrap();
    let time = rev["time_share_pct"].as_f64().unwrap() + still["time_share_pct"].as_f64().unwrap();
    let conc = rev["concentration"].as_f64().unwrap();
    // Friction shows where the motor stops and turns: the reversal windows carry far more than
    // their share of time, and they are the most concentrated regime.
    assert!(conc > 2.0, "reversal concentration {conc}");
    let best = v0["regimes"].as_array().unwrap().iter().max_by(|a, b| {
        a["concentration"]
            .as_f64()
            .unwrap()
            .total_cmp(&b["concentration"].as_f64().unwrap())
    });
    println!("most concentrated regime: {}; reversal+standstill: {err:.1} % of error in {time:.1} % of time", best.unwrap()["regime"]);
    let findings = v0["findings"].as_array().unwrap();
    assert!(
        findings
            .iter()
            .any(|f| f.as_str().unwrap().contains("velocity reversal")),
        "{findings:?}"
    );
}

#[test]
fn model_equal_to_truth_fits_within_noise() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("steps.csv");
    let model = dir.path().join("model.toml");
    let gains = dir.path().join("gains.toml");
    let truth = plant(Some(0.01));
    simulate_steps(&truth, &log);
    ModelFile::from_plant(&truth).save(&model).unwrap();
    gains_file(&gains);
    let cols = "time=time_s,u=u_V,theta_l=theta_l_rad,ref=ref_rad";
    let v = compare_json(
        &log,
        &model,
        &["--gains", gains.to_str().unwrap(), "--columns", cols],
    );
    let fit = v["fit_pct"].as_f64().unwrap();
    let rmse = v["rmse"].as_f64().unwrap();
    let count = std::f64::consts::TAU / 4096.0;
    println!(
        "truth model: fit {fit:.3} %, RMSE {rmse:.3e} rad = {:.2} counts, whiteness {}",
        rmse / count,
        v["whiteness"]["ljung_box_q"]
    );
    assert!(fit > 99.0, "fit {fit}");
    // What is left is the encoder quantisation and the stick-slip it triggers: the PID with
    // integral action hunts by a count or two, and a one-count difference at the moment the motor
    // sticks changes where it stops. A few counts, against ~50 counts without the friction.
    assert!(rmse < 3.0 * count, "rmse {rmse} vs one count {count}");
}

#[test]
fn real_closed_loop_steps_show_friction() {
    let _machine = servo_e2e::shared();
    let Some(dir) = realdata_dir() else { return };
    let log = dir.join("padova2021-jacopisky/csv/pid_bode_steps.csv");
    let tmp = tempfile::tempdir().unwrap();
    let nominal = tmp.path().join("nominal.toml");
    let friction = tmp.path().join("friction.toml");
    let gains = tmp.path().join("gains.toml");
    ModelFile::default().save(&nominal).unwrap();
    let mf = ModelFile::from_plant(&plant(Some(9.8e-3)));
    mf.save(&friction).unwrap();
    GainsFile {
        pid: PidSection {
            kp: PID.kp,
            ki: PID.ki,
            kd: PID.kd,
            tl_s: 0.0,
            ts_s: DT,
            kw: None,
            u_limit_v: None,
            derivative_on: None,
        },
        design: None,
    }
    .save(&gains)
    .unwrap();
    let cols = "time=t_s,theta_l=thl_meas_deg:deg,ref=thl_ref_deg:deg,u=u_V";
    let base = [log.to_str().unwrap(), "--columns", cols, "--json"];
    let with = |model: &Path, extra: &[&str]| {
        let mut a = vec!["compare"];
        a.extend_from_slice(&base);
        a.extend_from_slice(&["--model", model.to_str().unwrap()]);
        a.extend_from_slice(extra);
        run_json(&a)
    };
    // The published gains do not reproduce the logged u: compare says so.
    let stated = with(&nominal, &["--gains", gains.to_str().unwrap()]);
    let check = stated["controller"]["check_fit_pct"].as_f64().unwrap();
    println!(
        "published gains reproduce the logged u with fit {check:.1} %; LS gains {}",
        stated["controller"]["ls_gains"]
    );
    assert!(check < 90.0);
    // With the controller that reproduces the logged u, the nominal linear model fails at the
    // reversals and the identified friction raises the fit.
    let nom = with(&nominal, &["--gains-from-log"]);
    let fr = with(&friction, &["--gains-from-log"]);
    let (f_nom, f_fr) = (
        nom["fit_pct"].as_f64().unwrap(),
        fr["fit_pct"].as_f64().unwrap(),
    );
    println!(
        "nominal {f_nom:.2} % (RMSE {}), friction {f_fr:.2} % (RMSE {})",
        nom["rmse"], fr["rmse"]
    );
    println!("nominal regimes: {}", nom["regimes"]);
    println!("nominal findings: {}", nom["findings"]);
    assert_eq!(nom["mode"], "closed-loop");
    assert!(f_fr > f_nom + 2.0, "{f_nom} -> {f_fr}");
    assert!(fr["rmse"].as_f64().unwrap() < 0.5 * nom["rmse"].as_f64().unwrap());
    let rev = regime(&nom, "reversal");
    assert!(rev["concentration"].as_f64().unwrap() > 3.0, "{rev}");
}

/// The gains of [`gains_file`] designed for Tustin (`[design] discretization = "tustin"`), with
/// back-calculation anti-windup K_w = 30 1/s.
fn tustin_gains_file(path: &Path) {
    let text = format!(
        "[pid]\nkp = {}\nki = {}\nkd = {}\ntl_s = {}\nts_s = {DT}\nkw = 30.0\n\n[design]\ndiscretization = \"tustin\"\n",
        PID.kp, PID.ki, PID.kd, PID.tl_s
    );
    assert!(GainsFile::parse(&text).is_ok());
    std::fs::write(path, text).unwrap();
}

/// In `dir`: the Tustin gains, the model of `plant(Some(0.01))` and the path of the log `log_name`.
fn tustin_files(dir: &Path, log_name: &str) -> (PathBuf, PathBuf, PathBuf) {
    let (gains, model) = (dir.join("gains.toml"), dir.join("model.toml"));
    tustin_gains_file(&gains);
    ModelFile::from_plant(&plant(Some(0.01)))
        .save(&model)
        .unwrap();
    (gains, model, dir.join(log_name))
}

/// [`tustin_files`] and the [`SQUARE`] run with the derivative on the measurement, logged to
/// run.mcap.
fn tustin_square_run(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let (gains, model, log) = tustin_files(dir, "run.mcap");
    let mut run_args = SQUARE.to_vec();
    run_args.extend_from_slice(&["--derivative-on", "measurement"]);
    sim_run(&gains, &model, &log, &run_args);
    (gains, model, log)
}

/// `servo run` on the simulator (the plant of `model`, 4096-count encoder) with `gains` and
/// `extra` options, logged to `log`.
fn sim_run(gains: &Path, model: &Path, log: &Path, extra: &[&str]) {
    let mut a = vec![
        "run",
        "--gains",
        gains.to_str().unwrap(),
        "--plant",
        model.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
    ];
    a.extend_from_slice(extra);
    let (ok, out, err) = servo(&a);
    assert!(ok, "servo {a:?} failed: {err}\n{out}");
}

fn compare_json(log: &Path, model: &Path, extra: &[&str]) -> Value {
    let mut a = vec![
        "compare",
        log.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
        "--json",
    ];
    a.extend_from_slice(extra);
    run_json(&a)
}

/// The text of `servo compare LOG --model MODEL` (it must succeed).
fn compare_text(log: &Path, model: &Path) -> String {
    let (ok, text, err) = servo(&[
        "compare",
        log.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    text
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// Square steps of +-1.5 rad (the output saturates at 10 V and the anti-windup acts).
const SQUARE: [&str; 4] = ["--ref", "square:amp=1.5,period=1", "--duration", "4"];

#[test]
fn closed_loop_replay_uses_the_controller_the_run_used() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let (_gains, model, log) = tustin_square_run(dir.path());

    // The model is the truth: replayed with the controller of the log's metadata.
    let v = compare_json(&log, &model, &[]);
    let c = &v["controller"];
    println!("controller: {}", c["description"]);
    assert_eq!(v["mode"], "closed-loop");
    assert_eq!(c["discretization"], "tustin", "{c}");
    assert_eq!(c["derivative_on"], "measurement", "{c}");
    assert_eq!(c["anti_windup"], "back-calc", "{c}");
    assert_eq!(f(&c["kw"]), 30.0);
    assert_eq!(f(&c["u_limit_v"]), 10.0);
    assert_eq!(c["feedforward"], "none");
    for part in [
        "discretization",
        "derivative_on",
        "anti_windup",
        "u_limit_v",
    ] {
        assert_eq!(
            c["parts"][part]["source"], "from the log's metadata",
            "{part}: {c}"
        );
    }
    let (check, rms) = (f(&c["check_fit_pct"]), f(&c["check_rms_v"]));
    let (fit, rmse) = (f(&v["fit_pct"]), f(&v["rmse"]));
    println!(
        "same controller: check fit {check:.10} % (RMS {rms:.3e} V over {} samples), position fit {fit:.3} % (RMSE {rmse:.3e} rad)",
        c["check_samples"]
    );
    // The controller check runs the controller on the logged reference and angle: it reproduces
    // the logged u to rounding (measured RMS ~4e-13 V).
    assert!(rms < 1e-9 && check > 99.9999, "{c}");
    assert!(fit > 99.5, "fit {fit}");
    // The text says where the configuration came from.
    let text = compare_text(&log, &model);
    for part in [
        "Tustin (from the log's metadata)",
        "derivative on the measurement (from the log's metadata)",
        "back-calculation anti-windup, K_w = 30 1/s (from the log's metadata)",
    ] {
        assert!(text.contains(part), "missing `{part}` in:\n{text}");
    }

    // The wrong discretisation, forced: the check and the replay get measurably worse.
    let w = compare_json(&log, &model, &["--discretization", "backward-euler"]);
    let cw = &w["controller"];
    assert_eq!(cw["discretization"], "backward-euler");
    assert_eq!(
        cw["parts"]["discretization"]["source"],
        "given with --discretization"
    );
    assert_eq!(
        cw["derivative_on"], "measurement",
        "the rest still from the log"
    );
    let (check_w, rms_w) = (f(&cw["check_fit_pct"]), f(&cw["check_rms_v"]));
    let (fit_w, rmse_w) = (f(&w["fit_pct"]), f(&w["rmse"]));
    println!(
        "backward Euler forced: check fit {check_w:.3} % (RMS {rms_w:.3e} V), position fit {fit_w:.3} % (RMSE {rmse_w:.3e} rad)"
    );
    assert!(rms_w > 1e-2 && check_w < check - 1.0, "{cw}");
    assert!(rmse_w > 3.0 * rmse, "RMSE {rmse} -> {rmse_w}");
}

#[test]
fn logs_without_a_controller_record_replay_through_gains_and_options() {
    let _machine = servo_e2e::shared();
    use servo_cli::io::{mcap_read::read_mcap, meta_keys, McapLog, McapLogOptions};
    let dir = tempfile::tempdir().unwrap();
    let (gains, model, log) = tustin_square_run(dir.path());
    let g = gains.to_str().unwrap();

    // A CSV has no metadata: --gains gives gains, K_w and the [design]'s Tustin; the derivative
    // input is not recorded anywhere, so the default (error) does not reproduce the logged u
    // until --derivative-on says what ran.
    let csv = dir.path().join("run.csv");
    let (ok, _, err) = servo(&["export", log.to_str().unwrap(), "-o", csv.to_str().unwrap()]);
    assert!(ok, "{err}");
    let d = compare_json(&csv, &model, &["--gains", g]);
    let cd = &d["controller"];
    assert_eq!(cd["discretization"], "tustin");
    assert!(
        cd["parts"]["discretization"]["source"]
            .as_str()
            .unwrap()
            .contains("[design] of"),
        "{cd}"
    );
    assert_eq!(cd["parts"]["derivative_on"]["source"], "default");
    let e = compare_json(
        &csv,
        &model,
        &["--gains", g, "--derivative-on", "measurement"],
    );
    let ce = &e["controller"];
    println!(
        "CSV + --gains: check fit {:.3} % with the default derivative on the error, {:.8} % (RMS {:.3e} V) with --derivative-on measurement; position fit {:.3} %",
        f(&cd["check_fit_pct"]),
        f(&ce["check_fit_pct"]),
        f(&ce["check_rms_v"]),
        f(&e["fit_pct"])
    );
    assert!(f(&cd["check_rms_v"]) > 0.1, "{cd}");
    assert!(f(&ce["check_rms_v"]) < 1e-9, "{ce}");
    assert_eq!(
        ce["parts"]["derivative_on"]["source"],
        "given with --derivative-on"
    );
    assert!(f(&e["fit_pct"]) > 99.5);

    // An MCAP of an older servo: the same log without the controller record. The gains and their
    // [design] come from the log's gains; compare says what is missing.
    let run = read_mcap(&log).unwrap();
    let mut meta = run.metadata.clone();
    assert!(meta.remove(meta_keys::CONTROLLER_TOML).is_some());
    let old = dir.path().join("old.mcap");
    let mut w = McapLog::create(&old, &meta, McapLogOptions::default()).unwrap();
    for m in &run.loop_msgs {
        w.write_loop(m).unwrap();
    }
    w.finish().unwrap();
    let o = compare_json(&old, &model, &["--derivative-on", "measurement"]);
    let co = &o["controller"];
    println!("old log: {}; notes {}", co["description"], co["notes"]);
    assert!(co["notes"][0]
        .as_str()
        .unwrap()
        .contains("no record of its controller"));
    assert_eq!(co["discretization"], "tustin");
    assert_eq!(co["anti_windup"], "back-calc");
    assert!(f(&co["check_rms_v"]) < 1e-9, "{co}");
}

#[test]
fn the_logged_feedforward_is_replayed() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let (gains, model, log) = tustin_files(dir.path(), "ff.mcap");
    sim_run(
        &gains,
        &model,
        &log,
        &[
            "--ref",
            "trap:distance=3,vmax=10,amax=100",
            "--duration",
            "2",
            "--ff",
            "inertia,friction",
            "--model",
            model.to_str().unwrap(),
        ],
    );
    let v = compare_json(&log, &model, &[]);
    let c = &v["controller"];
    println!(
        "feedforward run: {}; check RMS {:.3e} V, position fit {:.3} %",
        c["parts"]["feedforward"]["text"],
        f(&c["check_rms_v"]),
        f(&v["fit_pct"])
    );
    assert!(
        c["feedforward"].as_str().unwrap().contains("inertia"),
        "{c}"
    );
    assert!(f(&c["check_rms_v"]) < 1e-9, "{c}");
    assert!(f(&v["fit_pct"]) > 99.5);
    // The same samples without the logged feedforward (a CSV) and the same controller: the PID
    // alone does not make the logged u.
    let csv = dir.path().join("ff.csv");
    let (ok, _, err) = servo(&["export", log.to_str().unwrap(), "-o", csv.to_str().unwrap()]);
    assert!(ok, "{err}");
    let n = compare_json(
        &csv,
        &model,
        &["--gains", gains.to_str().unwrap(), "--u-limit-v", "10"],
    );
    println!(
        "without it: check RMS {:.3e} V",
        f(&n["controller"]["check_rms_v"])
    );
    assert!(f(&n["controller"]["check_rms_v"]) > 0.1);
}

/// Every simulating command says in one line which plant and which controller it simulated:
/// `compare` in closed loop (the PID of the run, Tustin here), open loop (none in the replay, the
/// log's PID named beside it), and `diagnose` (none: the logged u drives the model).
#[test]
fn compare_and_diagnose_say_their_plant_and_controller_in_one_line() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let (_gains, model, log) = tustin_square_run(dir.path());
    let line_of = |out: &str| -> String {
        let lines: Vec<&str> = out
            .lines()
            .filter(|l| l.starts_with("simulated plant:"))
            .collect();
        assert_eq!(lines.len(), 1, "not one plant line:\n{out}");
        lines[0].to_string()
    };
    let (l, m) = (log.to_str().unwrap(), model.to_str().unwrap());
    let (ok, out, err) = servo(&["compare", l, "--model", m]);
    assert!(ok, "{err}\n{out}");
    let line = line_of(&out);
    assert!(
        line.contains(m) && line.contains("coulomb") && line.contains("controller: PID"),
        "{line}"
    );
    assert!(line.contains("Tustin"), "{line}");
    assert!(!out.lines().any(|l| l.starts_with("controller: ")), "{out}");

    let (ok, out, err) = servo(&["compare", l, "--model", m, "--mode", "speed"]);
    assert!(ok, "{err}\n{out}");
    let line = line_of(&out);
    assert!(
        line.contains("controller: none in the replay")
            && line.contains("the log's controller: PID"),
        "{line}"
    );

    let (ok, out, err) = servo(&["diagnose", l, "--model", m]);
    assert!(ok, "{err}\n{out}");
    let line = line_of(&out);
    assert!(
        line.contains(m)
            && line.contains("coulomb")
            && line.contains("controller: none in the simulation")
            && line.contains("0.250 s horizons"),
        "{line}"
    );
}

/// A logged speed that lags the angle's derivative (servo's own runs log a 50 Hz first-order
/// estimate) is replaced by the derivative, as `servo identify` does, and `servo compare` says
/// so: against the true model the speed's fit was 85.5 % (the estimate's lag counted as model
/// error) and is now above 99 %, while the position, current and voltage fits are unchanged (the
/// replay still starts from the logged speed). A lag-free logged speed (the angle's central
/// difference) is kept.
#[test]
fn a_lagging_logged_speed_is_replaced_by_the_angles_derivative() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let (gains, model, log) = tustin_files(dir.path(), "run.mcap");
    sim_run(&gains, &model, &log, &SQUARE);
    let v = compare_json(&log, &model, &[]);
    let l = &v["logs"][0];
    let lag = f(&l["logged_speed_lag_samples"]);
    assert!((1.0..15.0).contains(&lag), "lag {lag} samples");
    assert_eq!(l["speed_derived_from_position"], true, "{l}");
    let fit = |name: &str| {
        f(&l["signals"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["signal"] == name)
            .unwrap_or_else(|| panic!("no {name}: {l}"))["fit_pct"])
    };
    assert!(fit("omega_l") > 99.0, "speed fit {}", fit("omega_l"));
    assert!(fit("theta_l") > 99.5, "position fit {}", fit("theta_l"));
    let text = compare_text(&log, &model);
    assert!(
        text.contains("the logged speed lags the angle's derivative by"),
        "{text}"
    );

    // The same motion with a speed logged without lag: kept.
    let csv = dir.path().join("steps.csv");
    simulate_steps(&plant(Some(0.01)), &csv);
    let body = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<f64>> = body
        .lines()
        .skip(1)
        .map(|r| r.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    let mut with_speed = String::from("time_s,u_V,theta_l_rad,ref_rad,omega_l_rad_s\n");
    for k in 0..rows.len() {
        let (a, b) = (k.saturating_sub(1), (k + 1).min(rows.len() - 1));
        let w = (rows[b][2] - rows[a][2]) / (rows[b][0] - rows[a][0]);
        with_speed.push_str(&format!(
            "{},{},{},{},{w}\n",
            rows[k][0], rows[k][1], rows[k][2], rows[k][3]
        ));
    }
    let csv2 = dir.path().join("steps_speed.csv");
    std::fs::write(&csv2, with_speed).unwrap();
    let v = compare_json(
        &csv2,
        &model,
        &[
            "--gains",
            gains.to_str().unwrap(),
            "--columns",
            "time=time_s,u=u_V,theta_l=theta_l_rad,ref=ref_rad,omega_l=omega_l_rad_s",
        ],
    );
    let l = &v["logs"][0];
    assert_eq!(l["logged_speed_lag_samples"], Value::Null, "{l}");
    assert_eq!(l["speed_derived_from_position"], false, "{l}");
}
