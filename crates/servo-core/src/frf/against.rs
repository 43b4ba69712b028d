//! A measured frequency response against a model: where it fails, by how much, and which
//! physical effect has that frequency signature.
//!
//! * Band errors: runs of bins where the magnitude error exceeds max(bound, 1 dB) or the phase
//!   error exceeds max(bound, 3 deg) with one sign, said in words ("above 40 rad/s the measured
//!   phase lags the model by up to 25 deg").
//! * Delay: a phase lag growing linearly with frequency, e = -tau w (weighted least squares),
//!   against its look-alike, one unmodelled real pole, e = -atan(w/p).
//! * Resonance: a local peak of |measured/model| of more than 3 dB beyond its bounds.
//! * Amplitude dependence: two estimates taken at different amplitudes whose gains differ beyond
//!   their bounds: a linear plant has one gain, friction and gear play do not.
//! * No information: the frequency ranges where the coherence is below 0.5.

use super::Frf;
use crate::design::{deg, Complex};
use crate::math;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

/// Coherence from which a bin is used against the model.
pub const MIN_COHERENCE: f64 = 0.8;
/// Coherence below which a frequency carries no information.
pub const NO_INFORMATION: f64 = 0.5;

/// One bin of the comparison.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorPoint {
    pub omega_rad_s: f64,
    /// 20 log10 |measured / model| [dB].
    pub mag_err_db: f64,
    /// Half-width of the magnitude bound [dB] (the larger side).
    pub mag_bound_db: f64,
    /// angle(measured / model) [deg] in (-180, 180].
    pub phase_err_deg: f64,
    /// Half-width of the phase bound [deg].
    pub phase_bound_deg: f64,
    pub coherence: f64,
}

/// A run of bins where the model is off.
#[derive(Debug, Clone, PartialEq)]
pub struct BandError {
    /// "magnitude" or "phase".
    pub quantity: &'static str,
    pub lo_rad_s: f64,
    pub hi_rad_s: f64,
    /// Largest error in the run [dB or deg], signed.
    pub worst: f64,
    /// The run reaches the top of the coherent band.
    pub to_band_end: bool,
    pub sentence: String,
}

/// A delay fitted to the phase error, with the pole alternative.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DelayFit {
    pub delay_s: f64,
    /// 95 % half-width of the delay [s].
    pub delay_ci_s: f64,
    /// RMS residual of the delay fit [deg].
    pub delay_rms_deg: f64,
    /// The single real pole that best explains the lag [rad/s].
    pub pole_rad_s: f64,
    /// RMS residual of the pole fit [deg].
    pub pole_rms_deg: f64,
}

/// A resonance seen against the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonance {
    pub omega_rad_s: f64,
    pub peak_db: f64,
}

/// The whole comparison.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    pub points: Vec<ErrorPoint>,
    pub bands: Vec<BandError>,
    pub delay: Option<DelayFit>,
    pub resonance: Option<Resonance>,
    /// Frequency ranges [rad/s] with coherence below [`NO_INFORMATION`].
    pub no_information: Vec<(f64, f64)>,
    /// Everything above in words, most important first.
    pub sentences: Vec<String>,
}

fn wrap180(x: f64) -> f64 {
    x - 360.0 * math::round(x / 360.0)
}

/// Ranges [rad/s] of consecutive bins with coherence below `level`.
pub fn low_coherence_ranges(est: &Frf, level: f64) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut open: Option<(f64, f64)> = None;
    for i in 0..est.len() {
        let w = est.omega(i);
        if est.coherence[i] < level {
            open = Some(open.map_or((w, w), |(a, _)| (a, w)));
        } else if let Some(r) = open.take() {
            out.push(r);
        }
    }
    out.extend(open);
    out
}

