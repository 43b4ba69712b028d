//! A second simulator family, independent of servo's physics: a two-mass drive train (motor
//! inertia, a compliant shaft with stiffness and damping, load inertia) with a dynamic friction
//! model on the load (LuGre: a bristle state z with pre-sliding and frictional lag), the
//! handout's electrical part (driver lag, armature inductance and resistance, back-EMF), a
//! quantised load encoder and a noisy current sensor, integrated with classic RK4 at 25 us.
//!
//! LuGre (Canudas de Wit et al. 1995), load side [N m, rad, rad/s]:
//!
//! ```text
//! dz/dt = v - sigma0 |v| z / g(v),  g(v) = Fc + (Fs - Fc) exp(-(v / vs)^2)
//! F     = sigma0 z + sigma1 dz/dt + sigma2 v
//! ```
//!
//! Its steady-state (sliding) curve is F_ss(v) = sign(v) g(v) + sigma2 v: exactly servo's
//! Coulomb + Stribeck + viscous shape ([`servo_core::effects`] `stribeck`: tau_c + (tau_s -
//! tau_c) exp(-(omega_l / omega_s)^2), load side), with tau_sf = Fc, tau_s = Fs, omega_s = vs,
//! and B_eq = b_m + sigma2 / N^2 (the load's viscous torque seen at the motor through the gear
//! of ratio N, as the torque balance k_t i_a = J_eq dw_m/dt + B_eq w_m + tau_l / N sees every
//! load torque). The bristles add what no catalogue effect has: pre-sliding (a spring of
//! stiffness sigma0 below breakaway, a micro-displacement of Fs / sigma0) and the lag of the
//! friction behind the speed.

use crate::diagnose::{
    assert_no_resonance, identified, pid_log, print_balances, print_ranking, record, DT,
};
use servo_core::diagnose::{self, DiagnoseOptions, Diagnosis, Status};
use servo_core::effects::EffectKind;
use servo_core::fit::Equation;
use servo_core::record::Record;
use servo_core::sim::excitation::{RandomSteps, ZeroRamps};
use servo_core::sim::sensors::SplitMix64;
use servo_core::PlantParams;
use std::time::Instant;

/// LuGre friction on the load [N m, rad, rad/s], see the module's doc.
#[derive(Debug, Clone, Copy)]
struct LuGre {
    /// Coulomb level Fc [N m].
    fc: f64,
    /// Breakaway (static) level Fs [N m].
    fs: f64,
    /// Stribeck speed vs [rad/s].
    vs: f64,
    /// Bristle stiffness sigma0 [N m/rad].
    sigma0: f64,
    /// Bristle damping sigma1 [N m s/rad].
    sigma1: f64,
    /// Viscous coefficient sigma2 [N m s/rad].
    sigma2: f64,
}

impl LuGre {
    fn g(&self, v: f64) -> f64 {
        self.fc + (self.fs - self.fc) * (-(v / self.vs) * (v / self.vs)).exp()
    }
    /// (dz/dt, F) at speed v and bristle state z.
    fn eval(&self, v: f64, z: f64) -> (f64, f64) {
        let dz = v - self.sigma0 * v.abs() * z / self.g(v);
        (dz, self.sigma0 * z + self.sigma1 * dz + self.sigma2 * v)
    }
}

/// The drive train: the handout's motor and driver (Table 2), J_eq split between the motor and
/// the load (`load_share`), a shaft whose first mode sits at `shaft_hz` (locked-free two-mass
/// mode), LuGre friction on the load, motor-side viscous friction.
#[derive(Debug, Clone, Copy)]
struct DriveTrain {
    /// Equivalent inertia at the motor J_eq = J_m + J_l / N^2 [kg m^2].
    j_eq: f64,
    /// Share of J_eq on the load side [1].
    load_share: f64,
    /// Frequency of the shaft's mode [Hz].
    shaft_hz: f64,
    /// Damping ratio of the shaft's mode [1].
    shaft_zeta: f64,
    /// Motor-side viscous friction [N m s/rad].
    b_m: f64,
    friction: LuGre,
    /// A load clamped on during each log: from this share of the log's length on [1], the load
    /// inertia grows by this share of J_eq (seen at the motor) [1].
    inertia_step: Option<(f64, f64)>,
}

