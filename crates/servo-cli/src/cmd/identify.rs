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

use anyhow::{anyhow, bail, Context};
use servo_core::ident::combined::{identify_combined, CombinedConfig, CombinedFit};
use servo_core::ident::electrical::{identify_electrical, ElectricalFit};
use servo_core::ident::friction::{
    friction_points, identify_friction, FrictionConfig, FrictionFit,
};
use servo_core::ident::inertia::{identify_inertia, identify_inertia_ls, InertiaFit};
use servo_core::ident::phases::{find_phases, PhaseConfig};
use servo_core::ident::{Estimate, Experiment, IdentError};
use servo_core::PlantParams;
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

    /// Write a model file with the identified j_eq, b_eq, tau_sf and a [provenance] table.
    #[arg(short = 'o', long = "output", value_name = "MODEL_TOML")]
    pub output: Option<PathBuf>,

    /// Draw torque vs speed with the fitted friction line and the inertia phases (SVG).
    #[arg(long = "plot", value_name = "SVG")]
    pub plot: Option<PathBuf>,

    /// Run the identification experiments (friction staircase, inertia ramps) on the backend,
    /// log them to MCAP and estimate from them.
    #[arg(long = "ramp")]
    pub ramp: bool,

    /// Recipes of the `--ramp` experiments (TOML); default: the recipes built into servo (the
    /// same as experiments/identify_friction.toml and experiments/identify_inertia.toml).
    #[arg(long = "friction-recipe", value_name = "TOML")]
    pub friction_recipe: Option<PathBuf>,
    #[arg(long = "inertia-recipe", value_name = "TOML")]
    pub inertia_recipe: Option<PathBuf>,

    /// Backend of the `--ramp` experiments: the simulator (`--plant`) or a board on `--port`
    /// (`servo board --pty`/`--qemu` or real firmware). The staircase turns the load for many
    /// revolutions: start the board with wide position limits (e.g. `--theta-min-rad -1e6
    /// --theta-max-rad 1e6`); the host's own position limits are off for these runs.
    #[arg(long, value_enum, default_value = "sim")]
    pub backend: crate::cmd::run::BackendKind,
    /// Serial port of the board (`--backend serial`).
    #[arg(long, value_name = "PATH", default_value = "/dev/ttyACM0")]
    pub port: String,
    /// Baud rate of the serial port [bit/s] (ignored by USB CDC and pseudo-terminals).
    #[arg(long, value_name = "BAUD", default_value_t = 115_200)]
    pub baud: u32,
    /// A board silent for this long during a run is lost: 0 V, error [ms].
    #[arg(long = "board-timeout-ms", value_name = "MS", default_value_t = 250.0)]
    pub board_timeout_ms: f64,

    /// Live progress of the `--ramp` experiments on stderr (elapsed, left, missed deadlines):
    /// `auto` on a terminal, `always`, `never`.
    #[arg(long, value_enum, default_value = "auto")]
    pub progress: crate::runner::ProgressMode,

    /// Directory for the `--ramp` logs.
    #[arg(long = "log-dir", value_name = "DIR", default_value = ".")]
    pub log_dir: PathBuf,

    /// Simulated plant for `--ramp` on the simulator; default: the lab plant of `servo params`
    /// (friction as measured on real SRV-02s).
    #[command(flatten)]
    pub plant: crate::plant_args::PlantArgs,
}

/// Everything identified, with where it came from.
#[derive(Debug, Default)]
pub struct Report {
    pub friction: Option<FrictionFit>,
    pub inertia: Option<InertiaFit>,
    pub combined: Option<CombinedFit>,
    pub electrical: Option<ElectricalFit>,
    /// Methods that could not run, with the reason.
    pub skipped: Vec<String>,
}

