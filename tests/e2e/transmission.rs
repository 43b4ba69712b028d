//! Transmissions other than the handout's gear: a ball-screw axis and a belt axis with linear
//! units in their logs and model files, and a rotary rig with a motor-side encoder. Logs of
//! made-up rigs are simulated with servo's simulator (the core's rotary equations on the
//! equivalent rotation), written as a user's CSV (positions in mm or encoder counts at the
//! motor), and run through `servo identify`, `servo diagnose` and `servo compare --add` as a
//! user would, checking the linear figures they report against the truth.

use servo_core::effects::Effect;
use servo_core::sim::excitation::RandomSteps;
use servo_core::sim::sensors::SplitMix64;
use servo_core::sim::{PlantSim, SensorConfig, Sensors};
use servo_core::transmission::{EncoderSide, Transmission, TransmissionKind};
use servo_core::{Plant, PlantParams};
use servo_e2e::servo;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

const DT: f64 = 1e-3;

/// A made-up rig: its motor and drive, its transmission, its mechanics in the units a user of it
/// reads (mass [kg] or inertia, viscous, Coulomb), the encoder.
#[derive(Clone, Copy)]
struct Rig {
    name: &'static str,
    motor: PlantParams,
    transmission: Transmission,
    /// Total mass at the load [kg] (linear) or J_eq [kg m^2] at the motor (gear).
    mass: f64,
    /// Viscous friction [N s/m] (linear) or B_eq [N m s/rad] (gear).
    viscous: f64,
    /// Coulomb friction [N] (linear) or tau_sf [N m] at the load (gear).
    coulomb: f64,
    /// Encoder counts per revolution of the shaft it sits on.
    counts_per_rev: f64,
    /// Scale resolution of a linear encoder at the load [m] (when it has one).
    scale_m: f64,
    /// Position steps of the closed-loop log, in load units (m or rad).
    step: f64,
    /// PID gains (V per rad of the load shaft, ...), derivative on the measurement.
    pid: (f64, f64, f64),
}

impl Rig {
    /// The truth as the core's rotary parameters.
    fn params(&self) -> PlantParams {
        let n = self.motor.n;
        let t = &self.transmission;
        PlantParams {
            j_eq: Some(t.j_eq_of_mass(self.mass, n).unwrap_or(self.mass)),
            b_eq: Some(t.b_eq_of_viscous(self.viscous, n).unwrap_or(self.viscous)),
            tau_sf: Some(t.torque_of_force(self.coulomb).unwrap_or(self.coulomb)),
            ..self.motor
        }
    }

    /// The `--columns` map of its CSV logs.
    fn columns(&self) -> String {
        let mut c = String::from("time=t:s,u=u:V,i_a=ia:A");
        match self.transmission.encoder {
            EncoderSide::Motor => write!(c, ",theta_m=enc:counts:{}", self.counts_per_rev),
            EncoderSide::Load => write!(c, ",{}", self.load_column()),
            EncoderSide::Both => write!(
                c,
                ",theta_m=enc:counts:{},{}",
                self.counts_per_rev,
                self.load_column()
            ),
        }
        .unwrap();
        c
    }

    fn load_column(&self) -> &'static str {
        if self.transmission.is_linear() {
            "x=pos:mm"
        } else {
            "theta_l=pos:deg"
        }
    }

    /// The model file a user writes before identifying: the motor's datasheet and the
    /// transmission, no friction or mass.
    fn nominal_file(&self, dir: &Path) -> PathBuf {
        let m = servo_cli::model_file::ModelFile {
            params: self.motor,
            transmission: self.transmission,
            ..Default::default()
        };
        let p = dir.join(format!("{}-nominal.toml", self.name));
        m.save(&p).unwrap();
        p
    }
}

