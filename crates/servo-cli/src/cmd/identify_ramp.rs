//! `servo identify --ramp`: the identification experiments of the handout run on a backend.
//!
//! * friction (4.1): a closed-loop speed staircase (recipe `experiments/identify_friction.toml`,
//!   built into the binary; `--friction-recipe FILE` overrides it);
//! * inertia (4.2): constant acceleration/deceleration ramps (`experiments/identify_inertia.toml`,
//!   likewise).
//!
//! Both run on any backend: the simulator or a board over serial.
//!
//! The speed loop is a PI on the motor speed (differentiated encoder angle, first-order filtered)
//! with a back-EMF and inertia feedforward from the nominal parameters, designed for a 50 rad/s
//! crossover on the reduced model k_m / (T_m s + 1); it talks to the [`Backend`] trait directly.

use anyhow::{bail, Context};
use servo_core::record::Record;
use servo_core::PlantParams;
use servo_hw::backend::Backend;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::identify::Identify;
use crate::io::{LoopMsg, McapLog, McapLogOptions};

/// Friction staircase recipe.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionRecipe {
    /// Constant motor speeds [rad/s].
    pub speeds_rad_s: Vec<f64>,
    /// Time at each speed [s].
    pub step_duration_s: f64,
    /// Positive then negative staircase.
    #[serde(default = "yes")]
    pub both_directions: bool,
    /// Rest before each direction [s].
    #[serde(default = "one")]
    pub rest_s: f64,
}

/// Inertia ramps recipe.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InertiaRecipe {
    /// Acceleration magnitude [rad/s^2].
    pub accel_rad_s2: f64,
    /// Peak motor speed [rad/s].
    pub peak_speed_rad_s: f64,
    /// Lowest motor speed of a cycle [rad/s].
    #[serde(default)]
    pub base_speed_rad_s: f64,
    /// Up/down cycles.
    pub cycles: u32,
    /// Rest before the first cycle [s].
    #[serde(default = "half")]
    pub rest_s: f64,
}

fn yes() -> bool {
    true
}
fn one() -> f64 {
    1.0
}
fn half() -> f64 {
    0.5
}

/// The built-in friction recipe (experiments/identify_friction.toml at build time).
pub const FRICTION_RECIPE: &str = include_str!("../../../../experiments/identify_friction.toml");
/// The built-in inertia recipe (experiments/identify_inertia.toml at build time).
pub const INERTIA_RECIPE: &str = include_str!("../../../../experiments/identify_inertia.toml");
/// How the built-in recipes are named in messages and log metadata.
const BUILT_IN: &str = "built-in";

fn load_toml<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> anyhow::Result<T> {
    let text = if path == Path::new(BUILT_IN) {
        match what {
            "friction" => FRICTION_RECIPE.to_string(),
            _ => INERTIA_RECIPE.to_string(),
        }
    } else {
        std::fs::read_to_string(path)
            .with_context(|| format!("reading {what} recipe {}", path.display()))?
    };
    toml::from_str(&text).with_context(|| format!("in {what} recipe {}", path.display()))
}

impl FrictionRecipe {
    pub fn load(path: &Path) -> anyhow::Result<FrictionRecipe> {
        let r: FrictionRecipe = load_toml(path, "friction")?;
        if r.speeds_rad_s.is_empty() || r.speeds_rad_s.iter().any(|w| !(w.is_finite() && *w > 0.0))
        {
            bail!(
                "{}: speeds_rad_s must be a non-empty list of positive motor speeds [rad/s]",
                path.display()
            );
        }
        if !(r.step_duration_s >= 1.0 && r.step_duration_s.is_finite()) {
            bail!(
                "{}: step_duration_s must be >= 1 s (the estimator needs settled segments), got {}",
                path.display(),
                r.step_duration_s
            );
        }
        if !(r.rest_s >= 0.0 && r.rest_s.is_finite()) {
            bail!(
                "{}: rest_s must be >= 0 s, got {}",
                path.display(),
                r.rest_s
            );
        }
        Ok(r)
    }
    /// Length of the staircase [s].
    pub fn duration_s(&self) -> f64 {
        let one_dir = self.rest_s + self.step_duration_s * self.speeds_rad_s.len() as f64;
        one_dir * if self.both_directions { 2.0 } else { 1.0 }
    }
    /// Speed reference [rad/s] at time `t` [s]; None after the end.
    pub fn reference(&self, t: f64) -> Option<f64> {
        let one_dir = self.rest_s + self.step_duration_s * self.speeds_rad_s.len() as f64;
        let dirs = if self.both_directions { 2.0 } else { 1.0 };
        if t >= one_dir * dirs {
            return None;
        }
        let sign = if t < one_dir { 1.0 } else { -1.0 };
        let tt = t % one_dir - self.rest_s;
        if tt < 0.0 {
            return Some(0.0);
        }
        let k = ((tt / self.step_duration_s) as usize).min(self.speeds_rad_s.len() - 1);
        Some(sign * self.speeds_rad_s[k])
    }
}

