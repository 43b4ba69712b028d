//! Residual analysis as MATLAB's `resid`: autocorrelation of the residual with 99 % bounds, the
//! Ljung-Box portmanteau test, and the residual-input cross-correlation.
//!
//! A residual that is white and uncorrelated with past inputs means the model has extracted all
//! the information in the data; a correlated residual means dynamics are missing.

use super::chi2::chi2_sf;
use crate::math;
use alloc::vec::Vec;

/// Two-sided 99 % quantile of the standard normal distribution.
pub const Z99: f64 = 2.575_829_303_548_901;

/// Whiteness of a residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Whiteness {
    /// Normalised autocorrelation r(tau), tau = 0..=max_lag (r(0) = 1).
    pub autocorr: Vec<f64>,
    /// 99 % confidence bound for |r(tau)| of a white sequence, 2.576 / sqrt(N).
    pub bound99: f64,
    /// Lags tau >= 1 with |r(tau)| above the bound.
    pub lags_outside: usize,
    /// Ljung-Box statistic Q = N (N + 2) sum_{tau=1}^{m} r(tau)^2 / (N - tau).
    pub ljung_box_q: f64,
    /// Degrees of freedom of Q (the number of lags m).
    pub ljung_box_dof: usize,
    /// P(chi^2(m) > Q): small (< 0.01) rejects whiteness.
    pub ljung_box_p: f64,
    /// Lag (samples) where r(tau) first falls below 1/e, or max_lag + 1 if it never does: the
    /// correlation length of the residual.
    pub correlation_lags: usize,
    /// True when Ljung-Box does not reject whiteness at the 1 % level.
    pub white: bool,
}

/// Residual-input cross-correlation.
#[derive(Debug, Clone, PartialEq)]
pub struct CrossCorrelation {
    /// r_eu(tau) for tau = -max_lag..=max_lag (index tau + max_lag): correlation of e(t + tau)
    /// with u(t). Positive lags: the residual depends on past inputs (missing dynamics).
    pub xcorr: Vec<f64>,
    /// Largest number of lags on each side.
    pub max_lag: usize,
    /// 99 % bound, corrected for the autocorrelations of e and u (Bartlett).
    pub bound99: f64,
    /// Lags with |r_eu| above the bound.
    pub lags_outside: usize,
    /// The lag with the largest |r_eu| and its value.
    pub peak_lag: i64,
    pub peak: f64,
}

fn centred(x: &[f64]) -> Vec<f64> {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    x.iter().map(|v| v - m).collect()
}

/// Normalised autocorrelation r(0..=max_lag) (biased estimator, as `resid`).
pub fn autocorrelation(e: &[f64], max_lag: usize) -> Vec<f64> {
    let n = e.len();
    let c = centred(e);
    let c0: f64 = c.iter().map(|v| v * v).sum();
    (0..=max_lag)
        .map(|k| {
            if k >= n || c0 <= 0.0 {
                return if k == 0 { 1.0 } else { 0.0 };
            }
            c[..n - k]
                .iter()
                .zip(&c[k..])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / c0
        })
        .collect()
}

/// Whiteness test of residual `e` with `max_lag` lags (MATLAB's default is 25).
pub fn whiteness(e: &[f64], max_lag: usize) -> Whiteness {
    let n = e.len();
    let m = max_lag.min(n.saturating_sub(2)).max(1);
    let r = autocorrelation(e, m);
    let bound99 = Z99 / math::sqrt(n.max(1) as f64);
    let lags_outside = r[1..].iter().filter(|v| libm::fabs(**v) > bound99).count();
    let nf = n as f64;
    let q = nf * (nf + 2.0) * (1..=m).map(|k| r[k] * r[k] / (nf - k as f64)).sum::<f64>();
    let p = chi2_sf(q, m as f64);
    let correlation_lags = r
        .iter()
        .position(|v| *v < 1.0 / core::f64::consts::E)
        .unwrap_or(m + 1);
    Whiteness {
        autocorr: r,
        bound99,
        lags_outside,
        ljung_box_q: q,
        ljung_box_dof: m,
        ljung_box_p: p,
        correlation_lags,
        white: p >= 0.01,
    }
}

