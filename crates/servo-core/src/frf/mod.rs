//! Nonparametric frequency-response estimates from logged data (like MATLAB's `tfestimate` /
//! `spa`): Welch-averaged H1 estimates with coherence and confidence bounds, the plant from
//! open- and closed-loop logs, the loop L = C P and the margins it achieved.
//!
//! * [`welch`]: windowed (Hann, 50 % overlap) auto/cross spectra and the H1 estimate with
//!   Bendat & Piersol confidence circles.
//! * [`margins`]: crossover, phase margin and gain margin of a measured loop, with intervals.
//! * [`against`]: the measured response against a model: band errors in words and the frequency
//!   signatures of the catalogue effects (delay, unmodelled pole, resonance, amplitude dependence).
//!
//! **Which estimate.** Open loop (u is the excitation): P = H1(u -> delta theta) / (1 - z^-1), the
//! plant estimated on the increments of theta_l so that the integrator's drift and its 1/f
//! spectrum do not leak through the window, then integrated exactly in discrete time. Closed loop
//! (the reference r is the excitation): the joint input-output estimate
//! P = G_{r,dtheta} / G_{r,u} / (1 - z^-1): noise in the loop is correlated with u, so the direct
//! H1(u -> theta) would be biased towards -1/C; through r (which the noise does not reach) it is
//! consistent. T = H1(r -> theta_l) is the complementary sensitivity.
//!
//! Frequencies are in Hz where the name says so (`freq_hz`) and rad/s otherwise; phases in degrees
//! where the name ends in `_deg`. All estimates are of the *discrete* response at the log's
//! period: the plant with its zero-order hold, as a discrete controller sees it.

pub mod against;
pub mod analysis;
pub mod margins;
pub mod welch;

use crate::design::{c_expj, deg, Complex};
use crate::math;
use alloc::vec::Vec;

pub use margins::{achieved_margins, AchievedMargins, Interval};
pub use welch::{cross_spectra, Channels, CrossSpectra, WelchOptions};

/// Why an estimate could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FrfError {
    /// A setting or a signal is unusable; the message says which.
    #[error("{0}")]
    Invalid(&'static str),
    /// The records are shorter than one averaging segment.
    #[error(
        "the longest record has {samples} samples, fewer than one averaging segment of {needed}"
    )]
    TooShort { samples: usize, needed: usize },
}

/// A frequency-response estimate on the Welch bins.
#[derive(Debug, Clone, PartialEq)]
pub struct Frf {
    /// Bin frequencies [Hz].
    pub freq_hz: Vec<f64>,
    /// The complex response per bin.
    pub h: Vec<Complex<f64>>,
    /// Coherence gamma^2 in [0, 1] per bin (for derived estimates, the smallest coherence of the
    /// estimates they are made of).
    pub coherence: Vec<f64>,
    /// Radius of the confidence circle relative to |H| per bin (infinite: no information).
    pub rel_radius: Vec<f64>,
    /// Equivalent number of independent averages.
    pub averages: f64,
    /// Confidence level of the bounds.
    pub confidence: f64,
}

