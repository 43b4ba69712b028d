//! `servo identify`: friction, inertia and electrical constants from logs or from experiments run
//! on a backend (handout section 4).
//!
//! ```text
//! servo identify friction_pos.csv friction_neg.csv inertia.csv --columns time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A \
//!     --params course.toml --json -o identified.toml --plot fit.svg
//! servo identify --ramp                      # run the recipes of experiments/ on the simulator, then estimate
//! ```
//!
//! Without `--method` every applicable method runs: friction on the logs with constant-speed
//! segments, inertia (eqs. 67-70) on the logs with acceleration/deceleration phases using that
//! friction, the electrical check where the voltage u was logged, and the combined LS (4.3) for
//! whatever the dedicated tests could not give.

mod options;
mod plot;
mod report;
mod smart;
pub mod sysid;
mod without_current;

use options::parse_window;
use plot::*;
use report::*;

use anyhow::{anyhow, bail, Context};
use servo_core::ident::auto::{
    self, identify, needs_u_driven_balance, Identification, IdentifyOptions,
};
use servo_core::ident::combined::CombinedConfig;
use servo_core::ident::friction::FrictionConfig;
use servo_core::ident::phases::PhaseConfig;
use servo_core::ident::{Estimate, Experiment};
use std::path::PathBuf;

use crate::model_file::ModelFile;

/// Identification method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Constant-speed segments: B_eq and tau_sf (handout 4.1).
    Friction,
    /// Constant acceleration/deceleration phases: J_eq (4.2), with friction from friction logs.
    Inertia,
    /// One LS over the whole record(s): J_eq, B_eq, tau_sf (4.3).
    Combined,
    /// Steady-state voltage balance: k_drv and R_eq (needs u, i_a, speed).
    Electrical,
}

/// How the inertia is computed from the phases.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InertiaMethod {
    /// Eqs. 67-70: per acceleration/deceleration pair, averaged over the pairs.
    Phases,
    /// LS of tau_i = J_eq dw/dt over the samples with |dw/dt| above the threshold.
    Ls,
}

/// Identify friction, inertia and electrical constants from logs or experiments.
#[derive(Debug, clap::Parser)]
pub struct Identify {
    /// Logs to estimate from (MCAP, CSV or MATLAB .mat). Several logs give one joint estimate (e.g. the
    /// positive and negative friction runs and the inertia run).
    #[arg(value_name = "LOG")]
    pub logs: Vec<PathBuf>,

    /// Column map for CSV and .mat logs, e.g. `time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A` (MATLAB paths
    /// for .mat: `time=scope.time,omega_m=scope.signals(1).values:rpm`; `servo inspect` lists them). Given once it
    /// applies to every log; given once per log it applies to the logs in order.
    #[arg(long = "columns", value_name = "MAP")]
    pub columns: Vec<String>,

    #[command(flatten)]
    pub part: crate::log_part::LogPartArgs,

    /// Method; default: every method the data supports.
    #[arg(long = "method", value_enum)]
    pub method: Option<Method>,

    /// Inertia estimator.
    #[arg(long = "inertia-method", value_enum, default_value = "phases")]
    pub inertia_method: InertiaMethod,

    /// Model file with the known constants (k_t, k_e, N, k_drv, R_a, R_s); default Table 2.
    #[arg(long = "params", value_name = "FILE")]
    pub params: Option<PathBuf>,

    /// Override the torque constant k_t [N m/A].
    #[arg(long = "k-t", value_name = "NM_PER_A")]
    pub k_t: Option<f64>,

    /// Override the BEMF constant k_e [V s/rad].
    #[arg(long = "k-e", value_name = "V_S_PER_RAD")]
    pub k_e: Option<f64>,

    /// Override the gear ratio N [-].
    #[arg(long = "gear-ratio", value_name = "N")]
    pub gear_ratio: Option<f64>,

    /// Fit every plateau sample instead of the plateau means (friction).
    #[arg(long = "samples")]
    pub samples: bool,

