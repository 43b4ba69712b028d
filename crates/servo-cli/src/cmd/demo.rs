//! `servo demo`: the whole story on the simulator, as far as the parts exist, leaving its files
//! in a folder and printing where.
//!
//! The demo is a list of [`Stage`]s run in order on a shared [`DemoContext`]; each prints a
//! headline and returns the files it wrote. The story: design a PID on the nominal model, run it on
//! a simulated motor with a hidden effect ([`HIDDEN_EFFECT`]), run an open-loop identification
//! experiment on the same motor, identify the base model (viscous + Coulomb friction, J_eq) with
//! `servo identify`, compare it with the measurements (`servo compare`: fit and where it fails),
//! diagnose the missing effect (`servo diagnose`), add it (`servo compare --add`: the error falls)
//! and diagnose again (nothing significant left). The later stages call the real commands, so the
//! demo prints exactly what a user gets, and each stage shows the equivalent command line.

mod stages_loop;
mod stages_model;

pub use stages_loop::handout_gains;
use stages_loop::*;
use stages_model::*;

use crate::gains_file::{GainsFile, PidSection};
use crate::io::{meta_keys, write_csv, McapLog, McapLogOptions};
use crate::live;
use crate::model_file::ModelFile;
use anyhow::{anyhow, Context};
use servo_core::control::program::Program;
use servo_core::control::sequence::{PlacedSegment, Segment};
use servo_core::control::Reference;
use servo_core::effects::{Effect, EffectKind};
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use servo_hw::run::{RunConfig, RunOutput};
use servo_hw::{Backend, SimBackend};
use servo_io::controller::{pid_config, LoggedController, PidOptions, PidSources};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Tell the whole story on the simulator.
#[derive(Debug, clap::Parser)]
pub struct Demo {
    /// Folder for the demo's logs, plots and files (created if missing).
    #[arg(long, value_name = "DIR", default_value = "servo-demo")]
    pub out: PathBuf,
    /// Seed of the simulated sensor noise and of the identification experiment.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The effect hidden in the simulated motor (catalogue syntax `name:key=value,...`), which
    /// the story must find.
    #[arg(long, value_name = "EFFECT", default_value = HIDDEN_EFFECT)]
    pub hidden: String,
    /// Print each command's full text and every file written (default: each step's command
    /// line and its one-line result).
    #[arg(long)]
    pub verbose: bool,
}

/// What the stages share.
#[derive(Debug)]
pub struct DemoContext {
    /// Output folder.
    pub out: PathBuf,
    /// The simulated motor, with effects the model does not know about ("truth").
    pub truth: Plant,
    pub sensors: SensorConfig,
    /// The controller designed in the first stage.
    pub gains: Option<GainsFile>,
    /// The closed-loop run on the truth.
    pub run: Option<RunOutput>,
    /// Path of the run's MCAP log.
    pub run_log: Option<PathBuf>,
    /// Path of the run's CSV log.
    pub run_csv: Option<PathBuf>,
    /// Path of the open-loop identification log (CSV).
    pub ident_log: Option<PathBuf>,
    /// Model file identified by `servo identify`.
    pub ident_model: Option<PathBuf>,
    /// Files a stage's command already announced ("wrote ..."): the demo does not repeat them.
    pub announced: Vec<PathBuf>,
    /// Effect named by the first diagnosis.
    pub winner: Option<EffectKind>,
    /// Model file with the winner added (`servo compare --add --save`).
    pub extended_model: Option<PathBuf>,
}

/// A stage's body: returns its headline and the files it wrote.
pub type StageFn = fn(&mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)>;

/// One step of the story.
pub struct Stage {
    /// Short name (`design`, `run`, ...).
    pub name: &'static str,
    /// What the stage does, one line.
    pub what: &'static str,
    /// Runs the stage; returns its headline and the files it wrote.
    pub run: StageFn,
}

