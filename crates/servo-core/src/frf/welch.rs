//! Welch-averaged auto- and cross-spectra of one input against several outputs, pooled over
//! several records, and the H1 estimate with its coherence and confidence bounds.
//!
//! * Window: periodic Hann, `overlap` (default 50 %) between segments, mean removed per segment.
//! * H1 = G_xy / G_xx (Bendat & Piersol, *Random Data*, 4th ed., eq. 9.53): unbiased by noise on
//!   the output; coherence gamma^2 = |G_xy|^2 / (G_xx G_yy).
//! * Confidence: the (1 - alpha) region of H is the circle of radius r around the estimate,
//!   r^2 = 2/(n - 2) F_{2, n-2; alpha} (1 - gamma^2)/gamma^2 |H|^2 with n = 2 n_d
//!   (B&P eq. 9.90), n_d the number of independent averages. Overlapping Hann segments are not
//!   independent: n_d is Welch's equivalent count n_seg / (1 + 2 sum_k (1 - k/n_seg) rho_k) with
//!   rho_k the squared normalised overlap correlation of the window at shift k D.
//!   F_{2,m;alpha} = m/2 (alpha^{-2/m} - 1) in closed form.

use super::{Frf, FrfError};
use crate::design::Complex;
use crate::math;
use alloc::vec::Vec;
use realfft::RealFftPlanner;

/// How the spectra are averaged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WelchOptions {
    /// Segment length [samples]; `None`: the largest power of two giving at least ~16 averages
    /// (8 disjoint segments) over the data, within 256..=65536.
    pub segment_len: Option<usize>,
    /// Fraction of a segment shared with the next, in [0, 0.9].
    pub overlap: f64,
    /// Confidence level of the bounds, in (0, 1) (default 0.95).
    pub confidence: f64,
}

impl Default for WelchOptions {
    fn default() -> Self {
        WelchOptions {
            segment_len: None,
            overlap: 0.5,
            confidence: 0.95,
        }
    }
}

impl WelchOptions {
    /// The segment length for `total` samples split over records of at most `longest` samples.
    pub fn segment_for(&self, total: usize, longest: usize) -> usize {
        match self.segment_len {
            Some(n) => n,
            None => {
                let target = (total / 8).min(longest).max(16);
                let mut n = 256usize;
                while n * 2 <= target && n < 65536 {
                    n *= 2;
                }
                n.min(longest.max(16))
            }
        }
    }
}

/// One record: the input and the outputs sampled together (equal lengths).
#[derive(Debug, Clone)]
pub struct Channels<'a> {
    pub input: &'a [f64],
    pub outputs: Vec<&'a [f64]>,
}

/// Averaged one-sided spectra (unnormalised: only ratios are used).
#[derive(Debug, Clone, PartialEq)]
pub struct CrossSpectra {
    /// Bin frequencies [Hz], bins 1..N/2 (DC dropped).
    pub freq_hz: Vec<f64>,
    /// G_xx per bin.
    pub gxx: Vec<f64>,
    /// G_yy per output and bin.
    pub gyy: Vec<Vec<f64>>,
    /// G_xy = E[X* Y] per output and bin.
    pub gxy: Vec<Vec<Complex<f64>>>,
    /// Segments averaged.
    pub segments: usize,
    /// Equivalent number of independent averages n_d.
    pub averages: f64,
    /// Segment length [samples].
    pub segment_len: usize,
    /// Window: always "hann".
    pub window: &'static str,
    /// Overlap fraction used.
    pub overlap: f64,
}

/// Periodic Hann window of length n.
pub fn hann(n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| 0.5 - 0.5 * math::cos(math::TAU * k as f64 / n as f64))
        .collect()
}

/// Upper alpha point of the F distribution with (2, m) degrees of freedom.
pub fn f_2_m(m: f64, alpha: f64) -> f64 {
    0.5 * m * (math::pow(alpha, -2.0 / m) - 1.0)
}

/// Relative radius r/|H| of the confidence circle of an H1 estimate with coherence `gamma2` from
/// `averages` independent averages at `confidence` (B&P eq. 9.90); infinite when undetermined.
pub fn relative_radius(gamma2: f64, averages: f64, confidence: f64) -> f64 {
    let n = 2.0 * averages;
    if n.is_nan() || n <= 2.0 || gamma2.is_nan() || gamma2 <= 0.0 {
        return f64::INFINITY;
    }
    let g = gamma2.min(1.0);
    math::sqrt(2.0 / (n - 2.0) * f_2_m(n - 2.0, 1.0 - confidence) * (1.0 - g) / g)
}

