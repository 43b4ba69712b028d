//! `servo identify --drive position`: a smart servo (the host commands a goal position, the
//! servo's firmware closes its own P loop) fitted on whole trajectories
//! (`servo_core::smart::fit`).

use super::*;
use serde_json::{json, Value};
use servo_core::smart::{self, FitKind, GravityFit, PositionLoop, SmartLog, SmartPrior};
use std::time::Instant;

/// The flags of a smart servo's identification.
#[derive(Debug, Clone, clap::Args)]
pub struct SmartArgs {
    /// The drive of the logs: `position` for a smart servo (Dynamixel, Feetech, ...: the log
    /// holds the goal position, the firmware's loop drives the motor). The logs are smart-servo
    /// CSVs (goal_rad, theta_rad, omega_rad_s, duty, vin_meas_V, torque_enable) or BAM JSON logs;
    /// the model is fitted on the trajectories replayed from the goals.
    #[arg(long = "drive", value_parser = ["position"])]
    pub drive: Option<String>,
    /// The firmware's P gain in the vendor's units (Dynamixel's Position P Gain): once for
    /// every log, or once per log (the --held-out logs after the fitted ones).
    #[arg(
        long = "kp-fw",
        requires = "drive",
        value_name = "KP",
        value_delimiter = ','
    )]
    pub kp_fw: Vec<f64>,
    /// Duty per rad of position error per unit of the firmware gain [1/rad]; default Dynamixel
    /// X-series, 4096 / (2 pi 256 885).
    #[arg(long = "duty-per-rad-per-kp", requires = "drive", value_name = "PER_RAD",
          default_value_t = PositionLoop::xl330(1.0).duty_per_rad_per_kp)]
    pub duty_per_rad_per_kp: f64,
    /// The bridge's supply [V] (default: --params' [drive] v_supply_v, else each log's
    /// supply column, which then drives the replay row by row).
    #[arg(long = "v-supply-v", requires = "drive", value_name = "V")]
    pub v_supply_v: Option<f64>,
    /// The firmware's largest duty magnitude [-].
    #[arg(
        long = "duty-limit",
        requires = "drive",
        value_name = "FRACTION",
        default_value_t = 1.0
    )]
    pub duty_limit: f64,
    /// Counts per turn of the servo's encoder [counts] (the firmware's angle grid).
    #[arg(
        long = "encoder-counts",
        requires = "drive",
        value_name = "COUNTS",
        default_value_t = 4096
    )]
    pub encoder_counts: u32,
    /// The latency's search range, 0 to this [ms] (the firmware's and the bus's delay).
    #[arg(
        long = "latency-max-ms",
        requires = "drive",
        value_name = "MS",
        default_value_t = 150.0
    )]
    pub latency_max_ms: f64,
    /// A known gravity amplitude m g L [N m] (a pendulum's mass and length): it sets the
    /// torques' scale and k_t/R is fitted. Default: k_t/R from --params, the gravity fitted.
    #[arg(long = "gravity-nm", requires = "drive", value_name = "NM")]
    pub gravity_nm: Option<f64>,
    /// The least inertia at the output [kg m^2] (a known load's m L^2); default: --params'
    /// load inertia J_l.
    #[arg(long = "min-inertia-kg-m2", requires = "drive", value_name = "KG_M2")]
    pub min_inertia_kg_m2: Option<f64>,
    /// Logs not fitted on, replayed to choose between the fits and to report how each predicts.
    #[arg(long = "held-out", requires = "drive", value_name = "LOG")]
    pub held_out: Vec<PathBuf>,
}