/// The stages, in story order.
pub fn stages() -> Vec<Stage> {
    vec![
        Stage {
            name: "design",
            what:
                "Bode PID for w_gc = 30 rad/s, phase margin 60 deg on the nominal model (Table 2)",
            run: stage_design,
        },
        Stage {
            name: "run",
            what: "step sequence on a simulated motor with an effect the model does not know",
            run: stage_run,
        },
        Stage {
            name: "excite",
            what: "open-loop identification experiment on the same motor: voltage steps and ramps",
            run: stage_excite,
        },
        Stage {
            name: "identify",
            what: "servo identify: base model (viscous + Coulomb friction, J_eq) from the open-loop log",
            run: stage_identify,
        },
        Stage {
            name: "compare",
            what: "servo compare: the identified model against both logs, and where it fails",
            run: stage_compare,
        },
        Stage {
            name: "diagnose",
            what: "servo diagnose: which catalogue effect is the model missing?",
            run: stage_diagnose,
        },
        Stage {
            name: "add",
            what: "servo compare --add <winner>: fit the effect with the base parameters, watch the error fall",
            run: stage_add,
        },
        Stage {
            name: "re-diagnose",
            what: "servo diagnose on the extended model: is anything significant left?",
            run: stage_rediagnose,
        },
        Stage {
            name: "compensate",
            what: "servo run --ff all: the extended model's effects compensated in the loop; tracking error against the friction feedforward",
            run: stage_compensate,
        },
    ]
}

/// The effect hidden in the demo's motor: what the base model lacks and the diagnosis must find.
///
/// An eccentric load mass of 0.01 N m (the size of the Coulomb friction): the identified base
/// model cannot explain a torque that follows the load angle. (`--hidden` picks another one.)
pub const HIDDEN_EFFECT: &str = "imbalance:amplitude=0.01,phase=0.5";

/// Coulomb friction of the demo's motor [N m, load side], the size measured on the Padova motors.
pub const DEMO_TAU_SF: f64 = 0.0098;

/// The demo's simulated motor: Table 2 with viscous and Coulomb friction (tau_sf about 0.01 N m at
/// the load, as measured on the Padova motors) plus the hidden effect `hidden` (e.g.
/// [`HIDDEN_EFFECT`]).
pub fn demo_truth(hidden: &str) -> anyhow::Result<Plant> {
    let params = PlantParams {
        tau_sf: Some(DEMO_TAU_SF),
        ..PlantParams::TABLE2
    };
    let mut plant = Plant::from_params(params).map_err(|e| anyhow!("demo motor: {e}"))?;
    let e = Effect::parse(hidden).map_err(|e| anyhow!("--hidden `{hidden}`: {e}"))?;
    if matches!(e.kind, EffectKind::Viscous | EffectKind::Coulomb) {
        return Err(anyhow!(
            "--hidden `{hidden}`: viscous and Coulomb friction are part of the base model; hide another catalogue effect"
        ));
    }
    plant.effects.insert(e);
    Ok(plant)
}

/// The hidden effect of `truth` (the first effect that is not viscous or Coulomb friction).
fn hidden_effect(truth: &Plant) -> Option<Effect> {
    truth
        .effects
        .iter()
        .find(|e| !matches!(e.kind, EffectKind::Viscous | EffectKind::Coulomb))
        .copied()
}

/// The parameter that sizes an effect (the one quoted in the headlines), from the registry.
fn main_param(kind: EffectKind) -> Option<&'static str> {
    kind.main_param().map(|p| p.key)
}

/// Unit of an effect's main parameter.
fn main_unit(kind: EffectKind) -> &'static str {
    kind.main_param().map_or("", |p| p.unit)
}

/// Prints the command line a user would type for a stage, and parses it with the command's own
/// parser.
fn command<T: clap::Parser>(args: &[String]) -> anyhow::Result<T> {
    // Printed in the short story too (the command is what a user takes away from it).
    let was = crate::set_quiet(false);
    outln!("   $ servo {}", args.join(" "));
    crate::set_quiet(was);
    T::try_parse_from(args).map_err(|e| anyhow!("demo command `servo {}`: {e}", args.join(" ")))
}

fn path_arg(p: &Path) -> String {
    p.display().to_string()
}

fn need<'a>(p: &'a Option<PathBuf>, what: &str) -> anyhow::Result<&'a PathBuf> {
    p.as_ref()
        .ok_or_else(|| anyhow!("{what} is missing (an earlier stage failed)"))
}

/// The demo's reference: steps of 10, 30, 90 and -45 deg, 1.5 s each (like the lab's tests).
pub fn demo_program() -> anyhow::Result<Program> {
    let mut placed: Vec<PlacedSegment> = Vec::new();
    for deg in [10.0f64, 30.0, 90.0, -45.0] {
        let seg = Segment::position(Reference::step(deg.to_radians(), 0.0), 1.5);
        placed
            .push(PlacedSegment::after(&placed, seg).map_err(|e| anyhow!("demo reference: {e}"))?);
    }
    Ok(Program::Segments(placed))
}

