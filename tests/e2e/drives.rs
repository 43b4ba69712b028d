//! Drives other than the handout's linear amplifier (issue 27, item 1): a current (torque)
//! drive commanded by its current reference, and a PWM H-bridge / smart servo commanded by a
//! duty cycle on a supply that sags, beside the voltage drive. Logs of made-up rigs are
//! simulated with servo's simulator (the drive's equivalent voltage chain,
//! [`servo_core::drive`]), written as a user's CSV holding the drive's own command (`u` in V,
//! `i_ref` in A, `duty` in %), without the armature current, and run through `servo identify`,
//! `servo diagnose` and `servo compare --add` with a params file holding only what the drive
//! uses.
//!
//! - Each drive on a rotary gear: identify within 3 %; diagnose names a hidden imbalance within
//!   15 %; `compare --add imbalance` lowers the held-out error and the ladder says so.
//! - A smart servo (duty drive, supply sag, no current) lifting a pendulum whose gravity is 70
//!   times its Coulomb friction, N = 1: identify with the imbalance declared in the params file
//!   within 10 % on J_eq and the imbalance; diagnose on the bare params names the imbalance
//!   within 15 %.

use servo_core::drive::{Drive, DriveKind};
use servo_core::effects::Effect;
use servo_core::sim::excitation::RandomSteps;
use servo_core::sim::sensors::SplitMix64;
use servo_core::sim::PlantSim;
use servo_core::transmission::{EncoderSide, Transmission, TransmissionKind};
use servo_core::{Plant, PlantParams};
use servo_e2e::servo;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

const DT: f64 = 1e-3;
const COUNTS: f64 = 8192.0;

/// A made-up rig: its motor, its drive, the largest command (in the drive's units), its
/// mechanics (motor-side J_eq, B_eq; load-side tau_sf) and the position steps of its loop.
#[derive(Clone, Copy)]
struct Rig {
    name: &'static str,
    motor: PlantParams,
    drive: Drive,
    /// Largest command: V, A or duty (fraction).
    cmd_max: f64,
    /// Supply voltage of a duty drive [V].
    v_supply: f64,
    /// Position steps of the closed loop [rad] at the load.
    step_rad: f64,
    /// A screw axis instead of the rotary gear (its mechanics in the user's units).
    screw: Option<Screw>,
}

/// A ball-screw axis: lead, mass, viscous and Coulomb friction as its user reads them.
#[derive(Clone, Copy)]
struct Screw {
    lead_m: f64,
    mass_kg: f64,
    viscous_n_s_m: f64,
    coulomb_n: f64,
}

impl Screw {
    fn transmission(&self) -> Transmission {
        Transmission {
            kind: TransmissionKind::Screw {
                lead_m: self.lead_m,
            },
            encoder: EncoderSide::Load,
        }
    }
}

/// `rig`'s drive on a 12 mm lead ball screw directly coupled to its motor (N = 1): 9 kg at the
/// carriage (the rotor included), 70 N s/m, 24 N of Coulomb friction, read by a 1 um scale.
fn on_screw(rig: Rig, name: &'static str) -> Rig {
    let screw = Screw {
        lead_m: 0.012,
        mass_kg: 9.0,
        viscous_n_s_m: 70.0,
        coulomb_n: 24.0,
    };
    let t = screw.transmission();
    let motor = PlantParams {
        n: 1.0,
        j_eq: t.j_eq_of_mass(screw.mass_kg, 1.0),
        b_eq: t.b_eq_of_viscous(screw.viscous_n_s_m, 1.0),
        tau_sf: t.torque_of_force(screw.coulomb_n),
        ..rig.motor
    };
    Rig {
        name,
        motor,
        step_rad: 8.0,
        screw: Some(screw),
        ..rig
    }
}

/// A gearmotor of nobody's catalogue: 0.9 ohm, 45 mN m/A, an 8:1 gear.
fn motor() -> PlantParams {
    PlantParams {
        r_a: 0.9,
        l_a: 0.5e-3,
        k_e: 0.045,
        k_t: 0.045,
        j_m: 2.0e-5,
        b_m: 0.0,
        n: 8.0,
        j_72: 0.0,
        j_d: 0.0,
        b_l: 0.0,
        k_drv: 1.5,
        f_c_drv: 3000.0,
        r_s: 0.0,
        j_eq: Some(3.0e-5),
        b_eq: Some(1.5e-5),
        tau_sf: Some(0.06),
    }
}

fn voltage_rig() -> Rig {
    Rig {
        name: "voltage",
        motor: motor(),
        drive: Drive::VOLTAGE,
        cmd_max: 6.0,
        v_supply: f64::NAN,
        step_rad: 1.5,
        screw: None,
    }
}

fn current_rig() -> Rig {
    Rig {
        name: "current",
        motor: motor(),
        drive: Drive {
            i_limit_a: Some(5.0),
            ..Drive::current(Some(300.0))
        },
        cmd_max: 3.0,
        v_supply: f64::NAN,
        step_rad: 1.5,
        screw: None,
    }
}

fn duty_rig() -> Rig {
    Rig {
        name: "duty",
        // A bridge has no gain or lag of its own (the file leaves k_drv and f_c_drv out).
        motor: PlantParams {
            k_drv: 1.0,
            f_c_drv: servo_core::drive::NO_LAG_HZ,
            ..motor()
        },
        drive: Drive {
            t_dead_s: Some(0.5e-6),
            f_pwm_hz: Some(20e3),
            duty_limit: Some(0.95),
            ..Drive::duty(Some(24.0), Some(0.3))
        },
        cmd_max: 0.3,
        v_supply: 24.0,
        step_rad: 1.5,
        screw: None,
    }
}

