//! Compensation (issue #29): what `diagnose` found and `compare --add` fitted, cancelled in the
//! loop by `servo run --model M --ff all`, through the commands a user runs:
//!
//! 1. a plant with one hidden effect runs a PID square wave and the identification ramps;
//! 2. `servo diagnose` on those logs names the effect; `servo compare --add NAME --save` fits it;
//! 3. the standard tracking reference (`experiments/tracking.toml`: moves both ways and a slow
//!    sine) runs on the same plant with `--ff friction` (the handout's friction feedforward) and
//!    with `--ff all` (every term and every effect of the fitted model): the RMS tracking error
//!    falls by the bar;
//! 4. a model whose effect has the wrong sign makes the error rise, and `servo compare` on that
//!    run names the compensated effect as the suspect.

use servo_e2e::servo;
use std::path::{Path, PathBuf};

fn ok(args: &[&str]) -> String {
    let (ok, out, err) = servo(args);
    assert!(ok, "servo {args:?} failed: {err}\n{out}");
    out
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

pub(crate) fn tracking_experiment() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/tracking.toml")
}

/// The tracking error RMS [rad] `servo run` prints.
pub(crate) fn printed_rms_rad(out: &str) -> f64 {
    let line = out
        .lines()
        .find(|l| l.contains("tracking error RMS"))
        .unwrap_or_else(|| panic!("no tracking error in:\n{out}"));
    line.split_whitespace()
        .nth(3)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("unreadable: {line}"))
}

/// The lab plant with `hidden` (`name:key=value,...`): logs, identified model, diagnosis and the
/// fitted model with the effect `name` added, in `dir`. Returns the fitted model's path.
pub(crate) fn identified_with(dir: &Path, hidden: &str, name: &str) -> PathBuf {
    let d = |n: &str| dir.join(n).to_string_lossy().into_owned();
    let (plant, gains, run, model, fitted) = (
        d("plant.toml"),
        d("gains.toml"),
        d("run.mcap"),
        d("model.toml"),
        d("fitted.toml"),
    );
    let inertia = d("identify_inertia.mcap");
    std::fs::write(&plant, ok(&["params"])).unwrap();
    ok(&["design", "--wc", "30", "--pm", "60", "-o", &gains]);
    ok(&[
        "run",
        "--plant",
        &plant,
        "--plant-effect",
        hidden,
        "--gains",
        &gains,
        "--ref",
        "square:amp=1,period=2",
        "--duration",
        "8",
        "--log",
        &run,
    ]);
    ok(&[
        "identify",
        "--ramp",
        "--plant",
        &plant,
        "--plant-effect",
        hidden,
        "--log-dir",
        p(dir),
        "-o",
        &model,
    ]);
    let diag = ok(&["diagnose", &run, &inertia, "--model", &model]);
    assert!(
        diag.contains(name),
        "the diagnosis of {hidden} does not name {name}:\n{diag}"
    );
    let out = ok(&[
        "compare", &run, &inertia, "--model", &model, "--add", name, "--save", &fitted,
    ]);
    assert!(out.contains(&format!("model written to {fitted}")), "{out}");
    PathBuf::from(fitted)
}

/// The tracking reference on the plant with `hidden`, compensated by `ff` with `model`: the RMS
/// tracking error [rad] and what the run said.
fn tracking(dir: &Path, hidden: &str, model: &Path, ff: &str, log: Option<&str>) -> (f64, String) {
    let d = |n: &str| dir.join(n).to_string_lossy().into_owned();
    let (plant, gains) = (d("plant.toml"), d("gains.toml"));
    let exp = tracking_experiment();
    let mut args = vec![
        "run",
        "--plant",
        &plant,
        "--plant-effect",
        hidden,
        "--gains",
        &gains,
        "--experiment",
        p(&exp),
        "--model",
        p(model),
        "--ff",
        ff,
    ];
    let log_path = log.map(d);
    if let Some(l) = &log_path {
        args.extend_from_slice(&["--log", l]);
    }
    let (okk, out, err) = servo(&args);
    assert!(okk, "servo {args:?} failed: {err}\n{out}");
    (printed_rms_rad(&out), format!("{err}{out}"))
}