/// A small servo motor (100 W class, 24 V) with a linear amplifier, directly coupled (N = 1)
/// unless said otherwise; no Table 2 load parts.
fn small_motor(n: f64) -> PlantParams {
    PlantParams {
        r_a: 1.1,
        l_a: 0.35e-3,
        k_e: 0.052,
        k_t: 0.052,
        j_m: 1.4e-5,
        b_m: 0.0,
        n,
        j_72: 0.0,
        j_d: 0.0,
        b_l: 0.0,
        k_drv: 2.0,
        f_c_drv: 2000.0,
        r_s: 0.05,
        j_eq: None,
        b_eq: None,
        tau_sf: None,
    }
}

/// A 10 mm lead ball screw, a 5 kg carriage (plus the rotor's and the screw's inertia: 14.9 kg
/// equivalent), directly coupled, a 2000-count motor encoder.
fn screw_rig() -> Rig {
    Rig {
        name: "screw",
        motor: small_motor(1.0),
        transmission: Transmission {
            kind: TransmissionKind::Screw { lead_m: 0.01 },
            encoder: EncoderSide::Motor,
        },
        mass: 14.9,
        viscous: 60.0,
        coulomb: 14.0,
        counts_per_rev: 2000.0,
        scale_m: 1e-6,
        step: 0.015,
        pid: (3.0, 6.0, 0.04),
    }
}

/// A belt axis: a 15 mm pulley behind a 3:1 gearbox, a 2.5 kg carriage (3.1 kg equivalent with
/// the rotor), a linear scale of 1 um at the carriage and a motor encoder.
fn belt_rig() -> Rig {
    Rig {
        name: "belt",
        motor: small_motor(3.0),
        transmission: Transmission {
            kind: TransmissionKind::Belt { radius_m: 0.015 },
            encoder: EncoderSide::Both,
        },
        mass: 3.1 + 1.4e-5 * 9.0 / (0.015 * 0.015),
        viscous: 9.0,
        coulomb: 6.0,
        counts_per_rev: 4000.0,
        scale_m: 1e-6,
        step: 0.05,
        pid: (6.0, 12.0, 0.08),
    }
}

/// A rotary arm on a 20:1 gearbox (level, no gravity) read by a 1024-count motor encoder only.
fn rotary_motor_encoder_rig() -> Rig {
    let motor = small_motor(20.0);
    Rig {
        name: "rotary",
        motor,
        transmission: Transmission {
            kind: TransmissionKind::Gear,
            encoder: EncoderSide::Motor,
        },
        mass: motor.j_m + 0.02 / 400.0,
        viscous: 1.5e-4,
        coulomb: 0.35,
        counts_per_rev: 1024.0,
        scale_m: 0.0,
        step: 0.8,
        pid: (25.0, 40.0, 0.6),
    }
}

/// One log row: time, u, current, the load position and the motor counts.
struct Row {
    t: f64,
    u: f64,
    ia: f64,
    theta_l: f64,
}

/// Writes `rows` as the rig's CSV: `t,u,ia` and the encoder columns (motor counts as integers,
/// the load position in mm or deg, quantised to the scale).
fn write_log(rig: &Rig, rows: &[Row], path: &Path) {
    let n = rig.motor.n;
    let mut csv = String::from("t,u,ia,enc,pos\n");
    for r in rows {
        let counts = (r.theta_l * n / std::f64::consts::TAU * rig.counts_per_rev).floor();
        let pos = match rig.transmission.position_m(r.theta_l) {
            Some(x) => (x / rig.scale_m).floor() * rig.scale_m * 1e3,
            None => r.theta_l.to_degrees(),
        };
        writeln!(csv, "{:.4},{:.6},{:.6},{counts},{pos:.6}", r.t, r.u, r.ia).unwrap();
    }
    std::fs::write(path, csv).unwrap();
}

/// The sensors of the simulator: current noise only (the encoders are quantised in
/// [`write_log`], where they sit).
fn sensors(seed: u64) -> Sensors {
    Sensors::new(SensorConfig {
        counts_per_rev: 0,
        current_noise_a: 5e-3,
        current_offset_a: 0.0,
        seed,
    })
}

