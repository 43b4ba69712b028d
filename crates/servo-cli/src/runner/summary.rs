//! Figures of merit of a run: tracking error RMS and maximum, overshoot and settling time of
//! each reference step (5 % band, as in the handout's t_s,5%), time spent at the voltage limit.

use servo_core::record::Record;
use std::collections::BTreeMap;
use std::fmt;

/// One step of the reference and the response to it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepMetrics {
    /// Time of the step [s].
    pub time_s: f64,
    /// Reference before the step [rad] (the measured angle for a step at the start).
    pub from_rad: f64,
    /// Reference after the step [rad].
    pub to_rad: f64,
    /// Largest excursion beyond the new reference, in the step's direction [% of the step].
    pub overshoot_pct: f64,
    /// Time from the step until the error stays inside the band [s]; `None`: not settled before
    /// the next step or the end of the run.
    pub settling_time_s: Option<f64>,
}

/// Summary of a run.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RunSummary {
    /// Run length [s] and number of samples.
    pub duration_s: f64,
    pub samples: usize,
    /// RMS of the tracking error ref - theta_l [rad] (`None` in open loop).
    pub err_rms_rad: Option<f64>,
    /// Largest |ref - theta_l| [rad].
    pub err_max_rad: Option<f64>,
    /// Settling band as a fraction of each step (0.05).
    pub band: f64,
    /// The reference's steps.
    pub steps: Vec<StepMetrics>,
    /// Time with the controller output clipped at the voltage limit [s].
    pub saturation_time_s: f64,
    /// RMS of the driver input u [V].
    pub u_rms_v: f64,
}

impl RunSummary {
    /// Computes the summary of `rec` (needs `u_v`; tracking figures need `ref_rad` and
    /// `theta_l_rad`), with per-sample saturation flags `saturated` (empty: none known).
    pub fn compute(rec: &Record, saturated: &[bool], band: f64) -> RunSummary {
        let n = rec.len();
        let ts = if n >= 2 { rec.sample_period_s() } else { 0.0 };
        let mut s = RunSummary {
            duration_s: n as f64 * ts,
            samples: n,
            band,
            saturation_time_s: saturated.iter().filter(|&&b| b).count() as f64 * ts,
            ..RunSummary::default()
        };
        if let Some(u) = &rec.u_v {
            s.u_rms_v = rms(u.iter().copied());
        }
        let (Some(r), Some(y)) = (&rec.ref_rad, &rec.theta_l_rad) else {
            return s;
        };
        let valid: Vec<usize> = (0..n)
            .filter(|&k| r[k].is_finite() && y[k].is_finite())
            .collect();
        if valid.is_empty() {
            return s;
        }
        s.err_rms_rad = Some(rms(valid.iter().map(|&k| r[k] - y[k])));
        s.err_max_rad = Some(
            valid
                .iter()
                .map(|&k| (r[k] - y[k]).abs())
                .fold(0.0, f64::max),
        );
        s.steps = steps(&rec.time_s, r, y, band);
        s
    }

    /// Largest overshoot over the steps [%].
    pub fn overshoot_pct(&self) -> Option<f64> {
        self.steps.iter().map(|s| s.overshoot_pct).reduce(f64::max)
    }

    /// Longest settling time over the steps [s]; `Some(None)`: some step did not settle.
    pub fn settling_time_s(&self) -> Option<Option<f64>> {
        if self.steps.is_empty() {
            return None;
        }
        Some(
            self.steps
                .iter()
                .try_fold(0.0f64, |acc, s| s.settling_time_s.map(|t| acc.max(t))),
        )
    }

    /// Key/value form for the MCAP summary metadata record (SI units in the keys).
    pub fn to_map(&self) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        m.insert("duration_s".into(), self.duration_s.to_string());
        m.insert("samples".into(), self.samples.to_string());
        m.insert(
            "saturation_time_s".into(),
            self.saturation_time_s.to_string(),
        );
        m.insert("u_rms_v".into(), self.u_rms_v.to_string());
        if let Some(v) = self.err_rms_rad {
            m.insert("tracking_error_rms_rad".into(), v.to_string());
        }
        if let Some(v) = self.err_max_rad {
            m.insert("tracking_error_max_rad".into(), v.to_string());
        }
        if let Some(v) = self.overshoot_pct() {
            m.insert("overshoot_max_pct".into(), v.to_string());
        }
        if let Some(v) = self.settling_time_s() {
            m.insert(
                "settling_time_max_s".into(),
                v.map_or("not settled".into(), |t| t.to_string()),
            );
        }
        m.insert("settling_band".into(), self.band.to_string());
        m
    }
}

