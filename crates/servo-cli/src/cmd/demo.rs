//! `servo demo`: the whole story on the simulator, as far as the parts exist, leaving its files
//! in a folder and printing where.
//!
//! The demo is a list of [`Stage`]s run in order on a shared [`DemoContext`]; each prints a
//! headline and returns the files it wrote. Later stages (identify, compare, diagnose, add the
//! effect) are appended to [`stages`] as they land.

use crate::gains_file::{GainsFile, PidSection};
use crate::io::{meta_keys, write_csv, McapLog, McapLogOptions};
use crate::model_file::ModelFile;
use crate::runner::controller::{pid_config, PidOptions};
use crate::runner::{self, Program, RunConfig, RunOutput};
use anyhow::{anyhow, Context};
use servo_core::control::sequence::{PlacedSegment, Segment};
use servo_core::control::Reference;
use servo_core::effects::Effect;
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use servo_hw::SimBackend;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Tell the whole story on the simulator.
#[derive(Debug, clap::Parser)]
pub struct Demo {
    /// Folder for the demo's logs, plots and files (created if missing).
    #[arg(long, value_name = "DIR", default_value = "servo-demo")]
    pub out: PathBuf,
    /// Seed of the simulated sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
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
            what: "step sequence on a simulated motor with friction the model does not know",
            run: stage_run,
        },
    ]
}

