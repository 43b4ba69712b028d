//! `servo design`: PID / PI / PD position controller by Bode's method (handout §3, eqs. 33-53),
//! verified on the reduced model, the full model and the discrete loop at T_s.

mod bode_plot;

use crate::gains_file::{GainsFile, PidSection};
use crate::model_file::ModelFile;
use anyhow::{anyhow, bail, Context};
use serde_json::{json, Value};
use servo_core::design::bode::{required_compensation, DerivativeFilter};
use servo_core::design::closed_loop::Stability;
use servo_core::design::controller::Discretization;
use servo_core::design::spec::{translate, DampingSpec, SpeedSpec, Translation};
use servo_core::design::verify::{design, Achieved, DesignReport, DesignRequest};
use servo_core::design::{c_abs, c_arg, deg, rad, ControllerKind, PlantModel};
use servo_core::PlantParams;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Structure {
    Pid,
    Pi,
    Pd,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// s <- (z - 1)/(T_s z) (the default of `control::pid`)
    BackwardEuler,
    /// s <- 2/T_s (z - 1)/(z + 1)
    Tustin,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DesignModel {
    /// Eq. 29: k_m / ((T_m s + 1) N s) (the handout's choice)
    Reduced,
    /// Eq. 27: driver low-pass, armature R-L, mechanics, integrator
    Full,
}

/// Design a position controller by Bode's method and verify what it will achieve.
///
/// Loop spec: --wc and --pm, or time-domain specs (--overshoot with --settling-time,
/// --settling-time-1pct or --rise-time) translated by eqs. 36, 39-41.
/// Example: servo design --wc 30 --pm 60 ; servo design --overshoot 0.1 --settling-time 0.15
#[derive(Debug, clap::Parser)]
#[command(allow_negative_numbers = true)]
pub struct Design {
    /// Gain crossover frequency w_gc [rad/s].
    #[arg(long, value_name = "RAD_S", conflicts_with_all = ["settling_time", "settling_time_1pct", "rise_time"])]
    pub wc: Option<f64>,
    /// Phase margin phi_m [deg], in (0, 90).
    #[arg(long, value_name = "DEG", conflicts_with = "overshoot")]
    pub pm: Option<f64>,
    /// Step overshoot M_p as a fraction (0.1 = 10 %): phi_m by eqs. 36, 41.
    #[arg(long, value_name = "FRACTION")]
    pub overshoot: Option<f64>,
    /// 5 % settling time t_s,5% [s]: w_gc = 3/(delta t_s) (eq. 40).
    #[arg(long, value_name = "S", conflicts_with_all = ["settling_time_1pct", "rise_time"])]
    pub settling_time: Option<f64>,
    /// 1 % settling time t_s,1% [s]: w_gc = 4.6/(delta t_s) (eq. 40).
    #[arg(
        long = "settling-time-1pct",
        value_name = "S",
        conflicts_with = "rise_time"
    )]
    pub settling_time_1pct: Option<f64>,
    /// 10-90 % rise time t_r [s]: w_gc = 1.8/t_r (eq. 39).
    #[arg(long, value_name = "S")]
    pub rise_time: Option<f64>,
    /// Controller structure.
    #[arg(long, value_enum, default_value = "pid")]
    pub controller: Structure,
    /// alpha = T_I / T_D (PID, eq. 47).
    #[arg(long, default_value_t = 4.0)]
    pub alpha: f64,
    /// Real derivative (eq. 53): 1/T_L = factor x w_gc.
    #[arg(
        long,
        value_name = "FACTOR",
        default_value_t = 5.0,
        conflicts_with = "tl"
    )]
    pub tl_factor: f64,
    /// Real derivative time constant T_L [s] (overrides --tl-factor; 0 = ideal derivative, not
    /// verifiable in simulation).
    #[arg(long, value_name = "S")]
    pub tl: Option<f64>,
    /// Sample period T_s [s] of the discrete controller (ZOH).
    #[arg(long, value_name = "S", default_value_t = 1e-3)]
    pub ts: f64,
    /// Discretisation of the integral and the filtered derivative (as the running PID does it).
    #[arg(long, value_enum, default_value = "backward-euler")]
    pub discretization: Method,
    /// Model the gains are synthesised on.
    #[arg(long, value_enum, default_value = "reduced")]
    pub model: DesignModel,
    /// Solve numerically for gains whose achieved w_gc and phase margin on the discrete loop
    /// (real derivative, ZOH, full model when known) equal the spec.
    #[arg(long)]
    pub exact: bool,
    /// Plant parameter file (TOML, see `servo params`); default Table 2.
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Reduced model given directly: k_m [rad/(V s)] (needs --tm; N from --params or 14).
    #[arg(long, value_name = "RAD_PER_V_S", requires = "tm")]
    pub km: Option<f64>,
    /// Reduced model given directly: T_m [s] (needs --km).
    #[arg(long, value_name = "S", requires = "km")]
    pub tm: Option<f64>,
    /// Print one JSON object instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Write the loop's Bode plot (SVG) with crossover and margins marked.
    #[arg(long, value_name = "SVG")]
    pub plot: Option<PathBuf>,
    /// Write the closed-loop step responses (SVG).
    #[arg(long, value_name = "SVG")]
    pub step_plot: Option<PathBuf>,
    /// Write the controller (gains TOML) for `servo run --gains`.
    #[arg(short = 'o', long = "output", value_name = "TOML")]
    pub output: Option<PathBuf>,
}