/// Runs of `flag` (allowing gaps of up to 2 bins), at least 3 flagged bins long: (first, last).
fn runs(flag: &[bool]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < flag.len() {
        if !flag[i] {
            i += 1;
            continue;
        }
        let (start, mut last, mut count) = (i, i, 0);
        let mut j = i;
        while j < flag.len() && j <= last + 3 {
            if flag[j] {
                last = j;
                count += 1;
            }
            j += 1;
        }
        if count >= 3 {
            out.push((start, last));
        }
        i = last + 1;
    }
    out
}

fn band_sentence(q: &str, lo: f64, hi: f64, to_end: bool, from_start: bool, words: &str) -> String {
    let range = if to_end && !from_start {
        format!("above {lo:.3} rad/s")
    } else if from_start && !to_end {
        format!("below {hi:.3} rad/s")
    } else if from_start && to_end {
        format!("over the whole coherent band ({lo:.3}-{hi:.3} rad/s)")
    } else {
        format!("between {lo:.3} and {hi:.3} rad/s")
    };
    format!("{range} the measured {q} {words}")
}

/// Compares `measured` with `model(omega)` (the model's discrete response at the same period).
pub fn against_model(measured: &Frf, model: impl Fn(f64) -> Complex<f64>) -> Comparison {
    let points: Vec<ErrorPoint> = measured
        .coherent(MIN_COHERENCE)
        .filter_map(|i| {
            let w = measured.omega(i);
            let m = model(w);
            let q = measured.h[i] / m;
            if !(q.norm().is_finite() && q.norm() > 0.0) {
                return None;
            }
            let r = measured.rel_radius[i];
            Some(ErrorPoint {
                omega_rad_s: w,
                mag_err_db: 20.0 * math::log10(q.norm()),
                mag_bound_db: if r < 1.0 {
                    -20.0 * math::log10(1.0 - r)
                } else {
                    f64::INFINITY
                },
                phase_err_deg: wrap180(deg(math::atan2(q.im, q.re))),
                phase_bound_deg: measured.phase_bound_deg(i),
                coherence: measured.coherence[i],
            })
        })
        .collect();
    let no_information = low_coherence_ranges(measured, NO_INFORMATION);
    let mut out = Comparison {
        points,
        bands: Vec::new(),
        delay: None,
        resonance: None,
        no_information,
        sentences: Vec::new(),
    };
    let pts = &out.points;
    if pts.len() < 3 {
        out.sentences.push(format!(
            "fewer than three frequencies have coherence >= {MIN_COHERENCE}: the data say nothing about the model's frequency response"
        ));
        return out;
    }
    let n = pts.len();
    let (w_lo, w_hi) = (pts[0].omega_rad_s, pts[n - 1].omega_rad_s);
    // Band errors.
    type Pick = fn(&ErrorPoint) -> (f64, f64, f64);
    let quantities: [(&'static str, Pick); 2] = [
        ("magnitude", |p| (p.mag_err_db, p.mag_bound_db, 1.0)),
        ("phase", |p| (p.phase_err_deg, p.phase_bound_deg, 3.0)),
    ];
    for (q, pick) in quantities {
        for sign in [1.0, -1.0] {
            let flag: Vec<bool> = pts
                .iter()
                .map(|p| {
                    let (e, b, floor) = pick(p);
                    sign * e > b.max(floor)
                })
                .collect();
            for (a, b) in runs(&flag) {
                let worst = pts[a..=b].iter().map(|p| pick(p).0).fold(0.0, |m: f64, e| {
                    if sign * e > sign * m {
                        e
                    } else {
                        m
                    }
                });
                let (lo, hi) = (pts[a].omega_rad_s, pts[b].omega_rad_s);
                let to_end = b + 3 >= n;
                let from_start = a <= 2;
                let words = match (q, sign > 0.0) {
                    ("magnitude", true) => {
                        format!("is above the model by up to {:.1} dB", worst.abs())
                    }
                    ("magnitude", false) => {
                        format!("is below the model by up to {:.1} dB", worst.abs())
                    }
                    (_, true) => format!("leads the model by up to {:.1} deg", worst.abs()),
                    (_, false) => {
                        let mut s = format!("lags the model by up to {:.1} deg", worst.abs());
                        // the lag at the top of the run as a delay
                        let tau = worst.abs().to_radians() / hi;
                        s.push_str(&format!(
                            ": a delay of about {:.1} ms or an unmodelled pole",
                            tau * 1e3
                        ));
                        s
                    }
                };
                out.bands.push(BandError {
                    quantity: q,
                    lo_rad_s: lo,
                    hi_rad_s: hi,
                    worst,
                    to_band_end: to_end,
                    sentence: band_sentence(q, lo, hi, to_end, from_start, &words),
                });
            }
        }
    }
    out.bands
        .sort_by(|a, b| b.worst.abs().total_cmp(&a.worst.abs()));
    // Delay against one pole, on the phase error (weights 1/bound^2).
    let wts: Vec<f64> = pts
        .iter()
        .map(|p| 1.0 / p.phase_bound_deg.max(0.5).powi(2))
        .collect();
    let e_rad: Vec<f64> = pts.iter().map(|p| p.phase_err_deg.to_radians()).collect();
    let (mut sww, mut swe) = (0.0, 0.0);
    for ((p, e), wt) in pts.iter().zip(&e_rad).zip(&wts) {
        sww += wt * p.omega_rad_s * p.omega_rad_s;
        swe += wt * p.omega_rad_s * e;
    }
    let tau = -swe / sww;
    let rms = |f: &dyn Fn(f64) -> f64| {
        let (mut s, mut sw) = (0.0, 0.0);
        for ((p, e), wt) in pts.iter().zip(&e_rad).zip(&wts) {
            let r = deg(e - f(p.omega_rad_s));
            s += wt * r * r;
            sw += wt;
        }
        math::sqrt(s / sw)
    };
    let delay_rms = rms(&|w| -tau * w);
    let tau_ci = 1.96 * (delay_rms.to_radians() / math::sqrt(sww / wts.iter().sum::<f64>()))
        / math::sqrt(n as f64);
    // pole: golden-section on log p over [w_lo / 10, 1000 w_hi]
    let cost = |lp: f64| rms(&|w| -math::atan(w / math::exp(lp)));
    let (mut a, mut b) = (math::ln(w_lo / 10.0), math::ln(1000.0 * w_hi));
    let g = 0.618_033_988_75;
    for _ in 0..80 {
        let (c, d) = (b - g * (b - a), a + g * (b - a));
        if cost(c) < cost(d) {
            b = d;
        } else {
            a = c;
        }
    }
    let pole = math::exp(0.5 * (a + b));
    let pole_rms = cost(0.5 * (a + b));
    let lag_top = tau * w_hi;
    if tau > 0.0 && tau > 2.0 * tau_ci && deg(lag_top) > 3.0 {
        let fit = DelayFit {
            delay_s: tau,
            delay_ci_s: tau_ci,
            delay_rms_deg: delay_rms,
            pole_rad_s: pole,
            pole_rms_deg: pole_rms,
        };
        out.delay = Some(fit);
        let which = if delay_rms <= pole_rms {
            format!(
                "the phase lag grows linearly with frequency, the signature of a delay: {:.2} +- {:.2} ms (residual {:.1} deg; one unmodelled pole at {:.0} rad/s fits worse, residual {:.1} deg)",
                tau * 1e3, tau_ci * 1e3, delay_rms, pole, pole_rms
            )
        } else {
            format!(
                "the phase lag bends like an unmodelled pole at about {:.0} rad/s (residual {:.1} deg) rather than a delay ({:.2} ms, residual {:.1} deg)",
                pole, pole_rms, tau * 1e3, delay_rms
            )
        };
        out.sentences.push(which);
    }
    // Resonance: a local peak of the magnitude error of > 3 dB beyond its bound.
    let mut best: Option<Resonance> = None;
    for i in 0..n {
        let p = &pts[i];
        // a peak within [w/1.5, 1.5 w], both sides measured
        let lo = pts.partition_point(|q| q.omega_rad_s < p.omega_rad_s / 1.5);
        let hi = pts.partition_point(|q| q.omega_rad_s <= p.omega_rad_s * 1.5) - 1;
        if lo == 0 || hi + 1 >= n || hi < i + 2 || i < lo + 2 {
            continue;
        }
        let side = pts[lo].mag_err_db.max(pts[hi].mag_err_db);
        let is_max = pts[lo..=hi].iter().all(|q| q.mag_err_db <= p.mag_err_db);
        let rise = p.mag_err_db - side;
        if is_max
            && rise > 3.0 + p.mag_bound_db
            && i > lo
            && i < hi
            && !matches!(best, Some(r) if r.peak_db >= rise)
        {
            best = Some(Resonance {
                omega_rad_s: p.omega_rad_s,
                peak_db: rise,
            });
        }
    }
    if let Some(r) = best {
        out.sentences.push(format!(
            "a resonance near {:.1} rad/s ({:.2} Hz): the measured gain peaks {:.1} dB above the model's there (a compliant shaft, coupling or mount)",
            r.omega_rad_s,
            r.omega_rad_s / math::TAU,
            r.peak_db
        ));
        out.resonance = Some(r);
    }
    for b in &out.bands {
        out.sentences.push(b.sentence.clone());
    }
    if out.bands.is_empty() {
        out.sentences.push(format!(
            "the model matches the measured response within the bounds (and 1 dB, 3 deg) from {w_lo:.3} to {w_hi:.1} rad/s"
        ));
    }
    out
}

/// One estimate of the plant together with the amplitude it was taken at.
#[derive(Debug, Clone, Copy)]
pub struct AtAmplitude<'a> {
    /// A name for the user (the log's file name).
    pub name: &'a str,
    /// RMS of the driver input u over the record [V].
    pub u_rms_v: f64,
    pub estimate: &'a Frf,
}