/// Averages the spectra of `records` sampled every `dt_s` [s].
pub fn cross_spectra(
    records: &[Channels],
    dt_s: f64,
    opts: &WelchOptions,
) -> Result<CrossSpectra, FrfError> {
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(FrfError::Invalid(
            "the sample period must be finite and > 0",
        ));
    }
    if !(0.0..=0.9).contains(&opts.overlap) {
        return Err(FrfError::Invalid("the overlap must be between 0 and 0.9"));
    }
    if !(opts.confidence > 0.0 && opts.confidence < 1.0) {
        return Err(FrfError::Invalid("the confidence level must be in (0, 1)"));
    }
    let n_out = records.first().map_or(0, |r| r.outputs.len());
    if n_out == 0 || records.iter().any(|r| r.outputs.len() != n_out) {
        return Err(FrfError::Invalid(
            "every record needs the same outputs (at least one)",
        ));
    }
    for r in records {
        if r.outputs.iter().any(|o| o.len() != r.input.len()) {
            return Err(FrfError::Invalid(
                "input and outputs of a record must have equal lengths",
            ));
        }
        if r.input
            .iter()
            .chain(r.outputs.iter().flat_map(|o| o.iter()))
            .any(|v| !v.is_finite())
        {
            return Err(FrfError::Invalid(
                "a signal has a non-finite sample (NaN or infinity)",
            ));
        }
    }
    let total: usize = records.iter().map(|r| r.input.len()).sum();
    let longest = records.iter().map(|r| r.input.len()).max().unwrap_or(0);
    let n = opts.segment_for(total, longest);
    if n < 16 || longest < n {
        return Err(FrfError::TooShort {
            samples: longest,
            needed: n.max(16),
        });
    }
    let hop = ((n as f64 * (1.0 - opts.overlap)).round() as usize).clamp(1, n);
    let w = hann(n);
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let bins = n / 2;
    let mut gxx = alloc::vec![0.0; bins + 1];
    let mut gyy = alloc::vec![alloc::vec![0.0; bins + 1]; n_out];
    let mut gxy = alloc::vec![alloc::vec![Complex::new(0.0, 0.0); bins + 1]; n_out];
    let mut buf = fft.make_input_vec();
    let mut xs = fft.make_output_vec();
    let mut ys = fft.make_output_vec();
    let mut scratch = fft.make_scratch_vec();
    let mut segments = 0usize;
    let mut per_record = Vec::new();
    let mut transform = |sig: &[f64], out: &mut Vec<Complex<f64>>, buf: &mut Vec<f64>| {
        let mean = sig.iter().sum::<f64>() / sig.len() as f64;
        for ((b, s), wk) in buf.iter_mut().zip(sig).zip(&w) {
            *b = (s - mean) * wk;
        }
        // Lengths match the plan by construction; an error here would be a bug in this loop.
        fft.process_with_scratch(buf, out, &mut scratch)
            .map_err(|_| FrfError::Invalid("internal FFT length mismatch"))
    };
    for r in records {
        let len = r.input.len();
        if len < n {
            continue;
        }
        let mut count = 0;
        let mut start = 0;
        while start + n <= len {
            transform(&r.input[start..start + n], &mut xs, &mut buf)?;
            for (k, x) in xs.iter().enumerate() {
                gxx[k] += x.norm_sqr();
            }
            for (j, o) in r.outputs.iter().enumerate() {
                transform(&o[start..start + n], &mut ys, &mut buf)?;
                for k in 0..=bins {
                    gyy[j][k] += ys[k].norm_sqr();
                    gxy[j][k] += xs[k].conj() * ys[k];
                }
            }
            count += 1;
            start += hop;
        }
        segments += count;
        per_record.push(count);
    }
    let averages = per_record
        .iter()
        .map(|&c| equivalent_averages(&w, hop, c))
        .sum::<f64>();
    let df = 1.0 / (n as f64 * dt_s);
    Ok(CrossSpectra {
        freq_hz: (1..=bins).map(|k| k as f64 * df).collect(),
        gxx: gxx[1..].to_vec(),
        gyy: gyy.into_iter().map(|g| g[1..].to_vec()).collect(),
        gxy: gxy.into_iter().map(|g| g[1..].to_vec()).collect(),
        segments,
        averages,
        segment_len: n,
        window: "hann",
        overlap: 1.0 - hop as f64 / n as f64,
    })
}