impl Frf {
    /// Number of bins.
    pub fn len(&self) -> usize {
        self.h.len()
    }
    /// True when there are no bins.
    pub fn is_empty(&self) -> bool {
        self.h.is_empty()
    }
    /// Bin frequency [rad/s].
    pub fn omega(&self, i: usize) -> f64 {
        math::TAU * self.freq_hz[i]
    }
    /// |H| of bin i.
    pub fn mag(&self, i: usize) -> f64 {
        self.h[i].norm()
    }
    /// Magnitude bounds (lo, hi) of bin i at the estimate's confidence.
    pub fn mag_bounds(&self, i: usize) -> (f64, f64) {
        let (m, r) = (self.mag(i), self.rel_radius[i]);
        ((m * (1.0 - r)).max(0.0), m * (1.0 + r))
    }
    /// Half-width of the phase bound of bin i [deg] (180 when the circle holds the origin).
    pub fn phase_bound_deg(&self, i: usize) -> f64 {
        let r = self.rel_radius[i];
        if r >= 1.0 || !r.is_finite() {
            180.0
        } else {
            deg(r.asin())
        }
    }
    /// Phase per bin [deg], unwrapped along frequency through the bins with coherence >= 0.5
    /// (the others take the branch nearest the last trusted bin), starting on the branch nearest
    /// `start_deg` (e.g. -90 per integrator).
    pub fn phase_deg(&self, start_deg: f64) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.len());
        let mut reference = start_deg;
        for (h, g) in self.h.iter().zip(&self.coherence) {
            let p = deg(math::atan2(h.im, h.re));
            let p = p - 360.0 * math::round((p - reference) / 360.0);
            if *g >= 0.5 && p.is_finite() {
                reference = p;
            }
            out.push(p);
        }
        out
    }

    /// The estimate times a known response `g(omega)` (exact, no added uncertainty).
    pub fn times(&self, g: impl Fn(f64) -> Complex<f64>) -> Frf {
        let mut out = self.clone();
        for (i, h) in out.h.iter_mut().enumerate() {
            *h *= g(math::TAU * self.freq_hz[i]);
        }
        out
    }

    /// Bins with coherence >= `min` (indices).
    pub fn coherent(&self, min: f64) -> impl Iterator<Item = usize> + '_ {
        (0..self.len()).filter(move |&i| self.coherence[i] >= min && self.h[i].norm().is_finite())
    }
}

/// 1 / (1 - e^{-j w T}): the discrete integrator that turns increments back into positions.
fn integrator(omega: f64, ts_s: f64) -> Complex<f64> {
    Complex::new(1.0, 0.0) / (Complex::new(1.0, 0.0) - c_expj(-omega * ts_s))
}

/// First differences x[k] - x[k-1] (the first sample's difference is 0).
pub fn increments(x: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(x.len());
    let mut prev = x.first().copied().unwrap_or(0.0);
    for &v in x {
        out.push(v - prev);
        prev = v;
    }
    out
}

/// One open-loop record: the driver input u [V] and the load angle theta_l [rad].
#[derive(Debug, Clone, Copy)]
pub struct OpenLoopRecord<'a> {
    pub u_v: &'a [f64],
    pub theta_l_rad: &'a [f64],
}

/// One closed-loop record: reference r, driver input u and load angle theta_l.
#[derive(Debug, Clone, Copy)]
pub struct ClosedLoopRecord<'a> {
    pub ref_rad: &'a [f64],
    pub u_v: &'a [f64],
    pub theta_l_rad: &'a [f64],
}

/// The estimates of a closed-loop experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedLoopFrf {
    /// T = theta_l / r [rad/rad].
    pub t: Frf,
    /// u / r = C S (+ feedforward) [V/rad].
    pub u_over_r: Frf,
    /// The plant P = theta_l / u [rad/V] by the joint input-output method.
    pub plant: Frf,
    /// The spectra (segments, window, averages).
    pub spectra: CrossSpectra,
}

/// The plant u [V] -> theta_l [rad] from open-loop records sampled every `ts_s` [s].
pub fn open_loop(
    records: &[OpenLoopRecord],
    ts_s: f64,
    opts: &WelchOptions,
) -> Result<(Frf, CrossSpectra), FrfError> {
    let incs: Vec<Vec<f64>> = records.iter().map(|r| increments(r.theta_l_rad)).collect();
    let chans: Vec<Channels> = records
        .iter()
        .zip(&incs)
        .map(|(r, d)| Channels {
            input: r.u_v,
            outputs: alloc::vec![d.as_slice()],
        })
        .collect();
    let sp = cross_spectra(&chans, ts_s, opts)?;
    let mut p = sp.h1(0, opts.confidence).times(|w| integrator(w, ts_s));
    if let Some(half) = half_length(&chans, ts_s, opts, &sp)? {
        let ph = half.h1(0, opts.confidence).times(|w| integrator(w, ts_s));
        allow_leakage(&mut p, &ph);
    }
    Ok((p, sp))
}

