//! `servo compare`: simulate the model with the logged input, compare with the measurement, show
//! how well it fits and where it fails, and add catalogue effects to watch the error fall.

use crate::gains_file::{GainsFile, PidSection};
use crate::io::{meta_keys, LogMeta};
use crate::model_file::ModelFile;
use crate::plot::{line_chart_svg, Chart, Series};
use crate::runner::controller::{
    pid_config, ControllerPart, LoggedController, PidOptions, PidSources, ResolvedPid,
};
use anyhow::{anyhow, bail, Context};
use serde_json::{json, Value};
use servo_core::compare::controller_check::{check_controller, ControllerCheck};
use servo_core::compare::quantum::encoder_quantum;
use servo_core::compare::regimes::{detect_u_limit, Regime};
use servo_core::compare::report::{describe_window, regime_phrase, with_unit};
use servo_core::compare::Controller;
use servo_core::compare::{
    compare, replay, ClosedLoop, CompareOptions, CompareReport, Figures, Measured, ReplayMode,
    SignalKind,
};
use servo_core::control::pid::{AntiWindup, Pid, PidConfig};
use servo_core::fit::{fit_model, EffectToFit, FitOptions};
use servo_core::record::Record;
use servo_core::Plant;
use std::path::{Path, PathBuf};

/// Compare a model with measurements; add effects and watch the error fall.
///
/// The replay mode is chosen and stated: closed-loop replay when the controller (`--gains`, or
/// the log's metadata of a `servo run`) and the reference are known, otherwise open-loop speed
/// simulation (position of an integrating plant drifts open loop). `--mode` forces one.
///
/// The closed-loop replay runs the controller the run used, built as `servo run` builds it. Each
/// part takes the first of: the options here (`--discretization`, `--derivative-on`,
/// `--anti-windup`, `--kw`, `--u-limit-v`), the log's record of the controller, the gains file
/// (`[pid] kw`, `u_limit_v`, `[design] discretization`), the defaults (backward Euler, derivative on
/// the error, no anti-windup). The gains come from `--gains`, else from the log. A feedforward the
/// run added is replayed from the log (`ff_v`). The output says which configuration was used and
/// where each part came from.
#[derive(Debug, clap::Parser)]
pub struct Compare {
    /// Logs (servo MCAP, CSV or MATLAB .mat; foreign CSV and .mat through --columns). A log
    /// without u (angle, reference, current) is replayed in closed loop from --gains and the
    /// reference.
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Model file (TOML: [params], [effects.*]).
    #[arg(long, value_name = "model.toml")]
    pub model: PathBuf,
    /// Column map for foreign CSVs, e.g. `time=t_s,theta_l=thl_meas_deg:deg,u=u_V,ref=thl_ref_deg:deg`,
    /// or MATLAB paths for .mat files (`theta_l=scope.signals(1).values(:,1):deg`).
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    /// Gains of the controller that ran during the log (gains file of `servo design`): enables
    /// closed-loop replay; overrides the gains recorded in a `servo run` log.
    #[arg(long, value_name = "gains.toml")]
    pub gains: Option<PathBuf>,
    /// Closed-loop replay with the PID gains that best reproduce the logged u (least squares on
    /// the logged reference, position and u minus the logged feedforward; backward Euler,
    /// derivative on the error, no anti-windup unless the options say otherwise), instead of
    /// --gains or the log's metadata.
    #[arg(long)]
    pub gains_from_log: bool,
    /// The controller's options beyond its gains, as for `servo run` (they override the log).
    #[command(flatten)]
    pub pid: PidOptions,
    /// Replay mode: closed-loop, speed, k-step or segments (default: closed-loop when gains and
    /// reference are known, else speed).
    #[arg(long, value_parser = ["closed-loop", "speed", "k-step", "segments"])]
    pub mode: Option<String>,
    /// Prediction horizon of the k-step mode [samples].
    #[arg(long, default_value_t = 20, value_name = "K")]
    pub k_steps: usize,
    /// Segment length of the segments mode [s].
    #[arg(long, default_value_t = 0.5, value_name = "S")]
    pub segment_s: f64,
    /// Output limit of the controller and the board in closed-loop replay [V] (default: the
    /// log's metadata, else the gains file's u_limit_v, else the plateau of the logged u, e.g. the
    /// +/-10 V of the DAC).
    #[arg(long, value_name = "V")]
    pub u_limit_v: Option<f64>,
    /// Add a catalogue effect, or a user-defined one from --effects: `name[:key=value,...]`;
    /// given values are kept, the others fitted together with the base parameters. Repeat to add
    /// several, in order.
    #[arg(long = "add", value_name = "EFFECT")]
    pub add: Vec<String>,
    /// Effects file with user-defined effects (`[custom.NAME]` sections, docs/custom-effects.md)
    /// that --add can name. Repeat for several files.
    #[arg(long = "effects", value_name = "effects.toml")]
    pub effects: Vec<PathBuf>,
    /// Write the (extended) model to this file.
    #[arg(long, value_name = "model.toml")]
    pub save: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write the figures (measurement vs model, residual, residual vs speed and position) as one SVG.
    #[arg(long, value_name = "out.svg")]
    pub plot: Option<PathBuf>,
}

/// One log, read and checked.
pub struct LogData {
    pub path: PathBuf,
    pub record: Record,
    pub measured: Measured,
    /// The controller of the log (--gains, the log's metadata or --gains-from-log, with the
    /// options) and where each part of it came from; `None` when unknown.
    pub controller: Option<ResolvedPid>,
    /// The output limit of the replay [V] and where it came from.
    pub u_limit: Option<(f64, String)>,
    /// The feedforward part of the logged u [V] per sample, added to the replayed controller's
    /// output (`None`: no feedforward, or none the replay can add).
    pub feedforward_v: Option<Vec<f64>>,
    /// The feedforward of the run as a part of the controller description.
    pub feedforward: ControllerPart,
    /// What the log lacks to rebuild its controller, for the user.
    pub notes: Vec<String>,
    /// How well that controller reproduces the logged u.
    pub check: Option<ControllerCheck>,
}

/// The comparison of one model with every log.
pub struct ModelComparison {
    pub plant: Plant,
    /// One report per log, in the order of the logs.
    pub reports: Vec<CompareReport>,
}

/// How the model is driven, and why.
#[derive(Debug, Clone)]
pub struct ModeChoice {
    pub mode: ReplayMode,
    pub reason: String,
}

/// The controller of a closed-loop replay and of the controller check: servo's PID configured as
/// it ran ([`pid_config`]) plus the feedforward the run logged, sample by sample (it depends on
/// the reference only, so the model gets what the motor got).
pub struct ReplayController<'a> {
    pid: Pid,
    feedforward_v: Option<&'a [f64]>,
    k: usize,
}