impl InertiaRecipe {
    pub fn load(path: &Path) -> anyhow::Result<InertiaRecipe> {
        let r: InertiaRecipe = load_toml(path, "inertia")?;
        if !(r.accel_rad_s2 > 0.0 && r.accel_rad_s2.is_finite()) {
            bail!(
                "{}: accel_rad_s2 must be > 0 rad/s^2, got {}",
                path.display(),
                r.accel_rad_s2
            );
        }
        if !(r.peak_speed_rad_s > r.base_speed_rad_s
            && r.base_speed_rad_s >= 0.0
            && r.peak_speed_rad_s.is_finite())
        {
            bail!(
                "{}: need 0 <= base_speed_rad_s < peak_speed_rad_s",
                path.display()
            );
        }
        if r.cycles < 2 {
            bail!("{}: cycles must be >= 2 (eq. 69 averages over pairs; one pair gives no uncertainty)", path.display());
        }
        Ok(r)
    }
    /// Length of the ramps [s] (rest, run-up to the base speed, cycles).
    pub fn duration_s(&self) -> f64 {
        let half = (self.peak_speed_rad_s - self.base_speed_rad_s) / self.accel_rad_s2;
        self.rest_s + self.base_speed_rad_s / self.accel_rad_s2 + 2.0 * half * self.cycles as f64
    }
    /// (speed [rad/s], acceleration [rad/s^2]) reference at `t`; None after the end.
    pub fn reference(&self, t: f64) -> Option<(f64, f64)> {
        let half = (self.peak_speed_rad_s - self.base_speed_rad_s) / self.accel_rad_s2;
        // Reach the base speed first (at the same acceleration), then cycle.
        let lead = self.base_speed_rad_s / self.accel_rad_s2;
        let t = t - self.rest_s;
        if t < 0.0 {
            return Some((0.0, 0.0));
        }
        if t < lead {
            return Some((self.accel_rad_s2 * t, self.accel_rad_s2));
        }
        let tc = t - lead;
        if tc >= 2.0 * half * self.cycles as f64 {
            return None;
        }
        let p = tc % (2.0 * half);
        if p < half {
            Some((
                self.base_speed_rad_s + self.accel_rad_s2 * p,
                self.accel_rad_s2,
            ))
        } else {
            Some((
                self.peak_speed_rad_s - self.accel_rad_s2 * (p - half),
                -self.accel_rad_s2,
            ))
        }
    }
}

/// Closed-loop speed control of `backend` following `reference(t) -> (w_ref, a_ref)` until it
/// returns None; returns the log.
pub fn run_speed_loop(
    backend: &mut dyn Backend,
    p: &PlantParams,
    source: &str,
    reference: impl FnMut(f64) -> Option<(f64, f64)>,
) -> anyhow::Result<Record> {
    Ok(run_speed_loop_logged(backend, p, source, reference)?.0)
}

