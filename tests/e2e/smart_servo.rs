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
/// than BAM's published m1 on the same logs, with its gravity within 10 % of m g L, its inertia
/// at least the bob's m L^2; the torque-off phase of lift_and_drop is replayed as a free swing.
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
        // Fitted on the lower gain (the held-out logs saturate the PWM more), the gravity is
        // found within 10 %; fitted on kp 200 alone it trades off with the load-dependent
        // friction and k_t/R (printed, not asserted).
        if fit_kp == 100 {
            assert!(
                (p.gravity_nm / mgl - 1.0).abs() < 0.10,
                "m g L {} vs {mgl}",
                p.gravity_nm
            );
        }
        assert!(p.j_eq >= ml2, "J_eq {} below m L^2 {ml2}", p.j_eq);
        assert_eq!(f.candidates[f.kept].kind, FitKind::OutputError);
        // The whole fit's work is bounded (the time is printed above; under 10 s on two
        // idle cores).
        assert!(f.evaluations <= 3000 + 20);
        fitted.push(p);
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
