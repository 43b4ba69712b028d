//! Smart servos: the firmware's position loop as the drive, the torque-off phase replayed with
//! an open bridge, and the output-error fit on whole trajectories, on a smart servo simulated
//! here independently of servo's replay and on Rhoban BAM's real XL330 pendulum logs.

use servo_core::smart::{
    self, FitKind, PositionError, PositionLoop, SmartLog, SmartParams, SmartPrior,
};
use std::time::Instant;

const XL330_GAIN: f64 = 4096.0 / (2.0 * std::f64::consts::PI * 256.0 * 885.0);

fn kp_of(l: &SmartLog) -> f64 {
    if l.name.contains("kp200") {
        200.0
    } else {
        100.0
    }
}

/// On shared/realdata/bam-xl330: fitted on one firmware gain's logs and replayed in closed loop
/// from goal_rad on the other gain's, servo's model predicts the position better (MAE and RMSE)
/// than BAM's published m1 on the same logs, with the bob's m g L setting the torques' scale
/// (as in BAM) and its inertia at least the bob's m L^2; the torque-off phase of lift_and_drop is replayed as a free swing.
#[test]
fn xl330_held_out_logs_are_predicted_better_than_bam_m1() {
    let _machine = servo_e2e::shared();
    let Some(root) = servo_e2e::realdata_dir() else {
        return;
    };
    let dir = root.join("bam-xl330");
    let read = |kp: u32| -> Vec<SmartLog> {
        ["sin_sin", "lift_and_drop", "up_and_down", "sin_time_square"]
            .iter()
            .map(|t| {
                servo_io::smart_log::read_smart_csv(&dir.join(format!("csv/xl330_kp{kp}_{t}.csv")))
                    .unwrap()
            })
            .collect()
    };
    let published =
        servo_io::model_file::ModelFile::load(&dir.join("model_published.toml")).unwrap();
    let known = servo_io::model_file::ModelFile::load(&dir.join("params_known.toml")).unwrap();
    let m1 = SmartParams::from_model(&published.params, &published.effects, 0.0);
    let mgl = 0.49 * 9.80665 * 0.1;
    let ml2 = known.params.j_d;
    assert!((ml2 - 0.0049).abs() < 1e-12);
    let bam_drive = |l: &SmartLog| PositionLoop::xl330(kp_of(l));
    let drive = |l: &SmartLog| PositionLoop {
        supply_from_log: true,
        ..PositionLoop::xl330(kp_of(l))
    };
    assert!((PositionLoop::xl330(1.0).duty_per_rad_per_kp - XL330_GAIN).abs() < 1e-15);
    let k = &known.params;
    let prior = SmartPrior {
        k_t_per_r: k.k_t * k.n / (k.r_a + k.r_s),
        k_e: k.k_e * k.n,
        j_min: ml2,
        latency_max_s: 0.15,
        // The bench's m g L sets the torques' scale (positions alone do not), as in BAM.
        gravity_nm: Some(mgl),
        load_friction: true,
    };
    let mut fitted = Vec::new();
    for (fit_kp, held_kp) in [(100, 200), (200, 100)] {
        let fit_logs = read(fit_kp);
        let held = read(held_kp);
        let base = PositionError::pooled(&smart::errors(&m1, &bam_drive, &held).unwrap());
        let t0 = Instant::now();
        let f = smart::fit(&prior, &drive, &fit_logs, &[], 3000).unwrap();
        let secs = t0.elapsed().as_secs_f64();
        let p = f.params();
        let e = PositionError::pooled(&smart::errors(&p, &drive, &held).unwrap());
        eprintln!(
            "fit kp {fit_kp} ({secs:.2} s, {} replays), held out kp {held_kp}: m1 MAE {:.1} RMSE {:.1} mrad; servo MAE {:.1} RMSE {:.1} mrad; {p:?}",
            f.evaluations,
            base.mae_rad * 1e3,
            base.rmse_rad * 1e3,
            e.mae_rad * 1e3,
            e.rmse_rad * 1e3
        );
        assert!(e.mae_rad < base.mae_rad, "MAE {e:?} vs m1 {base:?}");
        assert!(e.rmse_rad < base.rmse_rad, "RMSE {e:?} vs m1 {base:?}");
        assert_eq!(p.gravity_nm, mgl);
        assert!(p.j_eq >= ml2, "J_eq {} below m L^2 {ml2}", p.j_eq);
        assert_eq!(f.candidates[f.kept].kind, FitKind::OutputError);
        // The whole fit's work is bounded (the time is printed above; under 10 s on two
        // idle cores).
        assert!(f.evaluations <= 3000 + 20);
        fitted.push(p);
    }
    // With k_t / R known (BAM's, params_known.toml) the gravity amplitude is fitted. With the
    // load-dependent friction the positions do not set the torques' scale against BAM's k_t / R
    // (the inertia goes to its bound): the fit must then say the gravity is not determined,
    // never print a wrong value as determined; where it says determined, the value is within
    // 10 % of the bob's m g L. In BAM's own model family (no load-dependent friction, where its
    // k_t / R belongs) the logs determine it.
    for (load_friction, fit_kp) in [(true, 100), (true, 200), (false, 100), (false, 200)] {
        let t0 = Instant::now();
        let free = SmartPrior {
            gravity_nm: None,
            load_friction,
            ..prior
        };
        let f = smart::fit(&free, &drive, &read(fit_kp), &[], 3000).unwrap();
        let secs = t0.elapsed().as_secs_f64();
        let p = f.params();
        eprintln!(
            "gravity fitted on kp {fit_kp}, load friction {load_friction} ({secs:.2} s, {} replays): m g L {:.4} N m ({:?}); {p:?}",
            f.evaluations, p.gravity_nm, f.gravity,
        );
        if f.gravity.determined() {
            assert!(
                (p.gravity_nm / mgl - 1.0).abs() < 0.10,
                "determined m g L {} vs {mgl}",
                p.gravity_nm
            );
        }
        assert!(p.j_eq >= ml2);
    }
    // The torque-off phase: after t = 2 s of lift_and_drop the arm swings freely; the model's
    // swing (open bridge, no back-EMF braking) follows the measured one far better than the
    // same model with the bridge kept driving.
    let drop = read(100).swap_remove(1);
    let off = drop
        .torque_enable
        .as_ref()
        .unwrap()
        .iter()
        .position(|e| !e)
        .unwrap();
    let p = fitted[1];
    let free = smart::replay(&p, &drive(&drop), &drop).unwrap();
    let driven = smart::replay(
        &p,
        &drive(&drop),
        &SmartLog {
            torque_enable: None,
            ..drop.clone()
        },
    )
    .unwrap();
    let e_free = PositionError::of(&free.theta_rad[off..], &drop.theta_rad[off..]);
    let e_driven = PositionError::of(&driven.theta_rad[off..], &drop.theta_rad[off..]);
    eprintln!("after the torque off: open bridge {e_free:?}, driven {e_driven:?}");
    assert!(free.duty[off..].iter().all(|d| *d == 0.0));
    assert!(e_free.rmse_rad < 0.5 * e_driven.rmse_rad);
}