impl DriveTrain {
    /// The null drive: J_eq 7e-7 kg m^2 half on the load, a 150 Hz shaft, B_eq 1e-6 N m s/rad
    /// (half of it the load's sigma2 / N^2), Coulomb 0.01 N m at the load with bristles
    /// (sigma0 = 10 N m/rad: pre-sliding of 1 mrad, two-thirds of an encoder count at the load),
    /// no Stribeck hump (Fs = Fc).
    fn null() -> DriveTrain {
        let n = PlantParams::TABLE2.n;
        DriveTrain {
            j_eq: 7.0e-7,
            load_share: 0.5,
            shaft_hz: 150.0,
            shaft_zeta: 0.05,
            b_m: 0.5e-6,
            friction: LuGre {
                fc: 0.01,
                fs: 0.01,
                vs: 0.5,
                sigma0: 10.0,
                sigma1: 0.01,
                sigma2: 0.5e-6 * n * n,
            },
            inertia_step: None,
        }
    }

    /// Open-loop (random voltage steps and ramps through zero, `open_s` seconds) and closed-loop
    /// (the PID of [`pid_log`], `closed_s` seconds) logs, noise and excitation drawn from `seed`.
    fn logs(&self, open_s: f64, closed_s: f64, seed: u64) -> Vec<Record> {
        let p = PlantParams::TABLE2;
        let (n, r, l, t_drv) = (p.n, p.r_eq(), p.l_a, p.t_drv());
        let j_m = self.j_eq * (1.0 - self.load_share);
        let j_l0 = self.j_eq * self.load_share * n * n;
        // Locked-free mode of the two masses (load side): w^2 = k (1 / J_l + 1 / (N^2 J_m)).
        let w = std::f64::consts::TAU * self.shaft_hz;
        let inv = 1.0 / j_l0 + 1.0 / (n * n * j_m);
        let k = w * w / inv;
        let c = 2.0 * self.shaft_zeta * (k / inv).sqrt();
        let fr = self.friction;
        // x = [u_drv, i_a, w_m, th_m, w_l, th_l, z]; time since the log's start t [s].
        let f = |x: &[f64; 7], u: f64, j_l: f64| -> [f64; 7] {
            let shaft = k * (x[3] / n - x[5]) + c * (x[2] / n - x[4]);
            let (dz, fric) = fr.eval(x[4], x[6]);
            [
                (p.k_drv * u - x[0]) / t_drv,
                (x[0] - r * x[1] - p.k_e * x[2]) / l,
                (p.k_t * x[1] - self.b_m * x[2] - shaft / n) / j_m,
                x[2],
                (shaft - fric) / j_l,
                x[4],
                dz,
            ]
        };
        let step = |x: &mut [f64; 7], u: f64, t: f64, length_s: f64| {
            let j_l = match self.inertia_step {
                Some((at, dj)) if t >= at * length_s => j_l0 + dj * self.j_eq * n * n,
                _ => j_l0,
            };
            let h = 25e-6;
            for _ in 0..(DT / h).round() as usize {
                let k1 = f(x, u, j_l);
                let a = |k: &[f64; 7], s: f64| core::array::from_fn(|i| x[i] + s * k[i]);
                let k2 = f(&a(&k1, h / 2.0), u, j_l);
                let k3 = f(&a(&k2, h / 2.0), u, j_l);
                let k4 = f(&a(&k3, h), u, j_l);
                for i in 0..7 {
                    x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
        };
        let cpr = 4096.0;
        let read = |x: &[f64; 7]| {
            (x[5] / std::f64::consts::TAU * cpr).floor() * std::f64::consts::TAU / cpr
        };
        let mut rng = SplitMix64(seed ^ 0x2_3A55);
        let mut out = Vec::new();
        let n_open = (open_s / DT) as usize;
        if n_open > 0 {
            let us = RandomSteps {
                ramps: Some(ZeroRamps {
                    probability: 0.25,
                    min_v: 3.0,
                    span_v: 3.0,
                }),
                ..RandomSteps::new(seed)
            }
            .voltages(n_open, DT);
            let mut x = [0.0; 7];
            let (mut t, mut th, mut ia) = (vec![], vec![], vec![]);
            for (kk, &u) in us.iter().enumerate() {
                let tk = kk as f64 * DT;
                t.push(tk);
                th.push(read(&x));
                ia.push(x[1] + 2e-3 * rng.normal());
                step(&mut x, u, tk, open_s);
            }
            out.push(record(t, th, ia, us, None, "two-mass open-loop"));
        }
        let n_closed = (closed_s / DT) as usize;
        if n_closed > 0 {
            let x = core::cell::RefCell::new([0.0; 7]);
            let kk = core::cell::Cell::new(0usize);
            out.push(pid_log(
                n_closed,
                &mut rng,
                |rng| {
                    let x = x.borrow();
                    (read(&x), x[1] + 2e-3 * rng.normal())
                },
                |u| {
                    let tk = kk.get() as f64 * DT;
                    kk.set(kk.get() + 1);
                    step(&mut x.borrow_mut(), u, tk, closed_s);
                },
                "two-mass closed-loop",
            ));
        }
        out
    }
}

/// Identifies the base model on the open-loop log and diagnoses every log; prints the ranking,
/// the balances and the verdict, tagged, and the time taken.
fn diagnose_drive(logs: &[Record], tag: &str) -> Diagnosis {
    let t0 = Instant::now();
    let model = identified(logs);
    let d = diagnose::diagnose(logs, &model, &DiagnoseOptions::default()).unwrap();
    print_ranking(tag, &d, 4);
    print_balances(tag, &d);
    eprintln!(
        "[{tag}] {:?} in {:.1} s: {}",
        d.status,
        t0.elapsed().as_secs_f64(),
        d.verdict
    );
    d
}

/// Null case: LuGre without a hump (Fs = Fc: Coulomb, viscous and bristle dynamics), 24 s of
/// logs (12 s open loop, 12 s closed loop), stiff and soft bristles: the viscous + Coulomb model
/// is complete, and no balance names a resonance (the shaft's mode, 150 Hz, is above every band
/// scanned). Seed 66 with stiff bristles rang at 14 Hz in a torque balance 1.3 times its floor
/// (a pre-sliding ringing), named a resonance before a complete balance could name none. Seeds
/// 72 and 73 with soft bristles (not tuned on: found at stop 42) named a gear play of 9-11 mrad,
/// twice the pre-sliding travel, until a play had to show the motor crossing its gap in the
/// electrical balance.
#[test]
fn two_mass_lugre_without_hump_is_complete() {
    let _machine = servo_e2e::shared();
    for (sigma0, seed) in [(10.0, 61), (2.0, 61), (10.0, 66), (2.0, 72), (2.0, 73)] {
        let tag = format!("two-mass null sigma0 {sigma0} seed {seed}");
        let mut drive = DriveTrain::null();
        drive.friction.sigma0 = sigma0;
        let logs = drive.logs(12.0, 12.0, seed);
        let d = diagnose_drive(&logs, &tag);
        assert_no_resonance(&tag, &d);
        assert_eq!(d.status, Status::Complete, "[{tag}] {}", d.verdict);
        assert!(d.changes.is_empty());
    }
}

/// A Stribeck hump in the LuGre steady-state curve (Fs = 0.02 N m over Fc = 0.01 N m, vs = 0.5
/// rad/s, load side) is named `stribeck`, with tau_s (= Fs, see the module's doc) within 25 %:
/// with stiff bristles (sigma0 = 10 N m/rad: pre-sliding of Fs / sigma0 = 2 mrad, 1.3 counts of
/// the load encoder) and with soft ones (sigma0 = 2 N m/rad: 10 mrad, 6.5 counts, where the
/// pre-sliding regime near reversals must be judged apart or it hides the hump).
#[test]
fn two_mass_lugre_stribeck_hump_is_named() {
    let _machine = servo_e2e::shared();
    for (sigma0, seed) in [(10.0, 62), (2.0, 62)] {
        let tag = format!("two-mass stribeck sigma0 {sigma0}");
        let mut drive = DriveTrain::null();
        drive.friction.fs = 0.02;
        drive.friction.sigma0 = sigma0;
        let logs = drive.logs(12.0, 12.0, seed);
        let d = diagnose_drive(&logs, &tag);
        let w = d
            .winner()
            .unwrap_or_else(|| panic!("[{tag}] nothing named: {:?}: {}", d.status, d.verdict));
        assert_eq!(w.effect, EffectKind::Stribeck, "[{tag}] {}", d.verdict);
        let tau_s = w.params.iter().find(|p| p.key == "tau_s").unwrap().value;
        eprintln!(
            "[{tag}] tau_s {tau_s:.4} N m (true {}), pre-sliding left out: {:?}",
            drive.friction.fs, d.presliding
        );
        assert!(
            (tau_s / drive.friction.fs - 1.0).abs() < 0.25,
            "[{tag}] tau_s {tau_s} against {}",
            drive.friction.fs
        );
    }
}

/// Three hump cases found by running the hump test on more seeds (not tuned on): at stop 45,
/// with stiff bristles, seed 81 named "missing cogging" of 34 cycles per motor revolution (a
/// residual of the closed loop's reversals, at fixed angles: the same on both halves, with
/// another phase in the open-loop log); with soft ones, seed 79 read "complete" while its torque
/// balance stood 3.4 times its floor and a Stribeck removed 18.5 % of its held-out residual (the
/// bristles' reversals held the rest); at stop 51, with bristles of 3 N m/rad, seed 196 read
/// "unexplained" with the hump (0.48 rad/s, inside the breakaway's search range) and not a word
/// on the Stribeck that fitted it (tau_s 0.019 N m) and made the held-out simulation 5.9 %
/// worse. None may name a torque of the angle, nor be complete: a Stribeck named has tau_s
/// within 25 %, and "unexplained" says what carries the residual and why the breakaway the hump
/// calls for was refused.
#[test]
fn two_mass_hump_is_neither_an_angle_locked_torque_nor_complete() {
    let _machine = servo_e2e::shared();
    for (sigma0, seed) in [(10.0, 81), (2.0, 79), (3.0, 196)] {
        let tag = format!("two-mass hump sigma0 {sigma0} seed {seed}");
        let mut drive = DriveTrain::null();
        drive.friction.fs = 0.02;
        drive.friction.sigma0 = sigma0;
        let logs = drive.logs(12.0, 12.0, seed);
        let d = diagnose_drive(&logs, &tag);
        assert_ne!(d.status, Status::Complete, "[{tag}] {}", d.verdict);
        for c in d.ranking.iter().filter(|c| c.significant) {
            assert!(
                !c.effect.model().depends_on_angle_only(),
                "[{tag}] {} named: {}",
                c.effect,
                d.verdict
            );
        }
        match d.winner() {
            Some(w) => {
                assert_eq!(w.effect, EffectKind::Stribeck, "[{tag}] {}", d.verdict);
                let tau_s = w.params.iter().find(|p| p.key == "tau_s").unwrap().value;
                assert!(
                    (tau_s / drive.friction.fs - 1.0).abs() < 0.25,
                    "[{tag}] {tau_s}"
                );
            }
            None => {
                let torque = d
                    .unexplained
                    .iter()
                    .find(|b| b.equation == Equation::Torque)
                    .unwrap_or_else(|| panic!("[{tag}] no torque balance left: {}", d.verdict));
                let first = torque
                    .signatures
                    .first()
                    .unwrap_or_else(|| panic!("[{tag}] no shape named: {}", d.verdict));
                assert!(
                    first.kind == "friction_curve" || first.kind == "partial_effect",
                    "[{tag}] first shape {}: {}",
                    first.kind,
                    first.description
                );
                assert!(
                    first.description.contains("hump") || first.description.contains("stribeck"),
                    "[{tag}] {}",
                    first.description
                );
                // A hump the catalogue's breakaway could take says why that one was refused
                // (seed 196, found at stop 51: the hump's words promised it, and the verdict
                // said nothing of the Stribeck the held-out simulation refused).
                if first.description.contains("so the verdict says why") {
                    assert!(
                        d.sliding_fit.is_some()
                            || d.verdict
                                .contains("The breakaway friction the hump calls for"),
                        "[{tag}] {}",
                        d.verdict
                    );
                }
            }
        }
    }
}

/// The hump with soft bristles at seeds 67 and 68 (not tuned on: found at stop 40 ending
/// "unexplained" without a word on the hump): on the sliding rows a Stribeck fits the measured
/// curve within 25 % of the true breakaway level, but the static stick-slip simulation with it
/// predicts the reversals worse than without (the bristles creep through the pre-sliding travel).
/// The verdict stays "unexplained" and says so, with the fitted steady-state curve; the joint
/// search is not run (no catalogue effect simulates bristles).
#[test]
fn two_mass_lugre_soft_hump_the_simulation_cannot_carry_is_reported() {
    let _machine = servo_e2e::shared();
    for seed in [67, 68] {
        let tag = format!("two-mass soft hump seed {seed}");
        let mut drive = DriveTrain::null();
        drive.friction.fs = 0.02;
        drive.friction.sigma0 = 2.0;
        let logs = drive.logs(12.0, 12.0, seed);
        let d = diagnose_drive(&logs, &tag);
        assert_eq!(d.status, Status::Unexplained, "[{tag}] {}", d.verdict);
        let lead = d
            .sliding_fit
            .as_ref()
            .unwrap_or_else(|| panic!("[{tag}] no sliding-rows lead: {}", d.verdict));
        assert_eq!(lead.candidate.effect, EffectKind::Stribeck, "[{tag}]");
        let tau_s = lead
            .candidate
            .params
            .iter()
            .find(|p| p.key == "tau_s")
            .unwrap()
            .value;
        eprintln!("[{tag}] tau_s {tau_s:.4} N m (true {})", drive.friction.fs);
        assert!(
            (tau_s / drive.friction.fs - 1.0).abs() < 0.25,
            "[{tag}] tau_s {tau_s}"
        );
        assert!(
            d.verdict.contains("fits the measured friction curve")
                && d.verdict
                    .contains("simulating it makes the held-out prediction"),
            "[{tag}] {}",
            d.verdict
        );
        // Through the command, on CSV logs and the handout's nominal model: the same lead
        // under `sliding_fit` in --json (validated against docs/schemas/diagnose.json).
        let dir = tempfile::tempdir().unwrap();
        let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
        let (ok, params, err) = servo_e2e::servo(&["params"]);
        assert!(ok, "{err}");
        std::fs::write(p("model.toml"), params).unwrap();
        for (k, r) in logs.iter().enumerate() {
            crate::diagnose::write_csv(std::path::Path::new(&p(&format!("log{k}.csv"))), r);
        }
        let (ok, out, err) = servo_e2e::servo(&[
            "diagnose",
            &p("log0.csv"),
            &p("log1.csv"),
            "--model",
            &p("model.toml"),
            "--json",
        ]);
        assert!(ok, "[{tag}] servo diagnose failed: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["status"], "unexplained", "[{tag}] {}", v["verdict"]);
        let s = &v["sliding_fit"];
        assert_eq!(s["effect"], "stribeck", "[{tag}] {}", v["verdict"]);
        let tau_s = s["params"]["tau_s"]["value"].as_f64().unwrap();
        assert!(
            (tau_s / drive.friction.fs - 1.0).abs() < 0.25,
            "[{tag}] servo diagnose: tau_s {tau_s}"
        );
        assert!(s["held_out_simulation_drop_pct"].as_f64().unwrap() < 1.0);
    }
}

/// Null case on 10 minutes of logs (5 min open loop, 5 min closed loop, one seed): complete;
/// the plant does not change, so no change of the base parameters is reported.
#[test]
fn two_mass_lugre_without_hump_is_complete_on_ten_minutes() {
    let _machine = servo_e2e::shared();
    let logs = DriveTrain::null().logs(300.0, 300.0, 64);
    let d = diagnose_drive(&logs, "two-mass null 10 min");
    assert_no_resonance("two-mass null 10 min", &d);
    assert_eq!(d.status, Status::Complete, "{}", d.verdict);
}

/// A load clamped on halfway through each log (the load inertia grows by 12 % of J_eq, so J_eq
/// rises 12 %, at 6.0 s of both 12-s logs): "unexplained", with a change signature whose time
/// is within 1 s of the true one.
#[test]
fn two_mass_inertia_change_mid_log_is_unexplained_with_its_time() {
    let _machine = servo_e2e::shared();
    let drive = DriveTrain {
        inertia_step: Some((0.5, 0.12)),
        ..DriveTrain::null()
    };
    let logs = drive.logs(12.0, 12.0, 65);
    let d = diagnose_drive(&logs, "two-mass J step");
    assert_eq!(d.status, Status::Unexplained, "{}", d.verdict);
    for (log, rec) in logs.iter().enumerate() {
        let t_true = 0.5 * rec.time_s.last().unwrap();
        let c = d
            .changes
            .iter()
            .find(|c| c.log == log)
            .unwrap_or_else(|| panic!("no change found in log {}: {}", log + 1, d.verdict));
        eprintln!(
            "[two-mass J step] log {}: {} (true: J_eq +12 % at {t_true:.2} s)",
            log + 1,
            c.phrase()
        );
        assert!((c.time_s - t_true).abs() < 1.0, "{}", c.phrase());
        assert_eq!(c.params[0].name, "J_eq", "{}", c.phrase());
        // The signature is the balance's first, in the verdict.
        assert!(d
            .unexplained
            .iter()
            .any(|b| b.signatures.first().is_some_and(|s| s.kind == "change")));
    }
}

/// Writes the two-mass family's logs of the diagnose benchmark
/// (`crates/servo-cli/benches/diagnose_other_sim.sh`) to `$OTHER_OUT/hump_SEED_{open,closed}.csv`:
/// a LuGre friction with a Stribeck hump (Fs 0.02 N m, bristles of 3 N m/rad: seed 196 reads
/// "unexplained"), 16 s open loop and 12 s closed loop per seed, for the seeds of
/// [`crate::diagnose::bench_out_and_seeds`].
#[test]
#[ignore = "writes the two-mass family's logs to $OTHER_OUT for the diagnose benchmark"]
fn write_two_mass_logs() {
    let _machine = servo_e2e::shared();
    let (out, seeds) = crate::diagnose::bench_out_and_seeds();
    let mut drive = DriveTrain::null();
    drive.friction.fs = 0.02;
    drive.friction.sigma0 = 3.0;
    for seed in seeds {
        for (log, part) in drive.logs(16.0, 12.0, seed).iter().zip(["open", "closed"]) {
            crate::diagnose::write_csv(&out.join(format!("hump_{seed}_{part}.csv")), log);
        }
    }
}