/// Open loop: the library's random voltage steps with ramps through zero, `seconds` long.
fn open_loop(plant: &Plant, seconds: f64, seed: u64) -> Vec<Row> {
    let n = (seconds / DT) as usize;
    let mut steps = RandomSteps::new(seed);
    steps.hold_samples = 300;
    steps.min_v = 0.5;
    steps.span_v = 4.5;
    steps.ramps = Some(servo_core::sim::excitation::ZeroRamps {
        probability: 0.25,
        min_v: 2.0,
        span_v: 2.0,
    });
    let u = steps.voltages(n, DT);
    let mut sim = PlantSim::new(plant, DT).unwrap();
    let mut s = sensors(seed);
    let mut rows = Vec::with_capacity(n);
    for (k, &uk) in u.iter().enumerate() {
        let m = s.measure(sim.state());
        rows.push(Row {
            t: k as f64 * DT,
            u: uk,
            ia: m.i_a_a,
            theta_l: sim.state().theta_l_rad,
        });
        sim.step(uk);
    }
    rows
}

/// Closed loop: a PID on the load position (from the motor encoder) following random steps of
/// the rig's size, +-10 V.
fn closed_loop(rig: &Rig, plant: &Plant, seconds: f64, seed: u64) -> Vec<Row> {
    let n = (seconds / DT) as usize;
    let step_rad = rig
        .transmission
        .metres_per_rad()
        .map_or(rig.step, |s| rig.step / s);
    let (kp, ki, kd) = rig.pid;
    let q = std::f64::consts::TAU / rig.counts_per_rev / rig.motor.n;
    let mut sim = PlantSim::new(plant, DT).unwrap();
    let mut s = sensors(seed + 11);
    let mut rng = SplitMix64(seed ^ 0xC105ED);
    let (mut integ, mut d, mut prev, mut r) = (0.0, 0.0, 0.0, 0.0);
    let mut rows = Vec::with_capacity(n);
    for k in 0..n {
        if k % 700 == 0 {
            r += (if rng.uniform() < 0.5 { -1.0 } else { 1.0 })
                * step_rad
                * (0.3 + 0.7 * rng.uniform());
        }
        let y = (sim.state().theta_l_rad / q).floor() * q;
        let e = r - y;
        d += DT / (0.003 + DT) * ((y - prev) / DT - d);
        prev = y;
        let raw = kp * e + ki * integ - kd * d;
        let u = raw.clamp(-10.0, 10.0);
        if raw == u {
            integ += e * DT;
        }
        let m = s.measure(sim.state());
        rows.push(Row {
            t: k as f64 * DT,
            u,
            ia: m.i_a_a,
            theta_l: sim.state().theta_l_rad,
        });
        sim.step(u);
    }
    rows
}

/// Simulates the rig (with `hidden` effects) and writes its open- and closed-loop logs.
fn logs(rig: &Rig, hidden: &[Effect], dir: &Path, seed: u64) -> Vec<PathBuf> {
    let mut plant = Plant::from_params(rig.params()).unwrap();
    for e in hidden {
        plant.effects.insert(*e);
    }
    let ol = dir.join(format!("{}-open-{seed}.csv", rig.name));
    let cl = dir.join(format!("{}-closed-{seed}.csv", rig.name));
    write_log(rig, &open_loop(&plant, 14.0, seed), &ol);
    write_log(rig, &closed_loop(rig, &plant, 10.0, seed), &cl);
    vec![ol, cl]
}