/// The bar on one hidden effect: `--ff all` cuts the RMS tracking error by `min_cut`
/// against `--ff friction`.
fn check_cut(hidden: &str, name: &str, min_cut: f64) {
    let _heavy = servo_e2e::cpu_heavy();
    let dir = tempfile::tempdir().unwrap();
    let fitted = identified_with(dir.path(), hidden, name);
    let (friction, _) = tracking(dir.path(), hidden, &fitted, "friction", None);
    let (linear, _) = tracking(dir.path(), hidden, &fitted, "inertia,friction", None);
    let (all, said) = tracking(dir.path(), hidden, &fitted, "all", None);
    // The effects' own share: against every linear term (inertia and back-EMF too).
    assert!(
        all < 0.7 * linear,
        "{hidden}: compensating the effects did not cut the error of the linear feedforward by \
         30 %: {linear:.4e} -> {all:.4e} rad"
    );
    assert!(
        said.contains(&format!("compensated: {name}")),
        "the run does not say it compensates {name}:\n{said}"
    );
    let cut = 1.0 - all / friction;
    eprintln!(
        "{hidden}: tracking error RMS {friction:.4e} rad with --ff friction, {linear:.4e} rad \
         with --ff inertia,friction, {all:.4e} rad with --ff all: cut {:.1} % (against every \
         linear term {:.1} %)",
        100.0 * cut,
        100.0 * (1.0 - all / linear)
    );
    assert!(
        cut >= min_cut,
        "{hidden}: --ff all cut the tracking error by {:.1} % (< {:.0} %): {friction:.4e} -> \
         {all:.4e} rad",
        100.0 * cut,
        100.0 * min_cut
    );
}

#[test]
fn an_identified_imbalance_is_compensated_and_the_error_falls_70_percent() {
    check_cut("imbalance:amplitude=0.01,phase=0.5", "imbalance", 0.70);
}

#[test]
fn an_identified_cogging_is_compensated_and_the_error_falls_50_percent() {
    check_cut(
        "cogging:amplitude=3e-4,harmonic=12,phase=0.3",
        "cogging",
        0.50,
    );
}

#[test]
fn an_identified_stribeck_hump_is_compensated_and_the_error_falls_50_percent() {
    check_cut("stribeck:tau_s=0.02,omega_s=1", "stribeck", 0.50);
}

#[test]
fn an_identified_asymmetry_is_compensated_and_the_error_falls_50_percent() {
    check_cut(
        "asymmetry:tau_sf_pos=0.004,tau_sf_neg=0.012",
        "asymmetry",
        0.50,
    );
}

#[test]
fn an_identified_dead_zone_is_compensated_and_the_error_falls_70_percent() {
    check_cut("deadzone:width=0.4", "deadzone", 0.70);
}

/// The imbalance of `model` with its phase turned by pi: the torque's sign flipped.
fn flipped(model: &Path, to: &Path) {
    let mut m = servo_cli::model_file::ModelFile::load(model).unwrap();
    let kind = servo_core::effects::EffectKind::from_name("imbalance").unwrap();
    let e = m
        .effects
        .get_mut(kind)
        .expect("the fitted model has an imbalance");
    let phase = e.get("phase").unwrap();
    e.set("phase", phase + std::f64::consts::PI).unwrap();
    m.save(to).unwrap();
}