/// A tiny generator of its own (the simulated family shares no code with servo).
struct Lcg(u64);
impl Lcg {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// One member of the simulated smart-servo family.
struct Member {
    truth: SmartParams,
    v_supply: f64,
    kp_fw: f64,
    gain: f64,
    /// The firmware's loop period in simulation steps of 0.1 ms.
    per_fw: usize,
    /// The host's polling jitter [s] (uniform, +/- this).
    jitter_s: f64,
}

/// A smart servo simulated here, independently of servo's replay: RK4 at 0.1 ms with a smooth
/// Coulomb friction growing with the motor's torque, the firmware's loop at its own rate holding
/// its duty between updates, a 12-bit (4096-count) encoder, the bus latency, gravity; the host
/// polls every 10 ms with jitter (it writes the goal and reads the angle at the jittered instant,
/// and logs them on the nominal grid; the firmware holds each goal until the next). The torque is
/// switched off at `drop_at_s` (an open bridge: no drive, no back-EMF braking).
fn simulate(
    m: &Member,
    rng: &mut Lcg,
    name: &str,
    goal: &dyn Fn(f64) -> f64,
    drop_at_s: Option<f64>,
) -> SmartLog {
    let p = m.truth;
    let h = 1e-4;
    let per_log = 100; // 10 ms
    let steps = 60_000; // 6 s
    let q = 2.0 * std::f64::consts::PI / 4096.0;
    let polls: Vec<f64> = (0..steps / per_log)
        .map(|k| (k as f64 * 0.01 + rng.uniform(-m.jitter_s, m.jitter_s)).max(0.0))
        .collect();
    let (mut th, mut w, mut d) = (0.0f64, 0.0f64, 0.0f64);
    let mut log = SmartLog {
        name: name.into(),
        omega_rad_s: Some(vec![0.0; polls.len()]),
        torque_enable: Some(vec![true; polls.len()]),
        time_s: (0..polls.len()).map(|k| k as f64 * 0.01).collect(),
        goal_rad: polls.iter().map(|&t| goal(t)).collect(),
        theta_rad: vec![0.0; polls.len()],
        ..SmartLog::default()
    };
    let mut next_poll = 0usize;
    for k in 0..steps {
        let t = k as f64 * h;
        let on = drop_at_s.is_none_or(|t_off| t < t_off);
        while next_poll < polls.len() && polls[next_poll] <= t {
            log.theta_rad[next_poll] = (th / q).round() * q;
            log.omega_rad_s.as_mut().unwrap()[next_poll] = w;
            log.torque_enable.as_mut().unwrap()[next_poll] = on;
            next_poll += 1;
        }
        if k % m.per_fw == 0 {
            // The goal the firmware holds: the last one written at least a latency ago.
            let seen = polls
                .iter()
                .rposition(|&tp| tp + p.latency_s <= t)
                .map_or(log.goal_rad[0], |i| log.goal_rad[i]);
            let th_q = (th / q).round() * q;
            d = (m.kp_fw * m.gain * (seen - th_q)).clamp(-1.0, 1.0);
        }
        let acc = |th: f64, w: f64| -> f64 {
            let motor = if on {
                p.k_t_per_r * (d * m.v_supply - p.k_e * w)
            } else {
                0.0
            };
            let coul = (p.tau_sf + p.load_friction * motor.abs()) * (w / 2e-3).tanh();
            (motor - p.b_eq * w - coul - p.gravity_nm * (th + p.phase_rad).sin()) / p.j_eq
        };
        let (k1t, k1w) = (w, acc(th, w));
        let (k2t, k2w) = (
            w + 0.5 * h * k1w,
            acc(th + 0.5 * h * k1t, w + 0.5 * h * k1w),
        );
        let (k3t, k3w) = (
            w + 0.5 * h * k2w,
            acc(th + 0.5 * h * k2t, w + 0.5 * h * k2w),
        );
        let (k4t, k4w) = (w + h * k3w, acc(th + h * k3t, w + h * k3w));
        th += h / 6.0 * (k1t + 2.0 * k2t + 2.0 * k3t + k4t);
        w += h / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w);
    }
    log
}

