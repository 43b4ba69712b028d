//! `servo identify --ramp`: the identification experiments of the handout run on a backend.
//!
//! * friction (4.1): a closed-loop speed staircase (recipe `experiments/identify_friction.toml`,
//!   built into the binary; `--friction-recipe FILE` overrides it);
//! * inertia (4.2): constant acceleration/deceleration ramps (`experiments/identify_inertia.toml`,
//!   likewise).
//!
//! Each recipe becomes a load-speed profile ([`SpeedProfile`]) that the shared runner
//! ([`crate::runner::run_loop`]) executes with its speed controller ([`SpeedLoopConfig`]: a PI on
//! the load-speed estimate with back-EMF and inertia feedforward from the nominal parameters,
//! 50 rad/s crossover) on any backend: the simulator, the virtual board or a board over serial.
//! The logs record the speed reference (`ref_omega_l_rad_s`) beside the measurements.

use anyhow::{bail, Context};
use servo_core::PlantParams;
use servo_hw::backend::Backend;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::identify::Identify;
use crate::io::{meta_keys, McapLog, McapLogOptions};
use crate::runner::speed::SPEED_LOOP_CROSSOVER_RAD_S;
use crate::runner::{self, Progress, RunConfig, SpeedLoopConfig, SpeedProfile, StopReason};

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
    /// The staircase as a load-speed profile for gear ratio `n` (the recipe's speeds are at
    /// the motor): a rest, then each speed for `step_duration_s`; then the same negative.
    pub fn profile(&self, n: f64) -> anyhow::Result<SpeedProfile> {
        let mut p = SpeedProfile::new();
        let signs: &[f64] = if self.both_directions {
            &[1.0, -1.0]
        } else {
            &[1.0]
        };
        for sign in signs {
            if self.rest_s > 0.0 {
                p.hold(self.rest_s, 0.0)?;
            }
            for w in &self.speeds_rad_s {
                p.hold(self.step_duration_s, sign * w / n)?;
            }
        }
        Ok(p)
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
    /// The ramps as a load-speed profile for gear ratio `n` (the recipe's speeds are at the
    /// motor): a rest, a run-up to the base speed at the same acceleration, then the cycles
    /// base -> peak -> base.
    pub fn profile(&self, n: f64) -> anyhow::Result<SpeedProfile> {
        let mut p = SpeedProfile::new();
        if self.rest_s > 0.0 {
            p.hold(self.rest_s, 0.0)?;
        }
        let (base, peak) = (self.base_speed_rad_s / n, self.peak_speed_rad_s / n);
        if self.base_speed_rad_s > 0.0 {
            p.ramp(self.base_speed_rad_s / self.accel_rad_s2, 0.0, base)?;
        }
        let half = (self.peak_speed_rad_s - self.base_speed_rad_s) / self.accel_rad_s2;
        for _ in 0..self.cycles {
            p.ramp(half, base, peak)?;
            p.ramp(half, peak, base)?;
        }
        Ok(p)
    }
}

/// The backend of one experiment: the simulator of the command's plant options, or the board on
/// `--port` with the host's position limits off (the staircase turns the load for many
/// revolutions; the board keeps its own).
fn open_backend(args: &Identify) -> anyhow::Result<Box<dyn Backend>> {
    if args.backend == crate::cmd::run::BackendKind::Serial {
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
        Ok(Box::new(servo_hw::SerialBackend::open(cfg).with_context(
            || format!("--backend serial --port {}", args.port),
        )?))
    } else {
        let (plant, sensors) = args.plant.load()?;
        Ok(Box::new(servo_hw::sim::SimBackend::new(
            &plant, sensors, 1e-3,
        )?))
    }
}