/// Where the plant came from, for the report.
struct PlantSource {
    params: PlantParams,
    label: String,
    bare_reduced: bool,
}

impl Design {
    fn plant_source(&self) -> anyhow::Result<PlantSource> {
        let (params, label) = match &self.params {
            Some(p) => {
                let file = ModelFile::load(p)?;
                let plant = file.plant()?;
                (plant.linear_params(), format!("{}", p.display()))
            }
            None => (PlantParams::TABLE2, "Table 2 (nominal)".to_string()),
        };
        Ok(PlantSource {
            params,
            label,
            bare_reduced: self.km.is_some(),
        })
    }

    fn translation(&self) -> anyhow::Result<(Translation, Vec<String>)> {
        let damping = match (self.pm, self.overshoot) {
            (Some(pm), None) => DampingSpec::PhaseMargin(rad(pm)),
            (None, Some(mp)) => DampingSpec::Overshoot(mp),
            (None, None) => bail!("no damping spec: give --pm <deg> (e.g. --pm 60) or --overshoot <fraction> (e.g. --overshoot 0.1)"),
            (Some(_), Some(_)) => bail!("--pm and --overshoot both set the phase margin; give one"),
        };
        let speed = match (self.wc, self.settling_time, self.settling_time_1pct, self.rise_time) {
            (Some(w), None, None, None) => SpeedSpec::OmegaGc(w),
            (None, Some(t), None, None) => SpeedSpec::Settling5(t),
            (None, None, Some(t), None) => SpeedSpec::Settling1(t),
            (None, None, None, Some(t)) => SpeedSpec::RiseTime(t),
            (None, None, None, None) => bail!(
                "no speed spec: give --wc <rad/s> (e.g. --wc 30), --settling-time <s>, --settling-time-1pct <s> or --rise-time <s>"
            ),
            _ => bail!("give only one of --wc, --settling-time, --settling-time-1pct, --rise-time"),
        };
        let t = translate(damping, speed).map_err(|e| anyhow!("{e}"))?;
        let mut lines = Vec::new();
        match damping {
            DampingSpec::Overshoot(mp) => lines.push(format!(
                "M_p = {:.4} ({:.2} %) -> delta = {:.5} (eq. 36) -> phi_m = {:.4} rad = {:.3} deg (eq. 41)",
                mp,
                100.0 * mp,
                t.delta,
                t.spec.phase_margin,
                deg(t.spec.phase_margin)
            )),
            DampingSpec::PhaseMargin(_) => lines.push(format!(
                "phi_m = {:.3} deg -> delta = {:.5} (inverse of eq. 41), expected M_p ~ {:.2} % (eq. 33)",
                deg(t.spec.phase_margin),
                t.delta,
                100.0 * t.overshoot
            )),
        }
        match speed {
            SpeedSpec::OmegaGc(w) => lines.push(format!("w_gc = {w:.4} rad/s (given)")),
            SpeedSpec::Settling5(ts) => lines.push(format!(
                "t_s,5% = {ts} s -> w_gc = 3/(delta t_s,5%) = {:.4} rad/s (eq. 40)",
                t.spec.omega_gc
            )),
            SpeedSpec::Settling1(ts) => lines.push(format!(
                "t_s,1% = {ts} s -> w_gc = 4.6/(delta t_s,1%) = {:.4} rad/s (eq. 40)",
                t.spec.omega_gc
            )),
            SpeedSpec::RiseTime(tr) => lines.push(format!(
                "t_r = {tr} s -> w_gc = 1.8/t_r = {:.4} rad/s (eq. 39)",
                t.spec.omega_gc
            )),
        }
        Ok((t, lines))
    }

