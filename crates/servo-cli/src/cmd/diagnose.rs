//! `servo diagnose LOG... --model model.toml`: which physical effect is the model missing?
//!
//! Every catalogue effect the model lacks is fitted with the base parameters (see
//! `servo_core::diagnose`) and ranked; `--auto` iterates diagnose, add the winner, refit, until
//! nothing significant is left, and prints the error ladder.

use crate::io::read_log;
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
    /// Print one JSON object `{ "ranking": [...], "verdict": ... }` instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write a self-contained HTML report (inline SVG) to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Iterate: diagnose, add the winner, refit, until nothing is significant; print the ladder.
    #[arg(long)]
    pub auto: bool,
    /// Most effects added by `--auto`.
    #[arg(long, default_value_t = 3)]
    pub max_steps: usize,
    /// Save the model with the accepted effects (with `--auto`) to this TOML file.
    #[arg(long)]
    pub save: Option<PathBuf>,
    /// Only try these effects (comma-separated catalogue names).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
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
}

impl Diagnose {
    pub fn run(self) -> anyhow::Result<()> {
        self.run_report().map(|_| ())
    }

    /// As [`Diagnose::run`] (prints the same output, writes the same files), also returning the
    /// ladder and the diagnoses (used by `servo demo`).
    pub fn run_report(self) -> anyhow::Result<(Vec<Rung>, Vec<Diagnosis>)> {
        let model_file = ModelFile::load(&self.model)?;
        let model = model_file.plant()?;
        let mut records = Vec::new();
        for p in &self.logs {
            let r = read_log(p, self.columns.as_deref())
                .with_context(|| format!("reading log {}", p.display()))?;
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
        let (ladder, diags) = diagnose::diagnose_loop(&records, &model, &opts, steps)
            .map_err(|e| anyhow!("diagnosis failed: {e}"))?;
        let first = diags
            .first()
            .ok_or_else(|| anyhow!("diagnosis produced no result"))?;
        let last = diags.last().unwrap_or(first);
        let final_plant = ladder.last().map(|r| r.plant).unwrap_or(model);
        let user = crate::cmd::diagnose_custom::run(
            &records,
            &final_plant,
            &opts,
            &library,
            last,
            self.discover,
            &self.effect_name,
        )?;
        if let Some(path) = &self.save_effect {
            user.save_effect(path)?;
        }
        if self.json {
            let mut v = json!({
                "status": last.status.name(),
                "unexplained": last.unexplained.iter().map(balance_json).collect::<Vec<_>>(),
                "balances": last.balances.iter().map(balance_json).collect::<Vec<_>>(),
                "thresholds": thresholds_json(&opts.thresholds),
                "ranking": last.ranking.iter().map(candidate_json).collect::<Vec<_>>(),
                "verdict": last.verdict,
                "base": base_json(first),
            });
            user.add_json(&mut v);
            if self.auto {
                v["ladder"] = Value::Array(ladder.iter().map(rung_json).collect());
                v["first_ranking"] =
                    Value::Array(first.ranking.iter().map(candidate_json).collect());
            }
            outln!("{}", serde_json::to_string_pretty(&v)?);
        } else {
            out!("{}", text_report(first, &ladder, &diags, self.auto));
            out!("{}", user.text());
            if let Some(p) = &self.save_effect {
                outln!("discovered effect written to {}", p.display());
            }
        }
        if let Some(path) = &self.report {
            let html = html_report(&records, &model, first, &ladder, &diags, &opts, &self.logs)?;
            std::fs::write(path, html)
                .with_context(|| format!("writing report {}", path.display()))?;
            if !self.json {
                outln!("report written to {}", path.display());
            }
        }
        if let Some(path) = &self.save {
            let final_plant = ladder.last().map(|r| r.plant).unwrap_or(model);
            let mut mf = ModelFile::from_plant(&final_plant);
            mf.sensors = model_file.sensors;
            mf.provenance = model_file.provenance.clone();
            mf.save(path)?;
            if !self.json {
                outln!("model saved to {}", path.display());
            }
        }
        Ok((ladder, diags))
    }
}

fn f(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

fn candidate_json(c: &Candidate) -> Value {
    let mut params = serde_json::Map::new();
    for p in &c.params {
        params.insert(
            p.key.to_string(),
            json!({ "value": f(p.value), "unit": p.unit, "std_err": p.std_err.map(f), "fitted": p.fitted }),
        );
    }
    json!({
        "effect": c.effect.name(),
        "significant": c.significant,
        "resolvable": c.resolvable,
        "error_reduction_pct": f(c.error_reduction_pct),
        "oe_reduction_pct": c.oe_reduction_pct.map(f),
        "bic_gain": f(c.bic_gain),
        "equation": c.equation.name(),
        "params": params,
        "evidence": c.evidence,
        "experiment": c.experiment,
        "noise_ratio": f(c.noise_ratio),
        "structured_share": f(c.structured_share),
        "checks": c.checks.iter().map(|k| json!({ "check": k.name, "passed": k.passed, "detail": k.detail })).collect::<Vec<_>>(),
    })
}

fn balance_json(b: &BalanceReport) -> Value {
    json!({
        "balance": b.balance.name(),
        "equation": b.equation.name(),
        "unit": b.equation.unit(),
        "rms": f(b.rms),
        "noise_floor": f(b.floor),
        "ratio_to_noise": f(b.ratio_to_noise),
        "above_noise": b.above_noise,
        "signatures": b.signatures.iter().map(|s| json!({
            "kind": s.kind,
            "description": s.description,
            "share_of_heldout_residual": f(s.share),
            "explained_rms": f(s.explained_rms),
        })).collect::<Vec<_>>(),
        "experiment": b.experiment,
    })
}

fn thresholds_json(t: &Thresholds) -> Value {
    json!({
        "min_noise_ratio": f(t.min_noise_ratio),
        "min_structured_share": f(t.min_structured_share),
        "unexplained_ratio": f(t.unexplained_ratio),
        "min_signature_share": f(t.min_signature_share),
        "consistency_tol": f(t.consistency_tol),
        "electrical_block_ratio": f(t.electrical_block_ratio),
    })
}

/// The headline of the text and HTML outputs: the final status and, after `--auto`, what was
/// added on the way.
fn headline(ladder: &[Rung], last: &Diagnosis) -> String {
    let added: Vec<String> = ladder
        .iter()
        .filter_map(|r| r.added.map(|k| k.name().to_string()))
        .collect();
    let status = match last.status {
        servo_core::diagnose::Status::Complete => "complete: nothing material is left",
        servo_core::diagnose::Status::Missing => "missing: a catalogue effect is still missing",
        servo_core::diagnose::Status::Unexplained => {
            "unexplained: structured error above the noise floor that no catalogue effect explains"
        }
    };
    if added.is_empty() {
        format!("Status: {status}")
    } else {
        format!("Added {}; status after them: {status}", added.join(", "))
    }
}

fn base_json(d: &Diagnosis) -> Value {
    json!({
        "equations": d.base.equations.iter().map(|(eq, rms, share, occ)| {
            let regimes: serde_json::Map<String, Value> = Regime::ALL.iter().enumerate().map(|(i, r)| {
                (r.name().to_string(), json!({ "share_of_squared_error": f(share[i]), "share_of_samples": f(occ[i]) }))
            }).collect();
            json!({ "equation": eq.name(), "unit": eq.unit(), "rms": f(*rms), "regimes": regimes })
        }).collect::<Vec<_>>(),
        "oe_cost_rad": d.base.oe_cost_rad.map(f),
        "current_noise_a": d.base.current_noise_a.map(f),
    })
}

fn rung_json(r: &Rung) -> Value {
    json!({
        "added": r.added.map(|k| k.name()),
        "equations": r.equations.iter().map(|(e, rms)| json!({ "equation": e.name(), "unit": e.unit(), "rms": f(*rms) })).collect::<Vec<_>>(),
        "oe_cost_rad": r.oe_cost_rad.map(f),
        "effects": r.plant.effects.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
    })
}

fn where_it_fails(d: &Diagnosis) -> String {
    let mut s = String::new();
    for (eq, rms, share, occ) in &d.base.equations {
        let _ = writeln!(s, "  {}: residual {:.3e} {} RMS", eq.name(), rms, eq.unit());
        let mut idx: Vec<usize> = (0..5).filter(|&i| occ[i] > 0.0).collect();
        idx.sort_by(|&a, &b| (share[b] / occ[b]).total_cmp(&(share[a] / occ[a])));
        for &i in idx.iter().take(2) {
            if share[i] / occ[i] > 1.2 {
                let _ = writeln!(
                    s,
                    "    {:.0} % of the squared error sits {} ({:.0} % of the samples)",
                    100.0 * share[i],
                    Regime::ALL[i].phrase(),
                    100.0 * occ[i]
                );
            }
        }
    }
    s
}

fn text_report(first: &Diagnosis, ladder: &[Rung], diags: &[Diagnosis], auto: bool) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "Model residual (base parameters refitted):");
    s.push_str(&where_it_fails(first));
    for b in &first.balances {
        let _ = writeln!(
            s,
            "  {}: noise floor {:.3e} {}, residual {:.1} x the floor{}",
            b.equation.name(),
            b.floor,
            b.equation.unit(),
            b.ratio_to_noise,
            b.signatures.first().map_or(String::new(), |g| format!(
                "; strongest shape: {} ({:.0} % of the held-out residual)",
                g.description,
                100.0 * g.share
            ))
        );
    }
    for (step, d) in diags.iter().enumerate() {
        if auto {
            let _ = writeln!(s, "\nStep {}:", step + 1);
        }
        let _ = writeln!(s, "\nCandidates, best first:");
        let _ = writeln!(
            s,
            "  {:<11} {:>11} {:>10} {:>10} {:>9}",
            "effect", "significant", "eq. drop", "sim. drop", "BIC gain"
        );
        for c in &d.ranking {
            let _ = writeln!(
                s,
                "  {:<11} {:>11} {:>9.1}% {:>10} {:>9.1}",
                c.effect.name(),
                if c.significant {
                    "YES"
                } else if c.resolvable {
                    "no"
                } else {
                    "unresolved"
                },
                c.error_reduction_pct,
                c.oe_reduction_pct
                    .map_or("-".to_string(), |v| format!("{v:.1}%")),
                c.bic_gain
            );
        }
        if let Some(w) = d.ranking.first() {
            let _ = writeln!(s, "\nBest candidate: {}", w.evidence);
        }
        let _ = writeln!(s, "\nVerdict: {}", d.verdict);
    }
    if auto {
        let _ = writeln!(s, "\nError ladder:");
        s.push_str(&ladder_text(ladder));
    }
    if let Some(last) = diags.last() {
        let _ = writeln!(s, "\n{}", headline(ladder, last));
    }
    s
}

