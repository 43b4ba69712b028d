//! The controller of servo-core in closed loop on the simulator, and its feedforward against the
//! real lab measurements.

use servo_core::control::{
    AntiWindup, DerivativeOn, Feedforward, FeedforwardConfig, FeedforwardParams, Pid, PidConfig,
    PidGains, Reference,
};
use servo_core::sim::PlantSim;
use servo_core::{Plant, PlantParams};
use std::f64::consts::PI;

/// The Bode gains of the 2021 Padova run (realdata README), with T_L = 1/(3 omega_gc).
fn bode_gains() -> PidGains {
    PidGains {
        kp: 7.5244,
        ki: 94.0379,
        kd: 0.1505,
        tl_s: 1.0 / (3.0 * 10.0 * PI),
    }
}

/// Table 2 plus the identified friction of the 2021 motor (realdata SOURCE: J_eq = 7.35e-7,
/// B_eq = 7.17e-7, tau_sf = 9.71e-3).
fn plant() -> Plant {
    Plant::from_params(PlantParams {
        j_eq: Some(7.35e-7),
        b_eq: Some(7.17e-7),
        tau_sf: Some(9.71e-3),
        ..PlantParams::TABLE2
    })
    .expect("valid plant")
}

/// Runs `duration_s` of closed loop at 1 kHz; returns (RMS tracking error [rad], peak load angle
/// [rad], time saturated [s]).
fn run(
    reference: &Reference,
    cfg: PidConfig,
    ff: Option<&Feedforward>,
    duration_s: f64,
) -> (f64, f64, f64) {
    let plant = plant();
    let mut sim = PlantSim::new(&plant, cfg.ts_s).expect("sim");
    let mut pid = Pid::new(cfg).expect("pid");
    let n = (duration_s / cfg.ts_s).round() as usize;
    let (mut sq, mut peak, mut sat) = (0.0, f64::MIN, 0.0);
    for k in 0..n {
        let t = k as f64 * cfg.ts_s;
        let r = reference.at(t);
        let y = sim.state().theta_l_rad;
        sq += (r.pos_rad - y) * (r.pos_rad - y);
        peak = peak.max(y);
        let u_ff = ff.map_or(0.0, |f| f.for_sample(&r).total_v);
        let o = pid.update(r.pos_rad, y, u_ff);
        if o.saturated {
            sat += cfg.ts_s;
        }
        sim.step(o.u_v);
    }
    ((sq / n as f64).sqrt(), peak, sat)
}

#[test]
fn feedforward_cuts_the_tracking_error_of_a_trapezoid() {
    let _machine = servo_e2e::shared();
    // 2 rad in about 0.6 s: well within the 10 V of the driver input.
    let reference = Reference::parse("trap:distance=2,vmax=5,amax=40@0.1").expect("reference");
    // Derivative on the error: on the measurement, K_D would brake the reference motion by
    // K_D omega_ref and undo part of the feedforward.
    let cfg = PidConfig {
        derivative_on: DerivativeOn::Error,
        ..PidConfig::new(bode_gains(), 1e-3)
    }
    .with_symmetric_limit(10.0);
    let params = FeedforwardParams::from_plant(&plant());
    let full = Feedforward::new(params, FeedforwardConfig::FULL).expect("ff");
    let inertia = Feedforward::new(params, FeedforwardConfig::INERTIA).expect("ff");
    let (rms_fb, _, _) = run(&reference, cfg, None, 1.5);
    let (rms_inertia, _, _) = run(&reference, cfg, Some(&inertia), 1.5);
    let (rms_full, _, sat) = run(&reference, cfg, Some(&full), 1.5);
    println!("RMS tracking error: feedback {rms_fb:.2e} rad, +inertia ff {rms_inertia:.2e}, +full ff {rms_full:.2e}");
    assert_eq!(sat, 0.0, "the test profile must not saturate");
    assert!(
        rms_inertia < 0.7 * rms_fb,
        "inertia ff {rms_inertia} vs feedback {rms_fb}"
    );
    assert!(
        rms_full < 0.05 * rms_fb,
        "full ff {rms_full} vs feedback {rms_fb}"
    );
    assert!(
        rms_full < rms_inertia,
        "friction compensation should help: {rms_full} vs {rms_inertia}"
    );
}

