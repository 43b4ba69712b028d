//! kS, kV, kA and kG in WPILib SysId's terms, for a `.wpilog` given to `servo identify`.
//!
//! SysId's own OLS (its feedforward analysis since 2023), on every part of the log (the tests
//! of a SysIdRoutine log, by its test state; the whole log without one), pairs of consecutive
//! samples inside one part: with the speed x in rotations/s and the voltage u [V],
//!
//! ```text
//! x[k+1] = alpha x[k] + beta u[k] + gamma sgn(x[k])  (+ delta, elevator)
//!                                                   (+ delta cos(theta[k]) + eps sin(theta[k]), arm)
//! kV = (1 - alpha) / beta      kA = (alpha - 1) T / (beta ln alpha)      kS = -gamma / beta
//! kG = -delta / beta (elevator); arm: kG = hypot(delta, eps) / beta at the angle offset
//! ```
//!
//! which is the discretised V = kS sgn(v) + kV v + kA a (+ kG, or + kG cos(theta - offset)) at
//! the log's period T. The speed is the log's velocity, else the position's difference.

use anyhow::bail;
use servo_core::ident::ls::{fit, Covariance};
use servo_core::record::Record;
use std::f64::consts::PI;
use std::path::Path;

/// The gravity term SysId fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mechanism {
    /// No gravity term (a flywheel, a drivetrain).
    Simple,
    /// A constant voltage against gravity (an elevator).
    Elevator,
    /// kG cos(theta - offset) (an arm; theta from the log's position).
    Arm,
}

/// The flags of the SysId report.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SysIdArgs {
    /// The gravity term of the kS/kV/kA/kG report of a `.wpilog` (SysId's mechanism); default:
    /// `arm` when --params declares a gravity load, else `elevator` (kG near 0 on a level axis).
    #[arg(long = "sysid-mechanism", value_enum, value_name = "KIND")]
    pub mechanism: Option<Mechanism>,
    /// The gains found, per `.wpilog` log (filled while the logs are read).
    #[arg(skip)]
    pub found: Vec<(String, Result<Gains, String>)>,
}

/// SysId's gains of one log.
#[derive(Debug, Clone, PartialEq)]
pub struct Gains {
    pub mechanism: Mechanism,
    /// [V]
    pub k_s_v: f64,
    /// [V/(rot/s)]
    pub k_v_v_per_rot_s: f64,
    /// [V/(rot/s^2)]
    pub k_a_v_per_rot_s2: f64,
    /// [V] (None for `simple`)
    pub k_g_v: Option<f64>,
    /// The arm's angle offset of the gravity term [rad].
    pub offset_rad: Option<f64>,
    /// RMS of the one-step speed prediction [rot/s].
    pub rms_rot_s: f64,
    /// Sample pairs used, parts used.
    pub pairs: usize,
    pub parts: usize,
}

impl SysIdArgs {
    /// Fits the gains of `rec` (read whole, before any window) when `path` is a `.wpilog`;
    /// `params` says whether the axis carries a gravity load.
    pub fn collect(&mut self, rec: &Record, path: &Path, params: &crate::model_file::ModelFile) {
        if servo_cli_ext(path) != "wpilog" {
            return;
        }
        let gravity = params.effects.contains(servo_core::effects::GRAVITY);
        let m = self.mechanism.unwrap_or(if gravity {
            Mechanism::Arm
        } else {
            Mechanism::Elevator
        });
        let g = sysid_gains(rec, m).map_err(|e| e.to_string());
        self.found.push((path.display().to_string(), g));
    }

