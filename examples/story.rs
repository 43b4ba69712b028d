//! The whole story as a library user tells it: simulate a gearmotor with a hidden imbalance,
//! identify the base model, compare it with the measurement, diagnose the missing effect, add it
//! and watch the error fall, then compensate it in the loop and watch the tracking error fall.
//! Run it with `cargo run --release --example story`.
use servo_core::compare::{compare, replay, CompareOptions, Measured, ReplayMode};
use servo_core::control::{
    EffectSelect, FeedforwardConfig, LoopCompensation, Pid, PidConfig, PidGains, Reference,
    SpeedEstimator,
};
use servo_core::diagnose::{diagnose, DiagnoseOptions};
use servo_core::effects::{Effect, EffectKind};
use servo_core::fit::{fit_model, EffectToFit, FitOptions};
use servo_core::sim::{sensors::SplitMix64, PlantSim, SensorConfig, Sensors};
use servo_core::{record::Record, Plant, PlantParams};

/// Model fit [%] on the load speed, replaying the logged voltage open loop.
fn fit_pct(model: &Plant, rec: &Record) -> Result<f64, Box<dyn std::error::Error>> {
    let m = Measured::from_record(rec, model.params.n, 50.0)?;
    let r = compare(
        &m,
        &replay(model, &m, ReplayMode::Speed, None)?,
        model.params.n,
        &CompareOptions::default(),
    );
    Ok(r.headline_signal().figures.fit_percent)
}

/// RMS tracking error [rad] of the handout's PID on `truth` following a 0.2 Hz sine of 1 rad for
/// 10 s, with the compensation `comp` (from the measured angle and speed).
fn tracking_rms(truth: &Plant, comp: &LoopCompensation) -> Result<f64, Box<dyn std::error::Error>> {
    let ts = 1e-3;
    let gains = PidGains {
        kp: 7.0476,
        ki: 86.121,
        kd: 0.14418,
        tl_s: 1.0 / 150.0,
    };
    let mut pid = Pid::new(PidConfig::new(gains, ts).with_symmetric_limit(comp.pid_limit_v(10.0)))?;
    let (mut sim, mut sensors) = (
        PlantSim::new(truth, ts)?,
        Sensors::new(SensorConfig::default()),
    );
    let mut speed = SpeedEstimator::new(2.0 * std::f64::consts::PI * 50.0, ts);
    let r = Reference::parse("sine:amp=1,freq=0.2")?;
    let mut sq = 0.0;
    for k in 0..10_000 {
        let t = k as f64 * ts;
        let theta = sensors.measure(sim.state()).theta_l_rad;
        let omega = speed.update(theta);
        let rs = r.at(t);
        sq += (rs.pos_rad - theta).powi(2);
        let ff = comp.feedforward(&rs, t, theta, omega).total_v;
        let u = comp.command_v(pid.update(rs.pos_rad, theta, ff).u_v, t, 10.0);
        sim.step(u);
    }
    Ok((sq / 10_000.0).sqrt())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // 1. simulate: Table 2 plant with a hidden 10 mN m imbalance, 12 s of random voltage steps
    let mut truth = Plant::from_params(PlantParams::TABLE2)?;
    truth
        .effects
        .insert(Effect::new(EffectKind::Imbalance, &[0.01, 0.5])?);
    let (dt, mut sim) = (1e-3, PlantSim::new(&truth, 1e-3)?);
    let (mut sensors, mut rng) = (Sensors::new(SensorConfig::default()), SplitMix64(7));
    let mut rec = Record {
        source: "examples/story.rs".into(),
        ..Record::default()
    };
    let (mut u, mut th, mut ia, mut uv) = (0.0, vec![], vec![], vec![]);
    for k in 0..12_000 {
        if k % 400 == 0 {
            u = (2.0 + 6.0 * rng.uniform()) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        }
        let meas = sensors.measure(sim.state());
        rec.time_s.push(k as f64 * dt);
        th.push(meas.theta_l_rad);
        ia.push(meas.i_a_a);
        uv.push(u);
        sim.step(u);
    }
    (rec.theta_l_rad, rec.i_a_a, rec.u_v) = (Some(th), Some(ia), Some(uv));
    let logs = [rec];
    // 2. identify the base model (J_eq, B_eq, tau_sf) by least squares on the log
    let base = fit_model(
        &logs,
        &Plant::from_params(PlantParams::TABLE2)?,
        &[],
        &FitOptions::default(),
    )?
    .plant;
    println!(
        "identify: J_eq = {:.3e} kg m^2 (truth {:.3e})",
        base.params.j_eq(),
        truth.params.j_eq()
    );
    // 3. compare the model with the measurement
    let before = fit_pct(&base, &logs[0])?;
    println!("compare: fit {before:.1} % on the load speed");
    // 4. diagnose: which catalogue effect is missing?
    let d = diagnose(&logs, &base, &DiagnoseOptions::default())?;
    let missing = d
        .winner()
        .ok_or("the diagnosis found nothing missing")?
        .effect;
    println!("diagnose: missing {}", missing.name());
    // 5. add it with a refit, and watch the error fall
    let added = fit_model(
        &logs,
        &base,
        &[EffectToFit::all(missing)],
        &FitOptions::default(),
    )?
    .plant;
    let after = fit_pct(&added, &logs[0])?;
    println!("add {}: fit {before:.1} % -> {after:.1} %", missing.name());
    assert!(
        missing == EffectKind::Imbalance && after > before,
        "the story did not end as told"
    );
    // 6. compensate it in the loop (`servo run --ff all`): the tracking error falls
    let linear = LoopCompensation::new(&added, FeedforwardConfig::FULL, EffectSelect::None, 0.0)?;
    let all = LoopCompensation::new(&added, FeedforwardConfig::FULL, EffectSelect::All, 0.0)?;
    let (e_lin, e_all) = (tracking_rms(&truth, &linear)?, tracking_rms(&truth, &all)?);
    println!(
        "compensate {}: tracking error RMS {e_lin:.2e} rad -> {e_all:.2e} rad ({:+.0} %)",
        missing.name(),
        100.0 * (e_all / e_lin - 1.0)
    );
    assert!(
        e_all < 0.5 * e_lin,
        "the compensation did not halve the error"
    );
    Ok(())
}
