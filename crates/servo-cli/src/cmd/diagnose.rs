//! `servo diagnose LOG... --model model.toml`: which physical effect is the model missing?
//!
//! Every catalogue effect the model lacks is fitted with the base parameters (see
//! `servo_core::diagnose`) and ranked; `--auto` iterates diagnose, add the winner, refit, until
//! nothing significant is left, and prints the error ladder.

mod report_compensation;
mod report_html;
mod report_json;
mod report_short;
mod report_text;

use report_html::*;
use report_json::*;
use report_short::*;
use report_text::*;

use crate::model_file::ModelFile;
use crate::plot::{line_chart_svg, Chart, Series};
use anyhow::{anyhow, Context};
use serde_json::{json, Value};
use servo_core::diagnose::{
    self, regimes::Regime, BalanceReport, Candidate, DiagnoseOptions, Diagnosis, Rung, Thresholds,
};
use servo_core::effects::EffectKind;
use servo_core::fit::{Dataset, Equation};
use servo_core::record::Record;
use servo_core::Plant;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, clap::Parser)]
pub struct Diagnose {
    /// Logs (MCAP, CSV or MATLAB .mat) of the same plant; open-loop and closed-loop runs are used together.
    #[arg(required = true)]
    pub logs: Vec<PathBuf>,
    /// The model to diagnose (TOML model file, e.g. from `servo identify`).
    #[arg(long)]
    pub model: PathBuf,
    /// Column map for foreign CSVs, e.g. `time=t_s,theta_l=thl_meas_deg:deg,u=u_V`, or MATLAB
    /// paths for .mat files (`theta_l=scope.signals(1).values(:,1):deg`).
    #[arg(long)]
    pub columns: Option<String>,
    #[command(flatten)]
    pub part: crate::log_part::LogPartArgs,
    /// Print one JSON object `{ "ranking": [...], "verdict": ... }` instead of text.
    #[arg(long)]
    pub json: bool,
    /// The full text report: every candidate, the measured friction curve, the bars.
    #[arg(long)]
    pub verbose: bool,
    /// Write a self-contained HTML report (inline SVG) to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Iterate: diagnose, add the winner, refit, until nothing is significant; print the ladder.
    #[arg(long)]
    pub auto: bool,
    /// Most effects added by `--auto`.
    #[arg(long, default_value_t = 3)]
    pub max_steps: usize,
    /// Save the model with the accepted effects (with `--auto`) to this TOML file: only when it
    /// predicts the held-out blocks (and the logs) at least as well as the model given with
    /// --model; otherwise it says so and writes nothing.
    #[arg(long)]
    pub save: Option<PathBuf>,
    /// With --save: write the model even when it predicts worse than the model given (it says
    /// so, and records it in the file's [provenance]).
    #[arg(long, requires = "save")]
    pub force: bool,
    /// Only try these effects (comma-separated catalogue names).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// When no single effect passes and a balance is still above its noise floor: how many of
    /// the best candidates to fit together with the effects already named, on the simulation,
    /// then eliminate backward until each survivor passes every check given the others
    /// (effects that hide each other, e.g. a gear play and a breakaway friction). 0: off. Adds
    /// about 5 s to 2 min to such a diagnosis.
    #[arg(long, value_name = "N", default_value_t = DiagnoseOptions::default().joint_candidates)]
    pub joint: usize,
    /// Cut-off of the zero-phase filter applied before differentiating [Hz].
    #[arg(long, default_value_t = 25.0)]
    pub filter_hz: f64,
    /// Effects file with user-defined effects (`[custom.NAME]`, docs/custom-effects.md): each one
    /// the model lacks joins the candidates. Repeat for several files.
    #[arg(long = "effects", value_name = "effects.toml")]
    pub effects: Vec<PathBuf>,
    /// When no catalogue or user effect explains the residual, search a library of physical
    /// terms for the smallest set that does, and propose it as a user-defined effect.
    #[arg(long)]
    pub discover: bool,
    /// Write the discovered effect (with --discover) to this effects file, ready for
    /// `--effects FILE --add NAME`.
    #[arg(long, value_name = "found.toml")]
    pub save_effect: Option<PathBuf>,
    /// Name of the discovered effect.
    #[arg(long, default_value = "found", value_name = "NAME")]
    pub effect_name: String,
    /// Cancel hook of the diagnosis (the Python binding's Ctrl-C; no flag on the command line).
    #[arg(skip)]
    pub cancel: servo_core::diagnose::cancel::Cancel,
}

impl Diagnose {
    pub fn run(self) -> anyhow::Result<()> {
        self.run_report().map(|_| ())
    }

