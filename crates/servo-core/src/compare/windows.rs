//! The worst time windows: where in the log the squared error piles up, ranked.

use super::regimes::{Classification, Regime};
use alloc::vec::Vec;

/// One window of the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// First and last sample index (inclusive).
    pub start: usize,
    pub end: usize,
    /// Start and end time [s].
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Share of the total squared error [%].
    pub error_share_pct: f64,
    /// RMS residual in the window.
    pub rms: f64,
    /// Mean residual (measurement minus model).
    pub mean: f64,
    /// The regime that carries most of the window's squared error.
    pub regime: Regime,
    /// Smallest and largest measured load speed in the window [rad/s].
    pub omega_min_rad_s: f64,
    pub omega_max_rad_s: f64,
    /// Largest |u| in the window [V].
    pub u_abs_max_v: f64,
}

/// The `count` worst non-overlapping windows of `len` samples, worst first.
pub fn worst_windows(
    residual: &[f64],
    time_s: &[f64],
    omega_l: &[f64],
    u: &[f64],
    c: &Classification,
    len: usize,
    count: usize,
) -> Vec<Window> {
    let n = residual
        .len()
        .min(time_s.len())
        .min(omega_l.len())
        .min(u.len())
        .min(c.regime.len());
    let len = len.clamp(1, n.max(1));
    if n == 0 {
        return Vec::new();
    }
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    for e in &residual[..n] {
        let last = *prefix.last().unwrap_or(&0.0);
        prefix.push(last + e * e);
    }
    let total = prefix[n];
    if !(total > 0.0) {
        return Vec::new();
    }
    let mut taken = alloc::vec![false; n];
    let mut out = Vec::new();
    while out.len() < count {
        let mut best: Option<(usize, f64)> = None;
        let mut s = 0;
        while s + len <= n {
            if taken[s] || taken[s + len - 1] {
                s += 1;
                continue;
            }
            let v = prefix[s + len] - prefix[s];
            if best.is_none_or(|(_, b)| v > b) {
                best = Some((s, v));
            }
            s += 1;
        }
        let Some((s, v)) = best else { break };
        if !(v > 0.0) || taken[s..s + len].iter().any(|t| *t) {
            // Only partial gaps left between taken windows.
            break;
        }
        for t in &mut taken[s..s + len] {
            *t = true;
        }
        let e = s + len - 1;
        let mut per = [0.0f64; 5];
        let mut sum = 0.0;
        for k in s..=e {
            per[Regime::ALL
                .iter()
                .position(|r| *r == c.regime[k])
                .unwrap_or(4)] += residual[k] * residual[k];
            sum += residual[k];
        }
        let ri = (0..5).fold(0, |b, i| if per[i] > per[b] { i } else { b });
        let (wmin, wmax) = omega_l[s..=e]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), w| {
                (a.min(*w), b.max(*w))
            });
        out.push(Window {
            start: s,
            end: e,
            t_start_s: time_s[s],
            t_end_s: time_s[e],
            error_share_pct: 100.0 * v / total,
            rms: crate::math::sqrt(v / len as f64),
            mean: sum / len as f64,
            regime: Regime::ALL[ri],
            omega_min_rad_s: wmin,
            omega_max_rad_s: wmax,
            u_abs_max_v: u[s..=e].iter().fold(0.0f64, |m, x| m.max(libm::fabs(*x))),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::regimes::{classify, RegimeOptions};
    use super::*;

    #[test]
    fn ranks_bursts_by_energy() {
        let n = 2000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let w = alloc::vec![5.0; n];
        let u = alloc::vec![1.0; n];
        let c = classify(&w, &u, None, 1e-3, &RegimeOptions::default());
        let mut e = alloc::vec![0.0; n];
        for v in &mut e[300..350] {
            *v = 1.0;
        }
        for v in &mut e[1500..1550] {
            *v = -2.0;
        }
        let ws = worst_windows(&e, &t, &w, &u, &c, 100, 3);
        assert_eq!(ws.len(), 2);
        assert!(ws[0].start <= 1500 && ws[0].end >= 1549);
        assert!((ws[0].error_share_pct - 80.0).abs() < 1e-9);
        assert!(ws[1].start <= 300 && ws[1].end >= 349);
        assert!(ws[0].mean < 0.0);
    }
}