#[allow(clippy::needless_range_loop)]
/// Cross-correlation of residual `e` with input `u`, lags -max_lag..=max_lag.
pub fn cross_correlation(e: &[f64], u: &[f64], max_lag: usize) -> CrossCorrelation {
    let n = e.len().min(u.len());
    let m = max_lag.min(n.saturating_sub(2)).max(1);
    let (ce, cu) = (centred(&e[..n]), centred(&u[..n]));
    let see: f64 = ce.iter().map(|v| v * v).sum();
    let suu: f64 = cu.iter().map(|v| v * v).sum();
    let norm = math::sqrt(see * suu);
    let mut xcorr = Vec::with_capacity(2 * m + 1);
    for lag in -(m as i64)..=(m as i64) {
        let mut s = 0.0;
        for t in 0..n {
            let te = t as i64 + lag;
            if te >= 0 && (te as usize) < n {
                s += ce[te as usize] * cu[t];
            }
        }
        xcorr.push(if norm > 0.0 { s / norm } else { 0.0 });
    }
    let (re, ru) = (autocorrelation(&e[..n], m), autocorrelation(&u[..n], m));
    let var: f64 = 1.0 + 2.0 * (1..=m).map(|k| re[k] * ru[k]).sum::<f64>();
    let bound99 = Z99 * math::sqrt(var.max(1.0) / n.max(1) as f64);
    let lags_outside = xcorr.iter().filter(|v| libm::fabs(**v) > bound99).count();
    let (mut peak_lag, mut peak) = (0i64, 0.0f64);
    for (i, v) in xcorr.iter().enumerate() {
        if libm::fabs(*v) > libm::fabs(peak) {
            peak = *v;
            peak_lag = i as i64 - m as i64;
        }
    }
    CrossCorrelation {
        xcorr,
        max_lag: m,
        bound99,
        lags_outside,
        peak_lag,
        peak,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::sensors::SplitMix64;

    #[test]
    fn ljung_box_by_hand() {
        // e = [1, -1, 1, -1, 1, -1]: mean 0, r(1) = -5/6, r(2) = 4/6.
        // Q(2) = 6 * 8 * ((25/36)/5 + (16/36)/4) = 48 * (0.138889 + 0.111111) = 12.0
        let w = whiteness(&[1.0, -1.0, 1.0, -1.0, 1.0, -1.0], 2);
        assert!((w.autocorr[1] + 5.0 / 6.0).abs() < 1e-12);
        assert!((w.autocorr[2] - 4.0 / 6.0).abs() < 1e-12);
        assert!((w.ljung_box_q - 12.0).abs() < 1e-9, "{}", w.ljung_box_q);
        // P(chi2(2) > 12) = exp(-6)
        assert!((w.ljung_box_p - (-6.0f64).exp()).abs() < 1e-12);
    }

    #[test]
    fn white_noise_passes_and_filtered_noise_fails() {
        let mut rng = SplitMix64(7);
        let e: Vec<f64> = (0..5000).map(|_| rng.normal()).collect();
        let w = whiteness(&e, 25);
        assert!(w.white, "p = {}", w.ljung_box_p);
        assert!(w.lags_outside <= 2);
        let mut f = e.clone();
        for i in 1..f.len() {
            f[i] = 0.9 * f[i - 1] + e[i];
        }
        let w = whiteness(&f, 25);
        assert!(!w.white && w.ljung_box_p < 1e-10);
        assert!(w.correlation_lags >= 5, "{}", w.correlation_lags);
    }

    #[test]
    fn cross_correlation_finds_the_delay() {
        let mut rng = SplitMix64(3);
        let u: Vec<f64> = (0..4000).map(|_| rng.normal()).collect();
        // e(t) = u(t - 3) + noise: peak at lag +3.
        let e: Vec<f64> = (0..4000)
            .map(|t| if t >= 3 { u[t - 3] } else { 0.0 } + 0.5 * rng.normal())
            .collect();
        let x = cross_correlation(&e, &u, 10);
        assert_eq!(x.peak_lag, 3);
        assert!(x.peak > 0.8 && x.lags_outside >= 1);
        let white: Vec<f64> = (0..4000).map(|_| rng.normal()).collect();
        let x = cross_correlation(&white, &u, 10);
        assert!(x.lags_outside <= 1, "{}", x.lags_outside);
    }
}
