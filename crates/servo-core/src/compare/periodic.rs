//! Position-periodic residual: how much of the residual follows sin/cos of a harmonic of the motor
//! angle (e.g. magnetic detents: several cycles per motor revolution) or of the load angle (e.g. an
//! eccentric load: one cycle per load revolution).
//!
//! For every harmonic h the residual is regressed on sin(h theta) and cos(h theta); the share of
//! variance explained (R^2) is tested against chance with the effective number of independent
//! samples of an autocorrelated residual, N_eff = N / (1 + 2 sum r(tau)), and a Bonferroni
//! correction for the number of harmonics searched. A harmonic is only tried when the angle covers
//! at least two of its cycles.

use crate::math;
use alloc::vec::Vec;

/// Which angle the residual follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AngleSource {
    /// Motor angle theta_m = N theta_l (magnetic detents).
    Motor,
    /// Load angle theta_l (an eccentric load).
    Load,
}

impl AngleSource {
    pub fn name(self) -> &'static str {
        match self {
            AngleSource::Motor => "motor",
            AngleSource::Load => "load",
        }
    }
}

/// The best periodic component for one angle source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeriodicFinding {
    pub source: AngleSource,
    /// Cycles per revolution of that angle.
    pub harmonic: u32,
    /// Share of the residual variance explained [%].
    pub share_pct: f64,
    /// Amplitude of the component (unit of the residual).
    pub amplitude: f64,
    /// Phase [rad]: component = amplitude sin(h theta + phase).
    pub phase_rad: f64,
    /// p-value after the correction for the harmonics searched.
    pub p_value: f64,
    /// p < 0.01 and at least 5 % of the variance explained.
    pub significant: bool,
    /// Effective number of independent samples used in the test.
    pub n_eff: f64,
}

/// Effective sample size of an autocorrelated sequence: N / (1 + 2 sum_{tau>=1} r(tau)), the sum
/// stopped where r first drops below 0.05 (at most 1000 lags).
pub fn effective_samples(e: &[f64]) -> f64 {
    let n = e.len();
    if n < 3 {
        return n as f64;
    }
    let m = e.iter().sum::<f64>() / n as f64;
    let c: Vec<f64> = e.iter().map(|v| v - m).collect();
    let c0: f64 = c.iter().map(|v| v * v).sum();
    if c0 <= 0.0 {
        return n as f64;
    }
    let mut tau = 1.0;
    for k in 1..n.min(1000) {
        let r = c[..n - k]
            .iter()
            .zip(&c[k..])
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / c0;
        if r < 0.05 {
            break;
        }
        tau += 2.0 * r;
    }
    (n as f64 / tau).max(1.0)
}

/// Searches harmonics 1..=`max_harmonic` of `theta` [rad] (already the motor or load angle) in
/// residual `e`; returns the best one, or `None` when no harmonic has two cycles of coverage.
pub fn best_harmonic(
    e: &[f64],
    theta: &[f64],
    source: AngleSource,
    max_harmonic: u32,
    n_eff: f64,
) -> Option<PeriodicFinding> {
    let n = e.len().min(theta.len());
    if n < 10 {
        return None;
    }
    let (lo, hi) = theta[..n]
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let span = hi - lo;
    let me = e[..n].iter().sum::<f64>() / n as f64;
    let var: f64 = e[..n].iter().map(|v| (v - me) * (v - me)).sum();
    if !(var > 0.0) {
        return None;
    }
    let tried: Vec<u32> = (1..=max_harmonic)
        .filter(|h| *h as f64 * span >= 2.0 * math::TAU)
        .collect();
    let mut best: Option<PeriodicFinding> = None;
    for &h in &tried {
        // Least squares on centred sin/cos (2x2 normal equations).
        let hf = h as f64;
        let (mut ms, mut mc) = (0.0, 0.0);
        for t in &theta[..n] {
            ms += math::sin(hf * t);
            mc += math::cos(hf * t);
        }
        ms /= n as f64;
        mc /= n as f64;
        let (mut ss, mut cc, mut sc, mut se, mut ce) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (t, ev) in theta[..n].iter().zip(&e[..n]) {
            let s = math::sin(hf * t) - ms;
            let c = math::cos(hf * t) - mc;
            let ev = ev - me;
            ss += s * s;
            cc += c * c;
            sc += s * c;
            se += s * ev;
            ce += c * ev;
        }
        let det = ss * cc - sc * sc;
        if !(det > 1e-12 * ss * cc) {
            continue;
        }
        let a = (cc * se - sc * ce) / det;
        let b = (ss * ce - sc * se) / det;
        let explained = a * se + b * ce;
        let r2 = (explained / var).clamp(0.0, 1.0);
        // Under the null, N_eff R^2 ~ chi^2(2): p = exp(-N_eff R^2 / 2); Bonferroni over the tries.
        let p = (math::exp(-0.5 * n_eff * r2) * tried.len() as f64).min(1.0);
        let f = PeriodicFinding {
            source,
            harmonic: h,
            share_pct: 100.0 * r2,
            amplitude: math::hypot(a, b),
            phase_rad: math::atan2(b, a),
            p_value: p,
            significant: p < 0.01 && r2 >= 0.05,
            n_eff,
        };
        if best.is_none_or(|bf| f.share_pct > bf.share_pct) {
            best = Some(f);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::sensors::SplitMix64;

    #[test]
    fn finds_motor_periodic_component() {
        let mut rng = SplitMix64(11);
        // Motor turns at constant speed through 20 revolutions; residual has 7 cycles per rev.
        let n = 4000;
        let th_m: Vec<f64> = (0..n)
            .map(|k| 20.0 * math::TAU * k as f64 / n as f64)
            .collect();
        let e: Vec<f64> = th_m
            .iter()
            .map(|t| 0.5 * math::sin(7.0 * t + 0.3) + 0.5 * rng.normal())
            .collect();
        let ne = effective_samples(&e);
        let f = best_harmonic(&e, &th_m, AngleSource::Motor, 30, ne).unwrap();
        assert_eq!(f.harmonic, 7);
        assert!(f.significant && f.share_pct > 20.0, "{f:?}");
        assert!(
            (f.amplitude - 0.5).abs() < 0.05 && (f.phase_rad - 0.3).abs() < 0.1,
            "{f:?}"
        );
        // Pure noise: nothing significant.
        let e: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let f = best_harmonic(&e, &th_m, AngleSource::Motor, 30, effective_samples(&e)).unwrap();
        assert!(!f.significant, "{f:?}");
        // Too little travel for any harmonic.
        let short: Vec<f64> = (0..n).map(|k| k as f64 * 1e-4).collect();
        assert!(best_harmonic(&e, &short, AngleSource::Load, 4, 100.0).is_none());
    }
}
