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
    let _machine = servo_e2e::shared();
    check_cut("imbalance:amplitude=0.01,phase=0.5", "imbalance", 0.70);
}

#[test]
fn an_identified_cogging_is_compensated_and_the_error_falls_50_percent() {
    let _machine = servo_e2e::shared();
    check_cut(
        "cogging:amplitude=3e-4,harmonic=12,phase=0.3",
        "cogging",
        0.50,
    );
}

#[test]
fn an_identified_stribeck_hump_is_compensated_and_the_error_falls_50_percent() {
    let _machine = servo_e2e::shared();
    check_cut("stribeck:tau_s=0.02,omega_s=1", "stribeck", 0.50);
}

#[test]
fn an_identified_asymmetry_is_compensated_and_the_error_falls_50_percent() {
    let _machine = servo_e2e::shared();
    check_cut(
        "asymmetry:tau_sf_pos=0.004,tau_sf_neg=0.012",
        "asymmetry",
        0.50,
    );
}

#[test]
fn an_identified_dead_zone_is_compensated_and_the_error_falls_70_percent() {
    let _machine = servo_e2e::shared();
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
    let _machine = servo_e2e::shared();
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
    let _machine = servo_e2e::shared();
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

// ---- the compensation in the library (servo_core::control::LoopCompensation) ----

mod library {
    use servo_core::control::{
        EffectSelect, Feedforward, FeedforwardConfig, FeedforwardParams, LoopCompensation,
        RefSample, SmoothSign,
    };
    use servo_core::effects::Effect;
    use servo_core::{Plant, PlantParams};

    fn plant(spec: &[&str]) -> Plant {
        let mut p = Plant::from_params(PlantParams {
            tau_sf: Some(0.01),
            ..PlantParams::TABLE2
        })
        .unwrap();
        for s in spec {
            p.effects.insert(Effect::parse(s).unwrap());
        }
        p
    }

    fn exact(cfg: FeedforwardConfig) -> FeedforwardConfig {
        FeedforwardConfig {
            sign: SmoothSign::Exact,
            ..cfg
        }
    }

    fn sample(pos: f64, vel: f64) -> RefSample {
        RefSample {
            pos_rad: pos,
            vel_rad_s: vel,
            acc_rad_s2: 0.0,
        }
    }

    #[test]
    fn without_effects_it_is_the_linear_feedforward() {
        let _machine = servo_e2e::shared();
        let p = plant(&[]);
        let cfg = exact(FeedforwardConfig::FULL);
        let c = LoopCompensation::new(&p, cfg, EffectSelect::None, 0.0).unwrap();
        let ff = Feedforward::new(FeedforwardParams::from_plant(&p), cfg).unwrap();
        let r = sample(0.3, 2.0);
        assert_eq!(
            c.feedforward(&r, 0.0, 0.3, f64::NAN).total_v,
            ff.for_sample(&r).total_v
        );
        assert!(c.effects().is_none());
        assert_eq!(c.pid_limit_v(10.0), 10.0);
        assert_eq!(c.command_v(12.0, 0.0, 10.0), 10.0);
    }

    #[test]
    fn a_friction_curve_replaces_the_linear_coulomb_term() {
        let _machine = servo_e2e::shared();
        // Stribeck: the curve's level at 0.5 rad/s is above tau_sf; the linear Coulomb is off.
        let p = plant(&["stribeck:tau_s=0.02,omega_s=0.5"]);
        let cfg = exact(FeedforwardConfig::FRICTION);
        let c = LoopCompensation::new(&p, cfg, EffectSelect::All, 0.0).unwrap();
        assert!(!c.linear_part().config().coulomb);
        let t = c.feedforward(&sample(0.0, 0.5), 1.0, 0.0, f64::NAN);
        let lin = LoopCompensation::new(&p, cfg, EffectSelect::None, 0.0).unwrap();
        let t0 = lin.feedforward(&sample(0.0, 0.5), 1.0, 0.0, f64::NAN);
        assert!(t.friction_v > 0.0 && t.friction_v > t0.total_v - t0.linear_v + 0.0);
        assert!(
            t.friction_v > t0.linear_v - t.linear_v,
            "curve {} V vs Coulomb {} V",
            t.friction_v,
            t0.linear_v - t.linear_v
        );
        // Odd in the speed.
        let m = c.feedforward(&sample(0.0, -0.5), 1.0, 0.0, f64::NAN);
        assert!((m.total_v + t.total_v).abs() < 1e-12);
    }

    #[test]
    fn the_ramp_scales_the_effects_not_the_linear_part() {
        let _machine = servo_e2e::shared();
        let p = plant(&["imbalance:amplitude=0.02,phase=0"]);
        let cfg = exact(FeedforwardConfig::INERTIA);
        let c = LoopCompensation::new(&p, cfg, EffectSelect::All, 2.0).unwrap();
        let r = sample(1.0, 0.0);
        let full = c.feedforward(&r, 5.0, 1.0, 0.0);
        let half = c.feedforward(&r, 1.0, 1.0, 0.0);
        assert!(full.torque_v.abs() > 0.01, "{full:?}");
        assert!((half.torque_v - 0.5 * full.torque_v).abs() < 1e-12);
        assert_eq!(half.linear_v, full.linear_v);
        assert_eq!(c.feedforward(&r, 0.0, 1.0, 0.0).torque_v, 0.0);
        assert!(LoopCompensation::new(&p, cfg, EffectSelect::All, -1.0).is_err());
    }

    #[test]
    fn the_dead_band_inverse_stays_inside_the_limit() {
        let _machine = servo_e2e::shared();
        let p = plant(&["deadzone:width=0.5"]);
        let c = LoopCompensation::new(&p, exact(FeedforwardConfig::OFF), EffectSelect::All, 0.0)
            .unwrap();
        let l = c.pid_limit_v(10.0);
        assert!((l - 9.5).abs() < 1e-6, "{l}");
        assert!(c.command_v(l, 1.0, 10.0) <= 10.0 + 1e-12);
        // Away from 0 the command adds the width.
        assert!((c.command_v(2.0, 1.0, 10.0) - 2.5).abs() < 1e-6);
        assert!((c.command_v(-2.0, 1.0, 10.0) + 2.5).abs() < 1e-6);
        assert_eq!(c.command_v(f64::NAN, 1.0, 10.0), 0.0);
    }

    #[test]
    fn a_compensated_saturation_narrows_the_limit() {
        let _machine = servo_e2e::shared();
        let p = plant(&["saturation:limit=4.5"]);
        let c = LoopCompensation::new(&p, exact(FeedforwardConfig::OFF), EffectSelect::All, 0.0)
            .unwrap();
        assert!((c.limit_v(10.0) - 4.5).abs() < 1e-9, "{}", c.limit_v(10.0));
        assert!((c.command_v(8.0, 0.0, 10.0) - 4.5).abs() < 1e-9);
    }
}

// ---- the compensation in the board core's on-board loop ----

mod board_core {
    fn board_config() -> servo_core::board::BoardConfig {
        servo_core::board::BoardConfig {
            firmware: servo_core::protocol::fixed_text("test"),
            sample_period_us: 1000,
            watchdog_ms: 50,
            limits: servo_core::safety::SafetyLimits::default(),
            counts_per_rev: 4096,
            current_scale_a_per_lsb: 1e-3,
        }
    }

    /// The simulated gearmotor behind the core, stepped `substeps` physics steps per tick.
    struct SimHal {
        drive: servo_core::board::SimDrive,
        now_us: u32,
    }

    impl servo_core::board::BoardHal for SimHal {
        fn now_us(&mut self) -> u32 {
            self.now_us
        }
        fn encoder_count(&mut self) -> i32 {
            self.drive.encoder_count()
        }
        fn current_raw(&mut self) -> i16 {
            self.drive.current_raw()
        }
        fn set_voltage(&mut self, u_v: f32) {
            self.drive.set_voltage(u_v);
        }
        fn restart_tick(&mut self) {}
        fn write(&mut self, _bytes: &[u8]) {}
    }

    /// The on-board loop holding 1 rad against an unbalanced load for 2 s, P only (no integral to
    /// hide the load): the final error [rad], with and without the compensation of the imbalance.
    fn onboard_hold_error(compensated: bool) -> f64 {
        use servo_core::control::{EffectSelect, FeedforwardConfig};
        // Table 2 without friction: the error the load needs is not hidden in a friction band.
        let mut plant = servo_core::Plant::nominal();
        plant.effects.insert(
            servo_core::effects::Effect::parse("imbalance:amplitude=0.01,phase=0.5").unwrap(),
        );
        let sensors = servo_core::sim::SensorConfig::default();
        let drive = servo_core::board::SimDrive::new(&plant, sensors, 2e-4, 1e-3).unwrap();
        let mut hal = SimHal { drive, now_us: 0 };
        let mut core = servo_core::board::BoardCore::new(board_config()).unwrap();
        if compensated {
            // The model knows the imbalance: its torque at the measured angle, no linear term.
            let c = servo_core::control::LoopCompensation::new(
                &plant,
                FeedforwardConfig::OFF,
                EffectSelect::All.with(servo_core::effects::EffectKind::Imbalance),
                0.0,
            )
            .unwrap();
            core.set_compensation(Some(c));
            assert!(core.compensation().is_some());
        }
        let g = servo_core::protocol::LoopGains {
            kp: 8.0,
            ki: 0.0,
            kd: 0.15,
            tau_f_s: 1.0 / 150.0,
        };
        core.receive(
            &mut hal,
            servo_core::protocol::Frame::new(&servo_core::protocol::Message::LoopGains(g))
                .as_bytes(),
        );
        for k in 0..2000u32 {
            if k % 20 == 0 {
                // The host's reference, often enough for the 50 ms watchdog.
                let m = servo_core::protocol::Message::LoopReference {
                    seq: k,
                    ref_rad: 1.0,
                };
                core.receive(&mut hal, servo_core::protocol::Frame::new(&m).as_bytes());
            }
            for _ in 0..5 {
                hal.drive.step();
            }
            hal.now_us += 1000;
            core.tick(&mut hal);
            assert!(core.is_running(), "the board stopped at tick {k}");
        }
        1.0 - hal.drive.plant_sim().state().theta_l_rad
    }

    #[test]
    fn onboard_loop_compensates_an_unbalanced_load() {
        let _machine = servo_e2e::shared();
        let plain = onboard_hold_error(false);
        let comp = onboard_hold_error(true);
        eprintln!("on-board hold of 1 rad, P only: error {plain:.4e} rad without, {comp:.4e} rad with the compensation");
        // P only: the imbalance's torque needs an error to hold; compensated, only the encoder's
        // quantum remains.
        assert!(
            plain.abs() > 0.01 && comp.abs() < 0.1 * plain.abs(),
            "hold error without {plain:.4e} rad, with the compensation {comp:.4e} rad"
        );
    }
}

/// `servo params` (the lab plant) with `extra` (effect tables) appended, as `model.toml` in
/// `dir`; its path.
fn model_with(dir: &Path, extra: &str) -> String {
    let path = dir.join("model.toml");
    std::fs::write(&path, format!("{}\n{extra}", ok(&["params"]))).unwrap();
    path.to_string_lossy().into_owned()
}

/// `servo run` of the model file `model` as the plant, with `gains`, on the standard tracking
/// reference, compensated by `ff` from the same model (and `--log log` when given): the RMS
/// tracking error it printed [rad] and all it said. Fails the test when the run fails.
fn tracking_on_model(model: &str, gains: &str, ff: &str, log: Option<&str>) -> (f64, String) {
    let exp = tracking_experiment();
    let mut args = vec![
        "run",
        "--plant",
        model,
        "--gains",
        gains,
        "--experiment",
        p(&exp),
        "--model",
        model,
        "--ff",
        ff,
    ];
    if let Some(l) = log {
        args.extend_from_slice(&["--log", l]);
    }
    let (okk, out, err) = servo(&args);
    assert!(okk, "--ff {ff}: {err}\n{out}");
    (printed_rms_rad(&out), format!("{err}{out}"))
}

/// Item 3 of #29: `servo design --model M --ff all` designs on the model's linear part and
/// verifies on its whole nonlinear model without and with the compensation. An unbalanced load
/// (0.03 N m) and a cogging torque: the margins of the linearised loop, the step cases and the
/// tracking ladder, without and with. The ladder's last rung is what `servo run` gives on that
/// model with the designed gains and `--ff all` (the claim checked through the command a user
/// runs next).
#[test]
fn design_on_the_identified_model_is_verified_with_and_without_compensation() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    let model = model_with(
        dir.path(),
        "[effects.imbalance]\namplitude = 0.03\nphase = 0.4\n\
             [effects.cogging]\namplitude = 0.0002\nharmonic = 12\nphase = 0.3\n",
    );
    let gains = d("gains.toml");
    let out = ok(&[
        "design", "--wc", "30", "--pm", "60", "--model", &model, "--ff", "all", "--json", "-o",
        &gains,
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let c = &v["compensation_check"];
    assert_eq!(c["effects"].as_array().unwrap().len(), 4, "{c}");
    // the design is on the file's linear part
    assert_eq!(v["plant_source"].as_str().unwrap(), model, "{v}");
    // margins: the angle torques' stiffness spans both signs without; cancelled with
    let m = &c["margins"];
    assert!(
        m["without"]["stiffness_min_nm_per_rad"].as_f64().unwrap() < 0.0
            && m["without"]["stiffness_max_nm_per_rad"].as_f64().unwrap() > 0.0,
        "{m}"
    );
    assert_eq!(
        m["with"]["stiffness_max_nm_per_rad"].as_f64().unwrap(),
        0.0,
        "{m}"
    );
    assert_eq!(m["with"]["stable"], true, "{m}");
    let lin_pm = m["linear"]["pm_deg"].as_f64().unwrap();
    assert!((lin_pm - 60.0).abs() < 5.0, "linear PM {lin_pm}");
    // the tracking ladder: none, linear terms, then each effect; the effects cut the error
    let ladder = c["tracking"]["ladder"].as_array().unwrap();
    let rms = |i: usize| ladder[i]["err_rms_rad"].as_f64().unwrap();
    assert_eq!(ladder[0]["rung"], "no compensation", "{ladder:?}");
    let last = ladder.len() - 1;
    assert_eq!(ladder[last]["rung"], "+ imbalance", "{ladder:?}");
    assert!(
        rms(last) < 0.3 * rms(1),
        "the effects cut the error < 70 %: {ladder:?}"
    );
    // steps: without, the imbalance leaves the shaft off target longer or overshooting more
    let sw = &c["steps_with"]["worst_settling_time_5pct_s"];
    assert!(sw.is_number(), "the compensated steps do not settle: {c}");
    // what `servo run` gives with the designed gains and --ff all on the same model
    let (said, _) = tracking_on_model(&model, &gains, "all", None);
    assert!(
        (said / rms(last) - 1.0).abs() < 0.02,
        "servo run says {said:.4e} rad, the design's ladder {:.4e} rad",
        rms(last)
    );
    // the text report says it
    let text = ok(&[
        "design",
        "--wc",
        "30",
        "--pm",
        "60",
        "--model",
        &model,
        "--ff",
        "imbalance",
    ]);
    assert!(
        text.contains("verified on the nonlinear model") && text.contains("+ imbalance"),
        "{text}"
    );
    // refusals: --ff without a model file; a --model that is no file
    let (okk, _, err) = servo(&["design", "--wc", "30", "--pm", "60", "--ff", "all"]);
    assert!(!okk && err.contains("--model FILE"), "{err}");
    let (okk, _, err) = servo(&[
        "design",
        "--wc",
        "30",
        "--pm",
        "60",
        "--model",
        "nosuch.toml",
    ]);
    assert!(
        !okk && err.contains("reduced") && err.contains("nosuch.toml"),
        "{err}"
    );
}

/// Item 4 of #29: `servo compare` on two runs of the standard tracking reference (the friction
/// feedforward, then `--ff all`) prints each run's measured RMS tracking error and, per
/// compensated effect, the model's ladder on the compensated run's reference and controller;
/// the figures are the ones `servo run` printed and the ladder ends near the measured error.
#[test]
fn compare_on_two_runs_prints_the_tracking_ladder_per_effect() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    let model = model_with(
        dir.path(),
        "[effects.imbalance]\namplitude = 0.02\nphase = 0.4\n",
    );
    let gains = d("gains.toml");
    ok(&["design", "--wc", "30", "--pm", "60", "-o", &gains]);
    let run = |ff: &str, log: &str| -> f64 { tracking_on_model(&model, &gains, ff, Some(log)).0 };
    let (a, b) = (d("friction.mcap"), d("all.mcap"));
    let (ea, eb) = (run("friction", &a), run("all", &b));
    let out = ok(&["compare", &a, &b, "--model", &model]);
    assert!(out.contains("tracking error of the runs"), "{out}");
    let line = |name: &str| {
        out.lines()
            .find(|l| l.contains(name) && l.contains("--ff"))
            .unwrap_or_else(|| panic!("no line for {name}:\n{out}"))
            .to_string()
    };
    let rms_of = |l: &str| -> f64 {
        l.split_whitespace()
            .find_map(|w| w.parse::<f64>().ok().filter(|v| *v > 0.0 && *v < 1.0))
            .unwrap_or_else(|| panic!("no figure in {l}"))
    };
    for (name, want) in [("friction.mcap", ea), ("all.mcap", eb)] {
        let got = rms_of(&line(name));
        assert!(
            (got / want - 1.0).abs() < 0.01,
            "{name}: compare {got}, run {want}\n{out}"
        );
    }
    let json: serde_json::Value =
        serde_json::from_str(&ok(&["compare", &a, &b, "--model", &model, "--json"])).unwrap();
    let ladder = json["tracking"]["ladder"]
        .as_array()
        .unwrap_or_else(|| panic!("{json}"));
    let names: Vec<&str> = ladder.iter().map(|r| r["rung"].as_str().unwrap()).collect();
    assert_eq!(names.first(), Some(&"no compensation"), "{names:?}");
    assert_eq!(names.last(), Some(&"+ imbalance"), "{names:?}");
    let last = ladder.last().unwrap()["err_rms_rad"].as_f64().unwrap();
    // the model is the plant: its ladder ends at what the compensated run measured
    assert!((last / eb - 1.0).abs() < 0.05, "ladder {last}, run {eb}");
    let before = ladder[ladder.len() - 2]["err_rms_rad"].as_f64().unwrap();
    assert!(
        last < 0.3 * before,
        "the imbalance's rung cuts < 70 %: {ladder:?}"
    );
}

/// Item 1 of #29 for user-defined effects: a user's torque expression (a cable pulling the arm
/// towards 0.3 rad) is compensated on the reference state and a user's input map (a dead band
/// written as an expression) is inverted numerically; `--ff all` cuts the tracking error of the
/// friction feedforward by more than half, the run says how each is compensated, `servo design
/// --ff all` shows their rungs, and a sensor map is refused with the reason.
#[test]
fn user_defined_torques_and_input_maps_are_compensated() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    let model = model_with(
        dir.path(),
        "[custom.cable]\nacts_on = \"load_torque\"\nexpr = \"k * (theta_l - theta0)\"\n\
             [custom.cable.params]\nk = { value = 0.04, unit = \"N m/rad\" }\n\
             theta0 = { value = 0.3, unit = \"rad\" }\n\
             [custom.band]\nacts_on = \"input\"\nexpr = \"sign(u) * max(abs(u) - d, 0)\"\n\
             [custom.band.params]\nd = { value = 0.6, unit = \"V\" }\n\
             [custom.eccentric]\nacts_on = \"sensor\"\nexpr = \"theta_l + e * sin(theta_l)\"\n\
             [custom.eccentric.params]\ne = { value = 0.0, unit = \"rad\" }\n",
    );
    let gains = d("gains.toml");
    ok(&["design", "--wc", "30", "--pm", "60", "-o", &gains]);
    let run = |ff: &str| tracking_on_model(&model, &gains, ff, None);
    let (friction, _) = run("friction");
    let (all, said) = run("all");
    eprintln!("user-defined: {friction:.4e} rad with --ff friction, {all:.4e} rad with --ff all");
    assert!(
        all < 0.5 * friction,
        "{friction:.4e} -> {all:.4e} rad\n{said}"
    );
    assert!(
        said.contains("compensated: cable (user-defined: its torque")
            && said.contains("compensated: band (user-defined: the numerical inverse"),
        "{said}"
    );
    assert!(
        said.contains("not compensated: eccentric (a sensor map"),
        "{said}"
    );
    // each one alone helps
    let (cable, _) = run("friction,cable");
    let (band, _) = run("friction,band");
    assert!(
        cable < friction && band < friction,
        "{friction} {cable} {band}"
    );
    // the design's ladder has their rungs
    let out = ok(&[
        "design", "--wc", "30", "--pm", "60", "--model", &model, "--ff", "all", "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rungs: Vec<String> = v["compensation_check"]["tracking"]["ladder"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["rung"].as_str().unwrap().to_string())
        .collect();
    assert!(
        rungs.contains(&"+ cable (user-defined)".to_string())
            && rungs.contains(&"+ band (user-defined)".to_string()),
        "{rungs:?}"
    );
    // a sensor map named is refused
    let (okk, _, err) = servo(&[
        "run",
        "--plant",
        &model,
        "--gains",
        &gains,
        "--ref",
        "step:1",
        "--duration",
        "1",
        "--model",
        &model,
        "--ff",
        "eccentric",
    ]);
    assert!(!okk && err.contains("a sensor map"), "{err}");
}