/// The demo's simulated motor: Table 2 plus Coulomb and Stribeck friction of the size measured on
/// the Padova motors (tau_sf about 0.01 N m at the load).
pub fn demo_truth() -> anyhow::Result<Plant> {
    let mut plant = Plant::from_params(PlantParams::TABLE2).map_err(|e| anyhow!("{e}"))?;
    for spec in ["coulomb:tau_sf=0.0098", "stribeck:tau_s=0.014,omega_s=0.5"] {
        let e = Effect::parse(spec).map_err(|e| anyhow!("demo effect `{spec}`: {e}"))?;
        plant.effects.insert(e);
    }
    Ok(plant)
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

fn stage_design(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    use servo_core::design::bode::DerivativeFilter;
    use servo_core::design::controller::Discretization;
    use servo_core::design::verify::{design, DesignRequest};
    use servo_core::design::{ControllerKind, LoopSpec, PlantModel};
    let params = PlantParams::TABLE2;
    let req = DesignRequest {
        kind: ControllerKind::Pid,
        spec: LoopSpec {
            omega_gc: 30.0,
            phase_margin: 60f64.to_radians(),
        },
        alpha: 4.0,
        filter: DerivativeFilter::Factor(5.0),
        ts_s: 1e-3,
        discretization: Discretization::Tustin,
        reduced: PlantModel::reduced(&params),
        full: Some(PlantModel::full(&params)),
        design_on_full: false,
        exact: false,
    };
    let r = design(&req).map_err(|e| anyhow!("design: {e}"))?;
    let g = r.gains;
    let mut d = toml::Table::new();
    d.insert(
        "method".into(),
        "Bode (handout eqs. 44-53), servo demo".into(),
    );
    d.insert("wgc_rad_s".into(), 30.0.into());
    d.insert("pm_deg".into(), 60.0.into());
    d.insert("alpha".into(), 4.0.into());
    d.insert("discretization".into(), "tustin".into());
    let gains = GainsFile {
        pid: PidSection {
            kp: g.kp,
            ki: g.ki,
            kd: g.kd,
            tl_s: g.tl_s,
            ts_s: 1e-3,
            kw: None,
            u_limit_v: None,
        },
        design: Some(d),
    };
    let path = ctx.out.join("gains.toml");
    gains.save(&path)?;
    let pm = r.discrete.margins.phase_margin_deg;
    ctx.gains = Some(gains);
    Ok((
        format!(
            "K_P = {:.4} V/rad, K_I = {:.3} V/(rad s), K_D = {:.5} V s/rad, T_L = {:.4} s; discrete loop phase margin {pm:.1} deg",
            g.kp, g.ki, g.kd, g.tl_s
        ),
        vec![path],
    ))
}

/// The handout's reference-point gains, used when the design stage is skipped or fails.
pub fn handout_gains() -> GainsFile {
    GainsFile {
        pid: PidSection {
            kp: 7.0476,
            ki: 86.121,
            kd: 0.14418,
            tl_s: 1.0 / 150.0,
            ts_s: 1e-3,
            kw: None,
            u_limit_v: None,
        },
        design: None,
    }
}

fn stage_run(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let gains = ctx.gains.clone().unwrap_or_else(handout_gains);
    let pid = pid_config(&gains, &PidOptions::default(), 1e-3, 10.0)?;
    let program = demo_program()?;
    let duration_s = program.duration_s().unwrap_or(6.0);
    let mut backend = SimBackend::new(&ctx.truth, ctx.sensors, 1e-3).context("simulator")?;
    let truth_path = ctx.out.join("truth_hidden.toml");
    let mut mf = ModelFile::from_plant(&ctx.truth);
    mf.sensors = Some(ctx.sensors);
    mf.save(&truth_path)?;
    let mut meta = BTreeMap::new();
    meta.insert(
        meta_keys::SERVO_VERSION.into(),
        env!("CARGO_PKG_VERSION").into(),
    );
    meta.insert(meta_keys::BACKEND.into(), "sim".into());
    meta.insert(meta_keys::SAMPLE_PERIOD_S.into(), "0.001".into());
    meta.insert(meta_keys::DURATION_S.into(), duration_s.to_string());
    meta.insert(
        meta_keys::REFERENCE.into(),
        "steps 10, 30, 90, -45 deg, 1.5 s each".into(),
    );
    meta.insert(meta_keys::GAINS_TOML.into(), gains.to_toml_commented());
    meta.insert(meta_keys::PLANT_TOML.into(), mf.to_toml()?);
    meta.insert(
        meta_keys::PLANT_EFFECTS.into(),
        ctx.truth
            .effects
            .iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
            .join(" "),
    );
    meta.insert(meta_keys::SEED.into(), ctx.sensors.seed.to_string());
    meta.insert(meta_keys::FEEDFORWARD.into(), "none".into());
    let log_path = ctx.out.join("run.mcap");
    let mut log = McapLog::create(&log_path, &meta, McapLogOptions::default())?;
    let cfg = RunConfig::closed_loop(program, pid, duration_s);
    let out = runner::run_loop(&mut backend, &cfg, Some(&mut log))?;
    let summary = out.summary();
    log.write_summary(&summary.to_map())?;
    log.finish()?;
    let csv_path = ctx.out.join("run.csv");
    write_csv(&csv_path, &out.record)?;
    let plot_path = ctx.out.join("run.svg");
    super::run::plot_run(&plot_path, &out)?;
    let u_plot = ctx.out.join("run_u.svg");
    let headline = format!(
        "{} steps: overshoot up to {:.1} %, tracking error RMS {:.2} deg, {:.3} s at the 10 V limit",
        summary.steps.len(),
        summary.overshoot_pct().unwrap_or(0.0),
        summary.err_rms_rad.unwrap_or(0.0).to_degrees(),
        summary.saturation_time_s
    );
    println!("{summary}");
    ctx.run = Some(out);
    ctx.run_log = Some(log_path.clone());
    ctx.run_csv = Some(csv_path.clone());
    Ok((
        headline,
        vec![truth_path, log_path, csv_path, plot_path, u_plot],
    ))
}

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
            truth: demo_truth()?,
            sensors,
            gains: None,
            run: None,
            run_log: None,
            run_csv: None,
        };
        let all = stages();
        let t0 = std::time::Instant::now();
        let mut files = Vec::new();
        for (i, st) in all.iter().enumerate() {
            println!("== [{}/{}] {}: {}", i + 1, all.len(), st.name, st.what);
            let (headline, written) =
                (st.run)(&mut ctx).with_context(|| format!("demo stage `{}`", st.name))?;
            println!("   -> {headline}");
            for f in &written {
                println!("      wrote {}", f.display());
            }
            files.extend(written);
        }
        println!(
            "demo done in {:.1} s; {} files in {}",
            t0.elapsed().as_secs_f64(),
            files.len(),
            display_dir(&self.out)
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