impl<'a> ReplayController<'a> {
    /// A controller at rest, at the start of the log.
    pub fn new(config: &PidConfig, feedforward_v: Option<&'a [f64]>) -> anyhow::Result<Self> {
        Ok(ReplayController {
            pid: Pid::new(*config).map_err(|e| anyhow!("controller: {e}"))?,
            feedforward_v,
            k: 0,
        })
    }

    /// The controller of `log` (None when the log's controller is unknown).
    pub fn of(log: &'a LogData) -> anyhow::Result<Option<Self>> {
        log.controller
            .as_ref()
            .map(|c| ReplayController::new(&c.config, log.feedforward_v.as_deref()))
            .transpose()
    }
}

impl Controller for ReplayController<'_> {
    fn update(&mut self, reference_rad: f64, measured_rad: f64) -> f64 {
        let ff = self
            .feedforward_v
            .and_then(|f| f.get(self.k))
            .copied()
            .filter(|v| v.is_finite())
            .unwrap_or(0.0);
        self.k += 1;
        self.pid.update(reference_rad, measured_rad, ff).u_v
    }
}

fn parse_mode(s: &str, k: usize, seg: usize) -> ReplayMode {
    match s {
        "closed-loop" => ReplayMode::ClosedLoop,
        "k-step" => ReplayMode::KStep { k },
        "segments" => ReplayMode::Segments { len: seg },
        _ => ReplayMode::Speed,
    }
}

impl Compare {
    fn mode_for(&self, log: &LogData) -> anyhow::Result<ModeChoice> {
        let gains = log.controller.as_ref();
        let m = &log.measured;
        let seg = ((self.segment_s / m.dt_s).round() as usize).max(1);
        let has_ref = m.ref_rad.is_some();
        let has_pos = m.theta_l_rad.is_some();
        if let Some(s) = &self.mode {
            let mode = parse_mode(s, self.k_steps.max(1), seg);
            if mode == ReplayMode::ClosedLoop {
                if gains.is_none() {
                    bail!("--mode closed-loop needs the controller of {}: give --gains gains.toml or --gains-from-log", log.path.display());
                }
                if !has_ref || !has_pos {
                    bail!(
                        "--mode closed-loop needs the position reference and the measured position in {} (map them with --columns ref=...,theta_l=...)",
                        log.path.display()
                    );
                }
            }
            if matches!(mode, ReplayMode::KStep { .. } | ReplayMode::Segments { .. }) && !has_pos {
                bail!(
                    "--mode {s} re-initialises from the measured position, which {} does not have",
                    log.path.display()
                );
            }
            return Ok(ModeChoice {
                mode,
                reason: String::from("forced with --mode"),
            });
        }
        Ok(match (gains.is_some(), has_ref && has_pos) {
            (true, true) => ModeChoice {
                mode: ReplayMode::ClosedLoop,
                reason: format!(
                    "controller (gains {}) and reference are known: the model runs in the logged loop, as the motor did",
                    gains
                        .and_then(|g| g.part("gains"))
                        .map(|p| p.source.as_str())
                        .unwrap_or_default()
                ),
            },
            (true, false) => ModeChoice {
                mode: ReplayMode::Speed,
                reason: String::from("gains given but the log has no reference/position: open-loop speed simulation with the logged u"),
            },
            _ => ModeChoice {
                mode: ReplayMode::Speed,
                reason: String::from("no controller known (--gains): open-loop speed simulation with the logged u (position would drift)"),
            },
        })
    }

    fn compare_all(
        &self,
        plant: &Plant,
        logs: &[LogData],
        modes: &[ModeChoice],
        opts: &CompareOptions,
    ) -> anyhow::Result<ModelComparison> {
        let mut reports = Vec::new();
        for (log, mc) in logs.iter().zip(modes) {
            let m = &log.measured;
            let rp = if mc.mode == ReplayMode::ClosedLoop {
                let mut pid = ReplayController::of(log)?
                    .ok_or_else(|| anyhow!("closed-loop replay without a controller"))?;
                let q = m.theta_l_rad.as_deref().and_then(encoder_quantum);
                replay(
                    plant,
                    m,
                    mc.mode,
                    Some(ClosedLoop {
                        controller: &mut pid,
                        u_limit_v: log.u_limit.as_ref().map(|l| l.0),
                        encoder_quantum_rad: q,
                    }),
                )
            } else {
                replay(plant, m, mc.mode, None)
            }
            .with_context(|| format!("replaying {} on the model", log.path.display()))?;
            reports.push(compare(m, &rp, plant.params.n, opts));
        }
        Ok(ModelComparison {
            plant: *plant,
            reports,
        })
    }