impl Rig {
    /// The truth: the drive's equivalent chain with the rig's mechanics and `hidden` effects.
    fn plant(&self, hidden: &[Effect]) -> Plant {
        let mut p = Plant::from_params(self.drive.equivalent(&self.motor)).unwrap();
        for e in hidden {
            p.effects.insert(*e);
        }
        p
    }
    /// The command's column and `--columns` entry.
    fn command_column(&self) -> &'static str {
        match self.drive.kind {
            DriveKind::Voltage => "u=cmd:V",
            DriveKind::Current => "i_ref=cmd:A",
            DriveKind::Duty => "duty=cmd:%",
        }
    }
    fn columns(&self) -> String {
        let current = if self.drive.kind == DriveKind::Voltage {
            ",i_a=ia:A"
        } else {
            ""
        };
        let position = if self.screw.is_some() {
            String::from("x=enc:mm")
        } else {
            format!("theta_l=enc:counts:{COUNTS}")
        };
        format!("time=t:s,{},{position}{current}", self.command_column())
    }
    /// The value written in the command column (duty in %).
    fn written(&self, cmd: f64) -> f64 {
        if self.drive.kind == DriveKind::Duty {
            100.0 * cmd
        } else {
            cmd
        }
    }
    /// Load torque per unit of command at stall [N m].
    fn torque_per_command(&self) -> f64 {
        let e = self.drive.equivalent(&self.motor);
        e.n * e.k_t * e.k_drv / e.r_eq() * self.drive.input(1.0, self.v_supply)
    }
    /// The params file a user writes: only what the drive uses, the mechanics as rough guesses
    /// (the truth times 2, 0.5, 2), and `extra` appended.
    fn params_toml(&self, extra: &str) -> String {
        let p = &self.motor;
        let mech = match self.screw {
            // The mechanics of a screw axis in its own units, in [transmission] (below).
            Some(_) => format!("k_t = {}\nj_m = {}\nn = {}\n", p.k_t, p.j_m, p.n),
            None => format!(
                "k_t = {}\nj_m = {}\nn = {}\nj_eq = {:e}\nb_eq = {:e}\ntau_sf = {:e}\n",
                p.k_t,
                p.j_m,
                p.n,
                2.0 * p.j_eq.unwrap(),
                0.5 * p.b_eq.unwrap(),
                2.0 * p.tau_sf.unwrap()
            ),
        };
        let mut s = String::from("[params]\n");
        match self.drive.kind {
            DriveKind::Voltage => {
                write!(
                    s,
                    "r_a = {}\nl_a = {}\nk_e = {}\nb_m = 0.0\nj_72 = 0.0\nj_d = 0.0\nb_l = 0.0\nk_drv = {}\nf_c_drv = {}\nr_s = 0.0\n{mech}",
                    p.r_a, p.l_a, p.k_e, p.k_drv, p.f_c_drv
                )
                .unwrap();
            }
            DriveKind::Current => {
                s.push_str(&mech);
                let d = &self.drive;
                write!(
                    s,
                    "\n[drive]\nkind = \"current\"\nbandwidth_hz = {}\ni_limit_a = {}\n",
                    d.bandwidth_hz.unwrap(),
                    d.i_limit_a.unwrap()
                )
                .unwrap();
            }
            DriveKind::Duty => {
                write!(
                    s,
                    "r_a = {}\nl_a = {}\nk_e = {}\n{mech}",
                    p.r_a, p.l_a, p.k_e
                )
                .unwrap();
                let d = &self.drive;
                write!(
                    s,
                    "\n[drive]\nkind = \"duty\"\nv_supply_v = {}\nr_supply_ohm = {}\n",
                    d.v_supply_v.unwrap(),
                    d.r_supply_ohm.unwrap()
                )
                .unwrap();
                if let (Some(t), Some(f)) = (d.t_dead_s, d.f_pwm_hz) {
                    write!(s, "t_dead_s = {t:e}\nf_pwm_hz = {f}\n").unwrap();
                }
                if let Some(l) = d.duty_limit {
                    writeln!(s, "duty_limit = {l}").unwrap();
                }
            }
        }
        if let Some(sc) = &self.screw {
            write!(
                s,
                "\n[transmission]\nkind = \"screw\"\nlead_m = {}\nencoder = \"load\"\nm_eq_kg = {:e}\nb_eq_n_s_m = {:e}\nf_c_n = {:e}\n",
                sc.lead_m,
                2.0 * sc.mass_kg,
                0.5 * sc.viscous_n_s_m,
                2.0 * sc.coulomb_n
            )
            .unwrap();
        }
        s.push_str(extra);
        s
    }
}

/// One row of a log: time, the drive's command, the load angle (true; quantised when written).
struct Row {
    t: f64,
    cmd: f64,
    theta_l: f64,
    /// Armature current [A] (written for a voltage drive only, as a lab's shunt logs it).
    ia: f64,
}

fn write_log(rig: &Rig, rows: &[Row], path: &Path) {
    let mut s = String::from("t,cmd,enc,ia\n");
    let q = std::f64::consts::TAU / COUNTS;
    for r in rows {
        // A screw axis's carriage position [mm] on a 1 um scale, else the load encoder's counts.
        let position = match rig.screw {
            Some(sc) => format!(
                "{:.3}",
                (r.theta_l * sc.lead_m / std::f64::consts::TAU * 1e6).floor() / 1e3
            ),
            None => format!("{}", (r.theta_l / q).floor()),
        };
        writeln!(
            s,
            "{:.6},{:.6},{position},{:.6}",
            r.t,
            rig.written(r.cmd),
            r.ia
        )
        .unwrap();
    }
    std::fs::write(path, s).unwrap();
}

/// Open loop: random command steps with ramps through zero, in the drive's units.
fn open_loop(rig: &Rig, plant: &Plant, seconds: f64, seed: u64) -> Vec<Row> {
    let n = (seconds / DT) as usize;
    let mut steps = RandomSteps::new(seed);
    steps.hold_samples = 300;
    steps.min_v = 0.1;
    steps.span_v = 0.9;
    steps.ramps = Some(servo_core::sim::excitation::ZeroRamps {
        probability: 0.25,
        min_v: 0.4,
        span_v: 0.4,
    });
    let c = steps.voltages(n, DT);
    let mut sim = PlantSim::new(plant, DT).unwrap();
    let mut rows = Vec::with_capacity(n);
    for (k, &ck) in c.iter().enumerate() {
        let cmd = ck * rig.cmd_max;
        rows.push(Row {
            t: k as f64 * DT,
            cmd,
            theta_l: sim.state().theta_l_rad,
            ia: sim.state().i_a_a,
        });
        sim.step(rig.drive.input(cmd, rig.v_supply));
    }
    rows
}