/// The gain difference between two estimates at different amplitudes.
#[derive(Debug, Clone, PartialEq)]
pub struct AmplitudeDependence {
    /// Indices of the small- and large-amplitude estimates.
    pub small: usize,
    pub large: usize,
    /// Mean of 20 log10 |H_small / H_large| over the common coherent bins [dB].
    pub gain_change_db: f64,
    /// Its 95 % half-width [dB].
    pub bound_db: f64,
    pub lo_rad_s: f64,
    pub hi_rad_s: f64,
    pub significant: bool,
    pub sentence: String,
}

/// Compares the gains of estimates taken at different amplitudes (same frequency grid). Returns
/// the comparison of the smallest with the largest amplitude, if they share coherent bins.
pub fn amplitude_dependence(ests: &[AtAmplitude]) -> Option<AmplitudeDependence> {
    if ests.len() < 2 {
        return None;
    }
    let by = |f: fn(f64, f64) -> bool| {
        (0..ests.len()).fold(0, |b, i| {
            if f(ests[i].u_rms_v, ests[b].u_rms_v) {
                i
            } else {
                b
            }
        })
    };
    let (small, large) = (by(|a, b| a < b), by(|a, b| a > b));
    let (s, l) = (ests[small].estimate, ests[large].estimate);
    if small == large || s.len() != l.len() || ests[large].u_rms_v < 1.2 * ests[small].u_rms_v {
        return None;
    }
    let (mut sum, mut sw, mut var) = (0.0, 0.0, 0.0);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for i in 0..s.len() {
        if s.coherence[i] < MIN_COHERENCE || l.coherence[i] < MIN_COHERENCE {
            continue;
        }
        let d = 20.0 * math::log10(s.mag(i) / l.mag(i));
        let r = s.rel_radius[i] + l.rel_radius[i];
        if !(d.is_finite() && r < 1.0) {
            continue;
        }
        // the bound is a ~2-sigma half-width; weight by 1/sigma^2
        let sigma_db = -20.0 * math::log10(1.0 - r) / 2.0;
        let wt = 1.0 / (sigma_db * sigma_db).max(1e-6);
        sum += wt * d;
        sw += wt;
        var += 1.0;
        lo = lo.min(s.omega(i));
        hi = hi.max(s.omega(i));
    }
    if var < 3.0 {
        return None;
    }
    let mean = sum / sw;
    let bound = 1.96 / math::sqrt(sw);
    let significant = mean.abs() > bound.max(1.0);
    let (a, b) = (&ests[small], &ests[large]);
    let sentence = if significant {
        format!(
            "the gain depends on the amplitude: with u at {:.2} V rms ({}) the plant gain is {:.1} dB {} than with {:.2} V rms ({}) over {lo:.2}-{hi:.1} rad/s: a nonlinearity such as friction (small motions stick) or gear play; a linear plant has one gain",
            a.u_rms_v, a.name, mean.abs(), if mean < 0.0 { "lower" } else { "higher" }, b.u_rms_v, b.name
        )
    } else {
        format!(
            "the gain does not depend on the amplitude between {:.2} and {:.2} V rms (difference {:.1} +- {:.1} dB over {lo:.2}-{hi:.1} rad/s): no sign of friction or gear play at these amplitudes",
            a.u_rms_v, b.u_rms_v, mean, bound
        )
    };
    Some(AmplitudeDependence {
        small,
        large,
        gain_change_db: mean,
        bound_db: bound,
        lo_rad_s: lo,
        hi_rad_s: hi,
        significant,
        sentence,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frf_of(h: impl Fn(f64) -> Complex<f64>) -> Frf {
        let freq_hz: Vec<f64> = (1..500).map(|k| k as f64 * 0.05).collect();
        Frf {
            h: freq_hz.iter().map(|f| h(math::TAU * f)).collect(),
            coherence: alloc::vec![0.99; freq_hz.len()],
            rel_radius: alloc::vec![0.01; freq_hz.len()],
            freq_hz,
            averages: 30.0,
            confidence: 0.95,
        }
    }

    fn model(w: f64) -> Complex<f64> {
        let s = Complex::new(0.0, w);
        Complex::new(30.0, 0.0) / (s * (s * 0.03 + 1.0))
    }

    #[test]
    fn a_delay_is_named_with_its_size() {
        let meas = frf_of(|w| model(w) * crate::design::c_expj(-w * 0.006));
        let c = against_model(&meas, model);
        let d = c.delay.expect("delay found");
        assert!((d.delay_s - 0.006).abs() < 2e-4, "{d:?}");
        assert!(d.delay_rms_deg < d.pole_rms_deg);
        assert!(c.sentences[0].contains("delay"), "{:?}", c.sentences);
        assert!(c
            .bands
            .iter()
            .any(|b| b.quantity == "phase" && b.worst < -20.0));
    }

    #[test]
    fn an_exact_model_matches() {
        let c = against_model(&frf_of(model), model);
        assert!(c.bands.is_empty() && c.delay.is_none() && c.resonance.is_none());
        assert!(c.sentences[0].contains("matches"));
    }

    #[test]
    fn a_resonance_is_found() {
        let wr = 60.0;
        let meas = frf_of(|w| {
            let s = Complex::new(0.0, w);
            let z = 0.05;
            let res =
                (s * s + s * (2.0 * 0.5 * wr) + wr * wr) / (s * s + s * (2.0 * z * wr) + wr * wr);
            model(w) * res
        });
        let c = against_model(&meas, model);
        let r = c.resonance.expect("resonance");
        assert!((r.omega_rad_s - wr).abs() < 3.0, "{r:?}");
    }
}