    /// The output limit for a replay and where it came from: --u-limit-v, the log's metadata,
    /// the gains file's limit, or the plateau of the logged u.
    fn u_limit(
        &self,
        m: &Measured,
        meta: &LogMeta,
        logged: Option<&LoggedController>,
        file: Option<(&GainsFile, &str)>,
    ) -> Option<(f64, String)> {
        if let Some(l) = self.u_limit_v {
            return Some((l, "given with --u-limit-v".into()));
        }
        let meta_limit = logged.and_then(|l| l.u_limit_v).or_else(|| {
            meta.get(meta_keys::U_LIMIT_V)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite() && *v > 0.0)
        });
        if let Some(l) = meta_limit {
            return Some((l, "from the log's metadata".into()));
        }
        if let Some((l, name)) = file.and_then(|(g, name)| g.pid.u_limit_v.map(|l| (l, name))) {
            return Some((l, format!("from {name}")));
        }
        detect_u_limit(&m.u_v).map(|l| (l, "the plateau of the logged u".into()))
    }

    /// The controller of one log: the gains of --gains or of the log's metadata, the options,
    /// the log's record and the gains file put together by [`pid_config`]; the output limit; the
    /// logged feedforward. Notes what an older log lacks.
    fn log_controller(
        &self,
        log: &mut LogData,
        meta: &LogMeta,
        given: Option<&GainsFile>,
    ) -> anyhow::Result<()> {
        let logged = meta.controller()?;
        let log_gains = meta.gains()?;
        let given_name = self
            .gains
            .as_deref()
            .map(|p| p.display().to_string())
            .unwrap_or_default();
        let file = match (given, &log_gains) {
            (Some(g), _) => Some((g, given_name.as_str())),
            (None, Some(g)) => Some((g, "the gains in the log's metadata")),
            (None, None) => None,
        };
        let m = &log.measured;
        log.u_limit = self.u_limit(m, meta, logged.as_ref(), file);
        let name = log.path.display();
        match &logged {
            None if log_gains.is_some() => log.notes.push(format!(
                "{name} has no record of its controller's configuration (a log written before servo \
                 recorded it): discretisation from the [design] of the gains, derivative input, \
                 anti-windup and limit from the options, the gains file or the defaults; see the \
                 controller check"
            )),
            Some(l) if !l.missing().is_empty() => log.notes.push(format!(
                "{name}: the log's controller record lacks {}; those parts come from the options, \
                 the gains file or the defaults",
                l.missing().join(", ")
            )),
            _ => {}
        }
        // Feedforward: the run's selection, and the logged voltage if it has one.
        let ff_name = logged
            .as_ref()
            .and_then(|l| l.feedforward.clone())
            .or_else(|| meta.get(meta_keys::FEEDFORWARD).map(str::to_string));
        let ff_on = ff_name.as_deref().is_some_and(|n| n != "none");
        let ff_logged = meta
            .feedforward_v
            .as_ref()
            .filter(|f| f.len() == m.u_v.len() && f.iter().any(|v| v.is_finite() && *v != 0.0));
        log.feedforward = match (ff_logged, &ff_name) {
            (Some(_), n) => ControllerPart {
                part: "feedforward",
                value: n.clone().unwrap_or_else(|| "logged".into()),
                words: format!(
                    "feedforward {} added as logged (ff_v)",
                    n.as_deref().unwrap_or("of unknown terms")
                ),
                source: "from the log's samples".into(),
            },
            (None, Some(n)) if ff_on && meta.feedforward_v.is_none() => {
                log.notes.push(format!(
                    "{name}: the run added feedforward `{n}` but the log has no ff_v samples: the \
                     replay and the controller check run WITHOUT it and cannot reproduce the logged u"
                ));
                ControllerPart {
                    part: "feedforward",
                    value: format!("{n} (not replayed)"),
                    words: format!("feedforward {n} NOT replayed (no ff_v in the log)"),
                    source: "from the log's metadata".into(),
                }
            }
            (None, n) => ControllerPart {
                part: "feedforward",
                value: "none".into(),
                words: if ff_on {
                    format!(
                        "feedforward {} (zero throughout this log)",
                        n.as_deref().unwrap_or_default()
                    )
                } else {
                    "no feedforward".into()
                },
                source: if n.is_some() {
                    "from the log's metadata".into()
                } else {
                    "none known".into()
                },
            },
        };
        if ff_logged.is_some() {
            log.feedforward_v = meta.feedforward_v.clone();
        }
        if file.is_none() && logged.is_none() {
            return Ok(());
        }
        let src = PidSources {
            opts: &self.pid,
            logged: logged.as_ref(),
            gains_file: file,
        };
        // The period the loop ran at, as recorded (the log's time stamps give it to rounding).
        let ts_s = logged
            .as_ref()
            .and_then(|l| l.ts_s)
            .filter(|t| (t - m.dt_s).abs() <= 1e-6 * m.dt_s)
            .unwrap_or(m.dt_s);
        let mut r = pid_config(&src, ts_s, log.u_limit.clone())
            .with_context(|| format!("the controller of {name}"))?;
        r.parts.push(log.feedforward.clone());
        log.controller = Some(r);
        Ok(())
    }

    /// Checks the log's controller against the logged u; with --gains-from-log replaces it by the
    /// least-squares PID.
    fn check_gains(&self, log: &mut LogData) -> anyhow::Result<()> {
        let m = &log.measured;
        let (Some(r), Some(th)) = (&m.ref_rad, &m.theta_l_rad) else {
            if self.gains_from_log {
                bail!(
                    "--gains-from-log needs the reference and the position in {}",
                    log.path.display()
                );
            }
            return Ok(());
        };
        let limit = log.u_limit.as_ref().map(|l| l.0);
        let ff = log.feedforward_v.as_deref();
        let check = match ReplayController::of(log)? {
            Some(mut c) => check_controller(&mut c, r, th, &m.u_v, ff, limit, m.dt_s),
            // No controller: only the least-squares PID is wanted.
            None => check_controller(&mut |_: f64, _: f64| 0.0, r, th, &m.u_v, ff, limit, m.dt_s),
        };
        if self.gains_from_log {
            let [kp, ki, kd] = check.ls_gains.ok_or_else(|| {
                anyhow!("--gains-from-log: the logged u of {} does not determine PID gains (singular least squares)", log.path.display())
            })?;
            if !(kp >= 0.0 && ki >= 0.0 && kd >= 0.0) {
                bail!(
                    "--gains-from-log: the least-squares PID of {} has a negative gain (kp = {kp:.4}, ki = {ki:.4}, kd = {kd:.4}); the logged u is not a PID on the logged error",
                    log.path.display()
                );
            }
            let fitted = GainsFile {
                pid: PidSection {
                    kp,
                    ki,
                    kd,
                    tl_s: 0.0,
                    ts_s: m.dt_s,
                    kw: None,
                    u_limit_v: None,
                    derivative_on: None,
                },
                design: None,
            };
            let label = format!(
                "the least-squares fit to the logged u (fit {:.1} %)",
                check.ls_fit_percent
            );
            let src = PidSources {
                opts: &self.pid,
                logged: None,
                gains_file: Some((&fitted, &label)),
            };
            let mut resolved = pid_config(&src, m.dt_s, log.u_limit.clone())?;
            resolved.parts.push(log.feedforward.clone());
            let mut c = ReplayController::new(&resolved.config, ff)?;
            let fitted_check = check_controller(&mut c, r, th, &m.u_v, ff, limit, m.dt_s);
            log.controller = Some(resolved);
            log.check = Some(fitted_check);
        } else if log.controller.is_some() {
            log.check = Some(check);
        }
        Ok(())
    }

    /// For a log without u: the u the controller commanded, rebuilt from the logged reference
    /// and position (the controller ran on exactly these), limited as the replay limits it. The
    /// closed-loop replay then runs from the reference; the u compared is this rebuilt one.
    fn reconstruct_u(&self, log: &mut LogData) -> anyhow::Result<()> {
        let name = log.path.display().to_string();
        if self.gains_from_log {
            bail!("--gains-from-log: {name} has no u to fit the gains to; give --gains gains.toml");
        }
        if log.controller.is_none() {
            bail!(
                "{name} has no u (driver voltage): servo replays such a log in closed loop from the reference, which needs the controller that ran: give --gains gains.toml (the PID of `servo design` or the lab's gains)"
            );
        }
        let Some((limit, _)) = log.u_limit.clone() else {
            bail!(
                "{name} has no u, so the controller's output limit cannot be read off it: give --u-limit-v (e.g. 10 for a +/-10 V DAC) or `u_limit_v` in the gains file"
            );
        };
        let m = &log.measured;
        let (Some(r), Some(th)) = (&m.ref_rad, &m.theta_l_rad) else {
            return Ok(());
        };
        let mut c = ReplayController::of(log)?
            .ok_or_else(|| anyhow!("{name}: no controller to rebuild u"))?;
        let u: Vec<f64> = r
            .iter()
            .zip(th)
            .map(|(&rk, &tk)| c.update(rk, tk).clamp(-limit, limit))
            .collect();
        log.notes.push(format!(
            "{name} has no u: the closed loop is replayed from the reference with the controller (gains {}); the u shown is the controller's output on the logged position (rebuilt, not measured), limited to +/-{limit} V",
            log.controller
                .as_ref()
                .and_then(|g| g.part("gains"))
                .map(|p| p.source.as_str())
                .unwrap_or_default()
        ));
        if !self.json {
            if let Some(n) = log.notes.last() {
                eprintln!("note: {n}");
            }
        }
        log.record.u_v = Some(u.clone());
        log.measured.u_v = u;
        log.check = None;
        Ok(())
    }

    pub fn run(self) -> anyhow::Result<()> {
        self.run_report().map(|_| ())
    }

    /// As [`Compare::run`] (prints the same output, writes the same files), also returning the
    /// error ladder and the comparison of the final model (used by `servo demo`).
    pub fn run_report(self) -> anyhow::Result<(Vec<LadderStep>, ModelComparison)> {
        let model_file = ModelFile::load(&self.model)?;
        let mut plant = model_file.plant()?;
        let gains = match &self.gains {
            Some(p) => Some(GainsFile::load(p)?),
            None => None,
        };
        if let Some(l) = self.u_limit_v {
            if !(l.is_finite() && l > 0.0) {
                bail!("--u-limit-v must be a positive voltage [V], got {l}");
            }
        }
        if !(self.segment_s.is_finite() && self.segment_s > 0.0) {
            bail!("--segment-s must be > 0 s, got {}", self.segment_s);
        }
        let library = crate::effects_file::load_many(&self.effects)?;
        let adds: Vec<(String, Added)> = self
            .add
            .iter()
            .map(|s| Added::parse(s, &library).map(|e| (s.clone(), e)))
            .collect::<anyhow::Result<_>>()?;
        let opts = CompareOptions::default();
        let mut logs = Vec::new();
        for path in &self.logs {
            let (mut record, meta) = crate::io::read_log_with_meta(path, self.columns.as_deref())
                .with_context(|| format!("reading log {}", path.display()))?;
            // A lab log without u (angle, reference, current): the closed loop is replayed from
            // the controller and the reference; u is what that controller commanded.
            let no_u = record.u_v.is_none()
                && record.ref_rad.is_some()
                && (record.theta_l_rad.is_some() || record.theta_m_rad.is_some());
            if no_u {
                record.u_v = Some(vec![0.0; record.len()]);
            }
            if !self.json {
                for n in &meta.notes {
                    eprintln!("note: {n}");
                }
            }
            let measured = Measured::from_record(&record, plant.params.n, opts.speed_filter_hz)
                .map_err(|e| anyhow!("log {}: {e}", path.display()))?;
            let mut log = LogData {
                path: path.clone(),
                record,
                measured,
                controller: None,
                u_limit: None,
                feedforward_v: None,
                feedforward: ControllerPart {
                    part: "feedforward",
                    value: "none".into(),
                    words: "no feedforward".into(),
                    source: "none known".into(),
                },
                notes: Vec::new(),
                check: None,
            };
            self.log_controller(&mut log, &meta, gains.as_ref())?;
            if !self.json {
                for n in &log.notes {
                    eprintln!("note: {n}");
                }
            }
            if no_u {
                self.reconstruct_u(&mut log)?;
            } else {
                self.check_gains(&mut log)?;
            }
            logs.push(log);
        }
        let modes: Vec<ModeChoice> = logs
            .iter()
            .map(|l| self.mode_for(l))
            .collect::<anyhow::Result<_>>()?;

        let mut ladder = Vec::new();
        let first = self.compare_all(&plant, &logs, &modes, &opts)?;
        ladder.push(LadderStep {
            label: String::from("model as given"),
            effect: None,
            cmp_fit: pooled(&first),
            fitted: Vec::new(),
        });
        let mut current = first;
        let records: Vec<Record> = logs.iter().map(|l| l.record.clone()).collect();
        for (spec, eff) in &adds {
            let mut start = plant;
            let catalogue: Vec<EffectToFit> = match eff {
                Added::Catalogue(e) => vec![*e],
                Added::Custom(c) => {
                    start
                        .custom
                        .insert(*c)
                        .map_err(|e| anyhow!("--add {spec}: {e}"))?;
                    Vec::new()
                }
            };
            let fit = fit_model(&records, &start, &catalogue, &FitOptions::default())
                .map_err(|e| anyhow!("--add {spec}: fitting the effect to the logs failed: {e}"))?;
            plant = fit.plant;
            let cmp = self.compare_all(&plant, &logs, &modes, &opts)?;
            let fitted = fit
                .params
                .iter()
                .map(|p| {
                    json!({
                        "effect": p.effect.map(|k| k.name()),
                        "key": p.key, "unit": p.unit, "value": p.value,
                        "std_err": p.std_err, "fitted": p.fitted,
                    })
                })
                .chain(fit.custom.iter().map(|p| {
                    json!({
                        "effect": p.effect,
                        "key": p.key, "unit": p.unit, "value": p.value,
                        "std_err": p.std_err, "fitted": p.fitted,
                    })
                }))
                .collect();
            ladder.push(LadderStep {
                label: format!("+ {}", eff.name()),
                effect: Some(eff.name()),
                cmp_fit: pooled(&cmp),
                fitted,
            });
            current = cmp;
        }

        if let Some(path) = &self.save {
            let mut mf = ModelFile::from_plant(&plant);
            mf.sensors = model_file.sensors;
            let mut prov = model_file.provenance.clone().unwrap_or_default();
            prov.insert(
                "compare_model".into(),
                toml::Value::String(self.model.display().to_string()),
            );
            prov.insert(
                "compare_logs".into(),
                toml::Value::Array(
                    self.logs
                        .iter()
                        .map(|p| toml::Value::String(p.display().to_string()))
                        .collect(),
                ),
            );
            if !self.add.is_empty() {
                prov.insert(
                    "compare_added".into(),
                    toml::Value::Array(
                        self.add
                            .iter()
                            .map(|s| toml::Value::String(s.clone()))
                            .collect(),
                    ),
                );
            }
            mf.provenance = Some(prov);
            mf.save(path)?;
        }
        if let Some(path) = &self.plot {
            let mut panels = Vec::new();
            for (log, r) in logs.iter().zip(&current.reports) {
                let name = log
                    .path
                    .file_name()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                for (_, svg) in compare_figures_svg(r, &name)? {
                    panels.push(svg);
                }
            }
            std::fs::write(path, stack_svg(&panels))
                .with_context(|| format!("writing plot {}", path.display()))?;
        }
        if self.json {
            let v = to_json(&logs, &modes, &current, &ladder, &opts);
            outln!("{}", serde_json::to_string_pretty(&v)?);
        } else {
            print_text(
                &logs,
                &modes,
                &current,
                &ladder,
                &opts,
                self.save.as_deref(),
                self.plot.as_deref(),
            );
        }
        Ok((ladder, current))
    }
}