fn run_json(args: &[&str]) -> serde_json::Value {
    let (ok, out, err) = servo(args);
    assert!(ok, "servo {args:?} failed: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

fn args_with<'a>(cmd: &'a str, logs: &'a [PathBuf], rest: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![cmd];
    a.extend(logs.iter().map(|p| p.to_str().unwrap()));
    a.extend_from_slice(rest);
    a
}

fn within(tag: &str, got: f64, want: f64, rel: f64) {
    eprintln!(
        "[{tag}] {got:.5} vs {want:.5} ({:+.2} %)",
        100.0 * (got / want - 1.0)
    );
    assert!(
        (got / want - 1.0).abs() < rel,
        "[{tag}] {got} vs truth {want}: beyond {} %",
        rel * 100.0
    );
}

/// `servo identify` on the rig's logs: the base parameters in the rig's own units within 3 %,
/// in the JSON and in the model file it writes. Returns the identified model file.
fn check_identify(rig: &Rig, logs: &[PathBuf], dir: &Path) -> PathBuf {
    let nominal = rig.nominal_file(dir);
    let out = dir.join(format!("{}-identified.toml", rig.name));
    let cols = rig.columns();
    let v = run_json(&args_with(
        "identify",
        logs,
        &[
            "--columns",
            &cols,
            "--params",
            nominal.to_str().unwrap(),
            "--json",
            "-o",
            out.to_str().unwrap(),
        ],
    ));
    let linear = rig.transmission.is_linear();
    let keys = if linear {
        ["m_eq_kg", "b_eq_n_s_m", "f_c_n"]
    } else {
        ["j_eq_kg_m2", "b_eq_n_m_s_rad", "tau_sf_n_m"]
    };
    for (key, want) in keys.iter().zip([rig.mass, rig.viscous, rig.coulomb]) {
        let got = v[key]["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("[{}] no {key} in {v}", rig.name));
        within(&format!("{} identify {key}", rig.name), got, want, 0.03);
    }
    if linear {
        assert_eq!(v["transmission"]["kind"], rig.transmission.kind_name());
        let text = std::fs::read_to_string(&out).unwrap();
        assert!(
            text.contains("m_eq_kg =") && text.contains("f_c_n ="),
            "{text}"
        );
        let back = servo_cli::model_file::ModelFile::load(&out).unwrap();
        assert_eq!(back.transmission, rig.transmission);
    }
    out
}

#[test]
fn a_screw_axis_is_identified_in_linear_units() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let rig = screw_rig();
    let logs = logs(&rig, &[], dir.path(), 3);
    check_identify(&rig, &logs, dir.path());
}

#[test]
fn a_belt_axis_with_two_encoders_is_identified_in_linear_units() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let rig = belt_rig();
    let logs = logs(&rig, &[], dir.path(), 5);
    check_identify(&rig, &logs, dir.path());
}

#[test]
fn a_rotary_rig_with_a_motor_encoder_is_identified() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let rig = rotary_motor_encoder_rig();
    let logs = logs(&rig, &[], dir.path(), 7);
    check_identify(&rig, &logs, dir.path());
}

/// Another screw: a 20 mm lead (s = 3.18 mm/rad), directly coupled, a 4 kg carriage (5.4 kg
/// equivalent with the rotor), a 1 um linear scale at the carriage and a 2000-count motor
/// encoder; `encoder` says which of them the logs are read from.
fn long_lead_screw_rig(encoder: EncoderSide) -> Rig {
    let s: f64 = 0.02 / std::f64::consts::TAU;
    Rig {
        name: "screw20",
        motor: small_motor(1.0),
        transmission: Transmission {
            kind: TransmissionKind::Screw { lead_m: 0.02 },
            encoder,
        },
        mass: 4.0 + 1.4e-5 / (s * s),
        viscous: 25.0,
        coulomb: 17.0,
        counts_per_rev: 2000.0,
        scale_m: 1e-6,
        step: 0.04,
        pid: (3.0, 6.0, 0.04),
    }
}

#[test]
fn a_second_screw_round_trips_with_its_encoder_on_the_motor_the_load_or_both() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    // One simulation; the logs hold both encoders, each identify reads the ones its model names.
    let logs = logs(&long_lead_screw_rig(EncoderSide::Load), &[], dir.path(), 21);
    for encoder in [EncoderSide::Motor, EncoderSide::Load, EncoderSide::Both] {
        let rig = long_lead_screw_rig(encoder);
        let model = check_identify(&rig, &logs, dir.path());
        let back = servo_cli::model_file::ModelFile::load(&model).unwrap();
        assert_eq!(back.transmission.encoder, encoder);
    }
}

/// The figures of one signal in a `compare --json` object.
fn signal<'a>(v: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    v["signals"]
        .as_array()
        .and_then(|s| s.iter().find(|s| s["signal"] == name))
        .unwrap_or_else(|| panic!("no signal {name} in {v}"))
}