    /// As [`Diagnose::run`] (prints the same output, writes the same files), also returning the
    /// ladder and the diagnoses (used by `servo demo`).
    pub fn run_report(self) -> anyhow::Result<(Vec<Rung>, Vec<Diagnosis>)> {
        keep_freed_memory();
        if self.joint == 1 {
            anyhow::bail!(
                "--joint must be 0 (off) or at least 2 candidates (a joint fit needs two), got 1"
            );
        }
        let model_file = ModelFile::load(&self.model)?;
        model_file.warn_defaults(&format!("--model {}", self.model.display()), &[]);
        let model = model_file.plant()?;
        let mut records = Vec::new();
        self.part.check(self.logs.len())?;
        let mut parts = Vec::new();
        for (k, p) in self.logs.iter().enumerate() {
            let mut r = servo_core::diagnose::timing::timed(
                || format!("read {}", p.display()),
                || crate::io::read_log_model(p, self.columns.as_deref(), &model_file),
            )
            .with_context(|| format!("reading log {}", p.display()))?;
            parts.push(self.part.apply(&mut r, p, k, self.logs.len())?);
            records.push(r);
        }
        if !(self.filter_hz > 0.0 && self.filter_hz.is_finite()) {
            anyhow::bail!(
                "--filter-hz must be a positive frequency in Hz, got {}",
                self.filter_hz
            );
        }
        let mut opts = DiagnoseOptions::default();
        opts.fit.filter_hz = self.filter_hz;
        opts.joint_candidates = self.joint;
        opts.cancel = self.cancel.clone();
        for name in &self.only {
            let k = EffectKind::from_name(name.trim()).ok_or_else(|| {
                anyhow!(
                    "--only: unknown effect `{name}`; the registry has {}",
                    servo_core::effects::RegisteredNames
                )
            })?;
            opts.candidates.push(k);
        }
        if self.save_effect.is_some() && !self.discover {
            anyhow::bail!("--save-effect writes what --discover finds: add --discover");
        }
        let library = crate::effects_file::load_many(&self.effects)?;
        let steps = if self.auto { self.max_steps } else { 0 };
        let (ladder, mut diags) = diagnose::diagnose_loop(&records, &model, &opts, steps)
            .map_err(|e| anyhow!("diagnosis failed: {e}"))?;
        let final_plant = ladder.last().map(|r| r.plant).unwrap_or(model);
        let user = {
            let last = diags
                .last()
                .ok_or_else(|| anyhow!("diagnosis produced no result"))?;
            servo_core::diagnose::timing::timed(
                || "user effects".into(),
                || {
                    crate::cmd::diagnose_custom::run(
                        &records,
                        &final_plant,
                        &opts,
                        &library,
                        last,
                        self.discover,
                        &self.effect_name,
                    )
                },
            )?
        };
        // A user effect or a discovered term that passes every guard is what the model misses.
        if let Some(last) = diags.last_mut() {
            servo_core::diagnose::user_effects::conclude(last, &user, &opts.thresholds);
        }
        let first = diags
            .first()
            .ok_or_else(|| anyhow!("diagnosis produced no result"))?;
        let last = diags.last().unwrap_or(first);
        // Written beside the report, never instead of it.
        let saved = match &self.save_effect {
            Some(path) => Some(user.save_effect(path)?),
            None => None,
        };
        let gate = self.save.as_ref().map(|_| {
            let added: Vec<&str> = ladder
                .iter()
                .flat_map(|r| r.added.iter().chain(&r.added_with).chain(&r.added_also))
                .map(|k| k.name())
                .collect();
            let change = if added.is_empty() {
                String::from("refitting the base parameters")
            } else {
                format!("adding {}", added.join(" + "))
            };
            servo_core::compare::gate::held_out_gate(
                &records,
                &model,
                &final_plant,
                change,
                &opts.fit,
            )
        });
        let worse = gate.as_ref().is_some_and(|g| g.worse().is_some());
        let save_ok = !worse || self.force;
        if self.json {
            let mut v = json!({
                "schema": "servo.diagnose/1",
                "status": last.status.name(),
                "unexplained": last.unexplained.iter().map(balance_json).collect::<Vec<_>>(),
                "balances": last.balances.iter().map(balance_json).collect::<Vec<_>>(),
                "neighbours": last.neighbours.iter().map(|n| neighbour_json(n, last.base.oe_cost_rad)).collect::<Vec<_>>(),
                "thresholds": thresholds_json(&opts.thresholds),
                "bars": bars_json(&opts),
                "ranking": last.ranking.iter().map(|c| candidate_json(c, &opts)).collect::<Vec<_>>(),
                "verdict": last.verdict,
                "not_resolvable": last.unresolvable.iter().map(unresolvable_json).collect::<Vec<_>>(),
                "friction_curve": first.friction_curve.as_ref().map(friction_curve_json),
                "changes": last.changes.iter().map(change_json).collect::<Vec<_>>(),
                "presliding": last.presliding.map(|e| json!({
                    "counts": f(e.counts),
                    "ratio_to_sliding": f(e.ratio),
                    "rows": e.rows,
                    "rms": f(e.rms),
                })),
                "sliding_fit": last.sliding_fit.as_ref().map(sliding_fit_json),
                "base": base_json(first),
                "log_parts": crate::log_part::json(&parts),
            });
            user.add_json(&mut v);
            if let Some(sv) = &saved {
                v["saved_effect"] = sv.json();
            }
            if let (Some(g), Some(p)) = (&gate, &self.save) {
                v["save"] = save_json(g, p, save_ok, self.force);
            }
            if let Some(axis) = crate::axis::Axis::of(&model_file) {
                linear_json(&mut v, &axis, first, last, &ladder);
            }
            if self.auto {
                v["ladder"] = Value::Array(ladder.iter().map(rung_json).collect());
                v["first_ranking"] = Value::Array(
                    first
                        .ranking
                        .iter()
                        .map(|c| candidate_json(c, &opts))
                        .collect(),
                );
            }
            crate::json_out::emit(&v)?;
        } else {
            out!("{}", crate::log_part::text(&parts));
            let plant_line = plant_and_controller(&self.model, &model, &opts);
            if self.verbose {
                outln!("{plant_line}");
                out!("{}", text_report(first, &ladder, &diags, self.auto, &opts));
            } else {
                let next = next_step(last, &self.logs, &self.model);
                let short =
                    short_report(first, &ladder, &diags, self.auto, &opts, &next, &plant_line);
                out!("{short}");
            }
            if let Some(axis) = crate::axis::Axis::of(&model_file) {
                out!("{}", linear_text(&axis, last, &ladder));
            }
            out!("{}", user.text());
            if let Some(sv) = &saved {
                outln!("{}", sv.text());
            }
            if !self.verbose {
                outln!("(--verbose: every candidate, the measured friction curve, the bars; --report FILE.html; --json)");
            }
        }
        if let Some(path) = &self.report {
            let html = html_report(
                &records,
                &model,
                first,
                &ladder,
                &diags,
                &opts,
                &self.logs,
                &model_file.drive,
            )?;
            crate::io::output::write_file(path, "report", html)?;
            if !self.json {
                outln!("report written to {}", path.display());
            }
        }
        if let Some(path) = &self.save {
            if let (Some(g), false) = (&gate, self.json) {
                if let Some(why) = &g.held_out_missing {
                    outln!("held-out check: not made ({why})");
                }
                outln!("{}", g.sentence());
            }
            if save_ok {
                let mut mf = ModelFile::from_plant(&final_plant);
                mf.sensors = model_file.sensors;
                mf.transmission = model_file.transmission;
                mf.drive = model_file.drive;
                mf.provenance = model_file.provenance.clone();
                if let Some(g) = gate.as_ref().filter(|_| worse) {
                    mf.provenance
                        .get_or_insert_with(Default::default)
                        .insert("diagnose_forced".into(), toml::Value::String(g.sentence()));
                }
                mf.limits = model_file.limits.clone();
                mf.save_over(path, &ModelFile::FRICTION_KINDS)?;
            }
            if !self.json {
                outln!(
                    "{}",
                    match (save_ok, worse) {
                        (true, true) => format!(
                            "model saved to {} although it predicts worse (--force)",
                            path.display()
                        ),
                        (true, false) => format!("model saved to {}", path.display()),
                        (false, _) => format!(
                            "model not saved to {} (--force saves it anyway)",
                            path.display()
                        ),
                    }
                );
            }
        }
        Ok((ladder, diags))
    }
}

