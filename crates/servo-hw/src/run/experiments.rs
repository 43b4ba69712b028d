//! The identification experiments of the handout (4.1 friction staircase, 4.2 inertia ramps) on
//! any backend: each recipe becomes a load-speed profile that [`super::run_loop`] executes with
//! its speed controller ([`SpeedLoopConfig`]: a PI on the load-speed estimate with back-EMF and
//! inertia feedforward from the nominal parameters), logged to MCAP with the speed reference
//! (`ref_omega_l_rad_s`) beside the measurements. `servo identify --ramp` runs them; the
//! estimators of `servo_core::ident` read the logs.

use super::{chain, run_loop_monitored, RunConfig, RunError, RunMonitor, StopReason};
use crate::backend::Backend;
use crate::serial::LinkStats;
use servo_core::control::speed::SPEED_LOOP_CROSSOVER_RAD_S;
use servo_core::control::{SpeedLoopConfig, SpeedLoopError, SpeedProfile};
use servo_core::PlantParams;
use servo_io::recipe_file::{FrictionRecipe, InertiaRecipe};
use servo_io::{meta_keys, Context as _, McapLog, McapLogOptions};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One experiment: its name (`identify_friction`, `identify_inertia`: the log's file stem), the
/// recipe it came from (a path or `built-in`, for the log's metadata) and its speed profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    pub name: &'static str,
    pub recipe: String,
    pub profile: SpeedProfile,
}

/// The two experiments of `identify --ramp` for the nominal parameters `p` (gear ratio: the
/// recipes give motor speeds) and the speed controller that runs them (crossover
/// [`SPEED_LOOP_CROSSOVER_RAD_S`]).
pub fn identification_experiments(
    p: &PlantParams,
    friction: (&FrictionRecipe, &str),
    inertia: (&InertiaRecipe, &str),
) -> Result<(Vec<Experiment>, SpeedLoopConfig), ExperimentError> {
    let speed_loop = SpeedLoopConfig::from_params(p, SPEED_LOOP_CROSSOVER_RAD_S)?;
    let experiments = vec![
        Experiment {
            name: "identify_friction",
            recipe: friction.1.to_string(),
            profile: friction.0.profile(p.n)?,
        },
        Experiment {
            name: "identify_inertia",
            recipe: inertia.1.to_string(),
            profile: inertia.0.profile(p.n)?,
        },
    ];
    Ok((experiments, speed_loop))
}

/// What one experiment left behind.
#[derive(Debug, Clone)]
pub struct ExperimentRun {
    /// The finished log.
    pub log: PathBuf,
    /// Samples that ran, and the run time of the last one [s].
    pub samples: usize,
    pub last_time_s: f64,
    /// Completed, or stopped by the monitor (the log then holds the samples so far).
    pub stop: StopReason,
    /// The link statistics of a board.
    pub link: Option<LinkStats>,
}

/// Why an experiment failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExperimentError {
    /// The speed controller of the nominal parameters.
    #[error(transparent)]
    SpeedLoop(#[from] SpeedLoopError),
    /// A recipe that gives no valid profile, or a log that cannot be written.
    #[error(transparent)]
    Io(#[from] servo_io::Error),
    /// The loop failed; the log holds the samples before the fault.
    #[error("{name} (log of the samples before the fault: {})", log.display())]
    Run {
        name: &'static str,
        log: PathBuf,
        link: Option<Box<LinkStats>>,
        #[source]
        source: Box<RunError>,
    },
}

/// Runs `experiment` on `backend` with the speed controller `speed_loop`, logged to
/// `log_dir/<name>.mcap` (metadata: experiment, recipe, `backend_name`, firmware, period,
/// duration, and `extra`, e.g. the serial port), watched by `monitor`. The log is finished in
/// every case, with a summary record (link statistics, samples, the error of a failed run).
pub fn run_experiment(
    backend: &mut dyn Backend,
    experiment: &Experiment,
    speed_loop: SpeedLoopConfig,
    log_dir: &Path,
    backend_name: &str,
    extra: &BTreeMap<String, String>,
    monitor: &mut dyn RunMonitor,
) -> Result<ExperimentRun, ExperimentError> {
    let name = experiment.name;
    let info = backend.info();
    let path = log_dir.join(format!("{name}.mcap"));
    let mut meta = BTreeMap::new();
    meta.insert("experiment".to_string(), name.to_string());
    meta.insert("recipe".to_string(), experiment.recipe.clone());
    meta.insert(meta_keys::BACKEND.to_string(), backend_name.to_string());
    meta.insert(meta_keys::FIRMWARE.to_string(), info.firmware.to_string());
    meta.insert(
        meta_keys::SAMPLE_PERIOD_S.to_string(),
        info.sample_period_s.to_string(),
    );
    meta.insert(
        meta_keys::DURATION_S.to_string(),
        experiment.profile.duration_s().to_string(),
    );
    meta.extend(extra.iter().map(|(k, v)| (k.clone(), v.clone())));
    let mut log = McapLog::create(&path, &meta, McapLogOptions::default())
        .with_context(|| format!("creating log {}", path.display()))?;
    let cfg = RunConfig {
        keep_record: false,
        ..RunConfig::speed(experiment.profile.clone(), speed_loop)
    };
    let result = run_loop_monitored(backend, &cfg, Some(&mut log), monitor);
    let link = backend.link_stats();
    let mut summary = link.as_ref().map(|ls| ls.to_map()).unwrap_or_default();
    let run = match result {
        Ok(r) => r,
        Err(e) => {
            summary.insert("stop_reason".into(), format!("error: {}", chain(&e)));
            let _ = log.write_summary(&summary);
            let _ = log.finish();
            return Err(ExperimentError::Run {
                name,
                // Unfinished (a full disk): the `.partial` file that holds the samples.
                log: log.writing().to_path_buf(),
                link: link.map(Box::new),
                source: Box::new(e),
            });
        }
    };
    summary.insert("samples".into(), run.samples.to_string());
    log.write_summary(&summary)?;
    log.finish()?;
    Ok(ExperimentRun {
        log: path,
        samples: run.samples,
        last_time_s: run.last_time_s,
        stop: run.stop,
        link,
    })
}