    pub fn run(self) -> anyhow::Result<()> {
        if !(self.alpha.is_finite() && self.alpha > 0.0) {
            bail!(
                "--alpha must be > 0 (T_I = alpha T_D; the handout uses alpha >= 4), got {}",
                self.alpha
            );
        }
        let src = self.plant_source()?;
        let (tr, translation_lines) = self.translation()?;
        let reduced = match (self.km, self.tm) {
            (Some(km), Some(tm)) => PlantModel::reduced_from(km, tm, src.params.n)
                .map_err(|e| anyhow!("--km/--tm: {e}"))?,
            _ => PlantModel::reduced(&src.params),
        };
        let full = if src.bare_reduced {
            None
        } else {
            Some(PlantModel::full(&src.params))
        };
        if self.model == DesignModel::Full && full.is_none() {
            bail!("--model full needs the full plant parameters (--params), not --km/--tm");
        }
        let kind = match self.controller {
            Structure::Pid => ControllerKind::Pid,
            Structure::Pi => ControllerKind::Pi,
            Structure::Pd => ControllerKind::Pd,
        };
        let filter = match self.tl {
            Some(t) => DerivativeFilter::TimeConstant(t),
            None => DerivativeFilter::Factor(self.tl_factor),
        };
        if self.tl == Some(0.0) && kind != ControllerKind::Pi {
            bail!("--tl 0 is an ideal derivative, which cannot be implemented or verified; use --tl > 0 or --tl-factor (2..5)");
        }
        let req = DesignRequest {
            kind,
            spec: tr.spec,
            alpha: self.alpha,
            filter,
            ts_s: self.ts,
            discretization: match self.discretization {
                Method::Tustin => Discretization::Tustin,
                Method::BackwardEuler => Discretization::BackwardEuler,
            },
            reduced,
            full,
            design_on_full: self.model == DesignModel::Full,
            exact: self.exact,
        };
        let report = design(&req)
            .map_err(|e| anyhow!("{e}"))
            .context("design failed")?;

        if let Some(path) = &self.output {
            self.gains_file(&report, &tr).save(path)?;
        }
        if let Some(path) = &self.plot {
            bode_plot::write(path, &report)
                .with_context(|| format!("--plot {}", path.display()))?;
        }
        if let Some(path) = &self.step_plot {
            write_step_plot(path, &report)
                .with_context(|| format!("--step-plot {}", path.display()))?;
        }
        if self.json {
            emit(&format!(
                "{}\n",
                serde_json::to_string_pretty(&self.json_report(&report, &tr, &src))?
            ))?;
        } else {
            let mut text = self.text_report(&report, &tr, &translation_lines, &src);
            if let Some(p) = &self.output {
                let _ = writeln!(text, "wrote controller to {}", p.display());
            }
            for p in [&self.plot, &self.step_plot].into_iter().flatten() {
                let _ = writeln!(text, "wrote {}", p.display());
            }
            emit(&text)?;
        }
        Ok(())
    }

    fn design_model(&self, r: &DesignReport) -> PlantModel {
        match (self.model, r.request.full) {
            (DesignModel::Full, Some(f)) => f,
            _ => r.request.reduced,
        }
    }