fn ladder_text(ladder: &[Rung]) -> String {
    let mut s = String::new();
    for r in ladder {
        let name = r
            .added
            .map_or("starting model".to_string(), |k| format!("+ {k}"));
        let eqs: Vec<String> = r
            .equations
            .iter()
            .map(|(e, v)| format!("{} {:.3e} {}", e.name(), v, e.unit()))
            .collect();
        let oe = r
            .oe_cost_rad
            .map_or(String::new(), |v| format!(", prediction error {v:.3e} rad"));
        let _ = writeln!(s, "  {name:<16} {}{oe}", eqs.join(", "));
    }
    s
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Residual of the torque (or u-driven) balance over time and versus speed, before and after the
/// winner, for the first record.
fn residual_charts(
    records: &[Record],
    model: &Plant,
    d: &Diagnosis,
    opts: &DiagnoseOptions,
) -> anyhow::Result<String> {
    let ds = Dataset::new(records, &model.params, &opts.fit).map_err(|e| anyhow!("{e}"))?;
    let base = ds.fit_config(model, &[]).map_err(|e| anyhow!("{e}"))?;
    let winner = d.winner();
    let eq = winner.map_or(base.mech.equation, |w| w.equation);
    let rows = if eq == Equation::Electrical {
        &ds.elec_rows
    } else {
        &ds.mech_rows
    };
    let sol_b = base
        .equation(eq)
        .ok_or_else(|| anyhow!("no {} equation", eq.name()))?;
    let after = match winner {
        Some(w) => Some(ds.fit_config(&w.plant, &[]).map_err(|e| anyhow!("{e}"))?),
        None => None,
    };
    let sol_a = after.as_ref().and_then(|a| a.equation(eq));
    let sel: Vec<usize> = (0..rows.len()).filter(|&i| rows.rec[i] == 0).collect();
    let t: Vec<f64> = sel.iter().map(|&i| ds.recs[0].time_s[rows.k[i]]).collect();
    let w: Vec<f64> = sel.iter().map(|&i| ds.recs[0].omega_f[rows.k[i]]).collect();
    let rb: Vec<f64> = sel.iter().map(|&i| sol_b.resid[i]).collect();
    let ra: Vec<f64> = sol_a
        .map(|s| sel.iter().map(|&i| s.resid[i]).collect())
        .unwrap_or_default();
    let label_a = winner.map_or(String::new(), |w| format!("with {}", w.effect));
    let mut series = vec![Series {
        label: "model",
        x: &t,
        y: &rb,
    }];
    if !ra.is_empty() {
        series.push(Series {
            label: &label_a,
            x: &t,
            y: &ra,
        });
    }
    let title = format!(
        "{} residual [{}] over time ({})",
        eq.name(),
        eq.unit(),
        ds.recs[0].source
    );
    let mut html = line_chart_svg(
        &Chart {
            title: &title,
            x_label: "time [s]",
            y_label: eq.unit(),
            ..Chart::default()
        },
        &series,
    )?;
    // Residual versus speed: sort by speed so that the line reads as a scatter envelope.
    let mut order: Vec<usize> = (0..w.len()).collect();
    order.sort_by(|&a, &b| w[a].total_cmp(&w[b]));
    let ws: Vec<f64> = order.iter().map(|&i| w[i]).collect();
    let rbs: Vec<f64> = order.iter().map(|&i| rb[i]).collect();
    let ras: Vec<f64> = if ra.is_empty() {
        vec![]
    } else {
        order.iter().map(|&i| ra[i]).collect()
    };
    let mut series = vec![Series {
        label: "model",
        x: &ws,
        y: &rbs,
    }];
    if !ras.is_empty() {
        series.push(Series {
            label: &label_a,
            x: &ws,
            y: &ras,
        });
    }
    let title = format!("{} residual versus motor speed", eq.name());
    html.push_str(&line_chart_svg(
        &Chart {
            title: &title,
            x_label: "motor speed [rad/s]",
            y_label: eq.unit(),
            ..Chart::default()
        },
        &series,
    )?);
    Ok(html)
}

fn html_report(
    records: &[Record],
    model: &Plant,
    first: &Diagnosis,
    ladder: &[Rung],
    diags: &[Diagnosis],
    opts: &DiagnoseOptions,
    logs: &[PathBuf],
) -> anyhow::Result<String> {
    let last = diags.last().unwrap_or(first);
    let mut h = String::from(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>servo diagnose report</title><style>\
         body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px;vertical-align:top}\
         .yes{color:#080;font-weight:bold}.no{color:#888}</style></head><body>",
    );
    let _ = write!(
        h,
        "<h1>servo diagnose</h1><p>Logs: {}</p>",
        esc(&logs
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "))
    );
    let effects: Vec<String> = model.effects.iter().map(|e| e.to_string()).collect();
    let _ = write!(
        h,
        "<p>Model effects: <code>{}</code></p>",
        esc(&effects.join(" "))
    );
    let _ = write!(
        h,
        "<h2>Verdict</h2><p class=\"status-{}\"><b>{}</b></p><p>{}</p>",
        last.status.name(),
        esc(&headline(ladder, last)),
        esc(&last.verdict)
    );
    let _ = write!(
        h,
        "<h2>The fit and where it fails</h2><pre>{}</pre>",
        esc(&where_it_fails(first))
    );
    h.push_str(&residual_charts(records, model, first, opts)?);
    for (step, d) in diags.iter().enumerate() {
        let _ = write!(h, "<h2>Ranking{}</h2><table><tr><th>effect</th><th>significant</th><th>equation residual drop (held out)</th><th>simulation error drop (held out)</th><th>BIC gain</th><th>evidence</th></tr>", if diags.len() > 1 { format!(", step {}", step + 1) } else { String::new() });
        for c in &d.ranking {
            let _ = write!(
                h,
                "<tr><td>{}</td><td class=\"{}\">{}</td><td>{:.1} %</td><td>{}</td><td>{:.1}</td><td>{}{}</td></tr>",
                c.effect,
                if c.significant { "yes" } else { "no" },
                if c.significant { "yes" } else if c.resolvable { "no" } else { "not resolvable" },
                c.error_reduction_pct,
                c.oe_reduction_pct.map_or("-".into(), |v| format!("{v:.1} %")),
                c.bic_gain,
                esc(&c.evidence),
                c.experiment.as_ref().map_or(String::new(), |e| format!("<br><i>To resolve: {}</i>", esc(e)))
            );
        }
        h.push_str("</table>");
    }
    let _ = write!(
        h,
        "<h2>Error ladder</h2><pre>{}</pre>",
        esc(&ladder_text(ladder))
    );
    if ladder.len() > 1 {
        let x: Vec<f64> = (0..ladder.len()).map(|i| i as f64).collect();
        let y: Vec<f64> = ladder
            .iter()
            .map(|r| r.equations.first().map_or(f64::NAN, |e| e.1))
            .collect();
        let unit = ladder[0].equations.first().map_or("", |e| e.0.unit());
        h.push_str(&line_chart_svg(
            &Chart {
                title: "equation residual RMS as effects are added",
                x_label: "effects added",
                y_label: unit,
                ..Chart::default()
            },
            &[Series {
                label: "residual",
                x: &x,
                y: &y,
            }],
        )?);
    }
    h.push_str("</body></html>\n");
    Ok(h)
}
