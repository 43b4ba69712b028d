//! Figures of merit of a run: tracking error RMS and maximum, overshoot and settling time of
//! each reference step (5 % band, as in the handout's t_s,5%), time spent at the voltage limit.
//!
//! [`SummaryAccumulator`] computes them while a run goes, in memory independent of its length
//! (the run loop of servo-hw feeds it); [`RunSummary::compute`] computes the same figures from a
//! finished [`Record`].

use crate::drive::DriveKind;
use crate::math;
use crate::record::Record;
use alloc::collections::BTreeMap;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::fmt;

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
    /// RMS of the drive's command: the driver input u [V], or, named by `command`, a current
    /// drive's reference i_ref [A] or a duty drive's duty cycle.
    pub u_rms_v: f64,
    /// The drive whose command `u_rms_v` measures (a voltage amplifier unless a run says so).
    pub command: DriveKind,
}

impl RunSummary {
    /// Computes the summary of `rec` (the command: `u_v`, else `i_ref_a`, else `duty`; tracking
    /// figures need `ref_rad` and `theta_l_rad`), with per-sample saturation flags
    /// `saturated` (empty: none known).
    /// The same figures as [`SummaryAccumulator`] fed sample by sample.
    pub fn compute(rec: &Record, saturated: &[bool], band: f64) -> RunSummary {
        let n = rec.len();
        let ts = if n >= 2 { rec.sample_period_s() } else { 0.0 };
        let mut acc = SummaryAccumulator::new(ts, band);
        let get = |v: &Option<Vec<f64>>, k: usize| v.as_ref().map_or(f64::NAN, |v| v[k]);
        let (command, u) = [
            (DriveKind::Voltage, &rec.u_v),
            (DriveKind::Current, &rec.i_ref_a),
            (DriveKind::Duty, &rec.duty),
        ]
        .into_iter()
        .find(|(_, v)| v.is_some())
        .unwrap_or((DriveKind::Voltage, &rec.u_v));
        for k in 0..n {
            acc.push(
                rec.time_s[k],
                get(&rec.ref_rad, k),
                get(&rec.theta_l_rad, k),
                get(u, k),
                saturated.get(k).copied().unwrap_or(false),
            );
        }
        let mut s = acc.finish();
        s.command = command;
        if u.is_none() {
            s.u_rms_v = 0.0;
        }
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

    /// The key of the command's RMS in [`RunSummary::to_map`]: `u_rms_v`, `i_ref_rms_a` or
    /// `duty_rms`.
    pub fn command_rms_key(&self) -> &'static str {
        match self.command {
            DriveKind::Voltage => "u_rms_v",
            DriveKind::Current => "i_ref_rms_a",
            DriveKind::Duty => "duty_rms",
        }
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
        m.insert(self.command_rms_key().into(), self.u_rms_v.to_string());
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

/// Samples per block of the step detector: the "ordinary per-sample change" of the reference is
/// the median |r_k - r_(k-1)| over a block (bounded memory, whatever the run's length).
const STEP_BLOCK: usize = 1024;

/// The response to the step being measured.
#[derive(Debug, Clone, Copy)]
struct OpenStep {
    k0: usize,
    time_s: f64,
    from_rad: f64,
    to_rad: f64,
    peak: f64,
    last_out: Option<usize>,
    /// Time of the sample after `last_out`.
    t_after_out_s: Option<f64>,
    /// The reference left the step's new value before the next step: not a step (a multisine,
    /// a chirp, a ramp after a jump), no overshoot or settling time to measure.
    moved: bool,
    /// Samples the reference held the new value.
    held: usize,
}

/// Samples a reference must hold after a jump for the jump to count as a step (a multisine's
/// fast change after a hold is a jump of one sample, not a step).
const MIN_HOLD_SAMPLES: usize = 10;

impl OpenStep {
    /// The step's figures, `None` when the reference did not hold after the jump.
    fn close(self, k1: usize) -> Option<StepMetrics> {
        if self.moved || self.held < MIN_HOLD_SAMPLES {
            return None;
        }
        let size = self.to_rad - self.from_rad;
        let settling_time_s = match self.last_out {
            None => Some(0.0),
            Some(k) if k + 1 < k1 => self.t_after_out_s.map(|t| t - self.time_s),
            Some(_) => None,
        };
        Some(StepMetrics {
            time_s: self.time_s,
            from_rad: self.from_rad,
            to_rad: self.to_rad,
            overshoot_pct: (100.0 * self.peak / size.abs()).max(0.0),
            settling_time_s,
        })
    }
}

/// The figures of a [`RunSummary`] computed while the run goes, in memory independent of its
/// length: running sums for the RMS values, and the reference's steps found block by block
/// (a jump larger than 50 times the block's median per-sample change, at least 1e-6 rad) and
/// measured until the next step.
#[derive(Debug, Clone)]
pub struct SummaryAccumulator {
    ts_s: f64,
    band: f64,
    n: usize,
    saturated: usize,
    u_sq: f64,
    u_n: usize,
    e_sq: f64,
    e_n: usize,
    e_max: f64,
    /// The block being collected: (t, r, y).
    block: Vec<(f64, f64, f64)>,
    /// Reference of the sample before the block.
    r_prev: Option<f64>,
    /// |r_prev - the reference before it| [rad]: a step jumps by much more than the previous
    /// sample's change (the last sample of a smooth move that stops is no step).
    d_prev: f64,
    open: Option<OpenStep>,
    steps: Vec<StepMetrics>,
}

impl SummaryAccumulator {
    /// For a run at sample period `ts_s` [s] with settling band `band` (0.05 = 5 %).
    pub fn new(ts_s: f64, band: f64) -> SummaryAccumulator {
        SummaryAccumulator {
            ts_s,
            band,
            n: 0,
            saturated: 0,
            u_sq: 0.0,
            u_n: 0,
            e_sq: 0.0,
            e_n: 0,
            e_max: 0.0,
            block: Vec::with_capacity(STEP_BLOCK),
            r_prev: None,
            d_prev: 0.0,
            open: None,
            steps: Vec::new(),
        }
    }

    /// One sample: time [s], reference [rad] (NaN in open loop), measured angle [rad], u [V],
    /// output clipped.
    pub fn push(&mut self, t_s: f64, r: f64, y: f64, u_v: f64, saturated: bool) {
        self.n += 1;
        self.saturated += saturated as usize;
        if u_v.is_finite() {
            self.u_sq += u_v * u_v;
            self.u_n += 1;
        }
        if r.is_finite() && y.is_finite() {
            let e = r - y;
            self.e_sq += e * e;
            self.e_n += 1;
            self.e_max = self.e_max.max(e.abs());
        }
        self.block.push((t_s, r, y));
        if self.block.len() == STEP_BLOCK {
            self.flush_block();
        }
    }

    fn flush_block(&mut self) {
        if self.block.is_empty() {
            return;
        }
        let first = self.n - self.block.len();
        let mut d: Vec<f64> = Vec::with_capacity(self.block.len());
        let mut prev = self.r_prev;
        for &(_, r, _) in &self.block {
            if let Some(p) = prev {
                let x = (r - p).abs();
                if x.is_finite() {
                    d.push(x);
                }
            }
            prev = Some(r);
        }
        d.sort_by(f64::total_cmp);
        let typical = d.get(d.len() / 2).copied().unwrap_or(0.0);
        let thresh = (50.0 * typical).max(1e-6);
        let block = core::mem::take(&mut self.block);
        for (j, &(t, r, y)) in block.iter().enumerate() {
            let k = first + j;
            let start = match self.r_prev {
                None if (r - y).abs() > thresh => Some(y),
                Some(p) if (r - p).abs() > thresh.max(50.0 * self.d_prev) => Some(p),
                _ => None,
            };
            if let Some(from) = start {
                if let Some(o) = self.open.take() {
                    self.steps.extend(o.close(k));
                }
                if (r - from).abs() > thresh {
                    self.open = Some(OpenStep {
                        k0: k,
                        time_s: t,
                        from_rad: from,
                        to_rad: r,
                        peak: f64::NEG_INFINITY,
                        last_out: None,
                        t_after_out_s: None,
                        moved: false,
                        held: 0,
                    });
                }
            }
            if let Some(o) = self.open.as_mut() {
                let size = o.to_rad - o.from_rad;
                if (r - o.to_rad).abs() > 1e-6 * size.abs() + 1e-12 {
                    o.moved = true;
                } else if !o.moved {
                    o.held += 1;
                }
                if o.last_out == Some(k.wrapping_sub(1)) && k > o.k0 {
                    o.t_after_out_s = Some(t);
                }
                let e = y - r;
                o.peak = o.peak.max(size.signum() * e);
                if e.abs() > self.band * size.abs() {
                    o.last_out = Some(k);
                }
            }
            if let Some(p) = self.r_prev {
                let x = (r - p).abs();
                self.d_prev = if x.is_finite() { x } else { 0.0 };
            }
            self.r_prev = Some(r);
        }
        self.block = block;
        self.block.clear();
    }

    /// Samples pushed so far.
    pub fn samples(&self) -> usize {
        self.n
    }

    /// The summary of everything pushed.
    pub fn finish(mut self) -> RunSummary {
        self.flush_block();
        if let Some(o) = self.open.take() {
            self.steps.extend(o.close(self.n));
        }
        let rms = |sq: f64, n: usize| {
            if n == 0 {
                0.0
            } else {
                math::sqrt(sq / n as f64)
            }
        };
        RunSummary {
            duration_s: self.n as f64 * self.ts_s,
            samples: self.n,
            err_rms_rad: (self.e_n > 0).then(|| rms(self.e_sq, self.e_n)),
            err_max_rad: (self.e_n > 0).then_some(self.e_max),
            band: self.band,
            steps: if self.e_n > 0 { self.steps } else { Vec::new() },
            saturation_time_s: self.saturated as f64 * self.ts_s,
            u_rms_v: rms(self.u_sq, self.u_n),
            command: DriveKind::Voltage,
        }
    }
}

/// A [`RunSummary`] shown on a linear axis: tracking errors in m (and mm) instead of rad
/// ([`RunSummary::on_axis`]).
pub struct SummaryOnAxis<'a> {
    summary: &'a RunSummary,
    metres_per_rad: Option<f64>,
}

impl RunSummary {
    /// The summary for display on a linear axis whose load shaft travels `metres_per_rad`
    /// [m/rad] (`None`: a rotary gear, as [`fmt::Display`] shows it).
    pub fn on_axis(&self, metres_per_rad: Option<f64>) -> SummaryOnAxis<'_> {
        SummaryOnAxis {
            summary: self,
            metres_per_rad,
        }
    }
}