fn rms(it: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in it.filter(|v| v.is_finite()) {
        s += v * v;
        n += 1;
    }
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// Finds the reference's steps (jumps much larger than its ordinary per-sample change) and
/// measures the response to each one until the next.
fn steps(t: &[f64], r: &[f64], y: &[f64], band: f64) -> Vec<StepMetrics> {
    let n = r.len();
    let mut d: Vec<f64> = r
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|v| v.is_finite())
        .collect();
    d.sort_by(f64::total_cmp);
    let typical = d.get(d.len() / 2).copied().unwrap_or(0.0);
    let thresh = (50.0 * typical).max(1e-6);
    // (index of the step, value before).
    let mut starts: Vec<(usize, f64)> = Vec::new();
    if n > 0 && (r[0] - y[0]).abs() > thresh {
        starts.push((0, y[0]));
    }
    for k in 1..n {
        if (r[k] - r[k - 1]).abs() > thresh {
            starts.push((k, r[k - 1]));
        }
    }
    let mut out = Vec::with_capacity(starts.len());
    for (j, &(k0, from)) in starts.iter().enumerate() {
        let k1 = starts.get(j + 1).map_or(n, |s| s.0);
        let to = r[k0];
        let size = to - from;
        if size.abs() <= thresh {
            continue;
        }
        let dir = size.signum();
        let mut peak = f64::NEG_INFINITY;
        let mut last_out = None;
        for k in k0..k1 {
            let e = y[k] - r[k];
            peak = peak.max(dir * e);
            if e.abs() > band * size.abs() {
                last_out = Some(k);
            }
        }
        let settling_time_s = match last_out {
            None => Some(0.0),
            Some(k) if k + 1 < k1 => Some(t[k + 1] - t[k0]),
            Some(_) => None,
        };
        out.push(StepMetrics {
            time_s: t[k0],
            from_rad: from,
            to_rad: to,
            overshoot_pct: (100.0 * peak / size.abs()).max(0.0),
            settling_time_s,
        });
    }
    out
}