/// Closed loop: a PD on the load angle (the encoder's counts) following random steps, its output
/// in the drive's units clipped at the largest command.
fn closed_loop(rig: &Rig, plant: &Plant, seconds: f64, seed: u64) -> Vec<Row> {
    let n = (seconds / DT) as usize;
    let j_load = rig.motor.j_eq.unwrap() * rig.motor.n * rig.motor.n;
    let w_n = 25.0;
    let kp = j_load * w_n * w_n / rig.torque_per_command();
    let kd = 1.2 * kp / w_n;
    let q = std::f64::consts::TAU / COUNTS;
    let mut sim = PlantSim::new(plant, DT).unwrap();
    let mut rng = SplitMix64(seed ^ 0xD21E5);
    let (mut d, mut prev, mut r) = (0.0, 0.0, 0.0);
    let mut rows = Vec::with_capacity(n);
    for k in 0..n {
        if k % 600 == 0 {
            r += (if rng.uniform() < 0.5 { -1.0 } else { 1.0 })
                * rig.step_rad
                * (0.3 + 0.7 * rng.uniform());
        }
        let y = (sim.state().theta_l_rad / q).floor() * q;
        d += DT / (0.003 + DT) * ((y - prev) / DT - d);
        prev = y;
        let dither = 0.05 * rig.cmd_max * (rng.uniform() - 0.5);
        let cmd = (kp * (r - y) - kd * d + dither).clamp(-rig.cmd_max, rig.cmd_max);
        rows.push(Row {
            t: k as f64 * DT,
            cmd,
            theta_l: sim.state().theta_l_rad,
            ia: sim.state().i_a_a,
        });
        sim.step(rig.drive.input(cmd, rig.v_supply));
    }
    rows
}

/// The rig's open- and closed-loop logs with `hidden` effects, and its nominal params file.
fn files(rig: &Rig, hidden: &[Effect], dir: &Path, seed: u64) -> (Vec<PathBuf>, PathBuf) {
    let plant = rig.plant(hidden);
    let ol = dir.join(format!("{}-open-{seed}.csv", rig.name));
    let cl = dir.join(format!("{}-closed-{seed}.csv", rig.name));
    write_log(rig, &open_loop(rig, &plant, 12.0, seed), &ol);
    write_log(rig, &closed_loop(rig, &plant, 10.0, seed), &cl);
    let params = dir.join(format!("{}-nominal.toml", rig.name));
    std::fs::write(&params, rig.params_toml("")).unwrap();
    (vec![ol, cl], params)
}

fn run_json(args: &[&str]) -> serde_json::Value {
    let (ok, out, err) = servo(args);
    assert!(ok, "servo {args:?} failed: {err}\n{out}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    servo_e2e::validate_output(&v).unwrap();
    v
}

fn args_with<'a>(cmd: &'a str, logs: &'a [PathBuf], rest: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![cmd];
    a.extend(logs.iter().map(|p| p.to_str().unwrap()));
    a.extend_from_slice(rest);
    a
}

fn within(tag: &str, got: f64, want: f64, rel: f64) {
    eprintln!(
        "[{tag}] {got:.6e} vs {want:.6e} ({:+.2} %)",
        100.0 * (got / want - 1.0)
    );
    assert!(
        (got / want - 1.0).abs() < rel,
        "[{tag}] {got} vs truth {want}: beyond {} %",
        rel * 100.0
    );
}

fn imbalance(amplitude_n_m: f64, phase_rad: f64) -> Effect {
    Effect::parse(&format!(
        "imbalance:amplitude={amplitude_n_m},phase={phase_rad}"
    ))
    .unwrap()
}