/// Runs both experiments on the command's backend through the shared runner, logs each to MCAP
/// in `--log-dir` (identify_friction.mcap, identify_inertia.mcap) and returns the paths.
pub fn run_experiments(args: &Identify, p: &PlantParams) -> anyhow::Result<Vec<PathBuf>> {
    let built_in = PathBuf::from(BUILT_IN);
    let friction_recipe = args.friction_recipe.clone().unwrap_or(built_in.clone());
    let inertia_recipe = args.inertia_recipe.clone().unwrap_or(built_in);
    let fr = FrictionRecipe::load(&friction_recipe).context("--friction-recipe")?;
    let ir = InertiaRecipe::load(&inertia_recipe).context("--inertia-recipe")?;
    let speed_loop = SpeedLoopConfig::from_params(p, SPEED_LOOP_CROSSOVER_RAD_S)?;
    std::fs::create_dir_all(&args.log_dir)
        .with_context(|| format!("--log-dir {}", args.log_dir.display()))?;
    let serial = args.backend == crate::cmd::run::BackendKind::Serial;
    let backend_name = if serial { "serial" } else { "sim" };
    let mut out = Vec::new();
    for (name, recipe, profile) in [
        ("identify_friction", &friction_recipe, fr.profile(p.n)?),
        ("identify_inertia", &inertia_recipe, ir.profile(p.n)?),
    ] {
        let mut b = open_backend(args)?;
        let info = b.info();
        let path = args.log_dir.join(format!("{name}.mcap"));
        let mut meta = BTreeMap::new();
        meta.insert("experiment".to_string(), name.to_string());
        meta.insert("recipe".to_string(), recipe.display().to_string());
        meta.insert(meta_keys::BACKEND.to_string(), backend_name.to_string());
        meta.insert(meta_keys::FIRMWARE.to_string(), info.firmware.to_string());
        meta.insert(
            meta_keys::SAMPLE_PERIOD_S.to_string(),
            info.sample_period_s.to_string(),
        );
        meta.insert(
            meta_keys::DURATION_S.to_string(),
            profile.duration_s().to_string(),
        );
        if serial {
            meta.insert("serial_port".to_string(), args.port.clone());
        }
        let mut log = McapLog::create(&path, &meta, McapLogOptions::default())
            .with_context(|| format!("creating log {}", path.display()))?;
        let cfg = RunConfig {
            keep_record: false,
            progress: Progress::from_mode(args.progress, name),
            ..RunConfig::speed(profile, speed_loop)
        };
        let result = runner::run_loop(&mut *b, &cfg, Some(&mut log));
        let link = b.link_stats();
        if let Some(ls) = &link {
            eprintln!(
                "  {name}: {} samples, {} missed deadlines, {} lost frames",
                ls.samples, ls.missed_deadlines, ls.lost_frames
            );
        }
        let mut summary = link.as_ref().map(|ls| ls.to_map()).unwrap_or_default();
        let run = match result {
            Ok(r) => r,
            Err(e) => {
                summary.insert("stop_reason".into(), format!("error: {e:#}"));
                let _ = log.write_summary(&summary);
                let _ = log.finish();
                return Err(e.context(format!(
                    "{name} (log of the samples before the fault: {})",
                    path.display()
                )));
            }
        };
        summary.insert("samples".into(), run.samples.to_string());
        log.write_summary(&summary)?;
        log.finish()?;
        if run.stop == StopReason::Interrupted {
            eprintln!(
                "the board was stopped at 0 V; {} holds the samples so far",
                path.display()
            );
            return Err(runner::Interrupted {
                at_s: run.last_time_s,
            }
            .into());
        }
        out.push(path);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staircase_profile_steps_through_the_speeds() {
        let r = FrictionRecipe {
            speeds_rad_s: vec![10.0, 20.0],
            step_duration_s: 2.0,
            both_directions: true,
            rest_s: 1.0,
        };
        // Motor speeds in the recipe, load speeds in the profile (N = 10).
        let p = r.profile(10.0).unwrap();
        assert_eq!(p.duration_s(), r.duration_s());
        assert_eq!(p.at(0.5), (0.0, 0.0));
        assert_eq!(p.at(1.5), (1.0, 0.0));
        assert_eq!(p.at(3.5), (2.0, 0.0));
        assert_eq!(p.at(5.5), (0.0, 0.0));
        assert_eq!(p.at(6.5), (-1.0, 0.0));
        assert_eq!(p.at(10.0), (0.0, 0.0));
    }

    #[test]
    fn ramps_profile_is_a_triangle() {
        let r = InertiaRecipe {
            accel_rad_s2: 100.0,
            peak_speed_rad_s: 100.0,
            base_speed_rad_s: 20.0,
            cycles: 2,
            rest_s: 0.5,
        };
        let p = r.profile(1.0).unwrap();
        assert!((p.duration_s() - r.duration_s()).abs() < 1e-12);
        assert_eq!(p.at(0.25), (0.0, 0.0));
        let close = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).abs() < 1e-9 && a.1 == b.1;
        assert!(close(p.at(0.6), (10.0, 100.0))); // run-up to the base speed
        assert!(close(p.at(1.0), (50.0, 100.0)));
        assert!(close(p.at(1.8), (70.0, -100.0)));
        assert!(close(p.at(2.5), (40.0, 100.0)));
        assert_eq!(p.at(4.0), (0.0, 0.0));
    }
}