impl Report {
    /// B_eq with the method that gave it.
    pub fn b_eq(&self) -> Option<(Estimate, &'static str)> {
        self.friction
            .as_ref()
            .map(|f| (f.b_eq, "friction"))
            .or_else(|| self.combined.as_ref().map(|c| (c.b_eq, "combined")))
    }
    pub fn tau_sf(&self) -> Option<(Estimate, &'static str)> {
        self.friction
            .as_ref()
            .map(|f| (f.tau_sf, "friction"))
            .or_else(|| self.combined.as_ref().map(|c| (c.tau_sf, "combined")))
    }
    pub fn j_eq(&self) -> Option<(Estimate, &'static str)> {
        self.inertia
            .as_ref()
            .map(|f| (f.j_eq, "inertia"))
            .or_else(|| self.combined.as_ref().map(|c| (c.j_eq, "combined")))
    }
}

impl Identify {
    pub fn run(self) -> anyhow::Result<()> {
        let mut params = match &self.params {
            Some(p) => ModelFile::load(p).context("--params")?,
            None => ModelFile::default(),
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
        let mut records = Vec::new();
        let mut logs: Vec<PathBuf> = Vec::new();
        for (k, path) in self.logs.iter().enumerate() {
            let cols = match self.columns.len() {
                0 => None,
                1 => Some(self.columns[0].as_str()),
                _ => Some(self.columns[k].as_str()),
            };
            let rec = crate::io::read_log(path, cols)
                .with_context(|| format!("reading log {}", path.display()))?;
            records.push(rec);
            logs.push(path.clone());
        }
        if self.ramp {
            for path in crate::cmd::identify_ramp::run_experiments(&self, &params.params)? {
                let rec = crate::io::read_log(&path, None)
                    .with_context(|| format!("reading log {}", path.display()))?;
                if !self.json {
                    outln!("logged {}", path.display());
                }
                records.push(rec);
                logs.push(path);
            }
        }
        if records.iter().all(|r| r.i_a_a.is_none() && r.u_v.is_some()) {
            return self.run_without_current(&records, &logs, params);
        }
        let mut exps = Vec::new();
        for (rec, path) in records.iter().zip(&logs) {
            let e = Experiment::from_record(rec, &params.params)
                .with_context(|| format!("log {}", path.display()))?;
            exps.push(e);
        }
        let report = self.estimate(&exps, &params.params)?;
        if self.json {
            outln!(
                "{}",
                serde_json::to_string_pretty(&self.json_report(&report, &logs))?
            );
        } else {
            out!("{}", self.text_report(&report, &logs, &params.params));
        }
        if let Some(path) = &self.plot {
            std::fs::write(path, plot_svg(&report, &exps)?)
                .with_context(|| format!("writing --plot {}", path.display()))?;
        }
        if let Some(out) = &self.output {
            let mut file = params.clone();
            let (b, t, j) = (report.b_eq(), report.tau_sf(), report.j_eq());
            if b.is_none() && j.is_none() {
                bail!("-o {}: nothing was identified to write", out.display());
            }
            if let Some((e, _)) = b {
                file.params.b_eq = Some(e.value.max(0.0));
            }
            if let Some((e, _)) = t {
                file.params.tau_sf = Some(e.value.max(0.0));
            }
            if let Some((e, _)) = j {
                file.params.j_eq = Some(e.value);
            }
            file.params
                .validate()
                .map_err(|e| anyhow!("identified parameters are not physical: {e}"))?;
            file.provenance = Some(provenance(&report, &logs));
            file.save(out)?;
            if !self.json {
                outln!("wrote {}", out.display());
            }
        }
        Ok(())
    }

    /// Logs of u and angle only: J_eq, B_eq and tau_sf from the u-driven balance with the drive
    /// constants of the params file (see `servo_core::fit::identify_without_current`).
    fn run_without_current(
        &self,
        records: &[servo_core::record::Record],
        logs: &[PathBuf],
        mut params: ModelFile,
    ) -> anyhow::Result<()> {
        use servo_core::fit::{identify_without_current, FitOptions, DRIVE_CONSTANT_TOLERANCE};
        let est = identify_without_current(records, &params.params, &FitOptions::default())
            .map_err(|e| anyhow!("identification from u and angle failed: {e}"))?;
        let tol_pct = 100.0 * DRIVE_CONSTANT_TOLERANCE;
        let note = format!(
            "no log records the armature current: J_eq, B_eq and tau_sf were estimated from u and the angle alone, with the u-driven balance k_drv k_t u / R_eq = J_eq dw/dt + (B_eq + k_t k_e / R_eq) w + tau_sf/N sign(w), taking k_drv = {}, R_eq = {} ohm, k_e = {}, k_t = {} from the params file; their {tol_pct:.0} % tolerance each is added to the intervals",
            params.params.k_drv,
            params.params.r_eq(),
            params.params.k_e,
            params.params.k_t
        );
        if self.json {
            let v = serde_json::json!({
                "method": "u-driven balance (no current logged)",
                "note": note,
                "drive_constant_tolerance": DRIVE_CONSTANT_TOLERANCE,
                "logs": logs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "estimates": est.iter().map(|e| serde_json::json!({
                    "key": e.key, "unit": e.unit, "value": e.value,
                    "std_err": e.std_err, "std_err_with_drive_tolerance": e.std_err_total,
                    "widening": if e.std_err > 0.0 { e.std_err_total / e.std_err } else { f64::NAN },
                })).collect::<Vec<_>>(),
            });
            outln!("{}", serde_json::to_string_pretty(&v)?);
        } else {
            outln!("{note}.");
            for e in &est {
                outln!(
                    "  {:<7} = {:.4e} {:<10} +/- {:.2e} (statistical) -> +/- {:.2e} with the drive-constant tolerance ({:.1}x wider)",
                    e.key,
                    e.value,
                    e.unit,
                    e.std_err,
                    e.std_err_total,
                    if e.std_err > 0.0 { e.std_err_total / e.std_err } else { f64::NAN }
                );
            }
        }
        if let Some(out) = &self.output {
            for e in &est {
                match e.key {
                    "j_eq" => params.params.j_eq = Some(e.value),
                    "b_eq" => params.params.b_eq = Some(e.value.max(0.0)),
                    "tau_sf" => params.params.tau_sf = Some(e.value.max(0.0)),
                    _ => {}
                }
            }
            params
                .params
                .validate()
                .map_err(|e| anyhow!("identified parameters are not physical: {e}"))?;
            params.save(out)?;
            if !self.json {
                outln!("wrote {}", out.display());
            }
        }
        Ok(())
    }

    fn friction_cfg(&self) -> FrictionConfig {
        FrictionConfig {
            samples: self.samples,
            ..FrictionConfig::default()
        }
    }
    fn phase_cfg(&self) -> PhaseConfig {
        PhaseConfig {
            cutoff_hz: self.cutoff_hz,
            min_accel_rad_s2: self.min_accel,
            window_frac: self.phase_window,
            ..PhaseConfig::default()
        }
    }

    /// Runs the chosen (or every applicable) method.
    pub fn estimate(&self, exps: &[Experiment], p: &PlantParams) -> anyhow::Result<Report> {
        let fcfg = self.friction_cfg();
        let pcfg = self.phase_cfg();
        let ccfg = CombinedConfig {
            cutoff_hz: self.cutoff_hz,
            ..CombinedConfig::default()
        };
        let mut r = Report::default();
        let inertia =
            |exps: &[Experiment], f: Option<&FrictionFit>| -> Result<InertiaFit, IdentError> {
                match self.inertia_method {
                    InertiaMethod::Phases => identify_inertia(exps, f, &pcfg),
                    InertiaMethod::Ls => identify_inertia_ls(exps, f, &pcfg),
                }
            };
        match self.method {
            Some(Method::Friction) => r.friction = Some(identify_friction(exps, p.n, &fcfg)?),
            Some(Method::Combined) => r.combined = Some(identify_combined(exps, p.n, &ccfg)?),
            Some(Method::Electrical) => r.electrical = Some(identify_electrical(exps, p, &fcfg)?),
            Some(Method::Inertia) => {
                let (fr, ir) = split_logs(exps, &fcfg, &pcfg)?;
                if ir.is_empty() {
                    inertia(exps, None)?; // produces the explanation
                }
                let f = if fr.is_empty() {
                    None
                } else {
                    identify_friction(&fr, p.n, &fcfg).ok()
                };
                r.friction = f.clone();
                r.inertia = Some(inertia(&ir, f.as_ref())?);
            }
            None => {
                let (fr, ir) = split_logs(exps, &fcfg, &pcfg)?;
                if !fr.is_empty() {
                    match identify_friction(&fr, p.n, &fcfg) {
                        Ok(f) => r.friction = Some(f),
                        Err(e) => r.skipped.push(format!("friction: {e}")),
                    }
                    if fr.iter().any(|e| e.u_v.is_some()) {
                        match identify_electrical(&fr, p, &fcfg) {
                            Ok(e) => r.electrical = Some(e),
                            Err(e) => r.skipped.push(format!("electrical: {e}")),
                        }
                    }
                } else {
                    r.skipped.push(String::from(
                        "friction: no log has constant-speed segments at two or more speeds (handout 4.1 staircase)",
                    ));
                }
                if !ir.is_empty() {
                    match inertia(&ir, r.friction.as_ref()) {
                        Ok(i) => r.inertia = Some(i),
                        Err(e) => r.skipped.push(format!("inertia: {e}")),
                    }
                } else {
                    r.skipped.push(String::from(
                        "inertia: no log has constant acceleration/deceleration phases (handout 4.2)",
                    ));
                }
                if r.friction.is_none() || r.inertia.is_none() {
                    match identify_combined(exps, p.n, &ccfg) {
                        Ok(c) => r.combined = Some(c),
                        Err(e) => r.skipped.push(format!("combined: {e}")),
                    }
                }
                if r.b_eq().is_none() && r.j_eq().is_none() {
                    bail!(
                        "nothing could be identified from these logs:\n  {}",
                        r.skipped.join("\n  ")
                    );
                }
            }
        }
        Ok(r)
    }

    fn text_report(&self, r: &Report, logs: &[PathBuf], p: &PlantParams) -> String {
        let mut s = String::new();
        s.push_str(&format!(
            "servo identify: {} log(s); k_t = {:e} N m/A, k_e = {:e} V s/rad, N = {}\n",
            logs.len(),
            p.k_t,
            p.k_e,
            p.n
        ));
        let line = |name: &str, unit: &str, e: &Estimate, how: &str| {
            format!(
                "  {name:<7}= {:.4e} {unit:<10} se {:.2e}  95% CI [{:.4e}, {:.4e}]  ({how}; residual rms {:.2e}, cond {:.1}, dof {})\n",
                e.value, e.std_err, e.ci95.0, e.ci95.1, e.residual_rms, e.cond, e.dof
            )
        };
        if let Some(f) = &r.friction {
            s.push_str(&format!(
                "friction (4.1): {} constant-speed segments\n",
                f.points.len()
            ));
            for pt in &f.points {
                s.push_str(&format!(
                    "    log {} {:7.3}..{:7.3} s  w_m = {:9.2} rad/s  tau_m = {:+.4e} N m\n",
                    pt.experiment + 1,
                    pt.t_start_s,
                    pt.t_end_s,
                    pt.omega_m_rad_s,
                    pt.tau_m_nm
                ));
            }
        }
        if let Some(i) = &r.inertia {
            s.push_str(&format!(
                "inertia (4.2): {} phases, {} acceleration/deceleration pairs\n",
                i.phases.len(),
                i.pairs.len()
            ));
            for &(a, d, j) in &i.pairs {
                let (pa, pd) = (&i.phases[a], &i.phases[d]);
                s.push_str(&format!(
                    "    a+ = {:7.1} rad/s^2 tau_i+ = {:+.3e}  a- = {:7.1} tau_i- = {:+.3e}  J_eq,n = {:.4e} kg m^2\n",
                    pa.accel_rad_s2, pa.tau_i_nm, pd.accel_rad_s2, pd.tau_i_nm, j
                ));
            }
        }
        if let Some(c) = &r.combined {
            s.push_str(&format!("combined LS (4.3): {} samples\n", c.rows));
        }
        s.push_str("estimates (B_eq, J_eq motor side; tau_sf load side):\n");
        if let Some((e, how)) = r.b_eq() {
            s.push_str(&line("B_eq", "N m s/rad", &e, how));
        }
        if let Some((e, how)) = r.tau_sf() {
            s.push_str(&line("tau_sf", "N m", &e, how));
        }
        if let Some((e, how)) = r.j_eq() {
            s.push_str(&line("J_eq", "kg m^2", &e, how));
        }
        if let Some(el) = &r.electrical {
            s.push_str(&line("k_drv", "V/V", &el.k_drv, "electrical"));
            s.push_str(&line("R_eq", "ohm", &el.r_eq, "electrical"));
            s.push_str(&format!(
                "    datasheet: k_drv = {:.4}, R_eq = {:.4} ohm\n",
                el.nominal_k_drv, el.nominal_r_eq
            ));
            for w in &el.warnings {
                s.push_str(&format!("  WARNING: {w}\n"));
            }
        }
        for n in notes(r) {
            s.push_str(&format!("  note: {n}\n"));
        }
        for k in &r.skipped {
            s.push_str(&format!("  not identified: {k}\n"));
        }
        s
    }

    fn json_report(&self, r: &Report, logs: &[PathBuf]) -> serde_json::Value {
        let est = |e: Option<(Estimate, &'static str)>, unit: &str, side: &str| match e {
            None => serde_json::Value::Null,
            Some((e, how)) => serde_json::json!({
                "value": e.value, "std_err": e.std_err, "ci95": [e.ci95.0, e.ci95.1], "unit": unit, "side": side,
                "method": how, "residual_rms": e.residual_rms, "cond": e.cond, "dof": e.dof, "n": e.n,
            }),
        };
        let mut v = serde_json::json!({
            "B_eq": est(r.b_eq(), "N m s/rad", "motor"),
            "tau_sf": est(r.tau_sf(), "N m", "load"),
            "J_eq": est(r.j_eq(), "kg m^2", "motor"),
            "logs": logs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "notes": notes(r),
            "not_identified": r.skipped,
        });
        if let Some(el) = &r.electrical {
            v["k_drv"] = est(Some((el.k_drv, "electrical")), "V/V", "driver");
            v["R_eq"] = est(Some((el.r_eq, "electrical")), "ohm", "armature");
            v["electrical_warnings"] = serde_json::json!(el.warnings);
        }
        if let Some(f) = &r.friction {
            v["friction_points"] = f
                .points
                .iter()
                .map(|p| serde_json::json!({"log": p.experiment, "t_start_s": p.t_start_s, "t_end_s": p.t_end_s, "omega_m_rad_s": p.omega_m_rad_s, "tau_m_nm": p.tau_m_nm}))
                .collect();
        }
        if let Some(i) = &r.inertia {
            v["inertia_pairs"] = i.pairs.iter().map(|p| serde_json::json!(p.2)).collect();
        }
        v
    }
}

fn notes(r: &Report) -> Vec<String> {
    let mut n = Vec::new();
    if let Some(f) = &r.friction {
        n.extend(f.notes.iter().cloned());
    }
    if let Some(i) = &r.inertia {
        n.extend(i.notes.iter().cloned());
    }
    if let Some(c) = &r.combined {
        n.extend(c.notes.iter().cloned());
    }
    n
}

/// Splits the experiments into those with constant-speed segments at >= 2 speeds (friction) and
/// those with >= 2 acceleration phases (inertia). A log may be in both.
fn split_logs(
    exps: &[Experiment],
    fcfg: &FrictionConfig,
    pcfg: &PhaseConfig,
) -> anyhow::Result<(Vec<Experiment>, Vec<Experiment>)> {
    let mut fr = Vec::new();
    let mut ir = Vec::new();
    for e in exps {
        let pts = friction_points(std::slice::from_ref(e), fcfg)?;
        let mags: Vec<f64> = pts.iter().map(|p| p.omega_m_rad_s.abs()).collect();
        let (lo, hi) = mags
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(a, b), &m| (a.min(m), b.max(m)));
        if pts.len() >= 2 && hi - lo > 0.1 * hi {
            fr.push(e.clone());
        }
        if find_phases(&e.time_s, &e.omega_m_rad_s, pcfg)?.len() >= 2 {
            ir.push(e.clone());
        }
    }
    Ok((fr, ir))
}