    /// The text lines (empty without a `.wpilog`).
    pub fn text(&self) -> String {
        let mut s = String::new();
        for (log, g) in &self.found {
            match g {
                Ok(g) => {
                    s.push_str(&format!(
                        "SysId gains of {log} (SysId's OLS, {} mechanism, {} sample pairs in {} part(s)):\n  \
                         kS = {} V, kV = {} V/(rot/s), kA = {} V/(rot/s^2)",
                        name(g.mechanism),
                        g.pairs,
                        g.parts,
                        sig(g.k_s_v),
                        sig(g.k_v_v_per_rot_s),
                        sig(g.k_a_v_per_rot_s2)
                    ));
                    if let Some(k) = g.k_g_v {
                        s.push_str(&format!(", kG = {} V", sig(k)));
                    }
                    if let Some(o) = g.offset_rad {
                        s.push_str(&format!(" at {} deg", sig(o.to_degrees())));
                    }
                    s.push_str(&format!(
                        "\n  one-step speed prediction RMS {} rot/s\n",
                        sig(g.rms_rot_s)
                    ));
                }
                Err(e) => s.push_str(&format!("SysId gains of {log}: not determined: {e}\n")),
            }
        }
        s
    }

    /// The `sysid` array of `--json` (null without a `.wpilog`).
    pub fn json(&self) -> serde_json::Value {
        if self.found.is_empty() {
            return serde_json::Value::Null;
        }
        self.found
            .iter()
            .map(|(log, g)| match g {
                Ok(g) => serde_json::json!({
                    "log": log, "method": "SysId OLS", "mechanism": name(g.mechanism),
                    "k_s_v": g.k_s_v, "k_v_v_per_rot_s": g.k_v_v_per_rot_s,
                    "k_a_v_per_rot_s2": g.k_a_v_per_rot_s2, "k_g_v": g.k_g_v,
                    "gravity_offset_rad": g.offset_rad, "rms_rot_s": g.rms_rot_s,
                    "sample_pairs": g.pairs, "parts": g.parts,
                }),
                Err(e) => serde_json::json!({ "log": log, "not_determined": e }),
            })
            .collect()
    }
}

fn servo_cli_ext(path: &Path) -> String {
    crate::io::log_reader::extension(path)
}

fn sig(x: f64) -> String {
    servo_core::math::sig(x, 4)
}

fn name(m: Mechanism) -> &'static str {
    match m {
        Mechanism::Simple => "simple",
        Mechanism::Elevator => "elevator",
        Mechanism::Arm => "arm",
    }
}

