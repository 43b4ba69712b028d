//! `servo identify --ramp`: the identification experiments of the handout run on a backend.
//!
//! * friction (4.1): a closed-loop speed staircase (recipe `experiments/identify_friction.toml`,
//!   built into the binary; `--friction-recipe FILE` overrides it);
//! * inertia (4.2): constant acceleration/deceleration ramps (`experiments/identify_inertia.toml`,
//!   likewise).
//!
//! The recipes ([`servo_io::recipe_file`]) become load-speed profiles that the library's
//! experiment runner ([`servo_hw::run::experiments`]) executes with its speed controller on any
//! backend: the simulator, the virtual board or a board over serial. This file opens the
//! backend, handles Ctrl-C and progress, and prints.

use anyhow::Context;
use servo_core::PlantParams;
use servo_hw::backend::Backend;
use servo_hw::run::experiments::{identification_experiments, run_experiment, ExperimentError};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::identify::Identify;
pub use crate::io::recipe_file::{
    FrictionRecipe, InertiaRecipe, BUILT_IN, FRICTION_RECIPE, INERTIA_RECIPE,
};
use crate::runner::{self, CliMonitor, Progress, StopReason};

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

/// Runs both experiments on the command's backend through the library's runner, logs each to
/// MCAP in `--log-dir` (identify_friction.mcap, identify_inertia.mcap) and returns the paths.
pub fn run_experiments(args: &Identify, p: &PlantParams) -> anyhow::Result<Vec<PathBuf>> {
    let built_in = PathBuf::from(BUILT_IN);
    let friction_recipe = args.friction_recipe.clone().unwrap_or(built_in.clone());
    let inertia_recipe = args.inertia_recipe.clone().unwrap_or(built_in);
    let fr = FrictionRecipe::load(&friction_recipe).context("--friction-recipe")?;
    let ir = InertiaRecipe::load(&inertia_recipe).context("--inertia-recipe")?;
    let label = |p: &Path| p.display().to_string();
    let (experiments, speed_loop) = identification_experiments(
        p,
        (&fr, &label(&friction_recipe)),
        (&ir, &label(&inertia_recipe)),
    )?;
    std::fs::create_dir_all(&args.log_dir)
        .with_context(|| format!("--log-dir {}", args.log_dir.display()))?;
    let serial = args.backend == crate::cmd::run::BackendKind::Serial;
    let mut extra = BTreeMap::new();
    if serial {
        extra.insert("serial_port".to_string(), args.port.clone());
    }
    let mut out = Vec::new();
    for e in &experiments {
        let mut b = open_backend(args)?;
        let mut monitor = CliMonitor::new(Progress::from_mode(args.progress, e.name));
        let backend_name = if serial { "serial" } else { "sim" };
        let result = run_experiment(
            &mut *b,
            e,
            speed_loop,
            &args.log_dir,
            backend_name,
            &extra,
            &mut monitor,
        );
        let link = match &result {
            Ok(r) => r.link,
            Err(ExperimentError::Run { link, .. }) => link.as_deref().copied(),
            Err(_) => None,
        };
        if let Some(ls) = &link {
            eprintln!(
                "  {}: {} samples, {} missed deadlines, {} lost frames",
                e.name, ls.samples, ls.missed_deadlines, ls.lost_frames
            );
        }
        let run = result?;
        if run.stop == StopReason::Interrupted {
            eprintln!(
                "the board was stopped at 0 V; {} holds the samples so far",
                run.log.display()
            );
            return Err(runner::Interrupted {
                at_s: run.last_time_s,
            }
            .into());
        }
        out.push(run.log);
    }
    Ok(out)
}