impl super::Identify {
    pub(super) fn run_smart(&self) -> anyhow::Result<()> {
        let a = &self.smart;
        let Some(params_path) = &self.params else {
            bail!("--drive position needs --params: the model file with the motor's k_t, k_e, R_a and N (k_t/R sets the torques' scale)");
        };
        let params = ModelFile::load(params_path).context("--params")?;
        if self.logs.is_empty() {
            bail!("no logs given: pass the smart servo's logs (CSV or BAM JSON)");
        }
        let all: Vec<&PathBuf> = self.logs.iter().chain(&a.held_out).collect();
        if !(a.kp_fw.len() == 1 || a.kp_fw.len() == all.len()) {
            bail!(
                "--kp-fw given {} times for {} logs: give the firmware gain once (every log) or once per log",
                a.kp_fw.len(),
                all.len()
            );
        }
        for (flag, v, ok) in [
            (
                "--kp-fw",
                a.kp_fw.iter().cloned().fold(f64::INFINITY, f64::min),
                !a.kp_fw.is_empty(),
            ),
            ("--duty-per-rad-per-kp", a.duty_per_rad_per_kp, true),
            ("--duty-limit", a.duty_limit, a.duty_limit <= 1.0),
            ("--latency-max-ms", a.latency_max_ms, true),
            ("--gravity-nm", a.gravity_nm.unwrap_or(1.0), true),
        ] {
            if !(ok && v > 0.0 && v.is_finite()) {
                bail!("{flag} must be a positive number (a duty limit at most 1), got {v}");
            }
        }
        let logs: Vec<SmartLog> = all
            .iter()
            .map(|p| {
                servo_io::smart_log::read_smart(p)
                    .with_context(|| format!("reading log {}", p.display()))
            })
            .collect::<anyhow::Result<_>>()?;
        let v_supply = a.v_supply_v.or(params.drive.v_supply_v);
        let loops: Vec<PositionLoop> = logs
            .iter()
            .enumerate()
            .map(|(k, l)| {
                let v = match (v_supply, &l.v_supply_v) {
                    (Some(v), _) => v,
                    (None, Some(col)) => col.iter().sum::<f64>() / col.len().max(1) as f64,
                    (None, None) => bail!("{}: no supply column: give --v-supply-v", l.name),
                };
                Ok(PositionLoop {
                    kp_fw: a.kp_fw[k.min(a.kp_fw.len() - 1)],
                    duty_per_rad_per_kp: a.duty_per_rad_per_kp,
                    duty_limit: a.duty_limit,
                    v_supply_v: v,
                    supply_from_log: l.v_supply_v.is_some(),
                    encoder_counts: (a.encoder_counts > 0).then_some(a.encoder_counts),
                    period_s: 1e-3,
                })
            })
            .collect::<anyhow::Result<_>>()?;
        let p = &params.params;
        let prior = SmartPrior {
            k_t_per_r: p.k_t * p.n / p.r_eq(),
            k_e: p.k_e * p.n,
            j_min: a.min_inertia_kg_m2.unwrap_or(p.j_l()),
            latency_max_s: a.latency_max_ms * 1e-3,
            gravity_nm: a.gravity_nm,
            load_friction: true,
        };
        let names: Vec<&str> = logs.iter().map(|l| l.name.as_str()).collect();
        let drive_of =
            |l: &SmartLog| loops[logs.iter().position(|x| std::ptr::eq(x, l)).unwrap_or(0)];
        let nfit = self.logs.len();
        let t0 = Instant::now();
        let f = smart::fit(&prior, &drive_of, &logs[..nfit], &logs[nfit..], 3000)?;
        let secs = t0.elapsed().as_secs_f64();
        let fitted = f.params();
        let gravity = match f.gravity {
            GravityFit::Given => json!({"status": "given", "value_n_m": fitted.gravity_nm}),
            GravityFit::Determined { rel_se } => {
                json!({"status": "determined", "value_n_m": fitted.gravity_nm, "rel_std_error": rel_se})
            }
            GravityFit::NotDetermined { rel_se } => json!({"status": "not determined",
                "value_n_m": Value::Null, "rel_std_error": if rel_se.is_finite() { json!(rel_se) } else { Value::Null }}),
        };
        let err = |e: &smart::PositionError| json!({"mae_rad": e.mae_rad, "rmse_rad": e.rmse_rad, "rows": e.rows});
        let candidates: Vec<Value> = f
            .candidates
            .iter()
            .map(|c| {
                json!({"fit": c.kind.name(), "unphysical": c.unphysical, "fit_error": err(&c.fit_error),
                       "held_out_error": c.held_out_error.as_ref().map(err)})
            })
            .collect();
        let v = json!({
            "schema": "servo.smart_identify/1",
            "logs": names[..nfit],
            "held_out": names[nfit..],
            "kept": f.candidates[f.kept].kind.name(),
            "candidates": candidates,
            "params": {
                "j_eq_kg_m2": fitted.j_eq, "b_eq_n_m_s_rad": fitted.b_eq, "tau_sf_n_m": fitted.tau_sf,
                "load_friction": fitted.load_friction, "k_t_per_r_n_m_v": fitted.k_t_per_r,
                "k_t_per_r_source": if a.gravity_nm.is_some() { "fitted" } else { "params" },
                "gravity_phase_rad": fitted.phase_rad, "latency_s": fitted.latency_s,
            },
            "gravity": gravity,
            "j_min_kg_m2": prior.j_min,
            "replays": f.evaluations,
            "fit_time_s": secs,
        });
        if self.json {
            crate::json_out::emit(&v)?;
        } else {
            out!("{}", text(&v, &f, &prior));
        }
        if let Some(out) = &self.output {
            let mut m = params.with_smart_fit(&fitted, &loops[0])?;
            let mut prov = toml::Table::new();
            prov.insert(
                "method".into(),
                toml::Value::String(format!(
                    "smart servo, {} fit on the trajectories replayed from the goals",
                    f.candidates[f.kept].kind.name()
                )),
            );
            let logs_toml = names[..nfit]
                .iter()
                .map(|n| toml::Value::String(n.to_string()))
                .collect();
            prov.insert("logs".into(), toml::Value::Array(logs_toml));
            if let GravityFit::NotDetermined { .. } = f.gravity {
                prov.insert(
                    "gravity".into(),
                    toml::Value::String(
                        "not determined by the logs: the amplitude is the fit's, not a measurement"
                            .into(),
                    ),
                );
            }
            m.provenance = Some(prov);
            let mut owned = ModelFile::FRICTION_KINDS.to_vec();
            owned.push(servo_core::effects::GRAVITY);
            m.save_over(out, &owned)?;
            if !self.json {
                outln!("wrote {}", out.display());
            }
        }
        Ok(())
    }
}