    /// Low-pass cut-off for differentiation (inertia phases, combined) [Hz].
    #[arg(long = "cutoff-hz", value_name = "HZ", default_value_t = 10.0)]
    pub cutoff_hz: f64,

    /// Acceleration threshold for the inertia phases [rad/s^2] (motor side); default 30 % of
    /// the 95th percentile of |dw_m/dt|.
    #[arg(long = "min-accel", value_name = "RAD_PER_S2")]
    pub min_accel: Option<f64>,
    /// Part of each acceleration/deceleration phase averaged for eqs. 67-70, as fractions of the
    /// phase `FROM,TO` (e.g. `0.7,0.9`: the last part, after the current transient); default:
    /// the phase minus 10 % at each end.
    #[arg(long = "phase-window", value_name = "FROM,TO", value_parser = parse_window)]
    pub phase_window: Option<(f64, f64)>,

    /// Print the estimates as JSON (B_eq, tau_sf, J_eq in SI; B_eq and J_eq motor side, tau_sf
    /// load side) instead of the text report.
    #[arg(long = "json")]
    pub json: bool,

    /// Print every friction segment and inertia pair the estimates rest on.
    #[arg(long)]
    pub verbose: bool,

    /// Write a model file with the identified j_eq, b_eq, tau_sf and a [provenance] table.
    #[arg(short = 'o', long = "output", value_name = "MODEL_TOML")]
    pub output: Option<PathBuf>,

    /// Electrical constants fitted by the electrical balance to write into the model (-o)
    /// instead of the datasheet values: `k_drv` (driver gain), `r_eq` (R_a + R_s; R_a is set
    /// to R_eq - R_s). Comma-separated or repeated; each is recorded in [provenance].
    #[arg(long = "keep-fitted", value_name = "KEY", value_delimiter = ',', value_parser = ["k_drv", "r_eq"])]
    pub keep_fitted: Vec<String>,

    /// Draw torque vs speed with the fitted friction line and the inertia phases (SVG).
    #[arg(long = "plot", value_name = "SVG")]
    pub plot: Option<PathBuf>,

    /// Run the identification experiments (friction staircase, inertia ramps) on the backend,
    /// log them to MCAP and estimate from them.
    #[arg(long = "ramp")]
    pub ramp: bool,

    /// The backend, recipes, progress and log directory of `--ramp`.
    #[command(flatten)]
    pub ramp_args: crate::cmd::identify_ramp::RampArgs,
    #[command(flatten)]
    pub smart: smart::SmartArgs,
    #[command(flatten)]
    pub sysid: sysid::SysIdArgs,
}

/// Everything identified, with where it came from (servo_core::ident::auto).
pub type Report = Identification;

