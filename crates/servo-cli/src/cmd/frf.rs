//! `servo frf`: the measured frequency response (plant, loop, complementary sensitivity) from
//! logs, the margins the loop achieved, and where the model fails in frequency.

mod plot;
mod report;

use plot::*;
use report::*;
mod json;

use json::{points, Doc};

use crate::cmd::compare::stack_svg;
use crate::gains_file::GainsFile;
use crate::io::{read_log_signals, Signal};
use crate::model_file::ModelFile;
use crate::plot::{line_chart_svg, Chart, Series};
use crate::runner::controller::{pid_config, PidOptions, PidSources};
use anyhow::{bail, Context};
use serde_json::{json, Value};
use servo_core::design::controller::discrete_response;
use servo_core::design::margins::margins;
use servo_core::design::verify::sweep_for;
use servo_core::design::{c_expj, Complex, PlantModel};
use servo_core::effects::EffectKind;
use servo_core::frf::against::{
    against_model, amplitude_dependence, low_coherence_ranges, AtAmplitude, Comparison,
};
use servo_core::frf::{
    achieved_margins, loop_from_t, AchievedMargins, Frf as Estimate, Interval, WelchOptions,
};
use servo_core::record::Record;
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

/// One log's signals: the varying reference (closed loop), u [V] and theta_l [rad].
use servo_core::frf::Signals;

struct Log {
    name: String,
    rec: Record,
    gains: Option<GainsFile>,
    logged: Option<crate::runner::controller::LoggedController>,
}