/// Has the C allocator (glibc) keep the memory a diagnosis frees for its next columns, instead
/// of handing every column of a long log (a few MB each) back to the system and faulting fresh
/// pages in for the next one: one allocation arena for all threads (the worker threads'
/// columns then reuse one another's freed memory), blocks up to 32 MB served from it, and freed
/// memory kept. On 10 minutes at 1 kHz this takes the system time of a diagnosis from about
/// 0.27 s to 0.08 s with a lower peak memory. A no-op on other platforms; the values only tune
/// the allocator, never what is computed.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn mallopt(param: std::ffi::c_int, value: std::ffi::c_int) -> std::ffi::c_int;
        }
        const M_TRIM_THRESHOLD: std::ffi::c_int = -1;
        const M_MMAP_THRESHOLD: std::ffi::c_int = -3;
        const M_ARENA_MAX: std::ffi::c_int = -8;
        // SAFETY: mallopt only sets parameters of glibc's allocator (it takes its lock); called
        // before the diagnosis starts its threads. A value it refuses leaves the default.
        unsafe {
            mallopt(M_ARENA_MAX, 1);
            mallopt(M_MMAP_THRESHOLD, 32 << 20);
            mallopt(M_TRIM_THRESHOLD, 1 << 30);
        }
    }
}
