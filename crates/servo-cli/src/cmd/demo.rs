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

use crate::gains_file::{GainsFile, PidSection};
use crate::io::{meta_keys, write_csv, McapLog, McapLogOptions};
use crate::model_file::ModelFile;
use crate::runner::controller::{pid_config, LoggedController, PidOptions, PidSources};
use crate::runner::{self, Program, RunConfig, RunOutput};
use anyhow::{anyhow, Context};
use servo_core::control::sequence::{PlacedSegment, Segment};
use servo_core::control::Reference;
use servo_core::effects::{Effect, EffectKind};
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use servo_hw::{Backend, SimBackend};
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
    outln!("   $ servo {}", args.join(" "));
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
            derivative_on: None,
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
            derivative_on: None,
        },
        design: None,
    }
}

fn stage_run(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let gains = ctx.gains.clone().unwrap_or_else(handout_gains);
    let src = PidSources {
        opts: &PidOptions::default(),
        logged: None,
        gains_file: Some((&gains, "the demo's gains")),
    };
    let pid = pid_config(&src, 1e-3, Some((10.0, String::new())))?.config;
    let program = demo_program()?;
    let duration_s = program.duration_s().unwrap_or(6.0);
    let mut backend = SimBackend::new(&ctx.truth, ctx.sensors, 1e-3).context("simulator")?;
    let truth_path = ctx.out.join("truth_hidden.toml");
    let mut mf = ModelFile::from_plant(&ctx.truth);
    mf.sensors = Some(ctx.sensors);
    mf.save(&truth_path)?;
    let cfg = RunConfig::closed_loop(program, pid, duration_s);
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
    meta.insert(
        meta_keys::CONTROLLER_TOML.into(),
        LoggedController::of(
            &runner::effective_pid_config(
                &pid,
                cfg.u_limit_v.min(backend.info().voltage_limit_v),
                backend.info().sample_period_s,
            ),
            None,
        )
        .to_toml()?,
    );
    let log_path = ctx.out.join("run.mcap");
    let mut log = McapLog::create(&log_path, &meta, McapLogOptions::default())?;
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
    outln!("{summary}");
    ctx.run = Some(out);
    ctx.run_log = Some(log_path.clone());
    ctx.run_csv = Some(csv_path.clone());
    Ok((
        headline,
        vec![truth_path, log_path, csv_path, plot_path, u_plot],
    ))
}

/// Length of the open-loop identification experiment [s].
const EXCITE_S: f64 = 16.0;
/// Time each voltage step or ramp of the identification experiment lasts [s].
const EXCITE_STEP_S: f64 = 0.4;

/// Open-loop identification experiment on the truth: every 0.4 s either a voltage step of random
/// size (0.8-7.8 V) and sign, or (one time in four) a ramp through zero from +/-(3-6) V to the
/// opposite value; seeded, so the log is the same on every run.
fn stage_excite(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    use servo_core::record::Record;
    use servo_core::sim::sensors::SplitMix64;
    let dt = 1e-3;
    let sensors = SensorConfig {
        seed: ctx.sensors.seed.wrapping_add(1),
        ..ctx.sensors
    };
    let mut backend = SimBackend::new(&ctx.truth, sensors, dt).context("simulator")?;
    let mut rng = SplitMix64(ctx.sensors.seed ^ 0x5EED);
    let n = (EXCITE_S / dt).round() as usize;
    let per = (EXCITE_STEP_S / dt).round() as usize;
    let mut rec = Record {
        source: String::from("servo demo: open-loop identification experiment (sim)"),
        ..Record::default()
    };
    let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
    let (mut u, mut ramp): (f64, Option<(f64, f64)>) = (0.0, None);
    let (mut steps, mut ramps) = (0usize, 0usize);
    for k in 0..n {
        if k % per == 0 {
            if rng.uniform() < 0.25 {
                let a = 3.0 + 3.0 * rng.uniform();
                let a = if rng.uniform() < 0.5 { a } else { -a };
                ramp = Some((a, -2.0 * a / EXCITE_STEP_S));
                ramps += 1;
            } else {
                ramp = None;
                let mag = 0.8 + 7.0 * rng.uniform();
                u = if rng.uniform() < 0.5 { -mag } else { mag };
                steps += 1;
            }
        }
        if let Some((a, slope)) = ramp {
            u = a + slope * ((k % per) as f64 * dt);
        }
        let s = backend.sample()?;
        rec.time_s.push(s.time_s);
        th.push(s.theta_l_rad);
        ia.push(s.i_a_a);
        uv.push(u);
        backend.apply(u)?;
    }
    backend.stop()?;
    rec.theta_l_rad = Some(th);
    rec.i_a_a = Some(ia);
    rec.u_v = Some(uv);
    let path = ctx.out.join("identify_openloop.csv");
    write_csv(&path, &rec)?;
    let plot = ctx.out.join("identify_openloop.svg");
    {
        use crate::plot::{line_chart, Chart, Series};
        let t = &rec.time_s;
        let u = rec.u_v.as_deref().unwrap_or(&[]);
        let th = rec.theta_l_rad.as_deref().unwrap_or(&[]);
        line_chart(
            &plot,
            &Chart {
                title: "open-loop identification experiment",
                x_label: "time [s]",
                y_label: "u [V], theta_l [rad]",
                ..Chart::default()
            },
            &[
                Series {
                    label: "u [V]",
                    x: t,
                    y: u,
                },
                Series {
                    label: "theta_l [rad]",
                    x: t,
                    y: th,
                },
            ],
        )?;
    }
    ctx.ident_log = Some(path.clone());
    Ok((
        format!(
            "{EXCITE_S:.0} s at 1 kHz: {steps} voltage steps and {ramps} ramps through zero, u, theta_l and i_a logged"
        ),
        vec![path, plot],
    ))
}