impl Identify {
    pub fn run(mut self) -> anyhow::Result<()> {
        if self.smart.drive.is_some() {
            return self.run_smart();
        }
        // Where the motor's constants come from, said where they are used (the report and the
        // file written): --params, the simulated motor of --ramp --plant, or Table 2.
        let mut defaults: Option<String> = None;
        let mut params = match &self.params {
            Some(p) => ModelFile::load(p).context("--params")?,
            None => match self.ramp_plant() {
                Some(plant) => {
                    let mut m = ModelFile::load(plant).context("--plant")?;
                    // The constants, drive and transmission of the simulated motor; what is
                    // identified starts unknown.
                    m.params.j_eq = None;
                    m.params.b_eq = None;
                    m.params.tau_sf = None;
                    m.effects = servo_core::effects::Effects::NONE;
                    m.custom = servo_core::custom::CustomSlots::NONE;
                    m.sensors = None;
                    m.provenance = None;
                    m.limits.clear();
                    let note = format!(
                        "no --params: the motor's constants (k_t, k_e, N, k_drv, R_a, R_s, L_a), drive and \
                         transmission are those of the simulated motor, --plant {}",
                        plant.display()
                    );
                    eprintln!("note: {note}");
                    m
                }
                None => {
                    defaults = Some(String::new());
                    ModelFile::default()
                }
            },
        };
        for (flag, v, slot) in [
            ("--k-t", self.k_t, &mut params.params.k_t),
            ("--k-e", self.k_e, &mut params.params.k_e),
            ("--gear-ratio", self.gear_ratio, &mut params.params.n),
        ] {
            if let Some(v) = v {
                if !(v > 0.0 && v.is_finite()) {
                    bail!("{flag} must be a positive number, got {v}");
                }
                *slot = v;
            }
        }
        if defaults.is_some() {
            let p = &params.params;
            let given = |v: Option<f64>| v.is_some();
            let mut used: Vec<String> = Vec::new();
            for (key, v, unit, flag) in [
                ("k_t", p.k_t, "N m/A", given(self.k_t)),
                ("k_e", p.k_e, "V s/rad", given(self.k_e)),
                ("N", p.n, "", given(self.gear_ratio)),
                ("k_drv", p.k_drv, "V/V", false),
                ("R_a", p.r_a, "ohm", false),
                ("R_s", p.r_s, "ohm", false),
                ("L_a", p.l_a, "H", false),
            ] {
                if !flag {
                    used.push(
                        format!("{key} = {} {unit}", servo_core::math::sig(v, 4))
                            .trim_end()
                            .to_string(),
                    );
                }
            }
            let sim_lab = self.ramp
                && self.ramp_args.backend == crate::cmd::run::BackendKind::Sim
                && self.ramp_args.plant.plant.is_none();
            defaults = Some(if sim_lab {
                format!(
                    "no --params: {} are the lab motor's defaults (the handout's Table 2), which the \
                     built-in simulated plant also uses; for another motor give its model file with --params",
                    used.join(", ")
                )
            } else {
                format!(
                    "no --params: {} are the lab motor's defaults (the handout's Table 2), not measured \
                     on this motor; every estimate rests on them (J_eq and B_eq scale with k_t and N): \
                     give the motor's model file with --params",
                    used.join(", ")
                )
            });
        }
        if !(self.cutoff_hz > 0.0 && self.cutoff_hz.is_finite()) {
            bail!(
                "--cutoff-hz must be a positive frequency in Hz, got {}",
                self.cutoff_hz
            );
        }
        if let Some(a) = self.min_accel {
            if !(a > 0.0 && a.is_finite()) {
                bail!("--min-accel must be a positive acceleration in rad/s^2, got {a}");
            }
        }
        if self.logs.is_empty() && !self.ramp {
            bail!("no logs given: pass LOG files (MCAP, or CSV/.mat with --columns) or --ramp to run the experiments");
        }
        if !(self.columns.len() <= 1 || self.columns.len() == self.logs.len()) {
            bail!(
                "--columns given {} times for {} logs: give it once (for every log) or once per log",
                self.columns.len(),
                self.logs.len()
            );
        }
        self.part.check(self.logs.len())?;
        let mut records = Vec::new();
        let mut logs: Vec<PathBuf> = Vec::new();
        let mut parts = Vec::new();
        for (k, path) in self.logs.iter().enumerate() {
            let cols = match self.columns.len() {
                0 => None,
                1 => Some(self.columns[0].as_str()),
                _ => Some(self.columns[k].as_str()),
            };
            let mut rec = crate::io::read_log_model(path, cols, &params)
                .with_context(|| format!("reading log {}", path.display()))?;
            self.sysid.collect(&rec, path, &params);
            parts.push(self.part.apply(&mut rec, path, k, self.logs.len())?);
            records.push(rec);
            logs.push(path.clone());
        }
        if self.ramp {
            for path in crate::cmd::identify_ramp::run_experiments(&self.ramp_args, &params.params)?
            {
                let rec = crate::io::read_log(&path, None)
                    .with_context(|| format!("reading log {}", path.display()))?;
                if !self.json {
                    outln!("logged {}", path.display());
                }
                records.push(rec);
                logs.push(path);
            }
        }
        // Effects declared in the params file are fitted with the base (never ignored): the
        // model fit of fit::udriven, on the balances the logs allow.
        let declares = params.effects.iter().any(|e| {
            !matches!(
                e.kind,
                servo_core::effects::EffectKind::Viscous | servo_core::effects::EffectKind::Coulomb
            )
        });
        if let Some(d) = &defaults {
            if self.json {
                eprintln!("note: {d}");
            } else {
                outln!("note: {d}");
            }
        }
        if needs_u_driven_balance(&records) || (declares && records.iter().all(|r| r.u_v.is_some()))
        {
            if let Some(d) = &defaults {
                params
                    .provenance
                    .get_or_insert_with(toml::Table::new)
                    .insert("defaults".into(), toml::Value::String(d.clone()));
            }
            return self.run_without_current(&records, &logs, &parts, params);
        }
        let mut exps = Vec::new();
        for (rec, path) in records.iter().zip(&logs) {
            let e = Experiment::from_record(rec, &params.params)
                .with_context(|| format!("log {}", path.display()))?;
            if let Some(note) = &e.speed_note {
                eprintln!("note: {note}");
            }
            exps.push(e);
        }
        let report = identify(&exps, &params.params, &self.options())?;
        if self.json {
            let mut v = self.json_report(&report, &logs, &params);
            v["log_parts"] = crate::log_part::json(&parts);
            v["sysid"] = self.sysid.json();
            crate::json_out::emit(&v)?;
        } else {
            out!("{}{}", crate::log_part::text(&parts), self.sysid.text());
            out!("{}", self.text_report(&report, &logs, &params));
        }
        if let Some(path) = &self.plot {
            crate::io::output::write_file(path, "--plot", plot_svg(&report, &exps)?)?;
        }
        if let Some(out) = &self.output {
            let mut file = params.clone();
            let (b, t, j) = (report.b_eq(), report.tau_sf(), report.j_eq());
            if b.is_none() && j.is_none() {
                bail!("-o {}: nothing was identified to write", out.display());
            }
            // Where the next command reads them: the friction effects of the template (which
            // override [params]) take the identified values too.
            // A negative friction estimate is unphysical: written as 0, and said so.
            let mut clamped: Vec<String> = Vec::new();
            for (name, unit, est) in [("B_eq", "N m s/rad", b), ("tau_sf", "N m", t)] {
                if let Some((e, _)) = est.filter(|(e, _)| e.value < 0.0) {
                    clamped.push(clamp_note(name, unit, &e, out));
                }
            }
            for c in &clamped {
                if self.json {
                    eprintln!("note: {c}");
                } else {
                    outln!("note: {c}");
                }
            }
            if let Some((e, _)) = b {
                file.params.b_eq = Some(e.value.max(0.0));
                file.effects
                    .remove(servo_core::effects::EffectKind::Viscous);
            }
            if let Some((e, _)) = t {
                file.params.tau_sf = Some(e.value.max(0.0));
                file.effects
                    .remove(servo_core::effects::EffectKind::Coulomb);
            }
            if let Some((e, _)) = j {
                file.params.j_eq = Some(e.value);
            }
            let mut prov = provenance(&report, &logs);
            if let Some(d) = &defaults {
                prov.insert("defaults".into(), toml::Value::String(d.clone()));
            }
            report::keep_fitted(&self.keep_fitted, &report, &mut file.params, &mut prov)?;
            file.params
                .validate()
                .map_err(|e| anyhow!("identified parameters are not physical: {e}"))?;
            file.provenance = Some(prov);
            file.save_over(out, &ModelFile::FRICTION_KINDS)?;
            if !self.json {
                let kept = if self.keep_fitted.is_empty() {
                    String::new()
                } else {
                    format!(" ({} kept as fitted)", self.keep_fitted.join(", "))
                };
                outln!("wrote {}{kept}", out.display());
            }
        }
        Ok(())
    }
}