/// As [`run_speed_loop`], also returning one [`LoopMsg`] per sample for the MCAP log (no position
/// reference: `ref_rad` and `err_rad` are null; `omega_l_rad_s` is the differenced encoder speed).
pub fn run_speed_loop_logged(
    backend: &mut dyn Backend,
    p: &PlantParams,
    source: &str,
    mut reference: impl FnMut(f64) -> Option<(f64, f64)>,
) -> anyhow::Result<(Record, Vec<LoopMsg>)> {
    let mut msgs = Vec::new();
    let info = backend.info();
    let dt = info.sample_period_s;
    let u_max = info.voltage_limit_v;
    // Reduced model k_m / (T_m s + 1) from the nominal parameters; PI cancels the pole.
    let (k_m, t_m) = (p.k_m(), p.t_m());
    let omega_c = 50.0;
    let kp = omega_c * t_m / k_m;
    let ki = kp / t_m;
    let tau_f = 0.005; // speed filter time constant [s]
    let mut rec = Record {
        source: source.to_string(),
        ..Record::default()
    };
    let (mut u_log, mut th_log, mut i_log) = (Vec::new(), Vec::new(), Vec::new());
    let mut last_theta: Option<f64> = None;
    let (mut w_f, mut integ) = (0.0, 0.0);
    let mut k = 0usize;
    let result = (|| -> anyhow::Result<()> {
        loop {
            let s = backend.sample()?;
            let t = k as f64 * dt;
            let Some((w_ref, a_ref)) = reference(t) else {
                break;
            };
            let w_meas = match last_theta {
                Some(th) => (s.theta_l_rad - th) / dt * p.n,
                None => 0.0,
            };
            last_theta = Some(s.theta_l_rad);
            w_f += (w_meas - w_f) * dt / (tau_f + dt);
            let err = w_ref - w_f;
            let ff = (p.k_e * w_ref + p.r_eq() * p.j_eq() * a_ref / p.k_t) / p.k_drv;
            // A zero reference is a rest: 0 V and the motor coasts (braking from full speed
            // against the back-EMF would draw more than the board's over-current trip).
            let rest = w_ref == 0.0 && a_ref == 0.0;
            if rest {
                integ = 0.0;
            }
            let u_unsat = if rest { 0.0 } else { ff + kp * err + integ };
            let u = u_unsat.clamp(-u_max, u_max);
            // Conditional integration (anti-windup).
            if !rest && (u == u_unsat || err.signum() != u_unsat.signum()) {
                integ += ki * err * dt;
            }
            backend.apply(u)?;
            msgs.push(LoopMsg {
                time_s: s.time_s,
                ref_rad: f64::NAN,
                theta_l_rad: s.theta_l_rad,
                omega_l_rad_s: w_meas / p.n,
                err_rad: f64::NAN,
                u_v: u,
                ff_v: if rest { 0.0 } else { ff },
                p_v: if rest { 0.0 } else { kp * err },
                i_v: integ,
                d_v: 0.0,
                i_a_a: s.i_a_a,
                saturated: u != u_unsat,
            });
            rec.time_s.push(s.time_s);
            th_log.push(s.theta_l_rad);
            i_log.push(s.i_a_a);
            u_log.push(u);
            k += 1;
        }
        Ok(())
    })();
    backend.stop()?;
    result?;
    rec.u_v = Some(u_log);
    rec.theta_l_rad = Some(th_log);
    rec.i_a_a = Some(i_log);
    Ok((rec, msgs))
}

/// The simulated plant of `--ramp`: `--plant`/`--plant-effect` when given, else the realistic
/// lab plant (`servo params --lab`: friction as measured on real SRV-02s), so that a fresh
/// install identifies meaningful friction rather than Table 2's zero.
fn sim_plant(
    args: &Identify,
) -> anyhow::Result<(servo_core::Plant, servo_core::sim::SensorConfig)> {
    let (mut plant, sensors) = args.plant.load()?;
    if args.plant.plant.is_none() {
        plant = servo_core::Plant::lab();
        for e in &args.plant.plant_effect {
            plant.effects.insert(*e);
        }
    }
    Ok((plant, sensors))
}

/// Live progress of a real-time run on stderr, every 5 s of run time: elapsed and remaining.
fn progress(name: &str, t: f64, total_s: f64, realtime: bool, next_s: &mut f64) {
    if realtime && t >= *next_s && t < total_s {
        eprintln!(
            "  {name}: {t:.0} s of {total_s:.0} s, {:.0} s left",
            total_s - t
        );
        *next_s += 5.0;
    }
}