/// `servo identify` on the rig's logs (no hidden effect): J_eq, B_eq and tau_sf within 3 %;
/// the model it writes keeps the drive and leaves out what the drive does not use.
fn check_identify(rig: &Rig, dir: &Path) {
    let (logs, nominal) = files(rig, &[], dir, 3);
    let out = dir.join(format!("{}-identified.toml", rig.name));
    let cols = rig.columns();
    let v = run_json(&args_with(
        "identify",
        &logs,
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
    let p = &rig.motor;
    for (key, want) in ["j_eq_kg_m2", "b_eq_n_m_s_rad", "tau_sf_n_m"].iter().zip([
        p.j_eq.unwrap(),
        p.b_eq.unwrap(),
        p.tau_sf.unwrap(),
    ]) {
        let got = v[key]["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("[{}] no {key} in {v}", rig.name));
        within(&format!("{} identify {key}", rig.name), got, want, 0.03);
    }
    let text = std::fs::read_to_string(&out).unwrap();
    let back = servo_cli::model_file::ModelFile::load(&out).unwrap();
    assert_eq!(back.drive, rig.drive, "{text}");
    if rig.drive.kind == DriveKind::Current {
        for key in ["r_a =", "l_a =", "k_e =", "k_drv =", "r_s ="] {
            assert!(!text.contains(&format!("\n{key}")), "{key} written: {text}");
        }
    }
}

#[test]
fn each_drive_on_a_rotary_gear_is_identified_within_3_percent() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    for rig in [voltage_rig(), current_rig(), duty_rig()] {
        check_identify(&rig, dir.path());
    }
}

/// A hidden imbalance (0.25 N m at the load, four times the Coulomb friction) on each drive:
/// `servo diagnose` names it first, its amplitude within 15 %; `servo compare --add imbalance`
/// lowers the held-out error and the ladder's error, and on the current drive refits neither
/// R_eq nor k_drv.
#[test]
fn each_drive_diagnoses_and_adds_a_hidden_imbalance() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let amplitude = 0.25;
    for rig in [voltage_rig(), current_rig(), duty_rig()] {
        let (logs, _) = files(&rig, &[imbalance(amplitude, 0.4)], dir.path(), 5);
        // The base as identified (the truth's base, as a user would have it after identify).
        let base = dir.path().join(format!("{}-base.toml", rig.name));
        std::fs::write(&base, true_base(&rig)).unwrap();
        let cols = rig.columns();
        let report = dir.path().join(format!("{}-report.html", rig.name));
        let v = run_json(&args_with(
            "diagnose",
            &logs,
            &[
                "--columns",
                &cols,
                "--model",
                base.to_str().unwrap(),
                "--json",
                "--report",
                report.to_str().unwrap(),
            ],
        ));
        let w = &v["ranking"][0];
        assert_eq!(w["effect"], "imbalance", "[{}] {}", rig.name, v["verdict"]);
        check_compensation_section(&rig, &report);
        let a = w["params"]["amplitude"]["value"].as_f64().unwrap();
        within(
            &format!("{} diagnose amplitude", rig.name),
            a,
            amplitude,
            0.15,
        );
        let saved = dir.path().join(format!("{}-added.toml", rig.name));
        let v = run_json(&args_with(
            "compare",
            &logs,
            &[
                "--columns",
                &cols,
                "--model",
                base.to_str().unwrap(),
                "--add",
                "imbalance",
                "--save",
                saved.to_str().unwrap(),
                "--json",
            ],
        ));
        let ladder = v["ladder"].as_array().unwrap();
        let (r0, r1) = (
            ladder[0]["rmse"].as_f64().unwrap(),
            ladder.last().unwrap()["rmse"].as_f64().unwrap(),
        );
        eprintln!("[{}] ladder rmse {r0:.4e} -> {r1:.4e}", rig.name);
        assert!(r1 < 0.7 * r0, "[{}] ladder {r0} -> {r1}", rig.name);
        let held = v["save"]["measures"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["measure"] == "held_out")
            .unwrap_or_else(|| panic!("[{}] no held-out measure: {}", rig.name, v["save"]));
        let (b, a) = (
            held["before"].as_f64().unwrap(),
            held["after"].as_f64().unwrap(),
        );
        eprintln!("[{}] held-out {b:.4e} -> {a:.4e}", rig.name);
        assert!(a < b, "[{}] held-out {b} -> {a}", rig.name);
        assert_eq!(v["save"]["saved"], true, "[{}] {}", rig.name, v["save"]);
        if rig.drive.kind == DriveKind::Current {
            let refit = v["refitted_base"].to_string();
            assert!(
                !refit.contains("r_eq") && !refit.contains("k_drv"),
                "[current] refitted {refit}"
            );
            let back = servo_cli::model_file::ModelFile::load(&saved).unwrap();
            assert_eq!(back.drive, rig.drive);
        }
    }
}

/// The report's compensation section runs through the rig's drive, says so, and the found
/// imbalance's compensation cuts the tracking error of the linear feedforward by a fifth or
/// more (measured at stop 54: to 0.23 of it on the voltage amplifier, 0.04 on the current
/// drive, 0.71 on the bridge, whose duty limit and dead time the loop now meets; before, the
/// section ran every drive as a voltage amplifier clipped at 10 V, whatever its own limit).
fn check_compensation_section(rig: &Rig, report: &Path) {
    let html = std::fs::read_to_string(report).unwrap();
    let (comp, rows) = crate::util::compensation_section(&html, rig.name);
    let words = match rig.drive.kind {
        DriveKind::Voltage => "through the model's voltage amplifier",
        DriveKind::Current => "through the model's current drive (the PID's output in A",
        DriveKind::Duty => "through the model's PWM bridge",
    };
    assert!(comp.contains(words), "[{}] {comp}", rig.name);
    eprintln!("[{}] compensation ladder {rows:?}", rig.name);
    assert_eq!(rows.len(), 3, "[{}] {rows:?}", rig.name);
    assert!(
        rows[2].0.starts_with("+ ") && rows[2].1 < 0.8 * rows[1].1,
        "[{}] {rows:?}",
        rig.name
    );
}

/// The rig's params file with its true base mechanics.
fn true_base(rig: &Rig) -> String {
    let p = &rig.motor;
    rig.params_toml("")
        .replace(
            &format!("j_eq = {:e}", 2.0 * p.j_eq.unwrap()),
            &format!("j_eq = {:e}", p.j_eq.unwrap()),
        )
        .replace(
            &format!("b_eq = {:e}", 0.5 * p.b_eq.unwrap()),
            &format!("b_eq = {:e}", p.b_eq.unwrap()),
        )
        .replace(
            &format!("tau_sf = {:e}", 2.0 * p.tau_sf.unwrap()),
            &format!("tau_sf = {:e}", p.tau_sf.unwrap()),
        )
}

/// A params file with only what a current drive uses reads; one without k_t is refused naming
/// the key and the drive; one with a key the drive does not use is refused; a log of another
/// drive's input is refused naming both.
#[test]
fn a_drive_needs_only_its_keys_and_its_input() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let rig = current_rig();
    let (logs, nominal) = files(&rig, &[], dir.path(), 9);
    let m = servo_cli::model_file::ModelFile::load(&nominal).unwrap();
    assert_eq!(m.drive, rig.drive);
    let text = rig.params_toml("");
    let no_kt = dir.path().join("no_kt.toml");
    std::fs::write(&no_kt, text.replace("k_t = 0.045\n", "")).unwrap();
    let e = format!(
        "{:#}",
        servo_cli::model_file::ModelFile::load(&no_kt).unwrap_err()
    );
    assert!(e.contains("k_t") && e.contains("current drive"), "{e}");
    let with_r = dir.path().join("with_r.toml");
    std::fs::write(&with_r, text.replace("[params]\n", "[params]\nr_a = 1.0\n")).unwrap();
    let e = format!(
        "{:#}",
        servo_cli::model_file::ModelFile::load(&with_r).unwrap_err()
    );
    assert!(e.contains("r_a") && e.contains("not used"), "{e}");
    // The current drive's log against the voltage drive's model.
    let volt = dir.path().join("volt.toml");
    std::fs::write(&volt, voltage_rig().params_toml("")).unwrap();
    let cols = rig.columns();
    for cmd in ["identify", "compare", "diagnose"] {
        let flag = if cmd == "identify" {
            "--params"
        } else {
            "--model"
        };
        let (ok, out, err) = servo(&args_with(
            cmd,
            &logs[..1],
            &["--columns", &cols, flag, volt.to_str().unwrap()],
        ));
        assert!(
            !ok,
            "{cmd} accepted a current log on a voltage model: {out}"
        );
        assert!(
            err.contains("i_ref") && err.contains("voltage"),
            "{cmd}: {err}"
        );
    }
}