impl fmt::Display for RunSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let deg = 180.0 / std::f64::consts::PI;
        writeln!(
            f,
            "run summary ({:.3} s, {} samples):",
            self.duration_s, self.samples
        )?;
        match (self.err_rms_rad, self.err_max_rad) {
            (Some(rms), Some(max)) => {
                writeln!(
                    f,
                    "  tracking error RMS   {rms:.5} rad ({:.3} deg)",
                    rms * deg
                )?;
                writeln!(
                    f,
                    "  tracking error max   {max:.5} rad ({:.3} deg)",
                    max * deg
                )?;
            }
            _ => writeln!(f, "  tracking error       n/a (open loop)")?,
        }
        match self.overshoot_pct() {
            Some(os) => writeln!(
                f,
                "  overshoot (max)      {os:.2} % over {} step(s)",
                self.steps.len()
            )?,
            None => writeln!(f, "  overshoot            n/a (no steps in the reference)")?,
        }
        match self.settling_time_s() {
            Some(Some(ts)) => writeln!(
                f,
                "  settling time (max)  {ts:.4} s ({:.0} % band)",
                self.band * 100.0
            )?,
            Some(None) => writeln!(
                f,
                "  settling time        not settled within {:.0} % by the next step or the end",
                self.band * 100.0
            )?,
            None => writeln!(f, "  settling time        n/a")?,
        }
        let pct = if self.duration_s > 0.0 {
            100.0 * self.saturation_time_s / self.duration_s
        } else {
            0.0
        };
        writeln!(
            f,
            "  saturation time      {:.4} s ({pct:.1} % of the run)",
            self.saturation_time_s
        )?;
        write!(f, "  u RMS                {:.3} V", self.u_rms_v)?;
        if self.steps.len() > 1 {
            writeln!(f)?;
            write!(
                f,
                "  steps:  t [s]   from -> to [deg]   overshoot [%]   settling [s]"
            )?;
            for s in &self.steps {
                write!(
                    f,
                    "\n  {:8.3}   {:8.2} -> {:8.2}   {:8.2}        {}",
                    s.time_s,
                    s.from_rad * deg,
                    s.to_rad * deg,
                    s.overshoot_pct,
                    s.settling_time_s
                        .map_or("not settled".to_string(), |t| format!("{t:.4}"))
                )?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Second-order step response with known overshoot and settling.
    fn second_order(zeta: f64, wn: f64, t: f64) -> f64 {
        let s = (1.0 - zeta * zeta).sqrt();
        1.0 - (-zeta * wn * t).exp() / s * (wn * s * t + zeta.acos()).sin()
    }

    #[test]
    fn metrics_of_a_known_response() {
        let (zeta, wn, ts) = (0.5, 20.0, 1e-4);
        let n = 20000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * ts).collect();
        let amp = 1.5;
        let y: Vec<f64> = t.iter().map(|&t| amp * second_order(zeta, wn, t)).collect();
        let rec = Record {
            time_s: t.clone(),
            u_v: Some(vec![1.0; n]),
            theta_l_rad: Some(y),
            ref_rad: Some(vec![amp; n]),
            ..Record::default()
        };
        let sat: Vec<bool> = (0..n).map(|k| k < 1000).collect();
        let s = RunSummary::compute(&rec, &sat, 0.05);
        let mp = 100.0 * (-zeta * std::f64::consts::PI / (1.0 - zeta * zeta).sqrt()).exp();
        assert_eq!(s.steps.len(), 1);
        assert!(
            (s.overshoot_pct().unwrap() - mp).abs() < 0.05,
            "{} vs {mp}",
            s.overshoot_pct().unwrap()
        );
        // 5 % settling of this response, found by brute force on the formula.
        let mut t_set = 0.0;
        for &tk in t.iter() {
            if (second_order(zeta, wn, tk) - 1.0).abs() > 0.05 {
                t_set = tk + ts;
            }
        }
        let st = s.settling_time_s().unwrap().unwrap();
        assert!((st - t_set).abs() < 2.0 * ts, "{st} vs {t_set}");
        assert!((s.saturation_time_s - 0.1).abs() < 1e-9);
        assert!((s.err_max_rad.unwrap() - amp).abs() < 1e-9);
        assert!(s.to_string().contains("overshoot (max)"));
    }

    #[test]
    fn step_sequence_and_open_loop() {
        let n = 3000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let r: Vec<f64> = (0..n)
            .map(|k| {
                if k < 1000 {
                    0.0
                } else if k < 2000 {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect();
        // First-order lag: no overshoot; the last step never settles (too short).
        let mut y = vec![0.0; n];
        for k in 1..n {
            let tau = if k < 2000 { 0.05 } else { 2.0 };
            y[k] = y[k - 1] + (r[k - 1] - y[k - 1]) * 1e-3 / tau;
        }
        let rec = Record {
            time_s: t,
            u_v: Some(vec![0.0; n]),
            theta_l_rad: Some(y),
            ref_rad: Some(r),
            ..Record::default()
        };
        let s = RunSummary::compute(&rec, &[], 0.05);
        assert_eq!(s.steps.len(), 2, "{:?}", s.steps);
        assert!(s.steps[0].overshoot_pct < 1e-9);
        let t1 = s.steps[0].settling_time_s.unwrap();
        assert!((t1 - 0.05 * 20f64.ln()).abs() < 0.003, "{t1}");
        assert_eq!(s.steps[1].settling_time_s, None);
        assert_eq!(s.settling_time_s(), Some(None));
        let ol = Record {
            time_s: vec![0.0, 0.001],
            u_v: Some(vec![1.0, 1.0]),
            ..Record::default()
        };
        let s = RunSummary::compute(&ol, &[], 0.05);
        assert!(s.err_rms_rad.is_none() && s.steps.is_empty());
        assert!(s.to_string().contains("n/a (open loop)"));
    }
}