impl fmt::Display for RunSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.on_axis(None), f)
    }
}

impl fmt::Display for SummaryOnAxis<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = self.summary;
        s.fmt_on(f, self.metres_per_rad)
    }
}

impl RunSummary {
    fn fmt_on(&self, f: &mut fmt::Formatter<'_>, metres_per_rad: Option<f64>) -> fmt::Result {
        let deg = 180.0 / core::f64::consts::PI;
        writeln!(
            f,
            "run summary ({:.3} s, {} samples):",
            self.duration_s, self.samples
        )?;
        match (self.err_rms_rad, self.err_max_rad, metres_per_rad) {
            (Some(rms), Some(max), Some(m)) => {
                writeln!(
                    f,
                    "  tracking error RMS   {:.4e} m ({:.4} mm)",
                    rms * m,
                    rms * m * 1e3
                )?;
                writeln!(
                    f,
                    "  tracking error max   {:.4e} m ({:.4} mm)",
                    max * m,
                    max * m * 1e3
                )?;
            }
            (Some(rms), Some(max), None) => {
                writeln!(
                    f,
                    "  tracking error RMS   {} rad ({} deg)",
                    math::sig(rms, 3),
                    math::sig(rms * deg, 3)
                )?;
                writeln!(
                    f,
                    "  tracking error max   {} rad ({} deg)",
                    math::sig(max, 3),
                    math::sig(max * deg, 3)
                )?;
            }
            _ => writeln!(f, "  tracking error       n/a (open loop)")?,
        }
        match self.overshoot_pct() {
            Some(os) => writeln!(
                f,
                "  overshoot (max)      {} % over {} step(s)",
                math::sig(os, 3),
                self.steps.len()
            )?,
            None if self.err_rms_rad.is_some() => writeln!(
                f,
                "  overshoot            n/a (the reference has no steps: see the tracking error)"
            )?,
            None => writeln!(f, "  overshoot            n/a (open loop)")?,
        }
        match self.settling_time_s() {
            Some(Some(ts)) => writeln!(
                f,
                "  settling time (max)  {} s ({:.0} % band)",
                math::sig(ts, 3),
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
            "  saturation time      {} s ({} % of the run)",
            math::sig(self.saturation_time_s, 3),
            math::sig(pct, 3)
        )?;
        let rms = math::sig(self.u_rms_v, 3);
        match self.command {
            DriveKind::Voltage => write!(f, "  u RMS                {rms} V")?,
            DriveKind::Current => write!(f, "  i_ref RMS            {rms} A")?,
            DriveKind::Duty => write!(f, "  duty RMS             {rms} (fraction of the supply)")?,
        }
        if self.steps.len() > 1 {
            writeln!(f)?;
            let (unit, k) = match metres_per_rad {
                Some(m) => ("mm", m * 1e3),
                None => ("deg", deg),
            };
            write!(
                f,
                "  steps:  t [s]   from -> to [{unit}]   overshoot [%]   settling [s]"
            )?;
            for s in &self.steps {
                write!(
                    f,
                    "\n  {:8.3}   {:8.2} -> {:8.2}   {:8.2}        {}",
                    s.time_s,
                    s.from_rad * k,
                    s.to_rad * k,
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

    /// The summary of `n` samples at 1 kHz: reference 0 until `hold_s` [s], then `r` from 0;
    /// the response a first-order lag of 10 ms.
    fn summary_after_hold(r: &crate::control::Reference, hold_s: f64, n: usize) -> RunSummary {
        let ts = 1e-3;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * ts).collect();
        let rr: Vec<f64> = t
            .iter()
            .map(|&t| {
                if t < hold_s {
                    0.0
                } else {
                    r.at(t - hold_s).pos_rad
                }
            })
            .collect();
        let mut y = vec![0.0; n];
        for k in 1..n {
            y[k] = y[k - 1] + (rr[k - 1] - y[k - 1]) * ts / 0.01;
        }
        let rec = Record {
            time_s: t,
            u_v: Some(vec![0.0; n]),
            theta_l_rad: Some(y),
            ref_rad: Some(rr),
            ..Record::default()
        };
        RunSummary::compute(&rec, &[], 0.05)
    }

    #[test]
    fn the_end_of_a_smooth_move_is_no_step() {
        // Holds, then a short move of 0.5 rad (0.32 s) that stops and holds, inside one block of
        // the detector: the move's last sample changes the reference by ~1e-5 rad after a
        // block that mostly holds; that is no step (it gave an overshoot of 10^5 % of it).
        let r = crate::control::Reference::parse("trap:distance=0.5,vmax=3,amax=20").unwrap();
        let s = summary_after_hold(&r, 2.3, 6_000);
        assert!(s.steps.is_empty(), "{:?}", s.steps);
    }

    #[test]
    fn a_multisine_has_no_steps() {
        // A hold at 0, then a multisine: its fast lines change the reference by more than 50
        // times the block's median change at places, but it never holds after such a jump.
        let r =
            crate::control::Reference::parse("multisine:amp=0.2,f0=0.2,f1=20,period=10,lines=40")
                .unwrap();
        let s = summary_after_hold(&r, 1.0, 12_000);
        assert!(s.steps.is_empty(), "{:?}", s.steps);
        let text = s.to_string();
        assert!(
            text.contains("no steps") && !text.contains("overshoot (max)"),
            "{text}"
        );
        assert!(s.err_rms_rad.is_some());
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