/// An effect given to `--add`: from the catalogue, or user-defined (from `--effects`) with its
/// unknown parameters NaN.
#[derive(Debug, Clone, Copy)]
pub enum Added {
    Catalogue(EffectToFit),
    Custom(servo_core::custom::CustomActive),
}

impl Added {
    /// Parses `name[:key=value,...]`: a user effect of `library` when the name is one, else a
    /// catalogue effect.
    pub fn parse(spec: &str, library: &crate::effects_file::EffectsFile) -> anyhow::Result<Added> {
        let (name, rest) = match spec.split_once(':') {
            Some((n, r)) => (n.trim(), Some(r)),
            None => (spec.trim(), None),
        };
        let Some(def) = library.get(name) else {
            return EffectToFit::parse(spec).map(Added::Catalogue).map_err(|e| {
                if library.defs.is_empty() {
                    anyhow!("--add {spec}: {e}")
                } else {
                    anyhow!(
                        "--add {spec}: {e}; the effects files define {}",
                        library.names()
                    )
                }
            });
        };
        let mut active = def.active();
        for v in active.values.iter_mut() {
            *v = f64::NAN;
        }
        for item in rest.into_iter().flat_map(|r| r.split(',')).map(str::trim) {
            if item.is_empty() {
                continue;
            }
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| anyhow!("--add {spec}: expected key=value, got `{item}`"))?;
            let x: f64 = v.trim().parse().map_err(|_| {
                anyhow!(
                    "--add {spec}: `{}` needs a number, got `{}`",
                    k.trim(),
                    v.trim()
                )
            })?;
            active
                .set(k.trim(), x)
                .map_err(|e| anyhow!("--add {spec}: {e}"))?;
        }
        Ok(Added::Custom(active))
    }

    /// The effect's name.
    pub fn name(&self) -> &'static str {
        match self {
            Added::Catalogue(e) => e.effect.kind.name(),
            Added::Custom(c) => c.name(),
        }
    }
}