    fn gains_file(&self, r: &DesignReport, tr: &Translation) -> GainsFile {
        let g = &r.gains;
        let mut d = toml::Table::new();
        d.insert("method".into(), "Bode (handout eqs. 44-53)".into());
        d.insert("controller".into(), r.request.kind.name().into());
        d.insert("model".into(), self.design_model(r).name().into());
        d.insert("wgc_rad_s".into(), tr.spec.omega_gc.into());
        d.insert("pm_deg".into(), deg(tr.spec.phase_margin).into());
        d.insert("alpha".into(), self.alpha.into());
        d.insert(
            "discretization".into(),
            r.request.discretization.name().into(),
        );
        d.insert("exact".into(), self.exact.into());
        let m = &r.discrete.margins;
        if m.phase_margin_deg.is_finite() {
            d.insert("achieved_discrete_pm_deg".into(), m.phase_margin_deg.into());
            d.insert("achieved_discrete_wgc_rad_s".into(), m.omega_gc.into());
        }
        GainsFile {
            pid: PidSection {
                kp: g.kp,
                ki: g.ki,
                kd: g.kd,
                tl_s: g.tl_s,
                ts_s: r.request.ts_s,
                kw: None,
                u_limit_v: None,
            },
            design: Some(d),
        }
    }

    fn json_report(&self, r: &DesignReport, tr: &Translation, src: &PlantSource) -> Value {
        let g = &r.gains;
        let model = self.design_model(r);
        let p_gc = model.response(tr.spec.omega_gc);
        let (dk, dphi) = required_compensation(&tr.spec, p_gc);
        let plant = match r.request.reduced {
            PlantModel::Reduced { k_m, t_m, n } => json!({"k_m": k_m, "t_m_s": t_m, "n": n}),
            PlantModel::Full { .. } => Value::Null,
        };
        json!({
            "controller": r.request.kind.name(),
            "kp": g.kp, "ki": g.ki, "kd": g.kd,
            "ti": num(g.ti_s()), "td": num(g.td_s()), "tl": g.tl_s,
            "wgc": tr.spec.omega_gc, "pm_deg": deg(tr.spec.phase_margin), "pm_rad": tr.spec.phase_margin,
            "delta": tr.delta, "alpha": self.alpha, "ts": r.request.ts_s,
            "discretization": r.request.discretization.name(),
            "exact": self.exact,
            "design_model": model.name(),
            "plant_source": src.label,
            "reduced_model": plant,
            "p_jwgc": {"re": p_gc.re, "im": p_gc.im},
            "delta_k": dk, "delta_phi_rad": dphi,
            "handout_gains": {"kp": r.handout_gains.kp, "ki": r.handout_gains.ki, "kd": r.handout_gains.kd},
            "achieved": {
                "reduced": achieved_json(&r.reduced),
                "full": r.full.as_ref().map(achieved_json).unwrap_or(Value::Null),
                "discrete": achieved_json(&r.discrete),
            },
        })
    }