/// Welch's equivalent number of independent averages of `count` segments of window `w` hopping
/// by `hop` samples.
fn equivalent_averages(w: &[f64], hop: usize, count: usize) -> f64 {
    if count == 0 {
        return 0.0;
    }
    let e: f64 = w.iter().map(|v| v * v).sum();
    let mut denom = 1.0;
    let mut k = 1;
    while k < count && k * hop < w.len() {
        let s: f64 = w[k * hop..].iter().zip(w).map(|(a, b)| a * b).sum::<f64>();
        let rho = (s / e) * (s / e);
        denom += 2.0 * (1.0 - k as f64 / count as f64) * rho;
        k += 1;
    }
    count as f64 / denom
}

impl CrossSpectra {
    /// H1 estimate of output `j`, with coherence and bounds at `confidence`.
    pub fn h1(&self, j: usize, confidence: f64) -> Frf {
        let (gyy, gxy) = (&self.gyy[j], &self.gxy[j]);
        let mut h = Vec::with_capacity(self.gxx.len());
        let mut coherence = Vec::with_capacity(self.gxx.len());
        let mut rel = Vec::with_capacity(self.gxx.len());
        for k in 0..self.gxx.len() {
            let (xx, yy, xy) = (self.gxx[k], gyy[k], gxy[k]);
            let ok = xx > 0.0 && yy > 0.0;
            let g2 = if ok {
                (xy.norm_sqr() / (xx * yy)).min(1.0)
            } else {
                0.0
            };
            h.push(if xx > 0.0 {
                xy / xx
            } else {
                Complex::new(f64::NAN, f64::NAN)
            });
            coherence.push(g2);
            rel.push(relative_radius(g2, self.averages, confidence));
        }
        // Resolution bias: the window smooths H over about one bin each side; allow for the
        // local curvature |H[k-1] - 2 H[k] + H[k+1]| / 2 on top of the random error.
        for k in 1..h.len().saturating_sub(1) {
            let curv = (h[k - 1] - h[k] * 2.0 + h[k + 1]).norm() / 2.0;
            let m = h[k].norm();
            if m > 0.0 && curv.is_finite() {
                rel[k] += curv / m;
            }
        }
        Frf {
            freq_hz: self.freq_hz.clone(),
            h,
            coherence,
            rel_radius: rel,
            averages: self.averages,
            confidence,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f_quantile_matches_tables() {
        // F_{2,10;0.05} = 4.10, F_{2,30;0.05} = 3.32 (standard tables)
        assert!((f_2_m(10.0, 0.05) - 4.10).abs() < 0.01);
        assert!((f_2_m(30.0, 0.05) - 3.32).abs() < 0.01);
    }

    #[test]
    fn disjoint_segments_are_independent_and_half_overlap_hann_nearly() {
        let w = hann(256);
        assert!((equivalent_averages(&w, 256, 10) - 10.0).abs() < 1e-12);
        let e = equivalent_averages(&w, 128, 19);
        // rho(N/2) for Hann = (1/6 / (3/8))^2 ... = 0.1975? no: (sum w w_shift / sum w^2)^2
        assert!(e > 15.0 && e < 19.0, "{e}");
    }

    #[test]
    fn h1_recovers_a_fir_filter_with_unit_coherence() {
        // y[k] = 0.5 x[k] + 0.25 x[k-1]: H = 0.5 + 0.25 e^{-j w T}
        let mut s = 12345u64;
        let x: Vec<f64> = (0..20000)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        let y: Vec<f64> = (0..x.len())
            .map(|k| 0.5 * x[k] + if k > 0 { 0.25 * x[k - 1] } else { 0.0 })
            .collect();
        let sp = cross_spectra(
            &[Channels {
                input: &x,
                outputs: alloc::vec![&y],
            }],
            1e-3,
            &WelchOptions::default(),
        )
        .unwrap();
        let est = sp.h1(0, 0.95);
        for (i, f) in est.freq_hz.iter().enumerate().step_by(37) {
            let wt = math::TAU * f * 1e-3;
            let truth = Complex::new(0.5 + 0.25 * math::cos(wt), -0.25 * math::sin(wt));
            assert!(
                (est.h[i] - truth).norm() < 2e-3,
                "{f}: {} vs {truth}",
                est.h[i]
            );
            assert!(est.coherence[i] > 0.999);
        }
    }
}
