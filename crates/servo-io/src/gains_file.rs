//! The controller file (TOML) that `servo design -o gains.toml` writes and `servo run --gains`
//! reads. The controller acts on the load-angle error [rad] and outputs the driver input u [V].
//!
//! ```toml
//! [pid]
//! kp = 7.0476      # K_P [V/rad]
//! ki = 86.121      # K_I [V/(rad s)]
//! kd = 0.14418     # K_D [V s/rad]
//! tl_s = 6.67e-3   # real-derivative time constant T_L [s] (eq. 53); 0 = ideal derivative
//! ts_s = 1e-3      # sample period T_s [s]
//! # kw = 30.0      # optional back-calculation anti-windup gain K_w [1/s]
//! # u_limit_v = 10 # optional output limit [V]
//! # derivative_on = "measurement"  # optional: "error" (default) or "measurement"
//! [design]         # optional, informational (spec the gains were designed for)
//! ```

use crate::error::{self as anyhow, anyhow, bail, Context};
use std::path::Path;

/// PID gains in parallel form C(s) = K_P + K_I/s + K_D s/(T_L s + 1).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PidSection {
    /// Proportional gain K_P [V/rad].
    pub kp: f64,
    /// Integral gain K_I [V/(rad s)] (required: write `ki = 0` for no integral action).
    pub ki: f64,
    /// Derivative gain K_D [V s/rad] (required: write `kd = 0` for no derivative action).
    pub kd: f64,
    /// Real-derivative time constant T_L [s] (eq. 53); 0 means an ideal derivative.
    #[serde(default)]
    pub tl_s: f64,
    /// Sample period T_s [s] the gains were designed for.
    #[serde(default = "default_ts")]
    pub ts_s: f64,
    /// Back-calculation anti-windup gain K_w [1/s], if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kw: Option<f64>,
    /// Controller output limit [V] (symmetric), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_limit_v: Option<f64>,
    /// What the derivative acts on (`error` or `measurement`); absent: the error (files written
    /// before this field existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub derivative_on: Option<servo_core::control::DerivativeOn>,
}

impl PidSection {
    /// The section of designed gains `g` at the period `ts_s` [s]: no anti-windup gain, no
    /// limit, the derivative on the error (each the run's default).
    pub fn of(g: &servo_core::design::PidGains, ts_s: f64) -> PidSection {
        PidSection {
            kp: g.kp,
            ki: g.ki,
            kd: g.kd,
            tl_s: g.tl_s,
            ts_s,
            kw: None,
            u_limit_v: None,
            derivative_on: None,
        }
    }
}

fn default_ts() -> f64 {
    1e-3
}

/// The whole gains file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainsFile {
    pub pid: PidSection,
    /// Free-form description of the design (spec, method, date).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub design: Option<toml::Table>,
}