/// The text report: the verdict (the fit kept, how it predicts), then the parameters.
fn text(v: &Value, f: &smart::SmartFit, prior: &SmartPrior) -> String {
    let p = f.params();
    let mrad = |e: &smart::PositionError| {
        format!(
            "MAE {:.1} mrad, RMSE {:.1} mrad",
            e.mae_rad * 1e3,
            e.rmse_rad * 1e3
        )
    };
    let kept = &f.candidates[f.kept];
    let mut s = format!(
        "smart servo: kept the {} fit ({} logs, position {} on the logs fitted{})\n",
        kept.kind.name(),
        v["logs"].as_array().map_or(0, Vec::len),
        mrad(&kept.fit_error),
        kept.held_out_error
            .as_ref()
            .map_or(String::new(), |e| format!(", {} held out", mrad(e)))
    );
    for c in &f.candidates {
        let why = if c.unphysical.is_empty() {
            String::new()
        } else {
            format!("; unphysical: {}", c.unphysical.join("; "))
        };
        let held = c
            .held_out_error
            .as_ref()
            .map_or(String::new(), |e| format!("; held out {}", mrad(e)));
        let how = match c.kind {
            FitKind::EquationError => "torque balance on the logged duty",
            FitKind::OutputError => "trajectories replayed from the goals",
        };
        s += &format!(
            "  {} ({how}): {}{held}{why}\n",
            c.kind.name(),
            mrad(&c.fit_error)
        );
    }
    let g = |x: f64| servo_core::math::sig(x, 4);
    s += &format!(
        "J_eq = {} kg m^2 (at the output; at least {} kg m^2)\n",
        g(p.j_eq),
        g(prior.j_min)
    );
    s += &format!(
        "B_eq = {} N m s/rad, tau_sf = {} N m, load-dependent friction {} of the motor's torque\n",
        g(p.b_eq),
        g(p.tau_sf),
        g(p.load_friction)
    );
    s += &format!(
        "k_t/R = {} N m/V ({})\n",
        g(p.k_t_per_r),
        if prior.gravity_nm.is_some() {
            "fitted: the given m g L sets the torques' scale"
        } else {
            "from --params: it sets the torques' scale"
        }
    );
    s += &match f.gravity {
        GravityFit::Given => format!("gravity m g L = {} N m (given), phase {} rad\n", g(p.gravity_nm), g(p.phase_rad)),
        GravityFit::Determined { rel_se } => format!("gravity m g L = {} N m (fitted, determined: relative standard error {:.1} %), phase {} rad\n", g(p.gravity_nm), rel_se * 100.0, g(p.phase_rad)),
        GravityFit::NotDetermined { rel_se } => format!("gravity m g L: not determined by these logs (relative standard error {:.0} %, above the {:.0} % bar: the angle does not move the gravity torque enough to separate it from the other torques); give --gravity-nm if known\n", rel_se * 100.0, smart::GRAVITY_MAX_REL_SE * 100.0),
    };
    s += &format!(
        "latency = {:.1} ms (firmware and bus, searched 0 to {:.0} ms)\n",
        p.latency_s * 1e3,
        prior.latency_max_s * 1e3
    );
    s += &format!(
        "fit time {:.2} s ({} replays)\n",
        v["fit_time_s"].as_f64().unwrap_or(0.0),
        f.evaluations
    );
    s
}