/// A smart servo at its output (N = 1): 12 V supply with 0.4 ohm of sag, 6 ohm, k_t = k_e =
/// 1.5 N m/A, a 1 kg pendulum at 0.1 m (0.98 N m of gravity, 70 times its 0.014 N m of
/// Coulomb friction), commanded by a duty cycle under its firmware's PD loop, no current sensor.
fn smart_servo() -> (Rig, f64, f64) {
    let j = 0.002 + 1.0 * 0.1 * 0.1;
    let rig = Rig {
        name: "smart servo",
        motor: PlantParams {
            r_a: 6.0,
            l_a: 2e-3,
            k_e: 1.5,
            k_t: 1.5,
            j_m: j,
            b_m: 0.0,
            n: 1.0,
            j_72: 0.0,
            j_d: 0.0,
            b_l: 0.0,
            k_drv: 1.0,
            f_c_drv: servo_core::drive::NO_LAG_HZ,
            r_s: 0.0,
            j_eq: Some(j),
            b_eq: Some(0.02),
            tau_sf: Some(0.014),
        },
        drive: Drive::duty(Some(12.0), Some(0.4)),
        cmd_max: 1.0,
        v_supply: 12.0,
        step_rad: 0.0,
        screw: None,
    };
    (rig, 1.0 * 9.81 * 0.1, 0.3)
}

/// The pendulum lifted between -1.6 and 1.6 rad by a PD with random targets and slow sweeps,
/// a small dither on the duty (as tests/e2e/gravity.rs lifts its arms, in duty).
fn lift_log(rig: &Rig, plant: &Plant, seconds: f64, seed: u64) -> Vec<Row> {
    let mut sim = PlantSim::new(plant, DT).unwrap();
    let mut rng = SplitMix64(seed ^ 0x5E2B0);
    let j_load = rig.motor.j_eq.unwrap();
    let w_n = 15.0;
    let kp = j_load * w_n * w_n / rig.torque_per_command();
    let kd = 0.3 * kp / w_n;
    let q = std::f64::consts::TAU / COUNTS;
    let n = (seconds / DT) as usize;
    let (mut r, mut prev, mut d, mut sweep, mut r0, mut dither) = (0.0, 0.0, 0.0, false, 0.0, 0.0);
    let mut rows = Vec::with_capacity(n);
    for k in 0..n {
        if k % 700 == 0 {
            sweep = rng.uniform() < 0.3;
            r0 = r;
            if !sweep {
                r = -1.6 + 3.2 * rng.uniform();
            }
        }
        if sweep {
            r = r0 + 0.8 * ((k % 700) as f64 / 700.0 * std::f64::consts::TAU).sin();
        }
        if k % 20 == 0 {
            dither = (rng.uniform() - 0.5) * 0.1;
        }
        let y = (sim.state().theta_l_rad / q).floor() * q;
        d += DT / (0.004 + DT) * ((y - prev) / DT - d);
        prev = y;
        let cmd = (kp * (r - y) - kd * d + dither).clamp(-1.0, 1.0);
        rows.push(Row {
            t: k as f64 * DT,
            cmd,
            theta_l: sim.state().theta_l_rad,
            ia: sim.state().i_a_a,
        });
        sim.step(rig.drive.input(cmd, rig.v_supply));
    }
    rows
}

#[test]
fn a_smart_servo_lifting_a_pendulum_is_identified_and_diagnosed() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let (rig, gravity, phase) = smart_servo();
    assert!(gravity > 50.0 * rig.motor.tau_sf.unwrap());
    let plant = rig.plant(&[imbalance(gravity, phase)]);
    let cols = rig.columns();
    let declared = dir.path().join("declared.toml");
    std::fs::write(
        &declared,
        rig.params_toml(&format!(
            "\n[effects.imbalance]\namplitude = {}\nphase = 0.0\n",
            2.0 * gravity
        )),
    )
    .unwrap();
    let bare = dir.path().join("bare.toml");
    std::fs::write(&bare, rig.params_toml("")).unwrap();
    for seed in [1, 2] {
        let log = dir.path().join(format!("lift-{seed}.csv"));
        write_log(&rig, &lift_log(&rig, &plant, 20.0, seed), &log);
        let logs = [log];
        let v = run_json(&args_with(
            "identify",
            &logs,
            &[
                "--columns",
                &cols,
                "--params",
                declared.to_str().unwrap(),
                "--json",
            ],
        ));
        let j = v["j_eq_kg_m2"]["value"].as_f64().unwrap();
        within(
            &format!("smart servo seed {seed} J_eq"),
            j,
            rig.motor.j_eq.unwrap(),
            0.10,
        );
        let a = v["effects_fitted"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["key"] == "amplitude")
            .and_then(|e| e["value"].as_f64())
            .unwrap_or_else(|| panic!("no amplitude: {v}"));
        within(
            &format!("smart servo seed {seed} amplitude"),
            a,
            gravity,
            0.10,
        );
        if seed == 1 {
            let v = run_json(&args_with(
                "diagnose",
                &logs,
                &[
                    "--columns",
                    &cols,
                    "--model",
                    bare.to_str().unwrap(),
                    "--json",
                ],
            ));
            let w = &v["ranking"][0];
            assert_eq!(w["effect"], "imbalance", "{}", v["verdict"]);
            let a = w["params"]["amplitude"]["value"].as_f64().unwrap();
            within("smart servo diagnose amplitude", a, gravity, 0.15);
        }
    }
}