#[test]
fn a_wrong_sign_makes_the_error_rise_and_compare_names_the_suspect() {
    let _heavy = servo_e2e::cpu_heavy();
    let dir = tempfile::tempdir().unwrap();
    let hidden = "imbalance:amplitude=0.01,phase=0.5";
    let fitted = identified_with(dir.path(), hidden, "imbalance");
    let wrong = dir.path().join("wrong.toml");
    flipped(&fitted, &wrong);
    // Every linear term, no effect: what the same run gives without compensating the imbalance.
    let (linear, _) = tracking(dir.path(), hidden, &fitted, "inertia,friction", None);
    let (right, _) = tracking(dir.path(), hidden, &fitted, "all", Some("right.mcap"));
    let (bad, _) = tracking(dir.path(), hidden, &wrong, "all", Some("wrong.mcap"));
    eprintln!("linear terms only {linear:.4e}, right {right:.4e}, wrong sign {bad:.4e} rad");
    assert!(
        bad > 1.3 * linear && bad > 3.0 * right,
        "a wrong-sign imbalance should make the error rise above leaving it out: linear terms \
         only {linear:.4e}, right {right:.4e}, wrong {bad:.4e} rad"
    );
    // compare on the wrong run with the wrong model: the compensated imbalance is the suspect.
    let wrong_log = dir.path().join("wrong.mcap");
    let out = ok(&["compare", p(&wrong_log), "--model", p(&wrong)]);
    assert!(
        out.contains("SUSPECT: the compensated imbalance"),
        "compare does not name the suspect:\n{out}"
    );
    // and on the right run with the right model: consistent, no suspect.
    let right_log = dir.path().join("right.mcap");
    let out = ok(&["compare", p(&right_log), "--model", p(&fitted)]);
    assert!(
        out.contains("compensated imbalance: consistent") && !out.contains("SUSPECT"),
        "the right compensation is called a suspect:\n{out}"
    );
    // --json carries the same verdicts (validated against docs/schemas/compare.json).
    let (okk, js, err) = servo(&["compare", p(&wrong_log), "--model", p(&wrong), "--json"]);
    assert!(okk, "{err}");
    let v: serde_json::Value = serde_json::from_str(&js).unwrap();
    let checks = v["compensation_checks"]
        .as_array()
        .expect("compensation_checks");
    assert!(checks
        .iter()
        .any(|c| c["effect"] == "imbalance" && c["suspect"] == true));
}

#[test]
fn doubtful_or_uncompensable_effects_are_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n);
    std::fs::write(d("plant.toml"), ok(&["params"])).unwrap();
    let (gains, m_toml) = (d("gains.toml"), d("m.toml"));
    ok(&["design", "--wc", "30", "--pm", "60", "-o", p(&gains)]);
    // A model with a gear play and an imbalance whose amplitude interval holds zero.
    let mut m = servo_cli::model_file::ModelFile::load(&d("plant.toml")).unwrap();
    m.effects
        .insert(servo_core::effects::Effect::parse("backlash:gap=0.01").unwrap());
    m.effects
        .insert(servo_core::effects::Effect::parse("imbalance:amplitude=0.002,phase=0").unwrap());
    m.set_interval("imbalance.amplitude", -0.001, 0.005);
    m.save(&d("m.toml")).unwrap();
    let run = |ff: &str| {
        servo(&[
            "run",
            "--gains",
            p(&gains),
            "--ref",
            "step:0.5",
            "--duration",
            "1",
            "--model",
            p(&m_toml),
            "--ff",
            ff,
        ])
    };
    let (okk, _, err) = run("backlash");
    assert!(!okk && err.contains("backlash is not compensated"), "{err}");
    let (okk, _, err) = run("imbalance");
    assert!(
        !okk && err.contains("imbalance.amplitude") && err.contains("holds zero"),
        "{err}"
    );
    let (okk, _, err) = run("cogging");
    assert!(!okk && err.contains("the model has no cogging"), "{err}");
    let (okk, _, err) = run("all");
    assert!(!okk && err.contains("doubtful"), "{err}");
    // Without the doubtful interval, `all` runs and says what it leaves out and why.
    let mut m = servo_cli::model_file::ModelFile::load(&d("m.toml")).unwrap();
    m.provenance = None;
    m.save(&d("m.toml")).unwrap();
    let (okk, out, err) = run("all");
    assert!(okk, "{err}");
    assert!(
        err.contains("compensated: imbalance") && err.contains("not compensated: backlash"),
        "{err}\n{out}"
    );
}
