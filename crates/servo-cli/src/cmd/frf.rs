//! `servo frf`: the measured frequency response (plant, loop, complementary sensitivity) from
//! logs, the margins the loop achieved, and where the model fails in frequency.

mod plot;
mod report;

use plot::*;
use report::*;
mod json;

use json::json_document;

use crate::cmd::compare::stack_svg;
use crate::gains_file::GainsFile;
use crate::io::{read_log_signals, Signal};
use crate::model_file::ModelFile;
use crate::plot::{line_chart_svg, Chart, Series};
use anyhow::{bail, Context};
use serde_json::{json, Value};
use servo_core::frf::analysis::{analyze, FrfController, FrfLog, FrfRequest};
use servo_core::frf::{Frf as Estimate, Interval};
use servo_core::record::Record;
use servo_io::controller::{pid_config, PidOptions, PidSources};
use std::path::PathBuf;

/// Estimate the frequency response from logs: the plant, the loop and its achieved margins.
///
/// Closed-loop logs (a varying reference) give the plant by the joint input-output method
/// P = G_{r,theta}/G_{r,u} (never the direct u -> theta estimate, which feedback biases) and the
/// loop L = C P (C from --gains or the log; without them L = T/(1 - T), valid without
/// feedforward). Open-loop logs give P = H1(u -> theta). Welch averaging, Hann window, 50 %
/// overlap, 95 % Bendat & Piersol bounds from the coherence and the number of averages.
/// Excite with `experiments/chirp.toml` or `experiments/multisine.toml`; steps carry little
/// information above a few rad/s.
#[derive(Debug, clap::Parser)]
pub struct Frf {
    /// Logs (servo MCAP or CSV; foreign CSV through --columns). Several logs are averaged
    /// together; at different amplitudes they also show whether the gain depends on it.
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Model file (TOML) to compare with: its discrete (ZOH) full model, with its delay effect.
    #[arg(long, value_name = "model.toml")]
    pub model: Option<PathBuf>,
    /// Gains of the controller that ran (default: the log's metadata): gives L = C P.
    #[arg(long, value_name = "gains.toml")]
    pub gains: Option<PathBuf>,
    /// Column map for foreign CSVs, e.g. `time=t_s,theta_l=thl_meas_deg:deg,u=u_V,ref=thl_ref_deg:deg`.
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    #[command(flatten)]
    pub part: crate::log_part::LogPartArgs,
    /// Averaging segment [s] (default: the largest power-of-two length giving ~16 averages).
    #[arg(long, value_name = "S")]
    pub segment_s: Option<f64>,
    /// Coherence from which a bin counts for the margins.
    #[arg(long, default_value_t = 0.8, value_name = "GAMMA2")]
    pub min_coherence: f64,
    /// Write the Bode plot (measured with bounds, model) and the coherence as SVG.
    #[arg(long, value_name = "frf.svg")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

struct Log {
    name: String,
    rec: Record,
    gains: Option<GainsFile>,
    logged: Option<servo_io::controller::LoggedController>,
}

impl Frf {
    pub fn run(self) -> anyhow::Result<()> {
        let given = self
            .gains
            .as_ref()
            .map(|p| GainsFile::load(p))
            .transpose()?;
        let mut logs = Vec::new();
        self.part.check(self.logs.len())?;
        let mut parts = Vec::new();
        for (k, p) in self.logs.iter().enumerate() {
            // Only the signals the estimate uses are read.
            let (mut rec, meta) = read_log_signals(
                p,
                self.columns.as_deref(),
                Some(&[
                    Signal::Time,
                    Signal::U,
                    Signal::ThetaL,
                    Signal::Ref,
                    Signal::Enable,
                ]),
            )
            .with_context(|| format!("reading {}", p.display()))?;
            parts.push(self.part.apply(&mut rec, p, k, self.logs.len())?);
            if !self.json {
                for n in &meta.notes {
                    eprintln!("note: {n}");
                }
            }
            logs.push(Log {
                name: p.display().to_string(),
                gains: meta.gains()?,
                logged: crate::io::logged_controller(&meta)?,
                rec,
            });
        }
        let mut inputs = Vec::new();
        for l in &logs {
            let r = &l.rec;
            let (Some(u), Some(th)) = (r.u_v.as_deref(), r.theta_l_rad.as_deref()) else {
                bail!("{}: needs the driver input u and the load angle theta_l (map them with --columns u=...,theta_l=...)", l.name);
            };
            inputs.push(FrfLog {
                name: &l.name,
                ref_rad: r.ref_rad.as_deref(),
                u_v: u,
                theta_l_rad: th,
                sample_period_s: r.sample_period_s(),
            });
        }
        if let Some(s) = self.segment_s {
            if !(s.is_finite() && s > 0.0) {
                bail!("--segment-s must be > 0 s, got {s}");
            }
        }
        // The controller: --gains, else the log's record.
        let gains_src = match (&given, &self.gains) {
            (Some(g), Some(p)) => Some((g, p.display().to_string())),
            _ => logs[0]
                .gains
                .as_ref()
                .map(|g| (g, "the log's gains".to_string())),
        };
        let pid_opts = PidOptions::default();
        // The output limit: the gains file's `u_limit_v`, else the logged controller's.
        let u_limit = gains_src
            .as_ref()
            .and_then(|(g, n)| {
                g.pid
                    .u_limit_v
                    .map(|l| (l, format!("from {n} [pid] u_limit_v")))
            })
            .or_else(|| {
                logs[0]
                    .logged
                    .as_ref()
                    .and_then(|l| l.u_limit_v)
                    .map(|l| (l, "from the log's controller record".to_string()))
            });
        let controller = match (&gains_src, &logs[0].logged) {
            (None, None) => None,
            (g, logged) => Some(pid_config(
                &PidSources {
                    opts: &pid_opts,
                    logged: logged.as_ref(),
                    gains_file: g.as_ref().map(|(g, n)| (*g, n.as_str())),
                },
                inputs[0].sample_period_s,
                u_limit,
            )?),
        };
        let described = controller.as_ref().map(|c| c.describe());
        let model = self
            .model
            .as_ref()
            .map(|p| {
                ModelFile::load(p)?
                    .plant()
                    .with_context(|| format!("the model {}", p.display()))
            })
            .transpose()?;
        let a = analyze(&FrfRequest {
            logs: &inputs,
            segment_s: self.segment_s,
            min_coherence: self.min_coherence,
            controller: controller
                .as_ref()
                .zip(described.as_deref())
                .map(|(c, d)| FrfController {
                    config: &c.config,
                    description: d,
                }),
            model: model.as_ref(),
        })?;
        let names: Vec<String> = logs.iter().map(|l| l.name.clone()).collect();
        if self.json {
            outln!(
                "{}",
                json_document(&a, &names, crate::log_part::json(&parts))?
            );
        } else {
            out!("{}", crate::log_part::text(&parts));
            print_text(&a, logs.len());
        }
        if let Some(path) = &self.plot {
            crate::io::output::write_file(path, "--plot", plot(&a)?)?;
            if !self.json {
                outln!("plot: {}", path.display());
            }
        }
        Ok(())
    }
}