impl GainsFile {
    /// Reads and validates a gains file.
    pub fn load(path: &Path) -> anyhow::Result<GainsFile> {
        let text = crate::text_file::read_text(path)
            .with_context(|| format!("reading gains file {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("in gains file {}", path.display()))
    }

    /// Parses and validates TOML text.
    ///
    /// `kp`, `ki` and `kd` must all be given: a file holding only `kp` is refused rather than
    /// run silently as a P controller (write `ki = 0`, `kd = 0` for that).
    pub fn parse(text: &str) -> anyhow::Result<GainsFile> {
        if let Ok(table) = text.parse::<toml::Table>() {
            if let Some(pid) = table.get("pid").and_then(|p| p.as_table()) {
                let missing: Vec<&str> = ["kp", "ki", "kd"]
                    .into_iter()
                    .filter(|k| !pid.contains_key(*k))
                    .collect();
                if !missing.is_empty() {
                    bail!(
                        "[pid] must give kp, ki and kd explicitly; missing: {} (write e.g. `ki = 0` \
                         and `kd = 0` for a P controller; `servo design -o gains.toml` writes a full file)",
                        missing.join(", ")
                    );
                }
            }
        }
        let g: GainsFile =
            toml::from_str(text).map_err(|e| anyhow!("{}", crate::text_file::toml_error(&e)))?;
        g.validate()?;
        Ok(g)
    }

    /// Checks signs and finiteness.
    pub fn validate(&self) -> anyhow::Result<()> {
        let p = &self.pid;
        for (k, v) in [("kp", p.kp), ("ki", p.ki), ("kd", p.kd), ("tl_s", p.tl_s)] {
            if !v.is_finite() || v < 0.0 {
                bail!("[pid] `{k}` must be a finite number >= 0, got {v}");
            }
        }
        if !(p.ts_s.is_finite() && p.ts_s > 0.0) {
            bail!(
                "[pid] `ts_s` (sample period [s]) must be > 0, got {}",
                p.ts_s
            );
        }
        if let Some(kw) = p.kw {
            if !(kw.is_finite() && kw >= 0.0) {
                bail!("[pid] `kw` (anti-windup gain [1/s]) must be >= 0, got {kw}");
            }
        }
        if let Some(u) = p.u_limit_v {
            if !(u.is_finite() && u > 0.0) {
                bail!("[pid] `u_limit_v` must be > 0 V, got {u}");
            }
        }
        Ok(())
    }

    /// What `[design]` says the gains were designed and checked for, against what a run uses:
    /// one warning per difference. `plant_key`: the simulated plant as `[design] plant` writes it
    /// (`lab`, `table2`, a file), `None` on a board; `plant_params`: the simulated plant's base
    /// parameters (without the effects a run adds on purpose), compared with `[design.plant_params]`
    /// value by value, so that the same plant under another name (the file `servo params` printed)
    /// is not a mismatch; `discretization`: the rule the PID runs.
    pub fn design_mismatches(
        &self,
        plant_key: Option<&str>,
        plant_params: Option<&servo_core::PlantParams>,
        discretization: servo_core::control::Discretization,
    ) -> Vec<String> {
        let Some(d) = &self.design else {
            return Vec::new();
        };
        let mut out = Vec::new();
        if let (Some(run), Some(designed)) = (plant_key, d.get("plant").and_then(|v| v.as_str())) {
            let designed_params = d.get("plant_params").and_then(|v| v.as_table());
            let differ = match (plant_params, designed_params) {
                (Some(p), Some(t)) => params_differ(p, t),
                // files without the parameters: the names, effects added by the run aside
                _ => {
                    if run.trim_end_matches("+effects") != designed {
                        vec![format!("`{run}`")]
                    } else {
                        Vec::new()
                    }
                }
            };
            if !differ.is_empty() {
                out.push(format!(
                    "the gains were designed and checked for the plant `{designed}` ([design] plant) but this run simulates `{run}`, another plant ({}): the design's figures (overshoot, settling, MET) do not apply; run with the design's plant (--plant-preset/--plant) or redesign for this one",
                    differ.join(", ")
                ));
            }
        }
        if let Some(designed) = d.get("discretization").and_then(|v| v.as_str()) {
            let run = match discretization {
                servo_core::control::Discretization::BackwardEuler => "backward-euler",
                servo_core::control::Discretization::Tustin => "tustin",
            };
            if run != designed {
                out.push(format!(
                    "the gains were designed for the {designed} discretisation ([design] discretization) but this run uses {run}"
                ));
            }
        }
        out
    }

    /// The unit of the controller's output [V or A]: amps when `[design] drive` says the gains
    /// were designed for a current drive (the output is the drive's current reference, the
    /// input of its equivalent chain); volts otherwise (a duty drive's bridge voltage, which the
    /// drive sends as the duty u / V_supply, included).
    pub fn output_unit(&self) -> &'static str {
        match self.design_drive() {
            Some("current") => "A",
            _ => "V",
        }
    }

    /// `[design] drive`: the drive the gains were designed for (absent: a voltage amplifier).
    fn design_drive(&self) -> Option<&str> {
        self.design.as_ref()?.get("drive")?.as_str()
    }

    /// Writes the file with units in comments, atomically ([`crate::output`]: a previous file
    /// with other contents is kept as `NAME.N`, said on stderr).
    pub fn save(&self, path: &Path) -> anyhow::Result<()> {
        crate::output::write_file(path, "gains file", self.to_toml_commented()).map(|_| ())
    }

    /// TOML with units in comments.
    pub fn to_toml_commented(&self) -> String {
        let p = &self.pid;
        let output = match self.design_drive() {
            Some("current") => "the current drive's reference i_ref [A]",
            Some("duty") => "the bridge's voltage u [V] (the duty drive sends u / V_supply)",
            _ => "driver input u [V]",
        };
        let a = self.output_unit();
        let mut s = format!(
            "# servo controller: PID on the load-angle error [rad], output {output}\n\
             # C(s) = kp + ki/s + kd s/(tl_s s + 1)\n[pid]\n\
             kp = {:e}  # K_P [{a}/rad]\nki = {:e}  # K_I [{a}/(rad s)]\nkd = {:e}  # K_D [{a} s/rad]\n\
             tl_s = {:e}  # real-derivative time constant T_L [s]\nts_s = {:e}  # sample period [s]\n",
            p.kp, p.ki, p.kd, p.tl_s, p.ts_s
        );
        if let Some(kw) = p.kw {
            s.push_str(&format!(
                "kw = {kw:e}  # back-calculation anti-windup gain K_w [1/s]\n"
            ));
        }
        if let Some(u) = p.u_limit_v {
            s.push_str(&format!("u_limit_v = {u:e}  # output limit [{a}]\n"));
        }
        if let Some(d) = p.derivative_on {
            let name = match d {
                servo_core::control::DerivativeOn::Error => "error",
                servo_core::control::DerivativeOn::Measurement => "measurement",
            };
            s.push_str(&format!(
                "derivative_on = \"{name}\"  # derivative of the error or of the measurement\n"
            ));
        }
        if let Some(d) = &self.design {
            // under [design], sub-tables ([design.plant_params]) included
            let mut root = toml::Table::new();
            root.insert("design".into(), toml::Value::Table(d.clone()));
            s.push('\n');
            s.push_str(&toml::to_string(&root).unwrap_or_default());
        }
        s
    }
}

/// The base parameters that differ between a run's plant and the one `[design.plant_params]`
/// records, in words (`k_t 0.0389 here, 0.00768 designed`). Equal within 1e-9 relative: the file
/// holds every digit.
fn params_differ(run: &servo_core::PlantParams, designed: &toml::Table) -> Vec<String> {
    let Ok(toml::Value::Table(here)) = toml::Value::try_from(run) else {
        return Vec::new();
    };
    let num = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
    let mut out = Vec::new();
    for (k, v) in &here {
        let (Some(a), Some(b)) = (num(v), designed.get(k).and_then(num)) else {
            if num(v).is_some() != designed.get(k).and_then(num).is_some() {
                out.push(format!("{k} given on one side only"));
            }
            continue;
        };
        if (a - b).abs() > 1e-9 * a.abs().max(b.abs()).max(f64::MIN_POSITIVE) {
            out.push(format!("{k} {a:e} here, {b:e} designed"));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_rejects() {
        let g = GainsFile {
            pid: PidSection {
                kp: 7.0476,
                ki: 86.121,
                kd: 0.14418,
                tl_s: 6.7e-3,
                ts_s: 1e-3,
                kw: Some(30.0),
                u_limit_v: Some(10.0),
                derivative_on: Some(servo_core::control::DerivativeOn::Measurement),
            },
            design: None,
        };
        assert_eq!(GainsFile::parse(&g.to_toml_commented()).unwrap(), g);
        // files written before kw, u_limit_v and derivative_on existed still read
        let old =
            GainsFile::parse("[pid]\nkp = 7\nki = 86\nkd = 0.14\ntl_s = 0.0067\nts_s = 0.001\n")
                .unwrap();
        assert_eq!(
            (old.pid.kw, old.pid.u_limit_v, old.pid.derivative_on),
            (None, None, None)
        );
        let e = format!(
            "{:#}",
            GainsFile::parse("[pid]\nkp = 1\nki = 0\nkd = 0\nderivative_on = \"output\"\n")
                .unwrap_err()
        );
        assert!(
            e.contains("derivative_on") || e.contains("measurement"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            GainsFile::parse("[pid]\nkp = -1\nki = 0\nkd = 0\n").unwrap_err()
        );
        assert!(e.contains("kp"), "{e}");
        let e = format!(
            "{:#}",
            GainsFile::parse("[pid]\nkp = 1\nki = 0\nkd = 0\nkq = 2\n").unwrap_err()
        );
        assert!(e.contains("kq"), "{e}");
    }

    #[test]
    fn gains_file_with_only_kp_is_refused() {
        let e = format!("{:#}", GainsFile::parse("[pid]\nkp = 5\n").unwrap_err());
        assert!(e.contains("missing: ki, kd") && e.contains("ki = 0"), "{e}");
        let g = GainsFile::parse("[pid]\nkp = 5\nki = 0\nkd = 0\n").unwrap();
        assert_eq!((g.pid.ki, g.pid.kd), (0.0, 0.0));
    }
}
