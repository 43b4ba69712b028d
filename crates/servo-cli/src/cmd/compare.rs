//! `servo compare`: simulate the model with the logged input, compare with the measurement, show
//! how well it fits and where it fails, and add catalogue effects to watch the error fall.

use crate::gains_file::{GainsFile, PidSection};
use crate::io::{meta_keys, LogMeta};
use crate::model_file::ModelFile;
use crate::plot::{line_chart_svg, Chart, Series};
use anyhow::{anyhow, bail, Context};
use serde_json::{json, Value};
use servo_core::compare::controller_check::{check_controller, ControllerCheck};
use servo_core::compare::regimes::{detect_u_limit, Regime};
use servo_core::compare::report::{describe_window, regime_phrase_on, with_unit_on};
use servo_core::compare::suspects::check_compensated;
use servo_io::controller::{
    pid_config, ControllerPart, LoggedController, PidOptions, PidSources, ResolvedPid,
};
mod added;
mod plots;
mod prepare;
mod report_json;
mod report_text;
mod save;
mod smart;
mod tracking;

pub use added::{Added, ParseAdded};
pub use plots::{compare_figures_svg, compare_figures_svg_on, stack_svg};
pub use report_text::{controller_description, controller_words, plant_and_controller};
pub use servo_core::compare::logs::LadderStep;
use servo_core::compare::logs::{
    choose_mode, error_ladder, rebuild_u, ErrorLadder, LadderError, LogReplay, ModeRefusal,
};
pub use servo_core::compare::{pooled, ModeChoice, ModelComparison, ReplayController};
use servo_core::compare::{
    CompareOptions, CompareReport, Figures, Measured, ReplayMode, SignalKind,
};
use {report_json::*, report_text::*};

/// The replay controller of `log` (None when the log's controller is unknown).
pub fn replay_controller(log: &LogData) -> anyhow::Result<Option<ReplayController<'_>>> {
    log.replay()
        .controller()
        .map_err(|e| anyhow!("controller: {e}"))
}
use servo_core::control::pid::AntiWindup;
use servo_core::record::Record;
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
    #[command(flatten)]
    pub part: crate::log_part::LogPartArgs,
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
    /// Write the (extended) model to this file. With --add, only when the model with the
    /// effects predicts the logs at least as well as the model it started from (on the replay
    /// and on held-out blocks refitted without them); otherwise it says so and writes nothing.
    #[arg(long, value_name = "model.toml")]
    pub save: Option<PathBuf>,
    /// With --save: write the model even when the added effects made it predict worse (it says
    /// so, and records it in the file's [provenance]).
    #[arg(long, requires = "save")]
    pub force: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write the figures (measurement vs model, residual, residual vs speed and position) as one SVG.
    #[arg(long, value_name = "out.svg")]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub smart: smart::SmartCompareArgs,
}

/// One log, read and checked.
pub struct LogData {
    pub path: PathBuf,
    /// The path as printed.
    pub name: String,
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
    /// The effects the run compensated (the log's `compensated_effects`).
    pub compensated: Vec<servo_core::effects::EffectKind>,
    /// The run's reference as its metadata records it (`--ref` text or experiment file).
    pub reference: Option<String>,
}

impl LogData {
    /// The log as the library replays it.
    pub fn replay(&self) -> LogReplay<'_> {
        LogReplay {
            name: &self.name,
            measured: &self.measured,
            controller: self.controller.as_ref().map(|c| &c.config),
            feedforward_v: self.feedforward_v.as_deref(),
            u_limit_v: self.u_limit.as_ref().map(|l| l.0),
        }
    }
}

impl Compare {
    pub fn run(self) -> anyhow::Result<()> {
        match ModelFile::load(&self.model)? {
            m if smart::applies(&m) => smart::run(&self, &m),
            _ => self.run_report().map(|_| ()),
        }
    }