/// Figures of one rung of the error ladder.
pub struct LadderStep {
    pub label: String,
    pub effect: Option<&'static str>,
    /// Pooled figures of each signal over the logs.
    pub cmp_fit: Vec<(SignalKind, Figures)>,
    /// Fitted parameters (JSON rows) of this step.
    pub fitted: Vec<Value>,
}

/// Figures of every signal pooled over the logs (the measurement and model concatenated), in the
/// order of first appearance; the first is the headline of the first log.
pub fn pooled(c: &ModelComparison) -> Vec<(SignalKind, Figures)> {
    let mut kinds: Vec<SignalKind> = Vec::new();
    if let Some(r) = c.reports.first() {
        kinds.push(r.headline_signal().kind);
    }
    for r in &c.reports {
        for s in &r.signals {
            if !kinds.contains(&s.kind) {
                kinds.push(s.kind);
            }
        }
    }
    kinds
        .into_iter()
        .map(|k| {
            let (mut y, mut yh) = (Vec::new(), Vec::new());
            for r in &c.reports {
                if let Some(s) = r.signals.iter().find(|s| s.kind == k) {
                    y.extend_from_slice(&s.measured);
                    yh.extend_from_slice(&s.model);
                }
            }
            (k, Figures::of(&y, &yh))
        })
        .collect()
}

fn figures_json(kind: SignalKind, f: &Figures) -> Value {
    json!({
        "signal": kind.name(), "unit": kind.unit(),
        "fit_percent": finite(f.fit_percent), "rmse": finite(f.rmse), "max_error": finite(f.max_abs_error),
        "mean_error": finite(f.mean_error), "samples": f.samples,
    })
}