/// Standard deviation of the central-difference speed [m/s] of a position column [mm] of a CSV
/// written by [`write_log`] (every 1 ms), low-passed over 10 ms as the comparison's derivative is.
fn speed_std_m_s(csv: &Path) -> f64 {
    let text = std::fs::read_to_string(csv).unwrap();
    let x: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(4).unwrap().parse::<f64>().unwrap() * 1e-3)
        .collect();
    let h = 5;
    let v: Vec<f64> = (h..x.len() - h)
        .map(|k| (x[k + h] - x[k - h]) / (2.0 * h as f64 * DT))
        .collect();
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

/// Text of a report that shows an angle unit where the user gave metres.
fn rad_in(text: &str) -> Option<&str> {
    ["rad/s", " rad ", " rad)", " rad,", "[rad", "rad^"]
        .into_iter()
        .find(|p| text.contains(p))
}

#[test]
fn a_screw_axis_with_a_direction_asymmetry_is_diagnosed_in_newtons_and_added() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let rig = long_lead_screw_rig(EncoderSide::Load);
    let (f_pos, f_neg) = (22.0, 12.0);
    let t = rig.transmission;
    let hidden = Effect::parse(&format!(
        "asymmetry:tau_sf_pos={},tau_sf_neg={}",
        t.torque_of_force(f_pos).unwrap(),
        t.torque_of_force(f_neg).unwrap()
    ))
    .unwrap();
    let logs = logs(&rig, &[hidden], dir.path(), 23);
    let cols = rig.columns();
    // identify the base (one Coulomb level), as a user would first.
    let nominal = rig.nominal_file(dir.path());
    let model = dir.path().join("screw20-base.toml");
    let (ok, _, err) = servo(&args_with(
        "identify",
        &logs,
        &[
            "--columns",
            &cols,
            "--params",
            nominal.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
        ],
    ));
    assert!(ok, "{err}");
    let m = model.to_str().unwrap();

    // diagnose names the asymmetry, its two levels in N within 15 %.
    let d = run_json(&args_with(
        "diagnose",
        &logs,
        &["--columns", &cols, "--model", m, "--json"],
    ));
    servo_e2e::validate_output(&d).unwrap();
    let best = &d["ranking"][0];
    assert_eq!(best["effect"], "asymmetry", "{}", d["verdict"]);
    assert_eq!(best["significant"], true, "{}", d["verdict"]);
    for (key, want) in [("tau_sf_pos_n", f_pos), ("tau_sf_neg_n", f_neg)] {
        let got = best["linear"][key]
            .as_f64()
            .unwrap_or_else(|| panic!("{best}"));
        within(&format!("diagnose {key}"), got, want, 0.15);
    }
    let (ok, text, err) = servo(&args_with(
        "diagnose",
        &logs,
        &["--columns", &cols, "--model", m],
    ));
    assert!(ok, "{err}");
    assert!(
        text.contains("best candidate asymmetry: tau_sf_pos_n = "),
        "{text}"
    );

    // compare --add asymmetry: the held-out error falls, the ladder says so, the model is saved
    // with the effect as the registry stores it (N m at the screw).
    let saved = dir.path().join("screw20-asym.toml");
    let v = run_json(&args_with(
        "compare",
        &logs,
        &[
            "--columns",
            &cols,
            "--model",
            m,
            "--add",
            "asymmetry",
            "--save",
            saved.to_str().unwrap(),
            "--json",
        ],
    ));
    servo_e2e::validate_output(&v).unwrap();
    let ladder = v["ladder"].as_array().unwrap();
    let (before, after) = (
        ladder[0]["rmse"].as_f64().unwrap(),
        ladder[1]["rmse"].as_f64().unwrap(),
    );
    eprintln!("[screw20 compare] replay RMSE {before:.4e} -> {after:.4e} m/s");
    assert!(after < 0.9 * before, "{before} -> {after}");
    // Linear units: the speed in m/s (its RMSE matches the fit and the measured speed's spread,
    // which the rotary rad/s would miss by 1/s = 314).
    assert_eq!(v["signal"], "v_x");
    assert_eq!(v["unit"], "m/s");
    assert_eq!(v["transmission"]["kind"], "screw");
    let log0 = &v["logs"][0];
    let s0 = signal(log0, "v_x");
    let from_fit = (1.0 - s0["fit_pct"].as_f64().unwrap() / 100.0) * speed_std_m_s(&logs[0]);
    within(
        "compare v_x rmse vs fit",
        s0["rmse"].as_f64().unwrap(),
        from_fit,
        0.1,
    );
    let lin = &v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["effect"] == "asymmetry")
        .unwrap()["linear"];
    within(
        "compare tau_sf_pos_n",
        lin["tau_sf_pos_n"].as_f64().unwrap(),
        f_pos,
        0.15,
    );
    within(
        "compare tau_sf_neg_n",
        lin["tau_sf_neg_n"].as_f64().unwrap(),
        f_neg,
        0.15,
    );
    assert!(v["base"]["m_eq_kg"].as_f64().unwrap() > 0.0);
    let save = &v["save"];
    assert_eq!(save["saved"], true, "{save}");
    assert_eq!(save["worse"], false, "{save}");
    let held = save["measures"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["measure"] == "held_out")
        .unwrap_or_else(|| panic!("no held-out measure: {save}"));
    eprintln!(
        "[screw20 compare] held-out error {} -> {} m",
        held["before"], held["after"]
    );
    assert_eq!(held["unit"], "m");
    assert!(
        held["after"].as_f64().unwrap() < held["before"].as_f64().unwrap(),
        "{held}"
    );
    let back = servo_cli::model_file::ModelFile::load(&saved).unwrap();
    assert_eq!(back.transmission, rig.transmission);
    let s = t.metres_per_rad().unwrap();
    let pos = back
        .effects
        .value(servo_core::EffectKind::Asymmetry, "tau_sf_pos")
        .unwrap();
    within("saved tau_sf_pos [N m]", pos, f_pos * s, 0.15);

    // The text: the ladder says the error fell, in linear units only.
    let (ok, text, err) = servo(&args_with(
        "compare",
        &logs,
        &["--columns", &cols, "--model", m, "--add", "asymmetry"],
    ));
    assert!(ok, "{err}");
    let line = text
        .lines()
        .find(|l| l.contains("+ asymmetry") || (l.contains("asymmetry") && l.contains("% RMSE")))
        .unwrap_or_else(|| panic!("no ladder line for asymmetry: {text}"));
    assert!(line.contains("m/s") && line.contains("(-"), "{line}");
    assert!(text.contains("v_x [m/s]"), "{text}");
    assert!(text.contains("tau_sf_pos_n = "), "{text}");
    assert!(rad_in(&text).is_none(), "`{:?}` in {text}", rad_in(&text));
}