    /// As [`Compare::run`] (prints the same output, writes the same files), also returning the
    /// error ladder and the comparison of the final model (used by `servo demo`).
    pub fn run_report(self) -> anyhow::Result<(Vec<LadderStep>, ModelComparison)> {
        let model_file = ModelFile::load(&self.model)?;
        model_file.warn_defaults(&format!("--model {}", self.model.display()), &[]);
        let plant = model_file.plant()?;
        let start = plant;
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
        // On a linear axis the reports are in m, m/s and N (the analysis runs on the equivalent
        // rotation either way).
        let axis = crate::axis::Axis::of(&model_file);
        let opts = CompareOptions {
            metres_per_rad: model_file.transmission.metres_per_rad(),
            ..CompareOptions::default()
        };
        let mut logs = Vec::new();
        self.part.check(self.logs.len())?;
        let mut parts = Vec::new();
        for (k, path) in self.logs.iter().enumerate() {
            let (mut record, mut meta) =
                crate::io::read_log_checked(path, self.columns.as_deref(), &model_file)
                    .with_context(|| format!("reading log {}", path.display()))?;
            model_file
                .drive
                .prepare(&mut record)
                .map_err(|e| anyhow!("reading log {}: {e}", path.display()))?;
            let used = self.part.apply(&mut record, path, k, self.logs.len())?;
            meta.feedforward_v = meta.feedforward_v.map(|f| used.slice_of(&f).to_vec());
            parts.push(used);
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
                name: path.display().to_string(),
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
                compensated: meta
                    .get(meta_keys::COMPENSATED_EFFECTS)
                    .map(|v| {
                        v.split(',')
                            .filter_map(|n| servo_core::effects::EffectKind::from_name(n.trim()))
                            .collect()
                    })
                    .unwrap_or_default(),
                reference: meta.reference().map(str::to_string),
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

        let records: Vec<Record> = logs.iter().map(|l| l.record.clone()).collect();
        let replays: Vec<LogReplay> = logs.iter().map(LogData::replay).collect();
        let effects: Vec<Added> = adds.iter().map(|a| a.1).collect();
        let ErrorLadder {
            steps: ladder,
            plant,
            comparison: current,
        } = error_ladder(&plant, &replays, &modes, &records, &effects, &opts).map_err(
            |e| match e {
                LadderError::Custom { rung, error, .. } => {
                    anyhow!("--add {}: {error}", adds[rung].0)
                }
                LadderError::Fit { rung, source, .. } => anyhow!(
                    "--add {}: fitting the effect to the logs failed: {source}",
                    adds[rung].0
                ),
                e => anyhow::Error::new(e),
            },
        )?;

        // The effects a run compensated, each checked against its log: is the model without
        // it a better prediction (a wrong compensation)?
        let compensated: Vec<_> = logs.iter().map(|l| l.compensated.clone()).collect();
        let checks = if compensated.iter().any(|c| !c.is_empty()) {
            check_compensated(&plant, &current, &replays, &modes, &compensated, &opts)?
        } else {
            Vec::new()
        };

        let saved = match &self.save {
            Some(path) => Some(save::gate_and_save(
                &self,
                path,
                &model_file,
                &start,
                &plant,
                &records,
                &effects,
                &ladder,
            )?),
            None => None,
        };
        let refitted = save::refitted_line(&start, &plant, &ladder);
        if let Some(path) = &self.plot {
            let mut panels = Vec::new();
            for (log, r) in logs.iter().zip(&current.reports) {
                let name = log
                    .path
                    .file_name()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                for (_, svg) in compare_figures_svg_on(r, &name, opts.metres_per_rad)? {
                    panels.push(svg);
                }
            }
            crate::io::output::write_file(path, "plot", stack_svg(&panels))?;
        }
        if self.json {
            let mut v = to_json(&logs, &modes, &current, &ladder, &opts);
            if !effects.is_empty() {
                v["refitted_base"] = save::refitted_json(&start, &plant);
            }
            if let Some(s) = &saved {
                v["save"] = s.json();
            }
            if let Some(a) = &axis {
                linear_json(&mut v, a, &current);
            }
            v["log_parts"] = crate::log_part::json(&parts);
            if !checks.is_empty() {
                v["compensation_checks"] = report_json::compensation_checks(&logs, &checks);
            }
            if let Some(t) =
                tracking::tracking_json(&tracking::tracking_ladders(&logs, &model_file, &plant))
            {
                v["tracking"] = t;
            }
            crate::json_out::emit(&v)?;
        } else {
            out!("{}", crate::log_part::text(&parts));
            print_text(
                &logs,
                &modes,
                &current,
                &ladder,
                &opts,
                refitted.as_deref(),
                &saved
                    .as_ref()
                    .map(save::SaveOutcome::lines)
                    .unwrap_or_default(),
                self.plot.as_deref(),
                axis.as_ref(),
                &self.model,
            );
            for line in report_text::compensation_lines(&logs, &checks, &self.model) {
                outln!("{line}");
            }
            for line in
                tracking::tracking_lines(&tracking::tracking_ladders(&logs, &model_file, &plant))
            {
                outln!("{line}");
            }
        }
        Ok((ladder, current))
    }
}

#[cfg(test)]
mod tests;