fn finite(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// Regime statistics pooled over the logs whose headline is `kind`.
fn pooled_regimes(c: &ModelComparison, kind: SignalKind) -> Vec<Value> {
    let mut per: Vec<(Regime, usize, f64, f64)> =
        Regime::ALL.iter().map(|r| (*r, 0, 0.0, 0.0)).collect();
    let (mut total_n, mut total_se) = (0usize, 0.0);
    for r in c
        .reports
        .iter()
        .filter(|r| r.headline_signal().kind == kind)
    {
        for (e, g) in r.residual.iter().zip(&r.classification.regime) {
            let i = Regime::ALL.iter().position(|x| x == g).unwrap_or(0);
            per[i].1 += 1;
            per[i].2 += e * e;
            per[i].3 += e;
            total_n += 1;
            total_se += e * e;
        }
    }
    let first = c.reports.iter().find(|r| r.headline_signal().kind == kind);
    per.iter()
        .map(|(g, n, se, s)| {
            let time = 100.0 * *n as f64 / total_n.max(1) as f64;
            let err = if total_se > 0.0 {
                100.0 * se / total_se
            } else {
                0.0
            };
            json!({
                "regime": g.name(),
                "where": first.map(|r| regime_phrase(*g, &r.classification, &Default::default())),
                "samples": n,
                "time_share_pct": time,
                "error_share_pct": err,
                "rms": if *n > 0 { (se / *n as f64).sqrt() } else { 0.0 },
                "mean": if *n > 0 { s / *n as f64 } else { 0.0 },
                "concentration": if time > 0.0 { err / time } else { 0.0 },
                "suspects": g.suspects(),
            })
        })
        .collect()
}

fn to_json(
    logs: &[LogData],
    modes: &[ModeChoice],
    c: &ModelComparison,
    ladder: &[LadderStep],
    opts: &CompareOptions,
) -> Value {
    let pooled_figs = pooled(c);
    let (hk, hf) = pooled_figs[0];
    let effects: Vec<Value> = c
        .plant
        .effects
        .iter()
        .map(|e| {
            let params: serde_json::Map<String, Value> = e
                .iter()
                .map(|(p, v)| (p.key.to_string(), json!(v)))
                .collect();
            let units: serde_json::Map<String, Value> = e
                .iter()
                .map(|(p, _)| (p.key.to_string(), json!(p.unit)))
                .collect();
            json!({ "effect": e.kind.name(), "params": params, "units": units })
        })
        .collect();
    let p = c.plant.params;
    let base = json!({
        "j_eq": p.j_eq(), "b_eq": c.plant.b_eq(), "tau_sf": c.plant.tau_sf(), "r_eq": p.r_eq(),
        "k_e": p.k_e, "k_t": p.k_t, "k_drv": p.k_drv, "n": p.n,
    });
    let ladder_json: Vec<Value> = ladder
        .iter()
        .map(|s| {
            let (k, f) = s.cmp_fit[0];
            json!({
                "step": s.label, "effect": s.effect, "signal": k.name(), "unit": k.unit(),
                "fit_percent": finite(f.fit_percent), "rmse": finite(f.rmse), "max_error": finite(f.max_abs_error),
                "signals": s.cmp_fit.iter().map(|(k, f)| figures_json(*k, f)).collect::<Vec<_>>(),
                "fitted_params": s.fitted,
            })
        })
        .collect();
    let mut windows: Vec<(f64, Value)> = Vec::new();
    let total_se: f64 = c
        .reports
        .iter()
        .filter(|r| r.headline_signal().kind == hk)
        .map(|r| r.residual.iter().map(|e| e * e).sum::<f64>())
        .sum();
    for (log, r) in logs
        .iter()
        .zip(&c.reports)
        .filter(|(_, r)| r.headline_signal().kind == hk)
    {
        let se_log: f64 = r.residual.iter().map(|e| e * e).sum();
        for w in &r.worst_windows {
            let share = if total_se > 0.0 {
                w.error_share_pct * se_log / total_se
            } else {
                0.0
            };
            windows.push((
                share,
                json!({
                    "log": log.path.display().to_string(),
                    "t_start_s": w.t_start_s, "t_end_s": w.t_end_s,
                    "error_share_pct": share, "rms": w.rms, "mean": w.mean,
                    "regime": w.regime.name(),
                    "omega_min_rad_s": w.omega_min_rad_s, "omega_max_rad_s": w.omega_max_rad_s,
                    "u_abs_max_v": w.u_abs_max_v,
                    "description": describe_window(w, r, opts),
                }),
            ));
        }
    }
    windows.sort_by(|a, b| b.0.total_cmp(&a.0));
    let r0 = &c.reports[0];
    let x = &r0.input_xcorr;
    let per_log: Vec<Value> = logs
        .iter()
        .zip(c.reports.iter().zip(modes))
        .map(|(l, (r, mc))| {
            json!({
                "log": l.path.display().to_string(),
                "mode": r.mode.name(), "mode_reason": mc.reason,
                "samples": r.time_s.len(), "dt_s": r.dt_s,
                "speed_derived_from_position": l.measured.speed_derived,
                "controller": controller_json(l),
                "signal": r.headline_signal().kind.name(),
                "signals": r.signals.iter().map(|s| figures_json(s.kind, &s.figures)).collect::<Vec<_>>(),
                "whiteness": whiteness_json(r),
                "periodic": r.periodic.iter().map(|p| json!({
                    "angle": p.source.name(), "harmonic": p.harmonic, "share_pct": p.share_pct,
                    "amplitude": p.amplitude, "phase_rad": p.phase_rad, "p_value": p.p_value, "significant": p.significant,
                })).collect::<Vec<_>>(),
                "findings": r.findings,
            })
        })
        .collect();
    json!({
        "mode": r0.mode.name(),
        "mode_reason": modes[0].reason,
        "controller": controller_json(&logs[0]),
        "signal": hk.name(),
        "unit": hk.unit(),
        "fit_percent": finite(hf.fit_percent),
        "rmse": finite(hf.rmse),
        "max_error": finite(hf.max_abs_error),
        "signals": pooled_figs.iter().map(|(k, f)| figures_json(*k, f)).collect::<Vec<_>>(),
        "effects": effects,
        "custom": c.plant.custom.iter().map(|e| {
            let params: serde_json::Map<String, Value> = e
                .def
                .params()
                .iter()
                .zip(e.values())
                .map(|(p, v)| (p.key.to_string(), json!(v)))
                .collect();
            let units: serde_json::Map<String, Value> = e
                .def
                .params()
                .iter()
                .map(|p| (p.key.to_string(), json!(p.unit)))
                .collect();
            json!({"effect": e.name(), "acts_on": e.def.acts_on().name(), "expr": e.def.expr(), "params": params, "units": units})
        }).collect::<Vec<_>>(),
        "base": base,
        "ladder": ladder_json,
        "regimes": pooled_regimes(c, hk),
        "worst_windows": windows.into_iter().take(opts.worst_count).map(|(_, v)| v).collect::<Vec<_>>(),
        "whiteness": whiteness_json(r0),
        "input_xcorr": json!({
            "input": r0.input_name, "max_lag": x.max_lag, "bound99": x.bound99, "lags_outside": x.lags_outside,
            "peak_lag": x.peak_lag, "peak": x.peak, "xcorr": x.xcorr,
        }),
        "findings": r0.findings,
        "logs": per_log,
    })
}

/// The controller check in words (None without a controller).
pub fn controller_words(log: &LogData) -> Option<String> {
    let c = log.check.as_ref()?;
    let mut s = format!(
        "controller check: this controller reproduces the logged u with fit {:.2} % (RMS {:.3e} V over {} samples inside the output limit)",
        c.fit_percent, c.rms_v, c.samples
    );
    // The logged u carries the encoder's quantisation through K_D, which no PID reproduces: judge
    // the given gains against the best PID on the same samples, not against 100 %.
    if c.fit_percent < c.ls_fit_percent - 10.0 {
        if let Some([kp, ki, kd]) = c.ls_gains {
            s.push_str(&format!(
                "\nWARNING: these gains do not reproduce the logged u, so the replay will differ for reasons unrelated to the plant. The PID that best reproduces it is kp = {kp:.4} V/rad, ki = {ki:.4} V/(rad s), kd = {kd:.4} V s/rad (fit {:.1} %): try --gains-from-log.",
                c.ls_fit_percent
            ));
        }
    }
    Some(s)
}

/// The controller of the replay in words: every part with where it came from.
pub fn controller_description(log: &LogData) -> Option<String> {
    log.controller
        .as_ref()
        .map(|c| format!("controller: {}", c.describe()))
}

fn controller_json(log: &LogData) -> Value {
    let Some(r) = &log.controller else {
        return Value::Null;
    };
    let g = &r.config;
    let c = log.check.as_ref();
    let value = |part: &str| r.part(part).map(|p| p.value.clone());
    let parts: serde_json::Map<String, Value> = r
        .parts
        .iter()
        .map(|p| {
            (
                p.part.to_string(),
                json!({ "value": p.value, "text": p.words, "source": p.source }),
            )
        })
        .collect();
    json!({
        "source": r.part("gains").map(|p| p.source.clone()),
        "kp": g.kp, "ki": g.ki, "kd": g.kd, "tl_s": g.tl_s, "ts_s": g.ts_s,
        "discretization": value("discretization"),
        "derivative_on": value("derivative_on"),
        "anti_windup": value("anti_windup"),
        "kw": match g.anti_windup { AntiWindup::BackCalculation { kw } => json!(kw), _ => Value::Null },
        "u_limit_v": log.u_limit.as_ref().map(|l| l.0),
        "feedforward": value("feedforward"),
        "parts": parts,
        "description": r.describe(),
        "notes": log.notes,
        "check_fit_percent": c.map(|c| finite(c.fit_percent)),
        "check_rms_v": c.map(|c| finite(c.rms_v)),
        "check_samples": c.map(|c| c.samples),
        "ls_gains": c.and_then(|c| c.ls_gains).map(|[kp, ki, kd]| json!({"kp": kp, "ki": ki, "kd": kd})),
        "ls_fit_percent": c.map(|c| finite(c.ls_fit_percent)),
    })
}

fn whiteness_json(r: &CompareReport) -> Value {
    let w = &r.whiteness;
    json!({
        "signal": r.headline_signal().kind.name(),
        "ljung_box_q": finite(w.ljung_box_q), "dof": w.ljung_box_dof, "p_value": finite(w.ljung_box_p), "white": w.white,
        "bound99": w.bound99, "lags_outside": w.lags_outside, "correlation_lags": w.correlation_lags,
        "autocorr": w.autocorr,
    })
}

fn print_text(
    logs: &[LogData],
    modes: &[ModeChoice],
    c: &ModelComparison,
    ladder: &[LadderStep],
    opts: &CompareOptions,
    save: Option<&Path>,
    plot: Option<&Path>,
) {
    for ((log, r), mc) in logs.iter().zip(&c.reports).zip(modes) {
        outln!(
            "== {} ({} samples, {:.3} s, dt = {:.4} s)",
            log.path.display(),
            r.time_s.len(),
            r.time_s.len() as f64 * r.dt_s,
            r.dt_s
        );
        outln!("mode: {} -- {}", r.mode.name(), mc.reason);
        if let Some(line) = controller_description(log) {
            outln!("{line}");
        }
        if let Some(line) = controller_words(log) {
            outln!("{line}");
        }
        if log.measured.speed_derived {
            let model_side = if matches!(r.mode, ReplayMode::ClosedLoop | ReplayMode::Speed) {
                "the model's speed is derived from its position the same way"
            } else {
                "the model's speed is its state at the end of each prediction"
            };
            outln!(
                "speed: derived from position (zero-phase {:.0} Hz low-pass + central differences); {model_side}",
                opts.speed_filter_hz
            );
        }
        outln!(
            "{:<10} {:>9} {:>14} {:>14} {:>14}",
            "signal",
            "fit [%]",
            "RMSE",
            "max error",
            "mean error"
        );
        for s in &r.signals {
            let f = &s.figures;
            outln!(
                "{:<10} {:>9.2} {:>14} {:>14} {:>14}",
                format!("{} [{}]", s.kind.name(), s.kind.unit()),
                f.fit_percent,
                format!("{:.4e}", f.rmse),
                format!("{:.4e}", f.max_abs_error),
                format!("{:.3e}", f.mean_error)
            );
        }
        outln!("where the {} error sits:", r.headline_signal().kind.words());
        outln!(
            "  {:<16} {:>8} {:>9} {:>12}",
            "regime",
            "time %",
            "error %",
            "rms"
        );
        for s in r.regimes.iter().filter(|s| s.samples > 0) {
            outln!(
                "  {:<16} {:>8.1} {:>9.1} {:>12.4e}",
                s.regime.name(),
                s.time_share_pct,
                s.error_share_pct,
                s.rms
            );
        }
        outln!("findings:");
        for f in &r.findings {
            outln!("  - {f}");
        }
        if !r.worst_windows.is_empty() {
            outln!("worst windows:");
            for (i, w) in r.worst_windows.iter().enumerate() {
                outln!("  {}. {}", i + 1, describe_window(w, r, opts));
            }
        }
        outln!();
    }
    if ladder.len() > 1 || logs.len() > 1 {
        let k = ladder[0].cmp_fit[0].0;
        outln!("error ladder ({} over all logs):", k.words());
        let mut prev: Option<f64> = None;
        for s in ladder {
            let f = s.cmp_fit[0].1;
            let change = prev
                .map(|p| format!(" ({:+.1} % RMSE)", 100.0 * (f.rmse - p) / p))
                .unwrap_or_default();
            outln!(
                "  {:<24} fit {:>7.2} %   RMSE {}{}",
                s.label,
                f.fit_percent,
                with_unit(f.rmse, k),
                change
            );
            prev = Some(f.rmse);
        }
    }
    if ladder.len() > 1 {
        outln!("model after the added effects:");
        for e in c.plant.effects.iter() {
            let kv: Vec<String> = e
                .iter()
                .map(|(p, v)| format!("{} = {:.4e} {}", p.key, v, p.unit))
                .collect();
            outln!("  {:<11} {}", e.kind.name(), kv.join(", "));
        }
        for e in c.plant.custom.iter() {
            let kv: Vec<String> = e
                .def
                .params()
                .iter()
                .zip(e.values())
                .map(|(p, v)| format!("{} = {:.4e} {}", p.key, v, p.unit))
                .collect();
            outln!(
                "  {:<11} {} = {}: {} (user-defined, {})",
                e.name(),
                e.def.acts_on().name(),
                e.def.expr(),
                kv.join(", "),
                e.def.acts_on().unit()
            );
        }
        outln!(
            "  base        J_eq = {:.4e} kg m^2, R_eq = {:.4} ohm, k_drv = {:.4}",
            c.plant.params.j_eq(),
            c.plant.params.r_eq(),
            c.plant.params.k_drv
        );
    }
    if let Some(p) = save {
        outln!("model written to {}", p.display());
    }
    if let Some(p) = plot {
        outln!("figures written to {}", p.display());
    }
}

/// Mean of `y` in `bins` equal bins of `x` over [lo, hi]; bins with fewer than 3 samples are
/// skipped. Returns (bin centres, means).
/// One titled chart of a single series: (title, SVG).
fn one_series_chart(
    title: String,
    x_label: &str,
    y_label: &str,
    label: &str,
    x: &[f64],
    y: &[f64],
) -> anyhow::Result<(String, String)> {
    let svg = line_chart_svg(
        &Chart {
            title: &title,
            x_label,
            y_label,
            ..Default::default()
        },
        &[Series { label, x, y }],
    )?;
    Ok((title, svg))
}

fn binned_mean(x: &[f64], y: &[f64], lo: f64, hi: f64, bins: usize) -> (Vec<f64>, Vec<f64>) {
    let mut s = vec![0.0; bins];
    let mut n = vec![0usize; bins];
    let w = (hi - lo) / bins as f64;
    if w.is_nan() || w <= 0.0 {
        return (Vec::new(), Vec::new());
    }
    for (a, b) in x.iter().zip(y) {
        if *a < lo || *a > hi {
            continue;
        }
        let i = (((a - lo) / w) as usize).min(bins - 1);
        s[i] += b;
        n[i] += 1;
    }
    let (mut cx, mut cy) = (Vec::new(), Vec::new());
    for i in 0..bins {
        if n[i] >= 3 {
            cx.push(lo + (i as f64 + 0.5) * w);
            cy.push(s[i] / n[i] as f64);
        }
    }
    (cx, cy)
}

/// The compare figures of one report as inline SVG strings (title, svg): measurement vs model of
/// the headline signal, the residual over time, the residual against the measured speed and
/// against the measured position (binned means). Used by `--plot` and the diagnose HTML report.
pub fn compare_figures_svg(r: &CompareReport, name: &str) -> anyhow::Result<Vec<(String, String)>> {
    let h = r.headline_signal();
    let (k, unit) = (h.kind.name(), h.kind.unit());
    let mut out = Vec::new();
    let t1 = format!(
        "{name}: {} measured vs model ({}, fit {:.1} %)",
        h.kind.words(),
        r.mode.name(),
        h.figures.fit_percent
    );
    let yl = format!("{k} [{unit}]");
    let svg = line_chart_svg(
        &Chart {
            title: &t1,
            x_label: "t [s]",
            y_label: &yl,
            ..Default::default()
        },
        &[
            Series {
                label: "measured",
                x: &r.time_s,
                y: &h.measured,
            },
            Series {
                label: "model",
                x: &r.time_s,
                y: &h.model,
            },
        ],
    )?;
    out.push((t1, svg));
    let t2 = format!(
        "{name}: residual (measured - model), RMSE {:.3e} {unit}",
        h.figures.rmse
    );
    let rl = format!("residual [{unit}]");
    out.push(one_series_chart(
        t2,
        "t [s]",
        &rl,
        "residual",
        &r.time_s,
        &r.residual,
    )?);
    let w = &r.omega_l_rad_s;
    let lim = servo_core::compare::regimes::abs_percentile(w, 0.995).max(1e-9);
    let (bx, by) = binned_mean(w, &r.residual, -lim, lim, 60);
    let t3 = format!("{name}: residual vs measured load speed (mean per speed bin)");
    out.push(one_series_chart(
        t3,
        "omega_l [rad/s]",
        &rl,
        "mean residual",
        &bx,
        &by,
    )?);
    if let Some(th) = &r.theta_l_rad {
        let (lo, hi) = th
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        let tau = std::f64::consts::TAU;
        let (xs, lo, hi, xl): (Vec<f64>, f64, f64, &str) = if hi - lo > tau {
            (
                th.iter().map(|v| v.rem_euclid(tau)).collect(),
                0.0,
                tau,
                "theta_l mod 2 pi [rad]",
            )
        } else {
            (th.clone(), lo, hi, "theta_l [rad]")
        };
        let (bx, by) = binned_mean(&xs, &r.residual, lo, hi, 90);
        let t4 = format!("{name}: residual vs measured load position (mean per position bin)");
        out.push(one_series_chart(t4, xl, &rl, "mean residual", &bx, &by)?);
    }
    Ok(out)
}

/// Stacks SVG documents vertically into one SVG document.
pub fn stack_svg(panels: &[String]) -> String {
    let mut y = 0u32;
    let mut width = 0u32;
    let mut body = String::new();
    for p in panels {
        let (w, h) = svg_size(p).unwrap_or((900, 400));
        let inner = match p.find("<svg") {
            Some(i) => &p[i..],
            None => p.as_str(),
        };
        body.push_str(&inner.replacen("<svg", &format!("<svg x=\"0\" y=\"{y}\""), 1));
        body.push('\n');
        y += h;
        width = width.max(w);
    }
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{y}\" viewBox=\"0 0 {width} {y}\">\n{body}</svg>\n"
    )
}