fn stage_identify(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let log = need(&ctx.ident_log, "the identification log")?;
    let model = ctx.out.join("model_identified.toml");
    let cmd: super::identify::Identify = command(&[
        "identify".into(),
        path_arg(log),
        "-o".into(),
        path_arg(&model),
    ])?;
    cmd.run()?;
    let id = ModelFile::load(&model)?.plant()?;
    let t = &ctx.truth;
    ctx.ident_model = Some(model.clone());
    Ok((
        format!(
            "J_eq = {:.3e} kg m^2 (truth {:.3e}), B_eq = {:.3e} N m s/rad (truth {:.3e}), tau_sf = {:.4} N m (truth {:.4}); no {} in the model",
            id.params.j_eq(),
            t.params.j_eq(),
            id.b_eq(),
            t.b_eq(),
            id.tau_sf(),
            t.tau_sf(),
            hidden_effect(t).map_or("hidden effect", |e| e.kind.name()),
        ),
        vec![model],
    ))
}

/// The logs every model is judged on: the closed-loop run and the open-loop experiment.
fn story_logs(ctx: &DemoContext) -> anyhow::Result<Vec<String>> {
    Ok(vec![
        path_arg(need(&ctx.run_log, "the run log")?),
        path_arg(need(&ctx.ident_log, "the identification log")?),
    ])
}

fn stage_compare(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let model = need(&ctx.ident_model, "the identified model")?.clone();
    let plot = ctx.out.join("compare.svg");
    let mut args = vec!["compare".to_string()];
    args.extend(story_logs(ctx)?);
    args.extend([
        "--model".into(),
        path_arg(&model),
        "--plot".into(),
        path_arg(&plot),
    ]);
    let cmd: super::compare::Compare = command(&args)?;
    let (ladder, cmp) = cmd.run_report()?;
    let (kind, f) = ladder
        .first()
        .and_then(|s| s.cmp_fit.first())
        .ok_or_else(|| anyhow!("compare gave no figures"))?;
    // Where it fails: the finding (of any log) that puts the largest share of the error in one
    // regime or pattern ("NN % of the squared error sits ...").
    let where_ = cmp
        .reports
        .iter()
        .flat_map(|r| r.findings.iter())
        .filter_map(|f| {
            let pct: f64 = f.split(" % ").next()?.trim().parse().ok()?;
            Some((pct, f))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, f)| format!("; where it fails: {f}"))
        .unwrap_or_default();
    Ok((
        format!(
            "fit {:.1} % on {} over both logs{where_}",
            f.fit_percent,
            kind.words()
        ),
        vec![plot],
    ))
}

/// Runs `servo diagnose` on the story's logs with `model`, writing the HTML `report`, and
/// returns the diagnosis of the first log set.
fn run_diagnose(
    ctx: &DemoContext,
    model: &Path,
    report: &Path,
) -> anyhow::Result<servo_core::diagnose::Diagnosis> {
    let mut args = vec!["diagnose".to_string()];
    args.extend(story_logs(ctx)?);
    args.extend([
        "--model".into(),
        path_arg(model),
        "--report".into(),
        path_arg(report),
    ]);
    let cmd: super::diagnose::Diagnose = command(&args)?;
    let (_, diags) = cmd.run_report()?;
    diags
        .into_iter()
        .next()
        .ok_or_else(|| anyhow!("diagnose gave no result"))
}