    fn text_report(
        &self,
        r: &DesignReport,
        tr: &Translation,
        translation: &[String],
        src: &PlantSource,
    ) -> String {
        let mut s = String::new();
        let g = &r.gains;
        let model = self.design_model(r);
        let w = tr.spec.omega_gc;
        let _ = writeln!(
            s,
            "servo design: {} by Bode's method (handout eqs. 44-53) on the {} model",
            r.request.kind.name().to_uppercase(),
            model.name()
        );
        match r.request.reduced {
            PlantModel::Reduced { k_m, t_m, n } => {
                let _ = writeln!(
                    s,
                    "plant: {}; reduced model P(s) = k_m/((T_m s + 1) N s), k_m = {k_m:.6} rad/(V s), T_m = {t_m:.6} s, N = {n}",
                    if src.bare_reduced { "given by --km/--tm".to_string() } else { src.label.clone() }
                );
            }
            PlantModel::Full { .. } => {}
        }
        let _ = writeln!(s, "\nspec translation:");
        for l in translation {
            let _ = writeln!(s, "  {l}");
        }
        let p_gc = model.response(w);
        let (dk, dphi) = required_compensation(&tr.spec, p_gc);
        let _ = writeln!(
            s,
            "  P(j w_gc) = {:.6} {:+.6}j (|P| = {:.6}, angle {:.3} deg) -> Delta K = {:.6}, Delta phi = {:.3} deg (eq. 44)",
            p_gc.re,
            p_gc.im,
            c_abs(p_gc),
            deg(c_arg(p_gc)),
            dk,
            deg(dphi)
        );
        let _ = writeln!(
            s,
            "\ngains{}:",
            if self.exact {
                " (--exact: achieved figures on the discrete loop match the spec)"
            } else {
                ""
            }
        );
        let _ = writeln!(
            s,
            "  K_P = {:<12.6} V/rad        T_I = {} s",
            g.kp,
            fmt_s(g.ti_s())
        );
        let _ = writeln!(
            s,
            "  K_I = {:<12.6} V/(rad s)    T_D = {} s",
            g.ki,
            fmt_s(g.td_s())
        );
        let tl_note = match (self.tl, r.request.kind) {
            (_, ControllerKind::Pi) => "(no derivative)".to_string(),
            (Some(_), _) => "(given)".to_string(),
            (None, _) => format!("(1/T_L = {} w_gc, eq. 53)", self.tl_factor),
        };
        let _ = writeln!(
            s,
            "  K_D = {:<12.6} V s/rad      T_L = {} s {tl_note}",
            g.kd,
            fmt_s(g.tl_s)
        );
        if self.exact {
            let h = &r.handout_gains;
            let _ = writeln!(
                s,
                "  (handout formulas would give K_P = {:.6}, K_I = {:.6}, K_D = {:.6})",
                h.kp, h.ki, h.kd
            );
        }
        let disc_plant = if r.request.full.is_some() {
            "full"
        } else {
            "reduced"
        };
        let _ = writeln!(
            s,
            "\nverification (real derivative; discrete = {} model, ZOH at T_s = {} s, {} PID):",
            disc_plant,
            r.request.ts_s,
            r.request.discretization.name()
        );
        let loops: Vec<&Achieved> = [Some(&r.reduced), r.full.as_ref(), Some(&r.discrete)]
            .into_iter()
            .flatten()
            .collect();
        let _ = write!(s, "  {:<22}{:>12}", "", "spec");
        for a in &loops {
            let _ = write!(s, "{:>12}", a.name);
        }
        let _ = writeln!(s);
        let d = tr.delta;
        let rows: [Row; 8] = [
            (
                "w_gc [rad/s]",
                format!("{w:.4}"),
                Box::new(|a: &Achieved| fmt_f(a.margins.omega_gc, 4)),
            ),
            (
                "phase margin [deg]",
                format!("{:.3}", deg(tr.spec.phase_margin)),
                Box::new(|a: &Achieved| fmt_f(a.margins.phase_margin_deg, 3)),
            ),
            (
                "gain margin [dB]",
                "-".into(),
                Box::new(|a: &Achieved| fmt_gm(a.margins.gain_margin_db)),
            ),
            (
                "overshoot [%]",
                format!("~{:.2}", 100.0 * tr.overshoot),
                Box::new(|a: &Achieved| {
                    a.step
                        .map_or("-".into(), |m| format!("{:.2}", m.overshoot_pct))
                }),
            ),
            (
                "rise 10-90 % [s]",
                format!("~{:.4}", 1.8 / w),
                Box::new(|a: &Achieved| a.step.map_or("-".into(), |m| opt(m.rise_time_s))),
            ),
            (
                "settling 5 % [s]",
                format!("~{:.4}", 3.0 / (d * w)),
                Box::new(|a: &Achieved| a.step.map_or("-".into(), |m| opt(m.settling_time_5pct_s))),
            ),
            (
                "settling 1 % [s]",
                format!("~{:.4}", 4.6 / (d * w)),
                Box::new(|a: &Achieved| a.step.map_or("-".into(), |m| opt(m.settling_time_1pct_s))),
            ),
            (
                "closed loop",
                "".into(),
                Box::new(|a: &Achieved| stability_name(a.stability).into()),
            ),
        ];
        for (name, spec, f) in rows.iter() {
            let _ = write!(s, "  {name:<22}{spec:>12}");
            for a in &loops {
                let _ = write!(s, "{:>12}", f(a));
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(
            s,
            "  (spec column: time figures are the 2nd-order estimates of eqs. 32-33, 39-40)"
        );
        let _ = writeln!(s, "\nclosed-loop poles:");
        for a in &loops {
            let unit = if a.name == "discrete" {
                "z"
            } else {
                "s [rad/s]"
            };
            let poles: Vec<String> = a
                .poles
                .iter()
                .map(|p| format!("{:.4}{:+.4}j", p.re, p.im))
                .collect();
            let _ = writeln!(s, "  {:<9} {unit}: {}", a.name, poles.join(", "));
        }
        let pm_short = deg(tr.spec.phase_margin) - r.discrete.margins.phase_margin_deg;
        if !self.exact && pm_short > 0.5 {
            let _ = writeln!(
                s,
                "\nnote: the derivative filter and the ZOH delay cost {pm_short:.2} deg of phase margin on the discrete loop; \
                 use --exact to compensate."
            );
        }
        if self.alpha < 4.0 && r.request.kind == ControllerKind::Pid {
            let _ = writeln!(
                s,
                "note: alpha < 4 gives complex PID zeros (the handout recommends alpha >= 4)."
            );
        }
        for a in &loops {
            if a.stability != Stability::Stable {
                let _ = writeln!(
                    s,
                    "WARNING: the {} loop is {}.",
                    a.name,
                    stability_name(a.stability)
                );
            }
        }
        s
    }
}

/// One row of the verification table: name, spec column, value per loop.
type Row = (&'static str, String, Box<dyn Fn(&Achieved) -> String>);

/// Writes to stdout; a closed pipe (`servo design | head`) is not an error.
fn emit(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.context("writing to stdout"),
    }
}

fn stability_name(s: Stability) -> &'static str {
    match s {
        Stability::Stable => "stable",
        Stability::Marginal => "MARGINAL",
        Stability::Unstable => "UNSTABLE",
    }
}

fn num(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

fn fmt_f(x: f64, prec: usize) -> String {
    if x.is_finite() {
        format!("{x:.prec$}")
    } else {
        "none".into()
    }
}

fn fmt_gm(x: f64) -> String {
    if x.is_infinite() {
        "inf".into()
    } else {
        format!("{x:.2}")
    }
}

fn fmt_s(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.6}")
    } else {
        "inf".into()
    }
}