fn svg_size(svg: &str) -> Option<(u32, u32)> {
    let i = svg.find("<svg")?;
    let head = &svg[i..i + svg[i..].find('>')?];
    let attr = |name: &str| -> Option<u32> {
        let j = head.find(&format!("{name}=\""))? + name.len() + 2;
        let rest = &head[j..];
        rest[..rest.find('"')?].trim_end_matches("px").parse().ok()
    };
    Some((attr("width")?, attr("height")?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replay_controller_adds_the_logged_feedforward() {
        use servo_core::control::PidGains;
        let cfg = PidConfig::new(
            PidGains {
                kp: 2.0,
                ki: 10.0,
                kd: 0.1,
                tl_s: 0.0,
            },
            1e-3,
        )
        .with_symmetric_limit(100.0);
        let ff = [0.5, -0.25];
        let mut c = ReplayController::new(&cfg, Some(&ff)).unwrap();
        // Backward Euler: I_0 = 10 * 1e-3 * 1 = 0.01; no derivative kick at the first sample.
        assert!((Controller::update(&mut c, 1.0, 0.0) - (2.01 + 0.5)).abs() < 1e-12);
        // e = 0.5: P = 1, I = 0.015, D = 0.1 * (-0.5) / 1e-3 = -50
        assert!((Controller::update(&mut c, 0.5, 0.0) - (1.015 - 50.0 - 0.25)).abs() < 1e-9);
        // Past the logged samples: no feedforward; the limit holds.
        assert_eq!(Controller::update(&mut c, 1e3, 0.0), 100.0);
    }

    #[test]
    fn stacks_panels() {
        let a = line_chart_svg(
            &Chart::default(),
            &[Series {
                label: "a",
                x: &[0.0, 1.0],
                y: &[0.0, 1.0],
            }],
        )
        .unwrap();
        let s = stack_svg(&[a.clone(), a]);
        assert!(
            s.contains("height=\"800\"") && s.matches("<svg").count() == 3,
            "{}",
            &s[..200]
        );
    }
}