impl Frf {
    pub fn run(self) -> anyhow::Result<()> {
        let given = self
            .gains
            .as_ref()
            .map(|p| GainsFile::load(p))
            .transpose()?;
        let mut logs = Vec::new();
        for p in &self.logs {
            // Only the signals the estimate uses are read.
            let (rec, meta) = read_log_signals(
                p,
                self.columns.as_deref(),
                Some(&[Signal::Time, Signal::U, Signal::ThetaL, Signal::Ref]),
            )
            .with_context(|| format!("reading {}", p.display()))?;
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
        let ts = logs[0].rec.sample_period_s();
        let mut recs = Vec::new();
        for l in &logs {
            let r = &l.rec;
            let (Some(u), Some(th)) = (r.u_v.as_deref(), r.theta_l_rad.as_deref()) else {
                bail!("{}: needs the driver input u and the load angle theta_l (map them with --columns u=...,theta_l=...)", l.name);
            };
            if ((r.sample_period_s() - ts) / ts).abs() > 1e-3 {
                bail!("{}: sample period {} s differs from the first log's {} s; give logs of one period", l.name, r.sample_period_s(), ts);
            }
            let rf = r.ref_rad.as_deref().filter(|x| std_dev(x) > 1e-9);
            recs.push((rf, u, th));
        }
        let closed = recs[0].0.is_some();
        if recs.iter().any(|r| r.0.is_some() != closed) {
            bail!("mix of closed-loop logs (a varying reference) and open-loop logs: estimate them separately");
        }
        let mut opts = WelchOptions::default();
        if let Some(s) = self.segment_s {
            if !(s.is_finite() && s > 0.0) {
                bail!("--segment-s must be > 0 s, got {s}");
            }
            opts.segment_len = Some(((s / ts).round() as usize).max(16));
        }
        // One segment length for the pooled and the per-log estimates.
        let total: usize = recs.iter().map(|r| r.1.len()).sum();
        let longest = recs.iter().map(|r| r.1.len()).max().unwrap_or(0);
        opts.segment_len = Some(opts.segment_for(total, longest));
        let estimate = |rs: &[Signals]| servo_core::frf::estimate(rs, closed, ts, &opts);
        let (plant, t, spectra) = estimate(&recs).context("estimating the frequency response")?;
        // The controller: --gains, else the log's record.
        let gains_src = given
            .as_ref()
            .map(|g| {
                (
                    g,
                    self.gains
                        .as_ref()
                        .map(|p| p.display().to_string())
                        .unwrap_or_default(),
                )
            })
            .or_else(|| {
                logs[0]
                    .gains
                    .as_ref()
                    .map(|g| (g, "the log's gains".to_string()))
            });
        let pid_opts = PidOptions::default();
        let controller = match (&gains_src, &logs[0].logged) {
            (None, None) => None,
            (g, logged) => Some(pid_config(
                &PidSources {
                    opts: &pid_opts,
                    logged: logged.as_ref(),
                    gains_file: g.as_ref().map(|(g, n)| (*g, n.as_str())),
                },
                ts,
                None,
            )?),
        };
        let mut notes = Vec::new();
        let c_of = |w: f64| -> Option<Complex<f64>> {
            controller.as_ref().map(|c| {
                let g = servo_core::design::PidGains {
                    kp: c.config.kp,
                    ki: c.config.ki,
                    kd: c.config.kd,
                    tl_s: c.config.tl_s,
                };
                discrete_response(&g, c.config.ts_s, c.config.discretization, w)
            })
        };
        let (l, l_from) = match (&controller, &t) {
            (Some(c), _) => (
                Some(plant.times(|w| c_of(w).unwrap_or(Complex::new(f64::NAN, 0.0)))),
                format!("L = C P with C {}", c.describe()),
            ),
            (None, Some(t)) => {
                notes.push("no controller known (--gains): L = T/(1 - T), which assumes u = C (r - theta_l) without feedforward".to_string());
                (Some(loop_from_t(t)), "L = T/(1 - T)".to_string())
            }
            (None, None) => (None, "no loop (open-loop logs without --gains)".to_string()),
        };
        let achieved: Option<AchievedMargins> = l
            .as_ref()
            .map(|l| achieved_margins(l, self.min_coherence, -180.0));
        // The model.
        let model = self
            .model
            .as_ref()
            .map(|p| {
                ModelFile::load(p)?
                    .plant()
                    .with_context(|| format!("the model {}", p.display()))
            })
            .transpose()?;
        let model_resp = model.map(|m| {
            let lin = PlantModel::full(&m.linear_params());
            let d = lin.state_space().discretize_zoh(ts);
            let delay = m.effects.value(EffectKind::Delay, "delay").unwrap_or(0.0);
            (m, lin, move |w: f64| d.response(w) * c_expj(-w * delay))
        });
        let comparison: Option<Comparison> = model_resp
            .as_ref()
            .map(|(_, _, pm)| against_model(&plant, pm));
        let design = match (&model_resp, &controller) {
            (Some((_, lin, pm)), Some(c)) => {
                let g = servo_core::design::PidGains {
                    kp: c.config.kp,
                    ki: c.config.ki,
                    kd: c.config.kd,
                    tl_s: c.config.tl_s,
                };
                let wc_guess = achieved
                    .as_ref()
                    .and_then(|a| a.crossover_rad_s)
                    .map_or(30.0, |i| i.value);
                let m = margins(
                    |w| c_of(w).unwrap_or_default() * pm(w),
                    &sweep_for(wc_guess, lin, &g, Some(ts)),
                );
                Some(
                    json!({"crossover_rad_s": m.omega_gc, "phase_margin_deg": m.phase_margin_deg,
                            "gain_margin_db": if m.gain_margin_db.is_finite() { json!(m.gain_margin_db) } else { Value::Null },
                            "loop": "model's full plant with ZOH (and its delay) and the discrete controller"}),
                )
            }
            _ => None,
        };
        // Friction against the excitation's amplitude.
        let u_rms: Vec<f64> = recs.iter().map(|r| std_dev(r.1)).collect();
        if let Some((m, _, _)) = &model_resp {
            let p = m.linear_params();
            let tau = m.tau_sf();
            if tau > 0.0 {
                let uf = tau / p.n * p.r_eq() / (p.k_t * p.k_drv);
                let umin = u_rms.iter().cloned().fold(f64::INFINITY, f64::min);
                if umin < 3.0 * uf {
                    notes.push(format!("u is only {umin:.2} V rms against the model's Coulomb friction voltage {uf:.2} V: friction shapes this estimate (excite with a larger amplitude to see the linear plant)"));
                }
            }
        }
        // Amplitude dependence between logs.
        let mut per_log = Vec::new();
        if recs.len() > 1 {
            for r in &recs {
                per_log.push(estimate(std::slice::from_ref(r)).map(|e| e.0).ok());
            }
        }
        let ats: Vec<AtAmplitude> = per_log
            .iter()
            .zip(&logs)
            .zip(&u_rms)
            .filter_map(|((e, l), u)| {
                e.as_ref().map(|e| AtAmplitude {
                    name: &l.name,
                    u_rms_v: *u,
                    estimate: e,
                })
            })
            .collect();
        let amplitude = amplitude_dependence(&ats);
        // Information content.
        let coh_hi: Vec<usize> = plant.coherent(0.9).collect();
        let band09 = (!coh_hi.is_empty()).then(|| {
            (
                plant.freq_hz[coh_hi[0]],
                plant.freq_hz[*coh_hi.last().unwrap_or(&0)],
            )
        });
        let frac09 = coh_hi.len() as f64 / plant.len().max(1) as f64;
        let no_info = low_coherence_ranges(&plant, 0.5);
        let df = plant.freq_hz.first().copied().unwrap_or(f64::NAN);
        let method = if closed {
            "joint input-output: P = G_{r,theta}/G_{r,u} (reference r as instrument; the direct u -> theta estimate is biased in closed loop)"
        } else {
            "open loop: P = H1(u -> theta_l)"
        };
        if self.json {
            let mut frf = vec![("plant", points(&plant, -90.0))];
            if let Some(l) = &l {
                frf.push(("loop", points(l, -180.0)));
            }
            if let Some(t) = &t {
                frf.push(("complementary_sensitivity", points(t, 0.0)));
            }
            let a = achieved.as_ref();
            let out = json!({
                "schema": "servo.frf/1",
                "mode": if closed { "closed-loop" } else { "open-loop" },
                "logs": logs.iter().map(|l| l.name.clone()).collect::<Vec<_>>(),
                "method": method,
                "loop_from": l_from,
                "welch": {"window": spectra.window, "segment_len": spectra.segment_len, "segment_s": spectra.segment_len as f64 * ts,
                          "overlap": spectra.overlap, "segments": spectra.segments, "averages": spectra.averages,
                          "resolution_hz": df, "confidence": opts.confidence},
                "achieved": a.map(|a| json!({
                    "crossover_rad_s": interval(&a.crossover_rad_s),
                    "phase_margin_deg": interval(&a.phase_margin_deg),
                    "gain_margin_db": interval(&a.gain_margin_db),
                    "phase_crossover_rad_s": interval(&a.phase_crossover_rad_s),
                    "band_rad_s": [a.band_rad_s.0, a.band_rad_s.1],
                    "notes": a.notes,
                })),
                "design": design,
                "coherence": {"fraction_above_0_9": frac09, "band_hz_above_0_9": band09.map(|b| vec![b.0, b.1]),
                              "no_information_rad_s": no_info.iter().map(|r| vec![r.0, r.1]).collect::<Vec<_>>()},
                "against_model": comparison.as_ref().map(|c| json!({
                    "sentences": c.sentences,
                    "bands": c.bands.iter().map(|b| json!({"quantity": b.quantity, "lo_rad_s": b.lo_rad_s, "hi_rad_s": b.hi_rad_s, "worst": b.worst})).collect::<Vec<_>>(),
                    "delay_s": c.delay.map(|d| json!({"value": d.delay_s, "ci": d.delay_ci_s, "rms_deg": d.delay_rms_deg, "pole_rad_s": d.pole_rad_s, "pole_rms_deg": d.pole_rms_deg})),
                    "resonance_rad_s": c.resonance.map(|r| json!({"value": r.omega_rad_s, "peak_db": r.peak_db})),
                })),
                "amplitude": amplitude.as_ref().map(|a| json!({"gain_change_db": a.gain_change_db, "bound_db": a.bound_db, "significant": a.significant, "sentence": a.sentence, "u_rms_v": u_rms})),
                "notes": notes,
            });
            let Value::Object(rest) = &out else {
                bail!("internal error: the JSON document is not an object");
            };
            let doc = serde_json::to_string_pretty(&Doc { rest, frf })?;
            outln!("{doc}");
        } else {
            outln!(
                "servo frf: {} log(s), {} at {:.0} Hz",
                logs.len(),
                if closed { "closed loop" } else { "open loop" },
                1.0 / ts
            );
            outln!("estimate: Welch/H1, Hann window of {} samples ({:.3} Hz resolution), {:.0} % overlap, {} segments (~{:.1} independent averages), {:.0} % bounds", spectra.segment_len, df, 100.0 * spectra.overlap, spectra.segments, spectra.averages, 100.0 * opts.confidence);
            outln!("plant: {method}");
            match band09 {
                Some((a, b)) => outln!("coherence: >= 0.9 in {:.0} % of the bins, between {a:.3} and {b:.2} Hz ({:.2}-{:.1} rad/s)", 100.0 * frac09, a * std::f64::consts::TAU, b * std::f64::consts::TAU),
                None => outln!("coherence: never reaches 0.9: the data carry little information on the frequency response (steps and holds excite few frequencies; use a chirp or multisine)"),
            }
            let shown: Vec<String> = no_info
                .iter()
                .filter(|r| r.1 > r.0)
                .take(6)
                .map(|r| format!("{:.2}-{:.1}", r.0, r.1))
                .collect();
            if !shown.is_empty() {
                outln!(
                    "no information (coherence < 0.5) at {} rad/s{}",
                    shown.join(", "),
                    if no_info.len() > 6 { ", ..." } else { "" }
                );
            }
            if let Some(a) = &achieved {
                outln!("achieved ({l_from}):");
                outln!(
                    "  {}; {}; {}",
                    fmt_i(&a.crossover_rad_s, "rad/s", "crossover"),
                    fmt_i(&a.phase_margin_deg, "deg", "phase margin"),
                    fmt_i(&a.gain_margin_db, "dB", "gain margin")
                );
                for n in &a.notes {
                    outln!("  {n}");
                }
            }
            if let Some(d) = &design {
                outln!(
                    "design ({}): crossover {:.2} rad/s, phase margin {:.2} deg, gain margin {}",
                    d["loop"].as_str().unwrap_or(""),
                    d["crossover_rad_s"].as_f64().unwrap_or(f64::NAN),
                    d["phase_margin_deg"].as_f64().unwrap_or(f64::NAN),
                    d["gain_margin_db"]
                        .as_f64()
                        .map_or("infinite".into(), |g| format!("{g:.2} dB"))
                );
            }
            if let Some(c) = &comparison {
                outln!("against the model:");
                for s in &c.sentences {
                    outln!("  - {s}");
                }
            }
            if let Some(a) = &amplitude {
                outln!("amplitude: {}", a.sentence);
            }
            for n in &notes {
                outln!("note: {n}");
            }
        }
        if let Some(path) = &self.plot {
            let model_h: Option<Vec<Complex<f64>>> = model_resp
                .as_ref()
                .map(|(_, _, pm)| (0..plant.len()).map(|i| pm(plant.omega(i))).collect());
            std::fs::write(path, plot(&plant, model_h.as_deref())?)
                .with_context(|| format!("writing {}", path.display()))?;
            if !self.json {
                outln!("plot: {}", path.display());
            }
        }
        Ok(())
    }
}