fn provenance(r: &Report, logs: &[PathBuf]) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert(
        "tool".into(),
        toml::Value::String(format!("servo identify {}", env!("CARGO_PKG_VERSION"))),
    );
    t.insert("date".into(), toml::Value::String(utc_now()));
    t.insert(
        "logs".into(),
        toml::Value::Array(
            logs.iter()
                .map(|p| toml::Value::String(p.display().to_string()))
                .collect(),
        ),
    );
    let mut methods = Vec::new();
    for (key, e) in [
        ("b_eq", r.b_eq()),
        ("tau_sf", r.tau_sf()),
        ("j_eq", r.j_eq()),
    ] {
        if let Some((e, how)) = e {
            methods.push(format!("{key}: {how}"));
            t.insert(
                format!("{key}_ci95"),
                toml::Value::Array(vec![e.ci95.0.into(), e.ci95.1.into()]),
            );
            t.insert(format!("{key}_std_err"), toml::Value::Float(e.std_err));
        }
    }
    t.insert("method".into(), toml::Value::String(methods.join(", ")));
    if let Some(el) = &r.electrical {
        t.insert(
            "k_drv_identified".into(),
            toml::Value::Float(el.k_drv.value),
        );
        t.insert(
            "r_eq_identified_ohm".into(),
            toml::Value::Float(el.r_eq.value),
        );
    }
    t
}