/// T, u/r and the plant (joint input-output) from closed-loop records sampled every `ts_s` [s].
pub fn closed_loop(
    records: &[ClosedLoopRecord],
    ts_s: f64,
    opts: &WelchOptions,
) -> Result<ClosedLoopFrf, FrfError> {
    let incs: Vec<Vec<f64>> = records.iter().map(|r| increments(r.theta_l_rad)).collect();
    let chans: Vec<Channels> = records
        .iter()
        .zip(&incs)
        .map(|(r, d)| Channels {
            input: r.ref_rad,
            outputs: alloc::vec![r.theta_l_rad, r.u_v, d.as_slice()],
        })
        .collect();
    let sp = cross_spectra(&chans, ts_s, opts)?;
    let mut t = sp.h1(0, opts.confidence);
    let mut u_over_r = sp.h1(1, opts.confidence);
    let dy_over_r = sp.h1(2, opts.confidence);
    let mut plant = ratio(&dy_over_r, &u_over_r).times(|w| integrator(w, ts_s));
    if let Some(half) = half_length(&chans, ts_s, opts, &sp)? {
        allow_leakage(&mut t, &half.h1(0, opts.confidence));
        allow_leakage(&mut u_over_r, &half.h1(1, opts.confidence));
        let ph = ratio(&half.h1(2, opts.confidence), &half.h1(1, opts.confidence))
            .times(|w| integrator(w, ts_s));
        allow_leakage(&mut plant, &ph);
    }
    Ok(ClosedLoopFrf {
        t,
        u_over_r,
        plant,
        spectra: sp,
    })
}

/// The same spectra with segments of half the length (None below 32 samples), for
/// [`allow_leakage`].
fn half_length(
    chans: &[Channels],
    ts_s: f64,
    opts: &WelchOptions,
    full: &CrossSpectra,
) -> Result<Option<CrossSpectra>, FrfError> {
    if full.segment_len < 32 {
        return Ok(None);
    }
    let half = WelchOptions {
        segment_len: Some(full.segment_len / 2),
        ..*opts
    };
    cross_spectra(chans, ts_s, &half).map(Some)
}

/// Leakage (transient) bias allowance. A segment of N samples does not hold the response to the
/// input before it, nor the end of the response to its own input; with nonstationary excitation
/// (a sweep entering or leaving a band, the loop's transient when the excitation stops) this error
/// does not average out and the coherence barely shows it. It falls like 1/N (Pintelon &
/// Schoukens, *System Identification*, 2nd ed., sec. 2.6), so the same estimate from segments of
/// N/2 carries about twice the error of the N estimate: |H_N - H_{N/2}| estimates it (together
/// with some random error and the larger resolution bias of the N/2 estimate, so it errs on the
/// wide side). It is added to the relative radius of `full`; `half` is interpolated linearly in
/// frequency onto the bins of `full`.
pub fn allow_leakage(full: &mut Frf, half: &Frf) {
    for i in 0..full.len() {
        let f = full.freq_hz[i];
        let j = half.freq_hz.partition_point(|&g| g < f);
        let hh = if j < half.len() && half.freq_hz[j] == f {
            half.h[j]
        } else if j > 0 && j < half.len() {
            let (f0, f1) = (half.freq_hz[j - 1], half.freq_hz[j]);
            let a = (f - f0) / (f1 - f0);
            half.h[j - 1] * (1.0 - a) + half.h[j] * a
        } else {
            continue;
        };
        let m = full.h[i].norm();
        let d = (full.h[i] - hh).norm();
        if m > 0.0 && d.is_finite() {
            full.rel_radius[i] += d / m;
        }
    }
}

