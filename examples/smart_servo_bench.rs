//! The smart-servo bench: on Rhoban BAM's Dynamixel XL330 pendulum logs
//! (shared/realdata/bam-xl330), each firmware gain's logs fitted in turn and the other gain's
//! logs replayed in closed loop from goal_rad; the position MAE and RMSE of servo's fit beside
//! BAM's published m1 (model_published.toml) on the same held-out logs, and the fit's time.
//!
//! Two protocols: each gain's four logs fitted and the other gain's four replayed, and each
//! trajectory left out in turn (fitted on the six other logs of both gains).
//!
//! `cargo run --release --example smart_servo_bench` (SERVO_REALDATA overrides the data's place;
//! SM_LOAD=0 fits without the load-dependent gearbox friction).

use servo_core::smart::{self, PositionError, PositionLoop, SmartLog, SmartParams, SmartPrior};
use std::path::PathBuf;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let dir = match std::env::var_os("SERVO_REALDATA") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/realdata"),
    }
    .join("bam-xl330");
    if !dir.is_dir() {
        println!("SKIP: {} not found", dir.display());
        return Ok(());
    }
    let trajs = ["sin_sin", "lift_and_drop", "up_and_down", "sin_time_square"];
    let read = |kp: u32| -> anyhow::Result<Vec<(u32, SmartLog)>> {
        trajs
            .iter()
            .map(|t| {
                let p = dir.join(format!("csv/xl330_kp{kp}_{t}.csv"));
                Ok((kp, servo_io::smart_log::read_smart_csv(&p)?))
            })
            .collect()
    };
    let published = servo_io::model_file::ModelFile::load(&dir.join("model_published.toml"))?;
    let known = servo_io::model_file::ModelFile::load(&dir.join("params_known.toml"))?;
    let m1 = SmartParams::from_model(&published.params, &published.effects, 0.0);
    let kp_of = |l: &SmartLog| -> f64 {
        if l.name.contains("kp200") {
            200.0
        } else {
            100.0
        }
    };
    // BAM's firmware model: a constant 7.4 V, no latency.
    let bam_drive = |l: &SmartLog| PositionLoop::xl330(kp_of(l));
    // servo's: the measured supply.
    let envf = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let drive = |l: &SmartLog| PositionLoop {
        supply_from_log: true,
        ..PositionLoop::xl330(kp_of(l))
    };
    let kp = &known.params;
    let prior = SmartPrior {
        k_t_per_r: kp.k_t * kp.n / (kp.r_a + kp.r_s),
        k_e: kp.k_e * kp.n,
        j_min: kp.j_d,
        latency_max_s: 0.15,
        gravity_nm: Some(
            published
                .effects
                .value(servo_core::effects::EffectKind::Imbalance, "amplitude")
                .unwrap_or(f64::NAN),
        ),
        load_friction: envf("SM_LOAD", 1.0) > 0.5,
    };
    println!(
        "{:<10} {:<10} {:>10} {:>10} {:>10} {:>10} {:>8} {:>9} {:>9} {:>7}",
        "fit on",
        "held out",
        "m1 MAE",
        "m1 RMSE",
        "MAE",
        "RMSE",
        "fit s",
        "J_eq",
        "m g L",
        "lat ms"
    );
    let all: Vec<SmartLog> = read(100)?
        .into_iter()
        .chain(read(200)?)
        .map(|x| x.1)
        .collect();
    let mut folds: Vec<(String, Vec<SmartLog>, Vec<SmartLog>)> = Vec::new();
    for (fit_kp, held_kp) in [(100, 200), (200, 100)] {
        let tag = format!("kp{fit_kp}");
        let (f, h): (Vec<SmartLog>, Vec<SmartLog>) =
            all.iter().cloned().partition(|l| l.name.contains(&tag));
        folds.push((format!("kp {fit_kp} | kp {held_kp}"), f, h));
    }
    for t in trajs {
        let (h, f): (Vec<SmartLog>, Vec<SmartLog>) =
            all.iter().cloned().partition(|l| l.name.contains(t));
        folds.push((format!("all but {t}"), f, h));
    }
    let (mut pooled_m1, mut pooled_s) = (Vec::new(), Vec::new());
    for (label, fit_logs, held) in &folds {
        let (fit_logs, held) = (fit_logs.as_slice(), held.as_slice());
        let fit_kp = label;
        let held_kp = "";
        let base = PositionError::pooled(&smart::errors(&m1, &bam_drive, held)?);
        let t0 = Instant::now();
        let f = smart::fit(&prior, &drive, fit_logs, &[], 3000)?;
        let secs = t0.elapsed().as_secs_f64();
        let p = f.params();
        let e = PositionError::pooled(&smart::errors(&p, &drive, held)?);
        if !label.starts_with("kp") {
            pooled_m1.push(base);
            pooled_s.push(e);
        }
        println!(
            "{:<20} {:<0} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>8.2} {:>9.5} {:>9.4} {:>7.1}",
            fit_kp,
            held_kp,
            base.mae_rad * 1e3,
            base.rmse_rad * 1e3,
            e.mae_rad * 1e3,
            e.rmse_rad * 1e3,
            secs,
            p.j_eq,
            p.gravity_nm,
            p.latency_s * 1e3
        );
        for c in &f.candidates {
            println!(
                "    {:<15} fit RMSE {:>8.1} mrad  mu {:.3} J_eq {:.5} B_eq {:.4} tau_sf {:.4} k_t/R {:.4} m g L {:.4} phase {:.4} {}",
                c.kind.name(),
                c.fit_error.rmse_rad * 1e3,
                c.params.load_friction,
                c.params.j_eq,
                c.params.b_eq,
                c.params.tau_sf,
                c.params.k_t_per_r,
                c.params.gravity_nm,
                c.params.phase_rad,
                c.unphysical.join("; ")
            );
        }
        println!("    evaluations {}", f.evaluations);
    }
    let (a, b) = (
        PositionError::pooled(&pooled_m1),
        PositionError::pooled(&pooled_s),
    );
    println!(
        "leave one trajectory out, pooled: m1 MAE {:.1} RMSE {:.1} mrad, servo MAE {:.1} RMSE {:.1} mrad",
        a.mae_rad * 1e3,
        a.rmse_rad * 1e3,
        b.mae_rad * 1e3,
        b.rmse_rad * 1e3
    );
    Ok(())
}