/// Runs both experiments on the simulator described by the command's plant options, logs each
/// to MCAP in `--log-dir` (identify_friction.mcap, identify_inertia.mcap) and returns the paths.
pub fn run_experiments(args: &Identify, p: &PlantParams) -> anyhow::Result<Vec<PathBuf>> {
    let built_in = PathBuf::from(BUILT_IN);
    let friction_recipe = args.friction_recipe.clone().unwrap_or(built_in.clone());
    let inertia_recipe = args.inertia_recipe.clone().unwrap_or(built_in);
    let fr = FrictionRecipe::load(&friction_recipe).context("--friction-recipe")?;
    let ir = InertiaRecipe::load(&inertia_recipe).context("--inertia-recipe")?;
    std::fs::create_dir_all(&args.log_dir)
        .with_context(|| format!("--log-dir {}", args.log_dir.display()))?;
    let serial = args.backend == crate::cmd::run::BackendKind::Serial;
    let backend_name = if serial { "serial" } else { "sim" };
    let mut out = Vec::new();
    for (name, recipe) in [
        ("identify_friction", &friction_recipe),
        ("identify_inertia", &inertia_recipe),
    ] {
        let mut b: Box<dyn Backend> = if serial {
            let cfg = servo_hw::SerialConfig {
                port: args.port.clone(),
                baud: args.baud,
                timeout_s: args.board_timeout_ms * 1e-3,
                limits: servo_core::safety::SafetyLimits {
                    theta_min_rad: -1e12,
                    theta_max_rad: 1e12,
                    ..Default::default()
                },
                ..Default::default()
            };
            Box::new(
                servo_hw::SerialBackend::open(cfg)
                    .with_context(|| format!("--backend serial --port {}", args.port))?,
            )
        } else {
            let (plant, sensors) = sim_plant(args)?;
            Box::new(servo_hw::sim::SimBackend::new(&plant, sensors, 1e-3)?)
        };
        let source = format!("servo identify --ramp: {name} ({backend_name})");
        let (_, msgs) = if name == "identify_friction" {
            let (total_s, mut next_s) = (fr.duration_s(), 0.0);
            run_speed_loop_logged(&mut *b, p, &source, |t| {
                progress(name, t, total_s, serial, &mut next_s);
                fr.reference(t).map(|w| (w, 0.0))
            })?
        } else {
            let (total_s, mut next_s) = (ir.duration_s(), 0.0);
            run_speed_loop_logged(&mut *b, p, &source, |t| {
                progress(name, t, total_s, serial, &mut next_s);
                ir.reference(t)
            })?
        };
        if let Some(ls) = b.link_stats() {
            eprintln!(
                "  {name}: {} samples, {} missed deadlines, {} lost frames",
                ls.samples, ls.missed_deadlines, ls.lost_frames
            );
        }
        let path = args.log_dir.join(format!("{name}.mcap"));
        let mut meta = BTreeMap::new();
        meta.insert("experiment".to_string(), name.to_string());
        meta.insert("recipe".to_string(), recipe.display().to_string());
        meta.insert("backend".to_string(), backend_name.to_string());
        if serial {
            meta.insert("serial_port".to_string(), args.port.clone());
        }
        let mut log = McapLog::create(&path, &meta, McapLogOptions::default())
            .with_context(|| format!("creating log {}", path.display()))?;
        for m in &msgs {
            log.write_loop(m)?;
        }
        log.finish()?;
        out.push(path);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staircase_reference_steps_through_the_speeds() {
        let r = FrictionRecipe {
            speeds_rad_s: vec![10.0, 20.0],
            step_duration_s: 2.0,
            both_directions: true,
            rest_s: 1.0,
        };
        assert_eq!(r.reference(0.5), Some(0.0));
        assert_eq!(r.reference(1.5), Some(10.0));
        assert_eq!(r.reference(3.5), Some(20.0));
        assert_eq!(r.reference(5.5), Some(0.0));
        assert_eq!(r.reference(6.5), Some(-10.0));
        assert_eq!(r.reference(10.0), None);
    }

    #[test]
    fn ramps_reference_is_a_triangle() {
        let r = InertiaRecipe {
            accel_rad_s2: 100.0,
            peak_speed_rad_s: 100.0,
            base_speed_rad_s: 0.0,
            cycles: 2,
            rest_s: 0.0,
        };
        assert_eq!(r.reference(0.5), Some((50.0, 100.0)));
        assert_eq!(r.reference(1.5), Some((50.0, -100.0)));
        assert!(r.reference(4.1).is_none());
    }
}