fn stage_diagnose(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let model = need(&ctx.ident_model, "the identified model")?.clone();
    let report = ctx.out.join("diagnose.html");
    let d = &run_diagnose(ctx, &model, &report)?;
    let hidden = hidden_effect(&ctx.truth);
    let truth_words = hidden.map_or(String::from("none"), |e| e.to_string());
    let Some(w) = d.winner() else {
        ctx.winner = None;
        return Ok((
            format!(
                "nothing significant found (hidden: {truth_words}): {}",
                d.verdict
            ),
            vec![report],
        ));
    };
    ctx.winner = Some(w.effect);
    let main = main_param(w.effect)
        .and_then(|k| w.params.iter().find(|p| p.key == k))
        .map(|p| format!(", {} {:.4} {}", p.key, p.value, p.unit))
        .unwrap_or_default();
    let verdict = if hidden.map(|h| h.kind) == Some(w.effect) {
        "the hidden effect"
    } else {
        "NOT the hidden effect"
    };
    Ok((
        format!(
            "missing effect: {} (error -{:.1} %{main}); {verdict} ({truth_words})",
            w.effect.name(),
            w.error_reduction_pct
        ),
        vec![report],
    ))
}

fn stage_add(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let model = need(&ctx.ident_model, "the identified model")?.clone();
    let Some(winner) = ctx.winner else {
        return Ok((
            String::from("nothing to add: the diagnosis found no missing effect"),
            vec![],
        ));
    };
    let saved = ctx.out.join(format!("model_plus_{}.toml", winner.name()));
    let plot = ctx.out.join(format!("compare_plus_{}.svg", winner.name()));
    let mut args = vec!["compare".to_string()];
    args.extend(story_logs(ctx)?);
    args.extend([
        "--model".into(),
        path_arg(&model),
        "--add".into(),
        winner.name().into(),
        "--save".into(),
        path_arg(&saved),
        "--plot".into(),
        path_arg(&plot),
    ]);
    let cmd: super::compare::Compare = command(&args)?;
    let (ladder, cmp) = cmd.run_report()?;
    let fit = |i: usize| ladder.get(i).and_then(|s| s.cmp_fit.first()).map(|f| f.1);
    let (Some(before), Some(after)) = (fit(0), fit(ladder.len().saturating_sub(1))) else {
        return Err(anyhow!("compare --add gave no ladder"));
    };
    let param = main_param(winner)
        .and_then(|k| cmp.plant.effects.value(winner, k).map(|v| (k, v)))
        .map(|(k, v)| {
            let truth = ctx
                .truth
                .effects
                .value(winner, k)
                .map(|t| format!(", truth {t:.4}"))
                .unwrap_or_default();
            format!(" ({k} {v:.4} {}{truth})", main_unit(winner))
        })
        .unwrap_or_default();
    ctx.extended_model = Some(saved.clone());
    Ok((
        format!(
            "fit {:.1} % -> {:.1} % after adding {}{param}; RMSE {:.2e} -> {:.2e} ({:+.0} %)",
            before.fit_percent,
            after.fit_percent,
            winner.name(),
            before.rmse,
            after.rmse,
            100.0 * (after.rmse - before.rmse) / before.rmse
        ),
        vec![saved, plot],
    ))
}

fn stage_rediagnose(ctx: &mut DemoContext) -> anyhow::Result<(String, Vec<PathBuf>)> {
    let Some(model) = ctx.extended_model.clone() else {
        return Ok((String::from("skipped: no effect was added"), vec![]));
    };
    let report = ctx.out.join("diagnose_after.html");
    let d = &run_diagnose(ctx, &model, &report)?;
    let headline = match d.winner() {
        None => String::from("nothing significant left: the model explains the data"),
        Some(w) => format!(
            "still missing: {} (error -{:.1} %)",
            w.effect.name(),
            w.error_reduction_pct
        ),
    };
    Ok((headline, vec![report]))
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
        };
        let all = stages();
        let t0 = std::time::Instant::now();
        let mut files = Vec::new();
        let mut story = Vec::new();
        for (i, st) in all.iter().enumerate() {
            outln!("== [{}/{}] {}: {}", i + 1, all.len(), st.name, st.what);
            let (headline, written) =
                (st.run)(&mut ctx).with_context(|| format!("demo stage `{}`", st.name))?;
            outln!("   -> {headline}");
            for f in &written {
                outln!("      wrote {}", f.display());
            }
            files.extend(written);
            story.push((st.name, headline));
        }
        outln!("== the story");
        for (name, headline) in &story {
            outln!("  {name:<12} {headline}");
        }
        outln!(
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