/// Each drive on a screw axis (12 mm lead, 9 kg, positions in mm on a 1 um scale): `servo
/// identify` gives the mass, viscous and Coulomb friction in kg, N s/m and N within 3 %; with a
/// hidden direction asymmetry of the Coulomb friction (30 N one way, 18 N the other) `servo
/// diagnose` names it first with both levels in N within 15 %, and `servo compare --add
/// asymmetry` lowers the held-out error, the ladder says so, and the model is saved.
#[test]
fn each_drive_on_a_screw_axis_is_identified_diagnosed_and_added() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let (f_pos, f_neg) = (30.0, 18.0);
    for rig in [
        on_screw(voltage_rig(), "voltage-screw"),
        on_screw(current_rig(), "current-screw"),
        on_screw(duty_rig(), "duty-screw"),
    ] {
        let sc = rig.screw.unwrap();
        let cols = rig.columns();
        // identify on logs without a hidden effect.
        let (logs, nominal) = files(&rig, &[], dir.path(), 7);
        let v = run_json(&args_with(
            "identify",
            &logs,
            &[
                "--columns",
                &cols,
                "--params",
                nominal.to_str().unwrap(),
                "--json",
            ],
        ));
        for (key, want) in [
            ("m_eq_kg", sc.mass_kg),
            ("b_eq_n_s_m", sc.viscous_n_s_m),
            ("f_c_n", sc.coulomb_n),
        ] {
            let got = v[key]["value"]
                .as_f64()
                .unwrap_or_else(|| panic!("[{}] no {key} in {v}", rig.name));
            within(&format!("{} identify {key}", rig.name), got, want, 0.03);
        }
        // A hidden asymmetry: identify the base (one Coulomb level) as a user would, then
        // diagnose and add.
        let t = sc.transmission();
        let hidden = Effect::parse(&format!(
            "asymmetry:tau_sf_pos={},tau_sf_neg={}",
            t.torque_of_force(f_pos).unwrap(),
            t.torque_of_force(f_neg).unwrap()
        ))
        .unwrap();
        let (logs, nominal) = files(&rig, &[hidden], dir.path(), 11);
        let base = dir.path().join(format!("{}-base.toml", rig.name));
        run_json(&args_with(
            "identify",
            &logs,
            &[
                "--columns",
                &cols,
                "--params",
                nominal.to_str().unwrap(),
                "--json",
                "-o",
                base.to_str().unwrap(),
            ],
        ));
        let m = base.to_str().unwrap();
        let d = run_json(&args_with(
            "diagnose",
            &logs,
            &["--columns", &cols, "--model", m, "--json"],
        ));
        let best = &d["ranking"][0];
        assert_eq!(
            best["effect"], "asymmetry",
            "[{}] {}",
            rig.name, d["verdict"]
        );
        assert_eq!(best["significant"], true, "[{}] {}", rig.name, d["verdict"]);
        for (key, want) in [("tau_sf_pos_n", f_pos), ("tau_sf_neg_n", f_neg)] {
            let got = best["linear"][key]
                .as_f64()
                .unwrap_or_else(|| panic!("[{}] {best}", rig.name));
            within(&format!("{} diagnose {key}", rig.name), got, want, 0.15);
        }
        let saved = dir.path().join(format!("{}-asym.toml", rig.name));
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
        assert_eq!(v["unit"], "m/s", "[{}]", rig.name);
        let ladder = v["ladder"].as_array().unwrap();
        let (r0, r1) = (
            ladder[0]["rmse"].as_f64().unwrap(),
            ladder.last().unwrap()["rmse"].as_f64().unwrap(),
        );
        eprintln!("[{}] ladder rmse {r0:.4e} -> {r1:.4e} m/s", rig.name);
        assert!(r1 < 0.9 * r0, "[{}] ladder {r0} -> {r1}", rig.name);
        let held = v["save"]["measures"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["measure"] == "held_out")
            .unwrap_or_else(|| panic!("[{}] no held-out measure: {}", rig.name, v["save"]));
        let (b, a) = (
            held["before"].as_f64().unwrap(),
            held["after"].as_f64().unwrap(),
        );
        eprintln!("[{}] held-out {b:.4e} -> {a:.4e}", rig.name);
        assert!(a < b, "[{}] held-out {b} -> {a}", rig.name);
        assert_eq!(v["save"]["saved"], true, "[{}] {}", rig.name, v["save"]);
        let back = servo_cli::model_file::ModelFile::load(&saved).unwrap();
        assert_eq!(back.drive, rig.drive, "[{}]", rig.name);
    }
}