/// Current UTC time as ISO 8601 (no external crate: civil-from-days).
fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The plot: torque vs speed (plateau means and the fitted friction line) and, when there are
/// phases, the inertial torque against the acceleration with the fitted J_eq line.
fn plot_svg(r: &Report, exps: &[Experiment]) -> anyhow::Result<String> {
    use crate::plot::{line_chart_svg, Chart, Series};
    let mut charts = Vec::new();
    if let Some(f) = &r.friction {
        let mut pts: Vec<(f64, f64)> = f
            .points
            .iter()
            .map(|p| (p.omega_m_rad_s, p.tau_m_nm))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (px, py): (Vec<f64>, Vec<f64>) = pts.into_iter().unzip();
        let wmax = px.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
        let lx = [-wmax, -1e-9 * wmax, 1e-9 * wmax, wmax];
        let ly: Vec<f64> = lx.iter().map(|&w| f.torque_nm(w)).collect();
        let chart = Chart {
            title: "Friction: motor torque k_t i_a vs motor speed at constant speeds",
            x_label: "omega_m [rad/s]",
            y_label: "tau_m [N m]",
            ..Chart::default()
        };
        charts.push(line_chart_svg(
            &chart,
            &[
                Series {
                    label: "plateau means (measured)",
                    x: &px,
                    y: &py,
                },
                Series {
                    label: "fit B_eq w + tau_sf/N sign(w)",
                    x: &lx,
                    y: &ly,
                },
            ],
        )?);
    }
    if let Some(i) = &r.inertia {
        if !i.phases.is_empty() {
            let mut pts: Vec<(f64, f64)> = i
                .phases
                .iter()
                .map(|p| (p.accel_rad_s2, p.tau_i_nm))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (px, py): (Vec<f64>, Vec<f64>) = pts.into_iter().unzip();
            let amax = px.iter().fold(0.0_f64, |m, a| m.max(a.abs()));
            let lx = [-amax, amax];
            let ly = [-amax * i.j_eq.value, amax * i.j_eq.value];
            let chart = Chart {
                title: "Inertia: mean inertial torque per phase vs acceleration",
                x_label: "a_m [rad/s^2]",
                y_label: "tau_i [N m]",
                ..Chart::default()
            };
            charts.push(line_chart_svg(
                &chart,
                &[
                    Series {
                        label: "phase means (measured)",
                        x: &px,
                        y: &py,
                    },
                    Series {
                        label: "fit J_eq a_m",
                        x: &lx,
                        y: &ly,
                    },
                ],
            )?);
            // Speed record with the phases marked.
            if let Some(e) = exps.get(i.phases[0].experiment) {
                let step = (e.time_s.len() / 4000).max(1);
                let tx: Vec<f64> = e.time_s.iter().step_by(step).copied().collect();
                let wy: Vec<f64> = e.omega_m_rad_s.iter().step_by(step).copied().collect();
                let mut mx = Vec::new();
                let mut my = Vec::new();
                for p in i
                    .phases
                    .iter()
                    .filter(|p| p.experiment == i.phases[0].experiment)
                {
                    let w0 = e.omega_m_rad_s[p.start];
                    mx.extend([e.time_s[p.start], e.time_s[p.end - 1]]);
                    my.extend([
                        w0,
                        w0 + p.accel_rad_s2 * (e.time_s[p.end - 1] - e.time_s[p.start]),
                    ]);
                }
                let chart = Chart {
                    title:
                        "Inertia test: motor speed and the detected constant-acceleration phases",
                    x_label: "t [s]",
                    y_label: "omega_m [rad/s]",
                    ..Chart::default()
                };
                charts.push(line_chart_svg(
                    &chart,
                    &[
                        Series {
                            label: "omega_m",
                            x: &tx,
                            y: &wy,
                        },
                        Series {
                            label: "phases (fitted slopes)",
                            x: &mx,
                            y: &my,
                        },
                    ],
                )?);
            }
        }
    }
    if charts.is_empty() {
        bail!("--plot: nothing to draw (no friction segments or inertia phases were identified)");
    }
    Ok(stack_svgs(&charts))
}