fn opt(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |v| format!("{v:.4}"))
}

fn achieved_json(a: &Achieved) -> Value {
    let m = &a.margins;
    let st = a.step;
    json!({
        "plant": a.plant,
        "pm_deg": num(m.phase_margin_deg),
        "wgc": num(m.omega_gc),
        "gm_db": num(m.gain_margin_db),
        "wpc": num(m.omega_pc),
        "gain_crossovers": m.gain_crossovers,
        "overshoot_pct": st.map(|s| s.overshoot_pct),
        "rise_time_s": st.and_then(|s| s.rise_time_s),
        "settling_time_5pct_s": st.and_then(|s| s.settling_time_5pct_s),
        "settling_time_1pct_s": st.and_then(|s| s.settling_time_1pct_s),
        "stable": a.stability == Stability::Stable,
        "stability": stability_name(a.stability).to_lowercase(),
        "poles": a.poles.iter().map(|p| json!([p.re, p.im])).collect::<Vec<_>>(),
    })
}

fn write_step_plot(path: &std::path::Path, r: &DesignReport) -> anyhow::Result<()> {
    use crate::plot::{line_chart, Chart, Series};
    let loops: Vec<&Achieved> = [Some(&r.reduced), r.full.as_ref(), Some(&r.discrete)]
        .into_iter()
        .flatten()
        .filter(|a| !a.response.time_s.is_empty())
        .collect();
    if loops.is_empty() {
        bail!("no loop is stable, there is no step response to plot");
    }
    // show up to the longest 1 % settling time x 1.5 (or the whole horizon)
    let t_end = loops
        .iter()
        .filter_map(|a| a.step.and_then(|m| m.settling_time_1pct_s))
        .fold(0.0, f64::max)
        .max(5.0 / r.request.spec.omega_gc)
        * 1.5;
    let cut: Vec<(String, Vec<f64>, Vec<f64>)> = loops
        .iter()
        .map(|a| {
            let n = a
                .response
                .time_s
                .iter()
                .take_while(|&&t| t <= t_end)
                .count()
                .max(2);
            (
                format!("{} loop", a.name),
                a.response.time_s[..n].to_vec(),
                a.response.y_rad[..n].to_vec(),
            )
        })
        .collect();
    let t_ref = vec![0.0, t_end];
    let y_ref = vec![1.0, 1.0];
    let mut series = vec![Series {
        label: "reference 1 rad",
        x: &t_ref,
        y: &y_ref,
    }];
    for (label, t, y) in &cut {
        series.push(Series { label, x: t, y });
    }
    line_chart(
        path,
        &Chart {
            title: "closed-loop step response (r = 1 rad)",
            x_label: "time [s]",
            y_label: "theta_l [rad]",
            ..Chart::default()
        },
        &series,
    )
}