/// `servo run --plant` on the built-in simulator runs the plant file's drive (issue 27's
/// drives, beyond the logs a user brings): an experiment's open-loop `u` segments are the
/// drive's command in its unit; the MCAP log and the CSV hold it under its own name (`i_ref`, `duty`; no `u`), the
/// summary names it with its unit, and `servo identify` on the run's own MCAP log with the rig's
/// nominal params recovers the truth within 3 %, which holds only if the run applied what its
/// log says through the drive (the current clipped at its limit; the duty times the sagging
/// supply, less the dead time). A closed loop with gains designed on the drive's model tracks
/// its steps, its command within the drive's limit. `--voltage` on a current drive is refused
/// naming `--command`; `servo board` with such a plant is refused naming the drive.
#[test]
fn servo_run_simulates_each_drive_and_logs_its_command() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for rig in [current_rig(), duty_rig()] {
        let truth = d.join(format!("{}-truth.toml", rig.name));
        std::fs::write(&truth, true_base(&rig)).unwrap();
        let nominal = d.join(format!("{}-nominal.toml", rig.name));
        std::fs::write(&nominal, rig.params_toml("")).unwrap();
        let (signal, csv_col, unit) = match rig.drive.kind {
            DriveKind::Current => ("i_ref", "i_ref_A", " A"),
            _ => ("duty", "duty", " (fraction"),
        };
        // Open loop: a staircase of the drive's command (levels of both signs held 0.3 s), as
        // an experiment file's `u` segments.
        let log = d.join(format!("{}-open.mcap", rig.name));
        let csv = d.join(format!("{}-open.csv", rig.name));
        let exp = d.join(format!("{}-stairs.toml", rig.name));
        let levels = [
            0.3, -0.6, 0.9, -0.2, 0.5, -1.0, 0.7, -0.4, 0.15, -0.8, 1.0, -0.5, 0.6, -0.3, 0.8,
            -0.9, 0.4, -0.7, 0.2, -0.15,
        ];
        let mut text = String::new();
        for l in levels.iter().chain(&levels) {
            let c = l * 0.6 * rig.cmd_max;
            write!(text, "[[segment]]\nu = \"step:{c}\"\nduration_s = 0.3\n\n").unwrap();
        }
        std::fs::write(&exp, text).unwrap();
        let (ok, out, err) = servo(&[
            "run",
            "--plant",
            truth.to_str().unwrap(),
            "--experiment",
            exp.to_str().unwrap(),
            "--seed",
            "5",
            "--log",
            log.to_str().unwrap(),
            "--csv",
            csv.to_str().unwrap(),
        ]);
        assert!(ok, "[{}] servo run: {err}\n{out}", rig.name);
        assert!(
            out.contains(&format!("{signal} RMS")) && out.contains(unit),
            "[{}] the summary does not name the command: {out}",
            rig.name
        );
        let header = std::fs::read_to_string(&csv).unwrap();
        let header = header.lines().next().unwrap().to_string();
        let cols: Vec<&str> = header.split(',').collect();
        assert!(
            cols.contains(&csv_col) && !cols.contains(&"u_V"),
            "[{}] CSV header {header}",
            rig.name
        );
        let rec = servo_cli::io::read_log(&log, None).unwrap();
        assert!(rec.u_v.is_none(), "[{}] the MCAP log holds u", rig.name);
        let cmd = match rig.drive.kind {
            DriveKind::Current => rec.i_ref_a.as_ref(),
            _ => rec.duty.as_ref(),
        }
        .unwrap_or_else(|| panic!("[{}] no {signal} in the MCAP log", rig.name));
        let top = cmd.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        assert!(
            (top - 0.6 * rig.cmd_max).abs() < 1e-9,
            "[{}] largest command {top}",
            rig.name
        );
        let v = run_json(&[
            "identify",
            log.to_str().unwrap(),
            "--params",
            nominal.to_str().unwrap(),
            "--json",
        ]);
        let p = &rig.motor;
        for (key, want) in ["j_eq_kg_m2", "b_eq_n_m_s_rad", "tau_sf_n_m"].iter().zip([
            p.j_eq.unwrap(),
            p.b_eq.unwrap(),
            p.tau_sf.unwrap(),
        ]) {
            let got = v[key]["value"].as_f64().unwrap_or(f64::NAN);
            within(
                &format!("{} run -> identify {key}", rig.name),
                got,
                want,
                0.03,
            );
        }
        // Closed loop on gains designed for the drive's model.
        let gains = d.join(format!("{}-gains.toml", rig.name));
        let (ok, out, err) = servo(&[
            "design",
            "--model",
            truth.to_str().unwrap(),
            "--pm",
            "60",
            "--wc",
            "30",
            "-o",
            gains.to_str().unwrap(),
        ]);
        assert!(ok, "[{}] design: {err}\n{out}", rig.name);
        let closed = d.join(format!("{}-closed.mcap", rig.name));
        let (ok, out, err) = servo(&[
            "run",
            "--plant",
            truth.to_str().unwrap(),
            "--gains",
            gains.to_str().unwrap(),
            "--ref",
            "square:amp=1,period=2",
            "--duration",
            "4",
            "--log",
            closed.to_str().unwrap(),
        ]);
        assert!(ok, "[{}] closed loop: {err}\n{out}", rig.name);
        // The gains' unit is the controller's output's: amps on the current drive (its
        // reference), volts on the bridge (sent as volts over the supply).
        let text = std::fs::read_to_string(&gains).unwrap();
        let unit = match rig.drive.kind {
            DriveKind::Current => "A",
            _ => "V",
        };
        assert!(
            text.contains(&format!("# K_P [{unit}/rad]"))
                && out.contains(&format!(" {unit}/rad, K_I"))
                && out.contains(&format!("output limit +-10 {unit}")),
            "[{}] {text}\n{out}",
            rig.name
        );
        let rec = servo_cli::io::read_log(&closed, None).unwrap();
        let (th, rf) = (rec.theta_l_rad.unwrap(), rec.ref_rad.unwrap());
        let cmd = match rig.drive.kind {
            DriveKind::Current => rec.i_ref_a.unwrap(),
            _ => rec.duty.unwrap(),
        };
        for t_end in [0.95, 1.95, 2.95, 3.95] {
            let k = (t_end / 1e-3) as usize;
            assert!(
                (th[k] - rf[k]).abs() < 0.05,
                "[{}] at {t_end} s theta {} vs ref {}",
                rig.name,
                th[k],
                rf[k]
            );
        }
        let limit = match rig.drive.kind {
            // The loop's 10 (A) limit; the drive clips at i_limit_a itself.
            DriveKind::Current => 10.0,
            // 10 V of the 24 V supply.
            _ => 10.0 / 24.0,
        };
        assert!(
            cmd.iter().all(|c| c.abs() <= limit + 1e-9),
            "[{}] a command beyond {limit}",
            rig.name
        );
    }
    // --command: the current drive's reference in A, as the summary says.
    let truth = d.join("current-truth.toml");
    let (ok, out, err) = servo(&[
        "run",
        "--plant",
        truth.to_str().unwrap(),
        "--command",
        "step:1.5",
        "--duration",
        "0.5",
    ]);
    assert!(
        ok && out.contains("i_ref RMS            1.50 A"),
        "{err}\n{out}"
    );
    // Open loop without gains, the loop's range is the drive's (not an amplifier's 10 V):
    // duty 0.9 of the 24 V bridge (21.6 V) is applied whole, and 8 A are clipped at the
    // current drive's 5 A limit, as the summary says.
    let duty_truth = d.join("duty-truth.toml");
    for (plant, cmd, rms, sat) in [
        (
            &duty_truth,
            "step:0.9",
            "duty RMS             0.900",
            "saturation time      0 s",
        ),
        (
            &truth,
            "step:8",
            "i_ref RMS            5.00 A",
            "saturation time      0.200 s",
        ),
    ] {
        let (ok, out, err) = servo(&[
            "run",
            "--plant",
            plant.to_str().unwrap(),
            "--command",
            cmd,
            "--duration",
            "0.2",
        ]);
        assert!(
            ok && out.contains(rms) && out.contains(sat),
            "{cmd}: {err}\n{out}"
        );
    }
    // A current drive commanded by an analog voltage (k_i_a_per_v = 0.5 A/V): its command is
    // the voltage u, logged as u, and 2 V make 1 A.
    let analog = d.join("analog.toml");
    std::fs::write(
        &analog,
        std::fs::read_to_string(&truth)
            .unwrap()
            .replace("[drive]\n", "[drive]\nk_i_a_per_v = 0.5\n"),
    )
    .unwrap();
    let csv = d.join("analog.csv");
    let (ok, out, err) = servo(&[
        "run",
        "--plant",
        analog.to_str().unwrap(),
        "--voltage",
        "step:2",
        "--duration",
        "0.5",
        "--current-noise-a",
        "0",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(
        ok && out.contains("u RMS                2.00 V"),
        "{err}\n{out}"
    );
    let rec = servo_cli::io::read_log(&csv, None).unwrap();
    assert!(rec.i_ref_a.is_none() && rec.u_v.is_some());
    let i_end = *rec.i_a_a.unwrap().last().unwrap();
    assert!((i_end - 1.0).abs() < 1e-3, "2 V at 0.5 A/V gave {i_end} A");
    // --voltage on a current drive: refused, naming --command.
    let (ok, _, err) = servo(&[
        "run",
        "--plant",
        truth.to_str().unwrap(),
        "--voltage",
        "step:1",
    ]);
    assert!(
        !ok && err.contains("--command") && err.contains("current"),
        "{err}"
    );
    let (ok, _, err) = servo(&["board", "--pty", "--plant", truth.to_str().unwrap()]);
    assert!(
        !ok && err.contains("current") && err.contains("volts"),
        "{err}"
    );
}

/// `servo design`'s check through `servo run`'s loop runs the design plant's drive, as `servo
/// run --plant` does: on a current drive whose reference is clipped at 0.5 A (below what the
/// 2 rad step asks), the overshoot and settling the design reports for the 2 rad step at t = 0 are
/// what `servo run` then measures with the written gains (the check had run the equivalent
/// chain without the drive's clip, and reported another loop).
#[test]
fn design_checks_gains_through_the_drive_servo_run_simulates() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let truth = dir.path().join("clipped.toml");
    std::fs::write(
        &truth,
        "[params]\nk_t = 0.045\nj_m = 2.0e-5\nn = 8.0\nj_eq = 6.0e-5\nb_eq = 1.0e-5\n\
         tau_sf = 0.1\n\n[drive]\nkind = \"current\"\nbandwidth_hz = 300\ni_limit_a = 0.5\n",
    )
    .unwrap();
    let gains = dir.path().join("gains.toml");
    let v = run_json(&[
        "design",
        "--model",
        truth.to_str().unwrap(),
        "--overshoot",
        "0.1",
        "--settling-time",
        "0.5",
        "--step-min",
        "0.5",
        "--step-max",
        "2",
        "--json",
        "-o",
        gains.to_str().unwrap(),
        // the specs are missed on this clipped drive: the gains are written all the same
        "--force",
    ]);
    let log = dir.path().join("step.mcap");
    let case = v["run_check"]["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["start"] == "atstart" && c["step_rad"].as_f64() == Some(2.0))
        .unwrap_or_else(|| panic!("no 2 rad case: {}", v["run_check"]))
        .clone();
    let (ok, out, err) = servo(&[
        "run",
        "--plant",
        truth.to_str().unwrap(),
        "--gains",
        gains.to_str().unwrap(),
        "--ref",
        "step:2",
        "--duration",
        "5",
        "--log",
        log.to_str().unwrap(),
    ]);
    assert!(ok, "{err}\n{out}");
    eprintln!("design's check: {case}\nservo run: {out}");
    // `  overshoot (max)      22.7 % over 1 step(s)`: three significant digits.
    let run_os: f64 = out
        .lines()
        .find_map(|l| l.trim().strip_prefix("overshoot (max)"))
        .and_then(|r| r.split_whitespace().next())
        .and_then(|x| x.parse().ok())
        .unwrap_or_else(|| panic!("no overshoot in {out}"));
    let design_os = case["overshoot_pct"].as_f64().unwrap_or(f64::NAN);
    assert!(
        (design_os - run_os).abs() < 0.051 * (1.0 + run_os.abs() / 10.0),
        "design's check {case} vs servo run overshoot {run_os} %"
    );
    // The clip acts here: the loop's output sits at the drive's 0.5 A for a while.
    let rec = servo_cli::io::read_log(&log, None).unwrap();
    let asked = rec
        .i_ref_a
        .unwrap()
        .iter()
        .fold(0.0f64, |m, i| m.max(i.abs()));
    assert!(
        (asked - 0.5).abs() < 1e-9 && !out.contains("saturation time      0 s"),
        "the loop asked for {asked} A at most: the clip did not act\n{out}"
    );
}

/// A current drive's user output says the drive's own terms: gains in A/rad in the design and
/// in the run's controller line, never V/rad; no internal equivalent constant (the current
/// source's R_eq and k_drv of 500) given a value in the text of design, run, identify,
/// compare --add and diagnose; no number printed with more than 6 significant figures.
#[test]
fn a_current_drive_says_amps_and_no_internal_constants() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let p = |f: &str| dir.path().join(f).to_str().unwrap().to_string();
    let rig = current_rig();
    std::fs::write(p("truth.toml"), true_base(&rig)).unwrap();
    std::fs::write(p("drive.toml"), rig.params_toml("")).unwrap();
    let mut said = Vec::new();
    let mut ok = |args: &[&str]| -> String {
        let (ok, out, err) = servo(args);
        assert!(ok, "servo {args:?}: {err}\n{out}");
        said.push((args.join(" "), format!("{out}{err}")));
        out
    };
    let design = ok(&[
        "design",
        "--model",
        &p("drive.toml"),
        "--wc",
        "20",
        "--pm",
        "60",
        "-o",
        &p("g.toml"),
    ]);
    assert!(
        design.contains("A/rad") && !design.contains("V/rad"),
        "{design}"
    );
    let run = ok(&[
        "run",
        "--plant",
        &p("truth.toml"),
        "--gains",
        &p("g.toml"),
        "--ref",
        "square:amp=0.5,period=2",
        "--duration",
        "6",
        "--seed",
        "3",
        "--log",
        &p("cl.mcap"),
    ]);
    assert!(
        run.contains("K_P = ") && run.contains("A/rad") && !run.contains("V/rad"),
        "{run}"
    );
    ok(&[
        "run",
        "--plant",
        &p("truth.toml"),
        "--command",
        "prbs:amp=0.5,bit=0.3",
        "--duration",
        "8",
        "--seed",
        "4",
        "--log",
        &p("open.mcap"),
    ]);
    ok(&[
        "identify",
        &p("open.mcap"),
        "--params",
        &p("drive.toml"),
        "-o",
        &p("id.toml"),
    ]);
    ok(&[
        "compare",
        &p("cl.mcap"),
        &p("open.mcap"),
        "--model",
        &p("id.toml"),
        "--add",
        "imbalance",
    ]);
    ok(&[
        "diagnose",
        &p("cl.mcap"),
        &p("open.mcap"),
        "--model",
        &p("id.toml"),
    ]);
    let long = |w: &str| {
        let digits: String = w
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == '.')
            .collect();
        digits.contains('.') && digits.chars().filter(char::is_ascii_digit).count() > 12
    };
    for (cmd, text) in &said {
        for bad in [
            "R_eq =", "k_drv =", "R_eq,", "k_drv,", "500.0000", "500 ohm",
        ] {
            assert!(!text.contains(bad), "servo {cmd} says `{bad}`:\n{text}");
        }
        for w in text.split(|c: char| c.is_whitespace() || c == '(' || c == ',') {
            assert!(
                !long(w.trim_start_matches('-')),
                "servo {cmd} prints `{w}`:\n{text}"
            );
        }
    }
}