/// SysId's OLS on the parts of `rec` (the runs of its enable column; the whole record without
/// one).
pub fn sysid_gains(rec: &Record, m: Mechanism) -> anyhow::Result<Gains> {
    let (Some(u), Some(theta)) = (&rec.u_v, &rec.theta_l_rad) else {
        bail!("the log needs a voltage and a position");
    };
    let n = rec.len();
    let t_s = rec.sample_period_s();
    if !(t_s > 0.0 && t_s.is_finite()) || n < 8 {
        bail!("too few samples or no sample period");
    }
    let speed: Vec<f64> = match &rec.omega_l_rad_s {
        Some(w) => w.iter().map(|w| w / (2.0 * PI)).collect(),
        None => (0..n)
            .map(|k| {
                let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
                (theta[b] - theta[a]) / (rec.time_s[b] - rec.time_s[a]) / (2.0 * PI)
            })
            .collect(),
    };
    let on = |k: usize| rec.enable.as_ref().is_none_or(|e| e[k] != 0.0);
    // Pairs (k, k+1) inside one part at the log's period (a gap between tests is not a pair).
    let mut rows = Vec::new();
    let mut parts = 0;
    for k in 0..n - 1 {
        let dt = rec.time_s[k + 1] - rec.time_s[k];
        let pair = on(k) && on(k + 1) && (dt - t_s).abs() <= 0.5 * t_s;
        let values = [speed[k], speed[k + 1], u[k], theta[k]];
        if pair && values.iter().all(|v| v.is_finite()) {
            if k == 0 || !on(k - 1) || rows.last() != Some(&(k - 1)) {
                parts += 1;
            }
            rows.push(k);
        }
    }
    let cols = 3 + match m {
        Mechanism::Simple => 0,
        Mechanism::Elevator => 1,
        Mechanism::Arm => 2,
    };
    if rows.len() < 4 * cols {
        bail!(
            "{} sample pairs inside the tests; at least {} are needed",
            rows.len(),
            4 * cols
        );
    }
    let col = |f: &dyn Fn(usize) -> f64| -> Vec<f64> { rows.iter().map(|&k| f(k)).collect() };
    let mut x: Vec<Vec<f64>> = vec![
        col(&|k| speed[k]),
        col(&|k| u[k]),
        col(&|k| servo_core::math::sign(speed[k])),
    ];
    match m {
        Mechanism::Simple => {}
        Mechanism::Elevator => x.push(col(&|_| 1.0)),
        Mechanism::Arm => {
            x.push(col(&|k| theta[k].cos()));
            x.push(col(&|k| theta[k].sin()));
        }
    }
    let y = col(&|k| speed[k + 1]);
    let refs: Vec<&[f64]> = x.iter().map(Vec::as_slice).collect();
    let f = fit(&refs, &y, Covariance::Iid).map_err(|e| anyhow::anyhow!("{e}"))?;
    let (alpha, beta, gamma) = (f.theta[0], f.theta[1], f.theta[2]);
    if !(alpha > 0.0 && alpha < 1.0 && beta > 0.0) {
        bail!(
            "the fit gives alpha = {}, beta = {} (alpha in (0, 1) and beta > 0 are needed for kV and \
             kA): the tests hold too little acceleration or speed to separate them",
            sig(alpha),
            sig(beta)
        );
    }
    let (k_g_v, offset_rad) = match m {
        Mechanism::Simple => (None, None),
        Mechanism::Elevator => (Some(-f.theta[3] / beta), None),
        Mechanism::Arm => {
            let (c, s) = (-f.theta[3] / beta, -f.theta[4] / beta);
            (Some(c.hypot(s)), Some(s.atan2(c)))
        }
    };
    Ok(Gains {
        mechanism: m,
        k_s_v: -gamma / beta,
        k_v_v_per_rot_s: (1.0 - alpha) / beta,
        k_a_v_per_rot_s2: (alpha - 1.0) * t_s / (beta * alpha.ln()),
        k_g_v,
        offset_rad,
        rms_rot_s: f.residual_rms,
        pairs: rows.len(),
        parts,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A motor that obeys V = kS sgn(v) + kV v + kA a + kG exactly (the discretised form),
    /// driven by ramps and steps both ways, in two parts.
    #[test]
    fn recovers_the_gains_of_an_exact_model() {
        let (ks, kv, ka, kg, t): (f64, f64, f64, f64, f64) = (0.3, 2.0, 0.25, 0.8, 0.005);
        let alpha = (-kv / ka * t).exp();
        let beta = (1.0 - alpha) / kv;
        let mut rec = Record::default();
        let (mut v, mut th) = (0.0f64, 0.0f64);
        let (mut time, mut uu, mut pos, mut vel, mut en) = (vec![], vec![], vec![], vec![], vec![]);
        for k in 0..2000 {
            let tk = k as f64 * t;
            let u = match k {
                0..=499 => 0.5 + 2.0 * tk,
                500..=999 => -0.5 - 2.0 * (tk - 2.5),
                1000..=1499 => 7.0,
                _ => -7.0,
            };
            time.push(tk);
            uu.push(u);
            pos.push(th);
            vel.push(v * 2.0 * PI);
            en.push(if k == 1000 { 0.0 } else { 1.0 });
            let g = ks * servo_core::math::sign(v) + kg;
            v = alpha * v + beta * (u - g);
            th += v * 2.0 * PI * t;
        }
        rec.time_s = time;
        rec.u_v = Some(uu);
        rec.theta_l_rad = Some(pos);
        rec.omega_l_rad_s = Some(vel);
        rec.enable = Some(en);
        let g = sysid_gains(&rec, Mechanism::Elevator).unwrap();
        for (got, want) in [
            (g.k_s_v, ks),
            (g.k_v_v_per_rot_s, kv),
            (g.k_a_v_per_rot_s2, ka),
            (g.k_g_v.unwrap(), kg),
        ] {
            assert!(
                (got - want).abs() < 1e-6 * want.abs().max(1.0),
                "{got} vs {want}"
            );
        }
        assert_eq!(g.parts, 2);
    }
}
