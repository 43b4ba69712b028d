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

pub use crate::io::recipe_file::{
    FrictionRecipe, InertiaRecipe, BUILT_IN, FRICTION_RECIPE, INERTIA_RECIPE,
};
use crate::live::{self, CliMonitor, Progress};
use servo_hw::run::StopReason;

/// The options of `servo identify --ramp` (flattened into [`super::identify::Identify`]).
#[derive(Debug, clap::Args)]
pub struct RampArgs {
    /// Recipes of the `--ramp` experiments (TOML); default: the recipes built into servo (the
    /// same as experiments/identify_friction.toml and experiments/identify_inertia.toml).
    #[arg(long = "friction-recipe", value_name = "TOML")]
    pub friction_recipe: Option<PathBuf>,
    #[arg(long = "inertia-recipe", value_name = "TOML")]
    pub inertia_recipe: Option<PathBuf>,

    /// Backend of the `--ramp` experiments: the simulator (`--plant`) or a board on `--port`
    /// (`servo board --pty`/`--qemu` or real firmware). The staircase turns the load for many
    /// revolutions: start the board with wide position limits (e.g. `--theta-min-rad -1e6
    /// --theta-max-rad 1e6`); the host's own position limits are off for these runs.
    #[arg(long, value_enum, default_value = "sim")]
    pub backend: crate::cmd::run::BackendKind,
    /// Serial port of the board (`--backend serial`).
    #[arg(long, value_name = "PATH", default_value = "/dev/ttyACM0")]
    pub port: String,
    /// Baud rate of the serial port [bit/s] (ignored by USB CDC and pseudo-terminals).
    #[arg(long, value_name = "BAUD", default_value_t = 115_200)]
    pub baud: u32,
    /// A board silent for this long during a run is lost: 0 V, error [ms].
    #[arg(long = "board-timeout-ms", value_name = "MS", default_value_t = 250.0)]
    pub board_timeout_ms: f64,

    /// Live progress of the `--ramp` experiments on stderr (elapsed, left, missed deadlines):
    /// `auto` on a terminal, `always`, `never`.
    #[arg(long, value_enum, default_value = "auto")]
    pub progress: crate::live::ProgressMode,

    /// Directory for the `--ramp` logs.
    #[arg(long = "log-dir", value_name = "DIR", default_value = ".")]
    pub log_dir: PathBuf,

    /// Simulated plant for `--ramp` on the simulator; default: the lab plant of `servo params`
    /// (friction as measured on real SRV-02s).
    #[command(flatten)]
    pub plant: crate::plant_args::PlantArgs,
}

/// The backend of one experiment: the simulator of the command's plant options, or the board on
/// `--port` with the host's position limits off (the staircase turns the load for many
/// revolutions; the board keeps its own).
fn open_backend(args: &RampArgs) -> anyhow::Result<Box<dyn Backend>> {
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
        crate::plant_args::voltage_drive_only(
            &args.plant,
            "identify --ramp (the handout's voltage experiments)",
        )?;
        Ok(Box::new(servo_hw::sim::SimBackend::new(
            &plant, sensors, 1e-3,
        )?))
    }
}

/// Runs both experiments on the command's backend through the library's runner, logs each to
/// MCAP in `--log-dir` (identify_friction.mcap, identify_inertia.mcap) and returns the paths.
pub fn run_experiments(args: &RampArgs, p: &PlantParams) -> anyhow::Result<Vec<PathBuf>> {
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
            return Err(live::Interrupted {
                at_s: run.last_time_s,
            }
            .into());
        }
        out.push(run.log);
    }
    Ok(out)
}
