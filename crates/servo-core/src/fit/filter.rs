//! Zero-phase low-pass filtering and differentiation of sampled signals.
//!
//! A second-order Butterworth section is run forward and backward (`filtfilt`), so the result has
//! no phase lag (a fourth-order magnitude response) and every regressor filtered with the same
//! [`ZeroPhase`] keeps the equation it belongs to consistent. Ends are padded by odd reflection, as
//! `scipy.signal.filtfilt` does, to avoid start-up transients.

use crate::math;
use alloc::vec::Vec;

/// A zero-phase second-order Butterworth low-pass filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZeroPhase {
    b: [f64; 3],
    a: [f64; 2],
    /// Reflection padding length [samples].
    pad: usize,
}

impl ZeroPhase {
    /// A filter with cut-off `fc_hz` for samples at `fs_hz` (cut-off clamped below Nyquist).
    pub fn new(fc_hz: f64, fs_hz: f64) -> ZeroPhase {
        let fc = fc_hz.min(0.45 * fs_hz).max(1e-6 * fs_hz);
        let k = math::tan(math::PI * fc / fs_hz);
        let s2 = core::f64::consts::SQRT_2;
        let norm = 1.0 / (1.0 + s2 * k + k * k);
        let b0 = k * k * norm;
        let pad = (3.0 * fs_hz / fc) as usize;
        ZeroPhase {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - s2 * k + k * k) * norm],
            pad,
        }
    }

    fn pass(&self, x: &mut [f64]) {
        if x.is_empty() {
            return;
        }
        // Direct form II transposed, initial state at the steady state of x[0].
        let [b0, b1, b2] = self.b;
        let [a1, a2] = self.a;
        let x0 = x[0];
        let mut z1 = x0 - b0 * x0;
        let mut z2 = b2 * x0 - a2 * x0;
        for v in x.iter_mut() {
            let xi = *v;
            let y = b0 * xi + z1;
            z1 = b1 * xi - a1 * y + z2;
            z2 = b2 * xi - a2 * y;
            *v = y;
        }
    }

    /// Filters `x` forward and backward; returns a signal of the same length.
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        if n < 3 {
            return x.to_vec();
        }
        let pad = self.pad.min(n - 1);
        let mut ext = Vec::with_capacity(n + 2 * pad);
        for i in (1..=pad).rev() {
            ext.push(2.0 * x[0] - x[i]);
        }
        ext.extend_from_slice(x);
        for i in 1..=pad {
            ext.push(2.0 * x[n - 1] - x[n - 1 - i]);
        }
        self.pass(&mut ext);
        ext.reverse();
        self.pass(&mut ext);
        ext.reverse();
        ext[pad..pad + n].to_vec()
    }
}

/// Central-difference derivative of `x` sampled every `dt_s` (one-sided at the ends).
pub fn derivative(x: &[f64], dt_s: f64) -> Vec<f64> {
    let n = x.len();
    let mut d = alloc::vec![0.0; n];
    if n < 2 {
        return d;
    }
    d[0] = (x[1] - x[0]) / dt_s;
    d[n - 1] = (x[n - 1] - x[n - 2]) / dt_s;
    for k in 1..n - 1 {
        d[k] = (x[k + 1] - x[k - 1]) / (2.0 * dt_s);
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_low_frequencies_without_phase_and_kills_high_ones() {
        let fs = 1000.0;
        let f = ZeroPhase::new(25.0, fs);
        let n = 4000;
        let slow: Vec<f64> = (0..n)
            .map(|k| math::sin(math::TAU * 2.0 * k as f64 / fs))
            .collect();
        let fast: Vec<f64> = (0..n)
            .map(|k| math::sin(math::TAU * 200.0 * k as f64 / fs))
            .collect();
        let ys = f.apply(&slow);
        let yf = f.apply(&fast);
        for k in 500..3500 {
            assert!(
                (ys[k] - slow[k]).abs() < 2e-3,
                "k={k}: {} vs {}",
                ys[k],
                slow[k]
            );
            assert!(yf[k].abs() < 1e-3);
        }
        // A ramp is preserved up to the ends thanks to the odd reflection.
        let ramp: Vec<f64> = (0..n).map(|k| 3.0 * k as f64 / fs).collect();
        let yr = f.apply(&ramp);
        assert!(yr.iter().zip(&ramp).all(|(a, b)| (a - b).abs() < 1e-6));
        let d = derivative(&yr, 1.0 / fs);
        assert!(d.iter().all(|v| (v - 3.0).abs() < 1e-3));
    }
}