#[test]
fn anti_windup_bounds_the_overshoot_of_a_saturating_step_on_the_simulator() {
    let _machine = servo_e2e::shared();
    let reference = Reference::step(2.0 * PI, 0.0); // 360 deg, the step that saturates on the real motor
    let base = PidConfig::new(bode_gains(), 1e-3).with_symmetric_limit(10.0);
    let overshoot = |aw: AntiWindup| {
        let (_, peak, sat) = run(
            &reference,
            PidConfig {
                anti_windup: aw,
                ..base
            },
            None,
            3.0,
        );
        (100.0 * (peak - 2.0 * PI) / (2.0 * PI), sat)
    };
    let (os_none, sat) = overshoot(AntiWindup::None);
    let (os_clamp, _) = overshoot(AntiWindup::Clamping);
    let (os_back, _) = overshoot(AntiWindup::BackCalculation { kw: 50.0 });
    println!("360 deg step: saturated {sat:.3} s; overshoot none {os_none:.1} %, clamping {os_clamp:.1} %, back-calculation {os_back:.1} %");
    assert!(sat > 0.1, "the step should saturate for long: {sat} s");
    assert!(os_none > 30.0, "windup overshoot {os_none} %");
    assert!(
        os_clamp < 0.5 * os_none,
        "clamping {os_clamp} % vs {os_none} %"
    );
    assert!(
        os_back < 0.5 * os_none,
        "back-calculation {os_back} % vs {os_none} %"
    );
}

/// On the real 2021 motor the position loop followed load-angle ramps at constant speeds
/// (friction_pos.csv). At steady state the integral action supplies exactly the voltage that
/// holds the speed, which the feedforward computes from the identified B_eq, tau_sf and the
/// nominal electrical constants: both must agree.
#[test]
fn feedforward_predicts_the_measured_steady_voltage_of_the_real_motor() {
    let _machine = servo_e2e::shared();
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
    let path = dir.join("padova2021-jacopisky/csv/friction_pos.csv");
    let text = std::fs::read_to_string(&path).expect("read friction_pos.csv");
    let mut rows: Vec<[f64; 4]> = Vec::new(); // t_s, ref_rad, u_V
    for line in text.lines().skip(1) {
        let f: Vec<f64> = line
            .split(',')
            .take(4)
            .map(|x| x.trim().parse().unwrap_or(f64::NAN))
            .collect();
        rows.push([f[0], f[2].to_radians(), f[3], 0.0]);
    }
    // Course parameter file: k_drv = 0.597802, k_t = 7.68128e-3, k_e = 7.6776e-3, R_eq = 3.1.
    let params = FeedforwardParams {
        j_eq: 7.35e-7,
        b_eq: 7.17e-7,
        tau_sf: 9.71e-3,
        r_eq: 3.1,
        k_t: 7.68128e-3,
        k_e: 7.6776e-3,
        k_drv: 0.597802,
        n: 14.0,
    };
    let ff = Feedforward::new(params, FeedforwardConfig::FULL).expect("ff");
    let mut checked = 0;
    for j in 0..9 {
        let (t0, t1) = (5.0 * j as f64 + 1.0, 5.0 * j as f64 + 4.9);
        let window: Vec<&[f64; 4]> = rows.iter().filter(|r| r[0] >= t0 && r[0] <= t1).collect();
        let (a, b) = (window[0], window[window.len() - 1]);
        let omega_l = (b[1] - a[1]) / (b[0] - a[0]);
        let u_meas = window.iter().map(|r| r[2]).sum::<f64>() / window.len() as f64;
        let u_ff = ff.voltage(omega_l, 0.0);
        println!("omega_l {omega_l:6.2} rad/s: measured {u_meas:.3} V, feedforward {u_ff:.3} V");
        assert!(
            (u_ff - u_meas).abs() < 0.03 * u_meas + 0.05,
            "at {omega_l} rad/s: ff {u_ff} V vs measured {u_meas} V"
        );
        checked += 1;
    }
    assert_eq!(checked, 9);
}

/// `experiments/steps.toml` reproduces the reference of the real Padova step run sample by sample
/// (the logged reference switches one 1 ms sample after the nominal instant).
#[test]
fn steps_recipe_matches_the_real_run_reference() {
    let _machine = servo_e2e::shared();
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
    let path = dir.join("padova2021-jacopisky/csv/pid_bode_steps.csv");
    let text = std::fs::read_to_string(&path).expect("read pid_bode_steps.csv");
    let recipe = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/steps.toml");
    let e = servo_cli::reference_file::load_experiment(&recipe).expect("steps.toml");
    let mut rows = 0;
    for line in text.lines().skip(1) {
        let f: Vec<f64> = line
            .split(',')
            .take(3)
            .map(|x| x.trim().parse().unwrap_or(f64::NAN))
            .collect();
        let (t, ref_deg) = (f[0], f[2]);
        let ours = match e.at(t - 1e-3) {
            servo_core::control::Setpoint::Position(r) => r.pos_rad.to_degrees(),
            other => panic!("{other:?}"),
        };
        assert!(
            (ours - ref_deg).abs() < 1e-9,
            "t = {t} s: recipe {ours} deg, real run {ref_deg} deg"
        );
        rows += 1;
    }
    assert!(rows > 25_000, "{rows} rows");
}