/// Ten members of the simulated family (each its own inertia, friction split, gravity, firmware
/// rate, gain, latency and host jitter): fitted on two logs (one with the torque switched off
/// half-way), servo's output-error fit finds the gravity amplitude within 5 % (k_t / R
/// given: it sets the torques' scale; the gravity is fitted and said to be determined; J_eq within
/// 10 %), the
/// friction at the servo's working torque within 15 %, the latency within a log period, and
/// predicts a third log it was not fitted on within a few mrad; the torque-off phase replays as a
/// free swing.
#[test]
fn a_simulated_smart_servo_family_is_identified_from_its_goal_positions() {
    let _machine = servo_e2e::shared();
    let sines = |t: f64| 0.9 * (1.3 * t).sin() + 0.4 * (4.1 * t).sin();
    let steps = |t: f64| [0.0, 0.8, -0.5, 1.2, -1.0, 0.3][((t / 1.0) as usize).min(5)];
    let lift = |t: f64| -1.2 * (t / 2.0).min(1.0);
    for seed in 1..=10u64 {
        let mut rng = Lcg(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let truth = SmartParams {
            j_eq: rng.uniform(0.006, 0.015),
            b_eq: rng.uniform(0.01, 0.03),
            tau_sf: rng.uniform(0.02, 0.06),
            load_friction: rng.uniform(0.1, 0.3),
            k_t_per_r: 0.1,
            k_e: 0.5,
            gravity_nm: rng.uniform(0.5, 1.0),
            phase_rad: rng.uniform(-0.15, 0.15),
            latency_s: rng.uniform(0.005, 0.04),
        };
        let m = Member {
            truth,
            v_supply: 12.0,
            kp_fw: rng.uniform(300.0, 500.0),
            gain: 3e-3,
            per_fw: [3usize, 5, 10][(rng.uniform(0.0, 3.0) as usize).min(2)],
            jitter_s: rng.uniform(0.0, 0.002),
        };
        let fit_logs = [
            simulate(&m, &mut rng, "sines", &sines, None),
            simulate(&m, &mut rng, "lift", &lift, Some(2.5)),
        ];
        let held = [simulate(&m, &mut rng, "steps", &steps, None)];
        let drive = |_: &SmartLog| PositionLoop {
            kp_fw: m.kp_fw,
            duty_per_rad_per_kp: m.gain,
            duty_limit: 1.0,
            v_supply_v: m.v_supply,
            supply_from_log: false,
            encoder_counts: Some(4096),
            period_s: 1e-3,
        };
        let prior = SmartPrior {
            k_t_per_r: truth.k_t_per_r,
            k_e: truth.k_e,
            j_min: 0.005,
            latency_max_s: 0.1,
            gravity_nm: None,
            load_friction: true,
        };
        let t0 = Instant::now();
        let f = smart::fit(&prior, &drive, &fit_logs, &held, 3000).unwrap();
        let secs = t0.elapsed().as_secs_f64();
        let p = f.params();
        let e = f.candidates[f.kept].held_out_error.unwrap();
        eprintln!(
            "seed {seed} ({secs:.2} s, {} replays): truth {truth:?}\n  fitted {p:?}\n  held out {e:?} gravity {:?}",
            f.evaluations, f.gravity
        );
        assert_eq!(f.candidates[f.kept].kind, FitKind::OutputError);
        assert!(f.gravity.determined(), "seed {seed}: {:?}", f.gravity);
        // The friction at the working torque (a quarter of the stall torque).
        let working = 0.25 * truth.k_t_per_r * m.v_supply;
        let fr = |q: &SmartParams| q.tau_sf + q.load_friction * working;
        for (name, got, want, tol) in [
            ("J_eq", p.j_eq, truth.j_eq, 0.10),
            ("m g L", p.gravity_nm, truth.gravity_nm, 0.05),
            ("friction at the working torque", fr(&p), fr(&truth), 0.15),
        ] {
            assert!(
                (got / want - 1.0).abs() < tol,
                "seed {seed}: {name}: {got} vs {want} (tolerance {tol})"
            );
        }
        assert!(
            (p.latency_s - truth.latency_s).abs() < 0.01,
            "seed {seed}: latency {} vs {}",
            p.latency_s,
            truth.latency_s
        );
        assert!(
            (p.phase_rad - truth.phase_rad).abs() < 0.02,
            "seed {seed}: phase {}",
            p.phase_rad
        );
        assert!(
            e.rmse_rad < 0.01,
            "seed {seed}: held-out RMSE {} rad",
            e.rmse_rad
        );
        // The torque-off phase of the lift log, replayed with the bridge open.
        let lift_log = &fit_logs[1];
        let off = (250..lift_log.time_s.len())
            .find(|&k| !lift_log.torque_enable.as_ref().unwrap()[k])
            .unwrap();
        let r = smart::replay(&p, &drive(lift_log), lift_log).unwrap();
        let e_off = PositionError::of(&r.theta_rad[off..], &lift_log.theta_rad[off..]);
        assert!(r.duty[off..].iter().all(|d| *d == 0.0));
        assert!(
            e_off.rmse_rad < 0.02,
            "seed {seed}: after the torque off {e_off:?}"
        );
    }
}

/// Through the CLI on shared/realdata/bam-xl330: `servo identify --drive position` on the kp 100
/// logs (the bench's m g L given, as BAM does) writes a smart servo's model (`[drive] kind = "position"`),
/// `servo compare` replays the kp 200 logs from their
/// goals with it and prints the position MAE beside the RMSE, both below BAM's published m1 on
/// the same logs; `servo inspect` guesses the smart-servo columns and never the supply as u.
#[test]
fn xl330_identify_and_compare_through_the_cli() {
    let _machine = servo_e2e::shared();
    let Some(root) = servo_e2e::realdata_dir() else {
        return;
    };
    let dir = root.join("bam-xl330");
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("xl330.toml");
    let csv = |kp: u32| -> Vec<String> {
        ["sin_sin", "lift_and_drop", "up_and_down", "sin_time_square"]
            .iter()
            .map(|t| {
                dir.join(format!("csv/xl330_kp{kp}_{t}.csv"))
                    .display()
                    .to_string()
            })
            .collect()
    };
    let params = dir.join("params_known.toml").display().to_string();
    let model_s = model.display().to_string();
    let mut args: Vec<&str> = vec!["identify"];
    let fit_logs = csv(100);
    args.extend(fit_logs.iter().map(String::as_str));
    args.extend([
        "--drive",
        "position",
        "--kp-fw",
        "100",
        "--params",
        &params,
        "--gravity-nm",
        "0.480526",
        "-o",
        &model_s,
        "--json",
    ]);
    let (ok, out, err) = servo_e2e::servo(&args);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let mgl = 0.49 * 9.80665 * 0.1;
    assert_eq!(v["gravity"]["status"], "given", "{v}");
    let g = v["gravity"]["value_n_m"].as_f64().unwrap();
    assert!((g / mgl - 1.0).abs() < 1e-4, "m g L {g} vs {mgl}");
    assert!(v["params"]["j_eq_kg_m2"].as_f64().unwrap() >= 0.0049);
    assert_eq!(v["kept"], "output error");
    assert!(v["fit_time_s"].as_f64().unwrap() < 30.0);
    let text = std::fs::read_to_string(&model).unwrap();
    assert!(
        text.contains("kind = \"position\"") && text.contains("[smart_servo]"),
        "{text}"
    );

    // The held-out kp 200 logs, replayed with the written model at their own gain.
    let held = csv(200);
    let mut args: Vec<&str> = vec!["compare"];
    args.extend(held.iter().map(String::as_str));
    args.extend(["--model", &model_s, "--kp-fw", "200"]);
    let (ok, text_out, err) = servo_e2e::servo(&args);
    assert!(ok, "{err}");
    assert!(
        text_out.contains("MAE") && text_out.contains("RMSE"),
        "{text_out}"
    );
    assert!(text_out.contains("open bridge"), "{text_out}");
    args.push("--json");
    let (ok, out, err) = servo_e2e::servo(&args);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let (mae, rmse) = (
        v["pooled"]["mae_rad"].as_f64().unwrap(),
        v["pooled"]["rmse_rad"].as_f64().unwrap(),
    );
    // BAM's m1 on the same held-out logs (its firmware model: 7.4 V, no latency).
    let published =
        servo_io::model_file::ModelFile::load(&dir.join("model_published.toml")).unwrap();
    let m1 = SmartParams::from_model(&published.params, &published.effects, 0.0);
    let logs: Vec<SmartLog> = held
        .iter()
        .map(|p| servo_io::smart_log::read_smart(std::path::Path::new(p)).unwrap())
        .collect();
    let base = PositionError::pooled(
        &smart::errors(&m1, &|_: &SmartLog| PositionLoop::xl330(200.0), &logs).unwrap(),
    );
    eprintln!(
        "CLI: held-out kp 200 MAE {:.1} RMSE {:.1} mrad; m1 {:.1} {:.1}",
        mae * 1e3,
        rmse * 1e3,
        base.mae_rad * 1e3,
        base.rmse_rad * 1e3
    );
    assert!(mae < base.mae_rad && rmse < base.rmse_rad);

    // inspect: the smart-servo columns guessed, the supply never as u.
    let (ok, out, err) = servo_e2e::servo(&["inspect", &held[0]]);
    assert!(ok, "{err}");
    for want in [
        "ref=goal_rad",
        "duty=duty",
        "v_supply=vin_meas_V",
        "enable=torque_enable",
    ] {
        assert!(out.contains(want), "{want}: {out}");
    }
    assert!(!out.contains(",u="), "{out}");
}

/// A BAM JSON log (jittered host timestamps, the firmware gain in the file) is read onto a
/// uniform grid, listed by `servo inspect`, and replayed by `servo compare` at its own gain; a
/// model file with `[drive] kind = "position"` and no `[smart_servo]` is refused with what to add.
#[test]
fn a_bam_json_log_is_read_inspected_and_compared() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let mut entries = Vec::new();
    for k in 0..400 {
        let t = k as f64 * 0.005 + if k % 3 == 1 { 0.0011 } else { 0.0 };
        let goal = 0.5 * (2.0 * t).sin();
        entries.push(serde_json::json!({
            "timestamp": 10.0 + t, "position": 0.9 * goal, "speed": 0.9 * (2.0 * t).cos(),
            "goal_position": goal, "load": 0.1, "input_volts": 7.4, "temp": 30,
            "torque_enable": k < 300,
        }));
    }
    let log = tmp.path().join("bam.json");
    std::fs::write(
        &log,
        serde_json::json!({"mass": 0.49, "length": 0.1, "kp": 150, "vin": 7.4, "motor": "xl330",
            "trajectory": "sin", "entries": entries})
        .to_string(),
    )
    .unwrap();
    let b = servo_io::bam_log::read_bam(&log).unwrap();
    assert_eq!(b.kp_fw, Some(150.0));
    let r = &b.record;
    assert!(r
        .time_s
        .windows(2)
        .all(|w| (w[1] - w[0] - 0.005).abs() < 1e-9));
    // Linear interpolation of a sine on a 5 ms grid: within its second-order error.
    for (t, g) in r.time_s.iter().zip(r.ref_rad.as_ref().unwrap()) {
        assert!((g - 0.5 * (2.0 * t).sin()).abs() < 1e-4, "t {t}: {g}");
    }
    let off = r
        .enable
        .as_ref()
        .unwrap()
        .iter()
        .filter(|e| **e == 0.0)
        .count();
    assert!((99..=101).contains(&off), "{off} rows off");
    let log_s = log.display().to_string();
    let (ok, out, err) = servo_e2e::servo(&["inspect", &log_s]);
    assert!(ok, "{err}");
    assert!(
        out.contains("BAM JSON") && out.contains("kp = 150"),
        "{out}"
    );
    assert!(out.contains("the supply, not u"), "{out}");

    let model = tmp.path().join("m.toml");
    let base = "[params]\nk_t = 0.3\nk_e = 0.3\nr_a = 4.8\nl_a = 1e-4\nn = 1.0\nj_m = 0.0016\nb_m = 0.0\nj_72 = 0.0\nj_d = 0.0049\nb_l = 0.0\nj_eq = 0.007\nb_eq = 0.01\ntau_sf = 0.01\n\n[effects.imbalance]\namplitude = 0.48\nphase = 0.0\n\n[drive]\nkind = \"position\"\nv_supply_v = 7.4\n";
    std::fs::write(&model, base).unwrap();
    let model_s = model.display().to_string();
    let (ok, _, err) = servo_e2e::servo(&["compare", &log_s, "--model", &model_s]);
    assert!(!ok && err.contains("[smart_servo]"), "{err}");
    std::fs::write(
        &model,
        format!("{base}\n[smart_servo]\nkp_fw = 100\nduty_per_rad_per_kp = 2.877378e-3\nlatency_s = 0.01\n"),
    )
    .unwrap();
    let (ok, out, err) = servo_e2e::servo(&["compare", &log_s, "--model", &model_s, "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["logs"][0]["kp_fw"], 150.0);
    assert_eq!(v["logs"][0]["torque_off_rows"].as_u64(), Some(off as u64));
    assert!(v["pooled"]["mae_rad"].as_f64().unwrap() > 0.0);
}
