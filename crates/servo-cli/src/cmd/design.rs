//! `servo design`: PID / PI / PD position controller by Bode's method (handout §3, eqs. 33-53),
//! verified on the reduced model, the full model and the discrete loop at T_s.

mod bode_plot;
mod spec_plot;

use crate::gains_file::{GainsFile, PidSection};
use crate::model_file::ModelFile;
use crate::runner::controller::DerivativeOnArg;
use anyhow::{anyhow, bail, Context};
use serde_json::{json, Value};
use servo_core::control::DerivativeOn;
use servo_core::design::bode::{required_compensation, DerivativeFilter};
use servo_core::design::closed_loop::Stability;
use servo_core::design::controller::{controller_tf_s, controller_tf_z, Discretization};
use servo_core::design::meet::{meet_specs, MeetRequest, MeetResult};
use servo_core::design::spec::{
    damping_from_phase_margin, translate, DampingSpec, SpeedSpec, Translation,
};
use servo_core::design::step_range::{
    check_report, traces, FastPlant, LoopStructure, RangeCheck, SpeedTarget, TimeSpecs,
};
use servo_core::design::tf::TransferFunction;
use servo_core::design::verify::{design, Achieved, DesignReport, DesignRequest};
use servo_core::design::{c_abs, c_arg, deg, rad, ControllerKind, PidGains, PlantModel};
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
    /// Search w_gc, phase margin, alpha, T_L, the derivative input and the anti-windup gain K_w
    /// for a PID (or PI) whose step responses on the loop that runs (full model, ZOH at T_s,
    /// voltage limit, anti-windup) meet --overshoot and --settling-time (or --settling-time-1pct,
    /// --rise-time) for every step from --step-min to --step-max.
    #[arg(long, conflicts_with_all = ["exact", "kw"])]
    pub meet_specs: bool,
    /// Smallest reference step [rad] the time-domain specs must hold for.
    #[arg(long, value_name = "RAD", default_value_t = 0.2)]
    pub step_min: f64,
    /// Largest reference step [rad] the time-domain specs must hold for.
    #[arg(long, value_name = "RAD", default_value_t = 1.0)]
    pub step_max: f64,
    /// What the derivative acts on in the loop that runs (with --meet-specs: the one preferred;
    /// the search switches only when needed). Written to the gains file.
    #[arg(long = "derivative-on", value_enum, default_value = "error")]
    pub derivative_on: DerivativeOnArg,
    /// Back-calculation anti-windup gain K_w [1/s] of the loop that runs (default: no
    /// anti-windup; --meet-specs chooses it). Written to the gains file.
    #[arg(long, value_name = "PER_SECOND")]
    pub kw: Option<f64>,
    /// Driver input limit [V] of the loop that runs (written to the gains file).
    #[arg(long = "u-limit", value_name = "VOLTS", default_value_t = 10.0)]
    pub u_limit: f64,
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
    /// Write the loop's Bode plot (SVG) with crossover and margins marked; with time-domain specs,
    /// also the achieved step responses of the loop that runs against the spec box.
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
        let structure = LoopStructure {
            derivative_on: self.derivative_on.into(),
            kw_per_s: self.kw,
            u_limit_v: self.u_limit,
            discretization: req.discretization,
        };
        structure
            .validate()
            .map_err(|e| anyhow!("--u-limit/--kw: {e}"))?;
        let specs = self.time_specs();
        if let Some(sp) = &specs {
            sp.validate()
                .map_err(|e| anyhow!("time-domain specs: {e}"))?;
        }
        let out = if self.meet_specs {
            let specs = specs
                .filter(|s| s.overshoot_max.is_some() && s.speed.is_some())
                .ok_or_else(|| {
                    anyhow!(
                        "--meet-specs needs time-domain specs: --overshoot and one of --settling-time,                          --settling-time-1pct, --rise-time (e.g. --overshoot 0.1 --settling-time 0.15)"
                    )
                })?;
            let t0 = std::time::Instant::now();
            let m = meet_specs(&MeetRequest {
                base: req,
                specs,
                u_limit_v: self.u_limit,
                derivative_on: structure.derivative_on,
            })
            .map_err(|e| anyhow!("{e}"))
            .context("--meet-specs failed")?;
            let elapsed_ms = t0.elapsed().as_secs_f64() * 1e3;
            Outcome {
                report: m.report.clone(),
                structure: m.structure,
                check: Some(m.check.clone()),
                meet: Some((m, elapsed_ms)),
            }
        } else {
            let report = design(&req)
                .map_err(|e| anyhow!("{e}"))
                .context("design failed")?;
            let check = match &specs {
                Some(sp) => Some(
                    check_report(&report, &structure, sp)
                        .map_err(|e| anyhow!("{e}"))
                        .context("checking the time-domain specs")?,
                ),
                None => None,
            };
            Outcome {
                report,
                structure,
                check,
                meet: None,
            }
        };
        let report = &out.report;

        if let Some(path) = &self.output {
            self.gains_file(&out, &tr).save(path)?;
        }
        if let Some(path) = &self.plot {
            let panel = match &out.check {
                Some(c) => Some(spec_panel(&out, c)?),
                None => None,
            };
            bode_plot::write(path, report, panel.as_ref())
                .with_context(|| format!("--plot {}", path.display()))?;
        }
        if let Some(path) = &self.step_plot {
            write_step_plot(path, report)
                .with_context(|| format!("--step-plot {}", path.display()))?;
        }
        if self.json {
            emit(&format!(
                "{}\n",
                serde_json::to_string_pretty(&self.json_report(&out, &tr, &src))?
            ))?;
        } else {
            let mut text = self.text_report(&out, &tr, &translation_lines, &src);
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

    /// The time-domain specs given on the command line, if any.
    fn time_specs(&self) -> Option<TimeSpecs> {
        let speed = match (self.settling_time, self.settling_time_1pct, self.rise_time) {
            (Some(t), _, _) => Some(SpeedTarget::Settling {
                band: 0.05,
                time_s: t,
            }),
            (_, Some(t), _) => Some(SpeedTarget::Settling {
                band: 0.01,
                time_s: t,
            }),
            (_, _, Some(t)) => Some(SpeedTarget::Rise { time_s: t }),
            _ => None,
        };
        if self.overshoot.is_none() && speed.is_none() {
            return None;
        }
        Some(TimeSpecs {
            overshoot_max: self.overshoot,
            speed,
            step_min_rad: self.step_min,
            step_max_rad: self.step_max,
        })
    }

    fn design_model(&self, r: &DesignReport) -> PlantModel {
        match (self.model, r.request.full) {
            (DesignModel::Full, Some(f)) => f,
            _ => r.request.reduced,
        }
    }

    fn gains_file(&self, out: &Outcome, tr: &Translation) -> GainsFile {
        let r = &out.report;
        let g = &r.gains;
        let mut d = toml::Table::new();
        d.insert("method".into(), "Bode (handout eqs. 44-53)".into());
        d.insert("controller".into(), r.request.kind.name().into());
        d.insert("model".into(), self.design_model(r).name().into());
        d.insert("wgc_rad_s".into(), r.request.spec.omega_gc.into());
        d.insert("pm_deg".into(), deg(r.request.spec.phase_margin).into());
        d.insert("alpha".into(), r.request.alpha.into());
        d.insert(
            "discretization".into(),
            r.request.discretization.name().into(),
        );
        d.insert("exact".into(), self.exact.into());
        d.insert("meet_specs".into(), self.meet_specs.into());
        if self.meet_specs {
            d.insert("translated_wgc_rad_s".into(), tr.spec.omega_gc.into());
            d.insert("translated_pm_deg".into(), deg(tr.spec.phase_margin).into());
        }
        let m = &r.discrete.margins;
        if m.phase_margin_deg.is_finite() {
            d.insert("achieved_discrete_pm_deg".into(), m.phase_margin_deg.into());
            d.insert("achieved_discrete_wgc_rad_s".into(), m.omega_gc.into());
        }
        if let Some(c) = &out.check {
            if let Some(o) = c.specs.overshoot_max {
                d.insert("spec_overshoot_pct".into(), (100.0 * o).into());
            }
            d.insert("step_min_rad".into(), c.specs.step_min_rad.into());
            d.insert("step_max_rad".into(), c.specs.step_max_rad.into());
            d.insert(
                "achieved_worst_overshoot_pct".into(),
                c.worst_overshoot_pct.into(),
            );
            if let Some(t) = c.worst_speed_s {
                d.insert(format!("achieved_worst_{}", speed_key(&c.specs)), t.into());
            }
            d.insert("time_specs_met".into(), c.met().into());
        }
        GainsFile {
            pid: PidSection {
                kp: g.kp,
                ki: g.ki,
                kd: g.kd,
                tl_s: g.tl_s,
                ts_s: r.request.ts_s,
                kw: out.structure.kw_per_s,
                u_limit_v: Some(out.structure.u_limit_v),
                derivative_on: Some(out.structure.derivative_on),
            },
            design: Some(d),
        }
    }

    fn json_report(&self, out: &Outcome, tr: &Translation, src: &PlantSource) -> Value {
        let r = &out.report;
        let g = &r.gains;
        let st = &out.structure;
        let ls = r.request.spec;
        let model = self.design_model(r);
        let p_gc = model.response(ls.omega_gc);
        let (dk, dphi) = required_compensation(&ls, p_gc);
        let plant = match r.request.reduced {
            PlantModel::Reduced { k_m, t_m, n } => json!({"k_m": k_m, "t_m_s": t_m, "n": n}),
            PlantModel::Full { .. } => Value::Null,
        };
        json!({
            "controller": r.request.kind.name(),
            "kp": g.kp, "ki": g.ki, "kd": g.kd,
            "ti": num(g.ti_s()), "td": num(g.td_s()), "tl": g.tl_s,
            "wgc": ls.omega_gc, "pm_deg": deg(ls.phase_margin), "pm_rad": ls.phase_margin,
            "delta": tr.delta, "alpha": r.request.alpha, "ts": r.request.ts_s,
            "translated": {"wgc": tr.spec.omega_gc, "pm_deg": deg(tr.spec.phase_margin)},
            "discretization": r.request.discretization.name(),
            "derivative_on": derivative_name(st.derivative_on),
            "kw": st.kw_per_s,
            "u_limit_v": st.u_limit_v,
            "exact": self.exact,
            "meet_specs": out.meet.as_ref().map(|(m, ms)| meet_json(m, *ms)),
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
            "time_specs": out.check.as_ref().map(check_json),
            "transfer_functions": tf_json(r, st),
        })
    }

    fn text_report(
        &self,
        out: &Outcome,
        tr: &Translation,
        translation: &[String],
        src: &PlantSource,
    ) -> String {
        let mut s = String::new();
        let r = &out.report;
        let g = &r.gains;
        let model = self.design_model(r);
        // the loop spec of the gains: the translation, or what --meet-specs found
        let ls = r.request.spec;
        let w = ls.omega_gc;
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
        let (dk, dphi) = required_compensation(&ls, p_gc);
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
        if let Some((m, ms)) = &out.meet {
            meet_section(&mut s, m, *ms, tr, self);
        }
        let _ = writeln!(
            s,
            "\ngains{}:",
            if self.exact {
                " (--exact: w_gc and phase margin on the discrete loop equal the loop spec; the step \
                 response is checked below)"
            } else if self.meet_specs {
                " (--meet-specs)"
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
        let tl_note = match (self.tl, r.request.kind, &out.meet) {
            (_, ControllerKind::Pi, _) => "(no derivative)".to_string(),
            (_, _, Some((m, _))) => format!(
                "(1/T_L = {:.3} w_gc, chosen by --meet-specs)",
                m.params.tl_factor
            ),
            (Some(_), _, _) => "(given)".to_string(),
            (None, _, _) => format!("(1/T_L = {} w_gc, eq. 53)", self.tl_factor),
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
        let d = if self.meet_specs {
            damping_from_phase_margin(ls.phase_margin).unwrap_or(tr.delta)
        } else {
            tr.delta
        };
        let rows: [Row; 8] = [
            (
                "w_gc [rad/s]",
                format!("{w:.4}"),
                Box::new(|a: &Achieved| fmt_f(a.margins.omega_gc, 4)),
            ),
            (
                "phase margin [deg]",
                format!("{:.3}", deg(ls.phase_margin)),
                Box::new(|a: &Achieved| fmt_f(a.margins.phase_margin_deg, 3)),
            ),
            (
                "gain margin [dB]",
                "-".into(),
                Box::new(|a: &Achieved| fmt_gm(a.margins.gain_margin_db)),
            ),
            (
                "overshoot [%]",
                format!(
                    "~{:.2}",
                    100.0 * servo_core::design::spec::overshoot_from_damping(d)
                ),
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
        let pm_short = deg(ls.phase_margin) - r.discrete.margins.phase_margin_deg;
        if !self.exact && !self.meet_specs && pm_short > 0.5 {
            let _ = writeln!(
                s,
                "\nnote: the derivative filter and the ZOH delay cost {pm_short:.2} deg of phase margin on the discrete loop; \
                 use --exact to compensate."
            );
        }
        if r.request.alpha < 4.0 && r.request.kind == ControllerKind::Pid {
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
        if let Some(c) = &out.check {
            check_section(&mut s, c, r, out.meet.is_some());
        }
        s
    }
}

/// A design and what it achieves on the loop that runs.
struct Outcome {
    report: DesignReport,
    /// The controller structure around the gains (given, or chosen by --meet-specs).
    structure: LoopStructure,
    /// The check of the time-domain specs, when the design comes from them.
    check: Option<RangeCheck>,
    /// The --meet-specs search and its run time [ms].
    meet: Option<(MeetResult, f64)>,
}

fn derivative_name(d: DerivativeOn) -> &'static str {
    match d {
        DerivativeOn::Error => "error",
        DerivativeOn::Measurement => "measurement",
    }
}

/// The structure in words.
fn structure_words(st: &LoopStructure) -> String {
    format!(
        "derivative on the {}, {}, +-{} V limit, {} PID",
        derivative_name(st.derivative_on),
        match st.kw_per_s {
            Some(kw) => format!("back-calculation anti-windup K_w = {kw:.4} 1/s"),
            None => "no anti-windup".to_string(),
        },
        st.u_limit_v,
        st.discretization.name()
    )
}

/// `settling_time_5pct_s`, `settling_time_1pct_s` or `rise_time_s`.
fn speed_key(sp: &TimeSpecs) -> String {
    match sp.speed {
        Some(SpeedTarget::Rise { .. }) => "rise_time_s".into(),
        _ => format!("settling_time_{}pct_s", (100.0 * sp.band()).round()),
    }
}

/// Name of the speed figure in a table header.
fn speed_label(sp: &TimeSpecs) -> String {
    match sp.speed {
        Some(SpeedTarget::Rise { .. }) => "rise 10-90 % [s]".into(),
        _ => format!("settling {} % [s]", (100.0 * sp.band()).round()),
    }
}

fn speed_spec_s(sp: &TimeSpecs) -> Option<f64> {
    match sp.speed? {
        SpeedTarget::Settling { time_s, .. } | SpeedTarget::Rise { time_s } => Some(time_s),
    }
}

/// The --meet-specs summary: what was searched, what was found, the margins, the verdict.
fn meet_section(s: &mut String, m: &MeetResult, ms: f64, tr: &Translation, d: &Design) {
    let p = &m.params;
    let c = &m.check;
    let _ = writeln!(
        s,
        "
--meet-specs: searched w_gc, phase margin, alpha, T_L, the derivative input and K_w on the loop that runs \
         ({} designs simulated in {ms:.0} ms)",
        m.evaluations
    );
    let _ = writeln!(
        s,
        "  handout's design: w_gc = {:.3} rad/s, PM = {:.2} deg, alpha = {}, 1/T_L = {} w_gc, derivative on the {}",
        tr.spec.omega_gc,
        deg(tr.spec.phase_margin),
        d.alpha,
        d.tl.map_or(format!("{}", d.tl_factor), |t| format!("{:.3}", 1.0 / (t * tr.spec.omega_gc))),
        derivative_name(d.derivative_on.into())
    );
    let _ = writeln!(
        s,
        "  found:            w_gc = {:.3} rad/s, PM = {:.2} deg, alpha = {:.3}, 1/T_L = {:.3} w_gc, derivative on the {}, K_w = {:.4} 1/s",
        p.omega_gc,
        deg(p.phase_margin),
        p.alpha,
        p.tl_factor,
        derivative_name(p.derivative_on),
        p.kw_per_s
    );
    let dm = &m.report.discrete.margins;
    let _ = writeln!(
        s,
        "  margins it ends with (discrete loop): phase margin {} deg at w_gc = {} rad/s, gain margin {} dB, \
         sensitivity peak Ms = {:.3} ({:.2} dB)",
        fmt_f(dm.phase_margin_deg, 2),
        fmt_f(dm.omega_gc, 3),
        fmt_gm(dm.gain_margin_db),
        m.sensitivity_peak,
        20.0 * m.sensitivity_peak.log10()
    );
    let (lo, hi) = (c.specs.step_min_rad, c.specs.step_max_rad);
    let worst_speed = c
        .worst_speed_s
        .map_or("not settled".into(), |t| format!("{t:.4} s"));
    if m.feasible {
        let _ = writeln!(
            s,
            "  result: the specs are MET for every step from {lo} to {hi} rad: worst overshoot {:.2} %, worst {} {}",
            c.worst_overshoot_pct,
            speed_label(&c.specs).trim_end_matches(" [s]"),
            worst_speed
        );
    } else {
        let _ = writeln!(
            s,
            "  result: the specs are INFEASIBLE on this loop (plant, T_s, +-{} V) within the search box; \
             the closest achievable pair is overshoot {:.2} %, {} {} (worst over {lo}..{hi} rad) with the design above",
            m.structure.u_limit_v,
            c.worst_overshoot_pct,
            speed_label(&c.specs).trim_end_matches(" [s]"),
            worst_speed
        );
    }
}

/// The time-domain check: achieved figures per step size next to the spec, and a warning in words
/// when missed.
fn check_section(s: &mut String, c: &RangeCheck, r: &DesignReport, meet: bool) {
    let sp = &c.specs;
    let _ = writeln!(
        s,
        "
time-domain specs on the loop that runs ({} model, ZOH at T_s = {} s, {}), steps {}..{} rad:",
        r.discrete.plant,
        r.request.ts_s,
        structure_words(&c.structure),
        sp.step_min_rad,
        sp.step_max_rad
    );
    let _ = writeln!(
        s,
        "  {:<12}{:>16}{:>20}{:>16}",
        "step [rad]",
        "overshoot [%]",
        speed_label(sp),
        "peak |u| [V]"
    );
    let _ = writeln!(
        s,
        "  {:<12}{:>16}{:>20}",
        "spec",
        sp.overshoot_max
            .map_or("-".into(), |m| format!("<= {:.2}", 100.0 * m)),
        speed_spec_s(sp).map_or("-".into(), |t| format!("<= {t:.4}"))
    );
    let n = c.outcomes.len();
    let rows: Vec<usize> = if n <= 5 {
        (0..n).collect()
    } else {
        (0..5).map(|k| k * (n - 1) / 4).collect()
    };
    let rise = matches!(sp.speed, Some(SpeedTarget::Rise { .. }));
    for k in rows {
        let o = &c.outcomes[k];
        let speed = if rise {
            o.rise_time_s
        } else {
            o.settling_time_s
        };
        let _ = writeln!(
            s,
            "  {:<12.4}{:>16.2}{:>20}{:>16}",
            o.step_rad,
            o.overshoot_pct,
            speed.map_or("not settled".into(), |t| format!("{t:.4}")),
            format!(
                "{:.2}{}",
                o.peak_u_v,
                if o.saturated_fraction > 0.0 {
                    " (limit)"
                } else {
                    ""
                }
            )
        );
    }
    let _ = writeln!(
        s,
        "  {:<12}{:>16.2}{:>20}   (over {} step sizes)",
        "worst",
        c.worst_overshoot_pct,
        c.worst_speed_s
            .map_or("not settled".into(), |t| format!("{t:.4}")),
        n
    );
    if let (Some(first), Some(lin)) = (c.outcomes.first(), r.discrete.step) {
        if first.saturated_fraction > 0.0 {
            let _ = writeln!(
                s,
                "  note: even the {} rad step reaches the voltage limit; smaller steps stay linear and behave as the \
                 'discrete' column above ({:.2} % overshoot, settling 5 % {} s)",
                first.step_rad,
                lin.overshoot_pct,
                opt(lin.settling_time_5pct_s)
            );
        }
    }
    if c.met() {
        let _ = writeln!(
            s,
            "  the time-domain specs are met for every step size checked."
        );
        return;
    }
    let _ = writeln!(
        s,
        "WARNING: the design MISSES the time-domain specs on the loop that will run:"
    );
    if let (Some(ex), Some(m)) = (c.overshoot_excess_pct(), sp.overshoot_max) {
        let _ = writeln!(
            s,
            "  overshoot {:.2} % exceeds the spec {:.2} % by {ex:.2} percentage points ({:.1} x the spec)",
            c.worst_overshoot_pct,
            100.0 * m,
            c.worst_overshoot_pct / (100.0 * m)
        );
    }
    if let (Some(ex), Some(t)) = (c.speed_excess_s(), speed_spec_s(sp)) {
        let what = speed_label(sp).trim_end_matches(" [s]").to_string();
        match c.worst_speed_s {
            Some(w) => {
                let _ = writeln!(
                    s,
                    "  {what} {w:.4} s exceeds the spec {t} s by {ex:.4} s ({:+.0} %)",
                    100.0 * ex / t
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "  {what}: some step does not settle within the simulated {:.2} s (spec {t} s)",
                    c.outcomes.first().map_or(0.0, |o| o.horizon_s)
                );
            }
        }
    }
    if !meet {
        let _ = writeln!(
            s,
            "  (the handout's translation, eqs. 36-41, assumes a second-order loop without PID zeros, derivative \
             filter, ZOH or voltage limit; --meet-specs searches for a design that meets the specs)"
        );
    }
}

/// The step-response panel of --plot: the smallest, middle and largest steps.
fn spec_panel(out: &Outcome, c: &RangeCheck) -> anyhow::Result<spec_plot::SpecPanel> {
    let r = &out.report;
    let plant = FastPlant::new(&r.discrete_plant).map_err(|e| anyhow!("{e}"))?;
    let sp = &c.specs;
    let steps: Vec<f64> = {
        let mut v = vec![sp.step_min_rad];
        for x in [0.5 * (sp.step_min_rad + sp.step_max_rad), sp.step_max_rad] {
            if x > v[v.len() - 1] {
                v.push(x);
            }
        }
        v
    };
    let worst = c.worst_speed_s.unwrap_or(0.0);
    let t_end = (2.0 * speed_spec_s(sp).unwrap_or(0.0))
        .max(1.3 * worst)
        .max(10.0 / r.request.spec.omega_gc);
    let tr = traces(&plant, &r.gains, &out.structure, sp.band(), &steps, t_end)
        .map_err(|e| anyhow!("{e}"))?;
    Ok(spec_plot::SpecPanel {
        specs: *sp,
        traces: tr,
        t_end_s: t_end,
        caption: format!(
            "achieved steps on the loop that runs ({} model, ZOH, {})",
            r.discrete.plant,
            structure_words(&out.structure)
        ),
    })
}

fn check_json(c: &RangeCheck) -> Value {
    let sp = &c.specs;
    json!({
        "overshoot_max_pct": sp.overshoot_max.map(|m| 100.0 * m),
        "speed": match sp.speed {
            Some(SpeedTarget::Settling { band, time_s }) => json!({"kind": "settling", "band": band, "time_s": time_s}),
            Some(SpeedTarget::Rise { time_s }) => json!({"kind": "rise_10_90", "time_s": time_s}),
            None => Value::Null,
        },
        "step_min_rad": sp.step_min_rad,
        "step_max_rad": sp.step_max_rad,
        "loop": {
            "derivative_on": derivative_name(c.structure.derivative_on),
            "kw": c.structure.kw_per_s,
            "u_limit_v": c.structure.u_limit_v,
            "discretization": c.structure.discretization.name(),
        },
        "met": c.met(),
        "worst_overshoot_pct": c.worst_overshoot_pct,
        "worst_speed_s": c.worst_speed_s,
        "worst_ratio": c.worst_ratio,
        "overshoot_excess_pct": c.overshoot_excess_pct(),
        "speed_excess_s": c.speed_excess_s().map(num),
        "steps": c.outcomes.iter().map(|o| json!({
            "step_rad": o.step_rad,
            "overshoot_pct": o.overshoot_pct,
            "settling_time_s": o.settling_time_s,
            "rise_time_s": o.rise_time_s,
            "peak_u_v": o.peak_u_v,
            "saturated_fraction": o.saturated_fraction,
        })).collect::<Vec<_>>(),
    })
}

fn meet_json(m: &MeetResult, ms: f64) -> Value {
    let p = &m.params;
    let dm = &m.report.discrete.margins;
    json!({
        "feasible": m.feasible,
        "closest_pair": {
            "overshoot_pct": m.check.worst_overshoot_pct,
            "speed_s": m.check.worst_speed_s,
        },
        "wgc": p.omega_gc,
        "pm_deg": deg(p.phase_margin),
        "alpha": p.alpha,
        "tl_factor": p.tl_factor,
        "derivative_on": derivative_name(p.derivative_on),
        "kw": p.kw_per_s,
        "margins": {
            "pm_deg": num(dm.phase_margin_deg),
            "wgc": num(dm.omega_gc),
            "gm_db": num(dm.gain_margin_db),
            "sensitivity_peak": m.sensitivity_peak,
        },
        "evaluations": m.evaluations,
        "elapsed_ms": ms,
    })
}

/// Coefficient lists in descending powers (MATLAB `tf(num, den)`, python-control
/// `control.tf(num, den[, dt])`).
fn tf_entry(t: &TransferFunction) -> Value {
    json!({
        "num": TransferFunction::descending(&t.num),
        "den": TransferFunction::descending(&t.den),
    })
}

fn tf_json(r: &DesignReport, st: &LoopStructure) -> Value {
    let g = &r.gains;
    let ts = r.request.ts_s;
    let method = r.request.discretization;
    // the reference path: C(s) with the derivative on the error, K_P + K_I/s on the measurement
    let g_ref = match st.derivative_on {
        DerivativeOn::Error => *g,
        DerivativeOn::Measurement => PidGains { kd: 0.0, ..*g },
    };
    let plant = r.request.full.unwrap_or(r.request.reduced);
    let mut cz = tf_entry(&controller_tf_z(g, ts, method));
    cz["ts_s"] = json!(ts);
    let mut crz = tf_entry(&controller_tf_z(&g_ref, ts, method));
    crz["ts_s"] = json!(ts);
    let mut p = tf_entry(&plant.transfer_function());
    p["model"] = json!(plant.name());
    let mut pr = tf_entry(&r.request.reduced.transfer_function());
    pr["model"] = json!("reduced");
    json!({
        "ordering": "coefficients in descending powers of s or z, as MATLAB tf(num, den) and python-control tf(num, den[, dt])",
        "loop": "u = C_r r - C y: the feedback controller C acts on the measurement y [rad], C_r on the reference r [rad] (C_r = C with the derivative on the error, K_P + K_I/s with it on the measurement)",
        "plant_s": p,
        "plant_reduced_s": pr,
        "controller_s": tf_entry(&controller_tf_s(g)),
        "controller_z": cz,
        "controller_ref_s": tf_entry(&controller_tf_s(&g_ref)),
        "controller_ref_z": crz,
    })
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