/// A belt axis run on servo's simulator as a user would: a model file with the belt, a
/// reference in mm, the CSV log in metres; `compare` and `identify` read that log back without
/// `--columns`, in m and kg.
#[test]
fn a_belt_axis_runs_with_references_in_mm_and_logs_in_metres() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let rig = belt_rig();
    let truth = dir.path().join("belt-truth.toml");
    servo_cli::model_file::ModelFile {
        params: rig.params(),
        transmission: rig.transmission,
        sensors: Some(SensorConfig {
            counts_per_rev: 4096,
            current_noise_a: 2e-3,
            current_offset_a: 0.0,
            seed: 4,
        }),
        ..Default::default()
    }
    .save(&truth)
    .unwrap();
    let gains = dir.path().join("belt-gains.toml");
    std::fs::write(
        &gains,
        "[pid]\nkp = 6.0\nki = 12.0\nkd = 0.08\ntl_s = 0.003\nts_s = 0.001\nu_limit_v = 10.0\n",
    )
    .unwrap();
    let closed = dir.path().join("belt-run.csv");
    let (ok, out, err) = servo(&[
        "run",
        "--plant",
        truth.to_str().unwrap(),
        "--gains",
        gains.to_str().unwrap(),
        "--ref",
        "square:amp=30mm,period=1.2",
        "--duration",
        "6",
        "--csv",
        closed.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("tracking error RMS") && out.contains(" mm)"),
        "{out}"
    );
    let text = std::fs::read_to_string(&closed).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    for c in ["time_s", "u_V", "x_m", "ref_m", "v_x_m_s"] {
        assert!(header.contains(&c), "{header:?}");
    }
    assert!(!header.contains(&"theta_l_rad"), "{header:?}");
    let col = |name: &str| -> Vec<f64> {
        let j = header.iter().position(|h| *h == name).unwrap();
        text.lines()
            .skip(1)
            .map(|l| l.split(',').nth(j).unwrap().parse().unwrap())
            .collect()
    };
    let (x, r) = (col("x_m"), col("ref_m"));
    let rmax = r.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!((rmax - 0.03).abs() < 1e-12, "reference {rmax} m");
    // Near +30 mm at the end of the first half period (0.6 s).
    let k = 590;
    assert!(
        (x[k] - 0.03).abs() < 2e-3,
        "x = {} m at {} s",
        x[k],
        k as f64 * DT
    );

    // compare reads it back in metres, no --columns.
    let g = gains.to_str().unwrap();
    let v = run_json(&[
        "compare",
        closed.to_str().unwrap(),
        "--model",
        truth.to_str().unwrap(),
        "--gains",
        g,
        "--json",
    ]);
    servo_e2e::validate_output(&v).unwrap();
    assert_eq!(v["mode"], "closed-loop");
    assert_eq!(v["signal"], "x");
    assert_eq!(v["unit"], "m");
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let std = (x.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
    let from_fit = (1.0 - v["fit_pct"].as_f64().unwrap() / 100.0) * std;
    within(
        "run compare x rmse vs fit",
        v["rmse"].as_f64().unwrap(),
        from_fit,
        0.02,
    );
    assert!(v["rmse"].as_f64().unwrap() < 1e-3, "{}", v["rmse"]);
    let plot = dir.path().join("belt-compare.svg");
    let (ok, text, err) = servo(&[
        "compare",
        closed.to_str().unwrap(),
        "--model",
        truth.to_str().unwrap(),
        "--gains",
        g,
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(text.contains("x [m]"), "{text}");
    assert!(rad_in(&text).is_none(), "`{:?}` in {text}", rad_in(&text));
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(
        svg.contains("x [mm]") && svg.contains("v_x [m/s]"),
        "plot axes"
    );
    assert!(!svg.contains("[rad"), "rad in the plot");

    // identify reads an open-loop run and the closed-loop run back, mass in kg within 3 %.
    // (A staircase of voltages, handout 4.1: the `u` segments of an experiment stay in volts on
    // a linear axis.)
    let open = dir.path().join("belt-open.csv");
    let stairs = dir.path().join("belt-stairs.toml");
    let mut exp = String::new();
    for u in [1.0, 2.0, 3.5, 5.0, -1.0, -2.0, -3.5, -5.0, 0.8, -0.8] {
        writeln!(exp, "[[segment]]\nu = \"step:{u}\"\nduration_s = 0.8\n").unwrap();
    }
    std::fs::write(&stairs, exp).unwrap();
    let (ok, _, err) = servo(&[
        "run",
        "--plant",
        truth.to_str().unwrap(),
        "--experiment",
        stairs.to_str().unwrap(),
        "--csv",
        open.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let nominal = rig.nominal_file(dir.path());
    let v = run_json(&[
        "identify",
        open.to_str().unwrap(),
        closed.to_str().unwrap(),
        "--params",
        nominal.to_str().unwrap(),
        "--json",
    ]);
    for (key, want) in [
        ("m_eq_kg", rig.mass),
        ("b_eq_n_s_m", rig.viscous),
        ("f_c_n", rig.coulomb),
    ] {
        within(
            &format!("run identify {key}"),
            v[key]["value"].as_f64().unwrap(),
            want,
            0.03,
        );
    }
}
