//! `servo design`: PID / PI / PD position controller by Bode's method (handout §3, eqs. 33-53),
//! verified on the reduced model, the full model and the discrete loop at T_s.

mod bode_plot;
mod compensated;
mod on_run;
mod outcome;
mod report_json;
mod report_specs;
mod report_text;
mod request;
mod spec_plot;
mod step_plot;
mod summary;
/// A number to six significant figures at most, without trailing zeros.
pub(crate) use summary::sig as sig6;
mod words;

use on_run::*;
use outcome::*;
use report_specs::*;
use report_text::*;
use request::parse_design_model;
pub use request::DesignModel;
use step_plot::*;
use words::*;

use crate::gains_file::{GainsFile, PidSection};
use crate::model_file::ModelFile;
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
use servo_io::controller::DerivativeOnArg;
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
    /// Model the gains are synthesised on: `reduced` (eq. 29, the handout's choice), `full`
    /// (eq. 27), or an identified model FILE: its linear part (J_eq, B_eq, the drive; reduced
    /// model), and with --ff the design verified on its whole nonlinear model.
    #[arg(long, value_name = "reduced|full|FILE", default_value = "reduced", value_parser = parse_design_model)]
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
    /// Plant parameter file (TOML, see `servo params`; the same file as `servo run --plant`);
    /// default: `--plant-preset`.
    #[arg(long, value_name = "FILE", conflicts_with = "plant_preset")]
    pub params: Option<PathBuf>,
    /// A built-in plant: `lab` (the default, as `servo run`'s: Table 2 with measured friction;
    /// the design uses its linear part, the check through `servo run`'s loop all of it) or
    /// `table2` (the handout's Table 2 without friction).
    #[arg(long = "plant-preset", value_enum, value_name = "PRESET")]
    pub plant_preset: Option<crate::plant_args::PlantPreset>,
    /// Reduced model given directly: k_m [rad/(V s)] (needs --tm; N from --params or 14).
    #[arg(long, value_name = "RAD_PER_V_S", requires = "tm")]
    pub km: Option<f64>,
    /// Reduced model given directly: T_m [s] (needs --km).
    #[arg(long, value_name = "S", requires = "km")]
    pub tm: Option<f64>,
    /// Print one JSON object instead of the report.
    #[arg(long)]
    pub json: bool,
    /// The whole report: the spec translation, the reduced, full and discrete linear loops'
    /// table and poles, every step case checked through `servo run`'s loop.
    #[arg(short, long)]
    pub verbose: bool,
    /// Write the gains file (-o) even when the time-domain specs are not met.
    #[arg(long)]
    pub force: bool,
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
    #[command(flatten)]
    pub comp: compensated::CompensationArgs,
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
            None => {
                let preset = self
                    .plant_preset
                    .unwrap_or(crate::plant_args::DEFAULT_PLANT);
                let plant = preset.model_file().plant()?;
                (plant.linear_params(), preset.describe().to_string())
            }
        };
        Ok(PlantSource {
            params,
            label,
            bare_reduced: self.km.is_some(),
        })
    }

    pub fn run(mut self) -> anyhow::Result<()> {
        if let DesignModel::File(p) = &self.model {
            if self.params.is_some() {
                bail!("--model FILE and --params both name the plant: give one");
            }
            self.params = Some(p.clone());
        }
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
            self.meet_through_run(&req, specs, structure.derivative_on, &tr)?
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
                run_check: None,
                compensated: None,
            }
        };
        let mut out = out;
        if let (false, None) = (src.bare_reduced, &out.run_check) {
            // what `servo run` gives with the gains: the time-domain specs when given, else the
            // default step range with nothing to meet
            let sp = out.check.as_ref().map(|c| c.specs).unwrap_or(TimeSpecs {
                overshoot_max: None,
                speed: None,
                step_min_rad: self.step_min,
                step_max_rad: self.step_max,
            });
            let gains = self.gains_file(&out, &tr);
            out.run_check = Some(self.run_check(&gains, &sp)?);
        }
        if self.comp.ff.is_some() {
            let gains = self.gains_file(&out, &tr);
            out.compensated = self.compensated_check(&out, &gains)?;
        }
        let report = &out.report;

        let gains = self.gains_file(&out, &tr);
        // gains that miss the specs asked for are written only when asked to (--force)
        let withheld = self
            .output
            .as_ref()
            .filter(|_| out.time_specs_met() == Some(false) && !self.force);
        if let (Some(path), None) = (&self.output, withheld) {
            gains.save(path)?;
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
            let mut v = self.json_report(&out, &tr, &src);
            v["compensation_check"] = out
                .compensated
                .as_ref()
                .map_or(Value::Null, compensated::compensated_json);
            crate::json_out::emit(&v)?;
        } else {
            let unit = gains.output_unit();
            let mut text = if self.verbose {
                self.text_report(&out, &tr, &translation_lines, &src, unit)
            } else {
                self.summary_report(&out, &src, unit)
            };
            if let (Some(p), None) = (&self.output, withheld) {
                let _ = writeln!(text, "wrote controller to {}", p.display());
            }
            for p in [&self.plot, &self.step_plot].into_iter().flatten() {
                let _ = writeln!(text, "wrote {}", p.display());
            }
            if !self.verbose {
                let _ = writeln!(
                    text,
                    "(--verbose: the spec translation, the linear loops' table and poles, every step case; --json)"
                );
            }
            emit(&text)?;
        }
        if let Some(p) = withheld {
            bail!(
                "the time-domain specs are NOT met: the gains were not written to {} \
                 (--force writes them anyway)",
                p.display()
            );
        }
        Ok(())
    }
}