/// Length of the open-loop identification experiment [s].
const EXCITE_S: f64 = 16.0;
/// Time each voltage step or ramp of the identification experiment lasts [s].
const EXCITE_STEP_S: f64 = 0.4;

impl Demo {
    pub fn run(self) -> anyhow::Result<()> {
        std::fs::create_dir_all(&self.out)
            .with_context(|| format!("creating --out folder {}", self.out.display()))?;
        let sensors = SensorConfig {
            seed: self.seed,
            ..SensorConfig::default()
        };
        let mut ctx = DemoContext {
            out: self.out.clone(),
            truth: demo_truth(&self.hidden)?,
            sensors,
            gains: None,
            run: None,
            run_log: None,
            run_csv: None,
            ident_log: None,
            ident_model: None,
            winner: None,
            extended_model: None,
            announced: Vec::new(),
        };
        let all = stages();
        let t0 = std::time::Instant::now();
        let mut files = Vec::new();
        let mut story = Vec::new();
        for (i, st) in all.iter().enumerate() {
            outln!("== [{}/{}] {}: {}", i + 1, all.len(), st.name, st.what);
            let was = crate::set_quiet(!self.verbose);
            let result = (st.run)(&mut ctx);
            crate::set_quiet(was);
            let (headline, written) =
                result.with_context(|| format!("demo stage `{}`", st.name))?;
            outln!("   -> {headline}");
            if self.verbose {
                for f in written.iter().filter(|f| !ctx.announced.contains(f)) {
                    outln!("      wrote {}", f.display());
                }
            }
            files.extend(written);
            story.push((st.name, headline));
        }
        if self.verbose {
            outln!("== the story");
            for (name, headline) in &story {
                outln!("  {name:<12} {headline}");
            }
        }
        outln!(
            "demo done in {:.1} s; {} files in {}{}",
            t0.elapsed().as_secs_f64(),
            files.len(),
            display_dir(&self.out),
            if self.verbose {
                ""
            } else {
                " (--verbose: each command's full text and every file it wrote)"
            }
        );
        Ok(())
    }
}

fn display_dir(p: &Path) -> String {
    std::fs::canonicalize(p)
        .unwrap_or_else(|_| p.to_path_buf())
        .display()
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truth_hides_exactly_the_given_effect() {
        let t = demo_truth(HIDDEN_EFFECT).unwrap();
        let h = hidden_effect(&t).unwrap();
        let want = Effect::parse(HIDDEN_EFFECT).unwrap();
        assert_eq!(h.kind, want.kind);
        let key = main_param(h.kind).unwrap();
        assert_eq!(h.get(key), want.get(key));
        assert!((t.tau_sf() - DEMO_TAU_SF).abs() < 1e-12);
        // Any other registered effect can be hidden instead.
        for k in EffectKind::ALL
            .into_iter()
            .filter(|k| !matches!(*k, EffectKind::Viscous | EffectKind::Coulomb))
        {
            let mut e = Effect::unset(k);
            for p in k.params() {
                if e.get(p.key).is_some_and(f64::is_nan) {
                    e.set(p.key, p.min.max(0.0) + 1.0).unwrap();
                }
            }
            let t = demo_truth(&e.to_string()).unwrap();
            assert_eq!(hidden_effect(&t).unwrap().kind, k, "{e}");
        }
    }

    #[test]
    fn truth_rejects_base_effects_and_bad_specs() {
        let e = demo_truth("coulomb:tau_sf=0.01").unwrap_err().to_string();
        assert!(e.contains("--hidden") && e.contains("base model"), "{e}");
        let e = demo_truth("nonsense").unwrap_err().to_string();
        assert!(e.contains("--hidden `nonsense`"), "{e}");
    }

    #[test]
    fn every_effect_has_a_main_parameter_of_the_catalogue() {
        for k in EffectKind::ALL {
            let key = main_param(k).unwrap();
            let e = Effect::parse(k.name()).unwrap();
            assert!(e.get(key).is_some(), "{} has no `{key}`", k.name());
        }
    }
}
