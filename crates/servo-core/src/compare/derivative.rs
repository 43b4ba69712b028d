//! Speed and acceleration from sampled position: a zero-phase low-pass (second-order Butterworth
//! run forwards and backwards, so no lag) followed by central differences.
//!
//! compare passes the model's position through the same filter whenever the measured speed is
//! derived from position, so both sides of the comparison see the same filtering.

use crate::math;
use alloc::vec::Vec;

/// Second-order Butterworth low-pass (bilinear transform with pre-warping), cut-off `fc_hz`.
#[derive(Debug, Clone, Copy)]
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

impl Biquad {
    fn butterworth(fc_hz: f64, dt_s: f64) -> Biquad {
        let k = math::tan(math::PI * fc_hz * dt_s);
        let s2 = core::f64::consts::SQRT_2;
        let norm = 1.0 / (1.0 + s2 * k + k * k);
        let b0 = k * k * norm;
        Biquad {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - s2 * k + k * k) * norm],
        }
    }

    /// Filters `x` in place, starting from the steady state of its first sample.
    fn run(&self, x: &mut [f64]) {
        let Some(&x0) = x.first() else { return };
        // Direct form II transposed, initial state for a constant input x0 (unit DC gain).
        let [b0, b1, b2] = self.b;
        let [a1, a2] = self.a;
        let mut z1 = x0 - b0 * x0;
        let mut z2 = b2 * x0 - a2 * x0;
        for v in x.iter_mut() {
            let xin = *v;
            let y = b0 * xin + z1;
            z1 = b1 * xin - a1 * y + z2;
            z2 = b2 * xin - a2 * y;
            *v = y;
        }
    }
}

/// Zero-phase low-pass of `x` (forward-backward Butterworth, cut-off `fc_hz`, sample period
/// `dt_s`), with odd reflection at both ends to avoid edge transients. `fc_hz` is clamped below
/// 0.45 of the sample rate; a non-positive `fc_hz` returns `x` unchanged.
pub fn lowpass_zero_phase(x: &[f64], dt_s: f64, fc_hz: f64) -> Vec<f64> {
    let n = x.len();
    if n < 3 || !(fc_hz > 0.0) || !(dt_s > 0.0) {
        return x.to_vec();
    }
    let fc = fc_hz.min(0.45 / dt_s);
    let f = Biquad::butterworth(fc, dt_s);
    let pad = ((3.0 / (fc * dt_s)) as usize).clamp(3, n - 1);
    let mut buf = Vec::with_capacity(n + 2 * pad);
    for i in (1..=pad).rev() {
        buf.push(2.0 * x[0] - x[i]);
    }
    buf.extend_from_slice(x);
    for i in 1..=pad {
        buf.push(2.0 * x[n - 1] - x[n - 1 - i]);
    }
    f.run(&mut buf);
    buf.reverse();
    f.run(&mut buf);
    buf.reverse();
    buf[pad..pad + n].to_vec()
}

/// Central differences of `x` with sample period `dt_s` (one-sided at the ends).
pub fn derivative(x: &[f64], dt_s: f64) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return alloc::vec![0.0; n];
    }
    (0..n)
        .map(|i| {
            if i == 0 {
                (x[1] - x[0]) / dt_s
            } else if i == n - 1 {
                (x[n - 1] - x[n - 2]) / dt_s
            } else {
                (x[i + 1] - x[i - 1]) / (2.0 * dt_s)
            }
        })
        .collect()
}

/// Speed from position: zero-phase low-pass at `fc_hz`, then central differences.
pub fn speed_from_position(theta: &[f64], dt_s: f64, fc_hz: f64) -> Vec<f64> {
    derivative(&lowpass_zero_phase(theta, dt_s, fc_hz), dt_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn ramp_and_sine_speed() {
        let dt = 1e-3;
        let ramp: Vec<f64> = (0..1000).map(|i| 2.0 * i as f64 * dt).collect();
        let w = speed_from_position(&ramp, dt, 30.0);
        assert!(w.iter().all(|v| (v - 2.0).abs() < 1e-5), "{:?}", &w[..5]);
        // A 2 Hz sine well below the cut-off keeps amplitude and phase.
        let f = 2.0;
        let th: Vec<f64> = (0..3000)
            .map(|i| (math::TAU * f * i as f64 * dt).sin())
            .collect();
        let w = speed_from_position(&th, dt, 30.0);
        for i in 500..2500 {
            let exact = math::TAU * f * (math::TAU * f * i as f64 * dt).cos();
            assert!(
                (w[i] - exact).abs() < 0.02 * math::TAU * f,
                "{i}: {} vs {exact}",
                w[i]
            );
        }
    }

    #[test]
    fn lowpass_removes_high_frequency() {
        let dt = 1e-3;
        let x: Vec<f64> = (0..2000)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let y = lowpass_zero_phase(&x, dt, 20.0);
        assert!(y[100..1900].iter().all(|v| v.abs() < 1e-3));
    }
}