/// Stacks SVG documents vertically into one SVG (nested <svg> elements).
fn stack_svgs(parts: &[String]) -> String {
    let (w, h) = (900, 400);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{}\" viewBox=\"0 0 {w} {}\">\n",
        h * parts.len(),
        h * parts.len()
    );
    for (k, p) in parts.iter().enumerate() {
        let body = p.trim_start_matches(|c| c != '<');
        let body = if body.starts_with("<?xml") {
            body.split_once("?>").map(|x| x.1).unwrap_or(body)
        } else {
            body
        };
        let body = body
            .trim_start()
            .replacen("<svg ", &format!("<svg y=\"{}\" ", k * h), 1);
        s.push_str(&body);
        s.push('\n');
    }
    s.push_str("</svg>\n");
    s
}

/// Parses `--phase-window FROM,TO` (fractions of a phase, 0 <= FROM < TO <= 1).
fn parse_window(s: &str) -> Result<(f64, f64), String> {
    let err =
        || format!("expected FROM,TO with 0 <= FROM < TO <= 1 (fractions of a phase), got `{s}`");
    let (a, b) = s.split_once(',').ok_or_else(err)?;
    let a: f64 = a.trim().parse().map_err(|_| err())?;
    let b: f64 = b.trim().parse().map_err(|_| err())?;
    if (0.0..1.0).contains(&a) && a < b && b <= 1.0 {
        Ok((a, b))
    } else {
        Err(err())
    }
}