/// a / b bin by bin; relative radii add (first order, conservative for correlated errors), the
/// coherence is the smaller one.
pub fn ratio(a: &Frf, b: &Frf) -> Frf {
    let mut out = a.clone();
    for i in 0..a.len() {
        out.h[i] = a.h[i] / b.h[i];
        out.coherence[i] = a.coherence[i].min(b.coherence[i]);
        out.rel_radius[i] = a.rel_radius[i] + b.rel_radius[i];
    }
    out
}

/// The loop L = T / (1 - T) from the complementary sensitivity, valid when u = C (r - theta_l)
/// (no feedforward, derivative on the error); relative radius |dL/L| = |dT/T| / |1 - T|.
pub fn loop_from_t(t: &Frf) -> Frf {
    let mut out = t.clone();
    for i in 0..t.len() {
        let one_minus = Complex::new(1.0, 0.0) - t.h[i];
        out.h[i] = t.h[i] / one_minus;
        out.rel_radius[i] = t.rel_radius[i] / one_minus.norm();
    }
    out
}

/// One log's signals for [`estimate`]: the position reference [rad] (`None` open loop), the
/// driver input u [V] and the load angle theta_l [rad].
pub type Signals<'a> = (Option<&'a [f64]>, &'a [f64], &'a [f64]);

/// The plant estimate of `records` pooled, and the complementary sensitivity T in closed loop:
/// with `closed`, the joint input-output estimate of [`closed_loop`] (every record must carry
/// its reference), otherwise H1(u -> theta_l) of [`open_loop`]. `ts_s` is the sample period [s].
pub fn estimate(
    records: &[Signals],
    closed: bool,
    ts_s: f64,
    opts: &WelchOptions,
) -> Result<(Frf, Option<Frf>, CrossSpectra), FrfError> {
    Ok(if closed {
        let cl: Vec<ClosedLoopRecord> = records
            .iter()
            .map(|r| ClosedLoopRecord {
                ref_rad: r.0.unwrap_or(&[]),
                u_v: r.1,
                theta_l_rad: r.2,
            })
            .collect();
        let e = closed_loop(&cl, ts_s, opts)?;
        (e.plant, Some(e.t), e.spectra)
    } else {
        let ol: Vec<OpenLoopRecord> = records
            .iter()
            .map(|r| OpenLoopRecord {
                u_v: r.1,
                theta_l_rad: r.2,
            })
            .collect();
        let (p, sp) = open_loop(&ol, ts_s, opts)?;
        (p, None, sp)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn increments_then_integrator_is_identity_in_frequency() {
        let ts = 1e-3;
        let w = 30.0;
        let d = Complex::new(1.0, 0.0) - c_expj(-w * ts);
        assert!((integrator(w, ts) * d - Complex::new(1.0, 0.0)).norm() < 1e-12);
        assert_eq!(increments(&[1.0, 3.0, 6.0]), [0.0, 2.0, 3.0]);
    }

    #[test]
    fn leakage_allowance_is_the_gap_to_the_half_length_estimate() {
        let frf = |freq_hz: Vec<f64>, h: Vec<Complex<f64>>| Frf {
            coherence: alloc::vec![1.0; h.len()],
            rel_radius: alloc::vec![0.01; h.len()],
            freq_hz,
            h,
            averages: 16.0,
            confidence: 0.95,
        };
        let one = Complex::new(1.0, 0.0);
        let mut full = frf(alloc::vec![1.0, 2.0, 3.0, 4.0], alloc::vec![one; 4]);
        // Half-length bins at 2 and 4 Hz; 3 Hz interpolated between 1.0 and 1.2.
        let half = frf(alloc::vec![2.0, 4.0], alloc::vec![one, one * 1.2]);
        allow_leakage(&mut full, &half);
        assert_eq!(full.rel_radius[0], 0.01); // below the half grid: untouched
        assert!((full.rel_radius[1] - 0.01).abs() < 1e-12);
        assert!((full.rel_radius[2] - 0.11).abs() < 1e-12);
        assert!((full.rel_radius[3] - 0.21).abs() < 1e-12);
    }
}
