//! Zero-phase low-pass filtering (forward-backward 2nd-order Butterworth, like MATLAB's and
//! SciPy's `filtfilt`) and filtered differentiation.
//!
//! Forward-backward filtering squares the magnitude response (-6 dB at the cut-off, 4th-order
//! roll-off) and has zero phase, so filtered speed, acceleration and torque stay aligned in time.
//! The ends are padded with an odd reflection and the filter starts in its steady state, which
//! removes the start-up transients.

use alloc::vec::Vec;

use super::IdentError;
use crate::math;

/// A 2nd-order Butterworth low-pass biquad (bilinear transform with pre-warping).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Butter2 {
    b: [f64; 3],
    a: [f64; 2],
}

impl Butter2 {
    /// Low-pass with cut-off `cutoff_hz` for sample period `dt_s`; the cut-off must lie below
    /// the Nyquist frequency.
    pub fn lowpass(cutoff_hz: f64, dt_s: f64) -> Result<Butter2, IdentError> {
        let nyquist = 0.5 / dt_s;
        if !(cutoff_hz > 0.0 && cutoff_hz < 0.95 * nyquist && dt_s > 0.0) {
            return Err(IdentError::BadConfig(alloc::format!(
                "filter cut-off {cutoff_hz} Hz must be > 0 and below 0.95 x the Nyquist frequency {nyquist} Hz"
            )));
        }
        let k = math::tan(math::PI * cutoff_hz * dt_s);
        let q = core::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + k / q + k * k);
        let b0 = k * k * norm;
        Ok(Butter2 {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm],
        })
    }

    fn run(&self, x: &mut [f64]) {
        if x.is_empty() {
            return;
        }
        let [b0, b1, b2] = self.b;
        let [a1, a2] = self.a;
        // Steady state for a constant input x[0] (direct form II transposed).
        let x0 = x[0];
        let mut z2 = (b2 - a2) * x0;
        let mut z1 = (b1 - a1) * x0 + z2;
        for v in x.iter_mut() {
            let xin = *v;
            let y = b0 * xin + z1;
            z1 = b1 * xin - a1 * y + z2;
            z2 = b2 * xin - a2 * y;
            *v = y;
        }
    }

    /// Zero-phase (forward-backward) filtering of `x`.
    pub fn filtfilt(&self, x: &[f64], pad: usize) -> Vec<f64> {
        let n = x.len();
        if n < 2 {
            return x.to_vec();
        }
        let pad = pad.min(n - 1);
        let mut buf = Vec::with_capacity(n + 2 * pad);
        // Odd reflection about the end points keeps value and slope continuous.
        for k in (1..=pad).rev() {
            buf.push(2.0 * x[0] - x[k]);
        }
        buf.extend_from_slice(x);
        for k in 1..=pad {
            buf.push(2.0 * x[n - 1] - x[n - 1 - k]);
        }
        self.run(&mut buf);
        buf.reverse();
        self.run(&mut buf);
        buf.reverse();
        buf[pad..pad + n].to_vec()
    }
}

/// Zero-phase low-pass of `x` sampled every `dt_s`, padding three time constants of the cut-off.
pub fn lowpass_zero_phase(x: &[f64], dt_s: f64, cutoff_hz: f64) -> Result<Vec<f64>, IdentError> {
    let f = Butter2::lowpass(cutoff_hz, dt_s)?;
    let pad = (3.0 / (cutoff_hz * dt_s)) as usize + 3;
    Ok(f.filtfilt(x, pad))
}

/// Centred moving average over `half` samples each side (shrinking at the ends). O(n).
pub fn moving_average(x: &[f64], half: usize) -> Vec<f64> {
    let n = x.len();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    let mut s = 0.0;
    for v in x {
        s += v;
        prefix.push(s);
    }
    (0..n)
        .map(|k| {
            let lo = k.saturating_sub(half);
            let hi = (k + half + 1).min(n);
            (prefix[hi] - prefix[lo]) / (hi - lo) as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_dc_and_slow_sines_without_delay() {
        let dt = 1e-3;
        let x: Vec<f64> = (0..5000)
            .map(|k| 2.0 + math::sin(math::TAU * 1.0 * k as f64 * dt))
            .collect();
        let y = lowpass_zero_phase(&x, dt, 20.0).unwrap();
        // A 1 Hz sine through a 20 Hz zero-phase filter: same amplitude, no lag.
        for k in 500..4500 {
            assert!((y[k] - x[k]).abs() < 2e-3, "k {k}: {} vs {}", y[k], x[k]);
        }
    }

    #[test]
    fn attenuates_fast_sines() {
        let dt = 1e-3;
        let x: Vec<f64> = (0..5000)
            .map(|k| math::sin(math::TAU * 200.0 * k as f64 * dt))
            .collect();
        let y = lowpass_zero_phase(&x, dt, 10.0).unwrap();
        let rms = (y[500..4500].iter().map(|v| v * v).sum::<f64>() / 4000.0).sqrt();
        // |H|^2 at 20x the cut-off of a 2nd-order Butterworth is 1/(1+20^4) ~ 6e-6.
        assert!(rms < 1e-4, "{rms}");
    }

    #[test]
    fn cutoff_is_minus_6db_after_forward_backward() {
        let dt = 1e-3;
        let f = 10.0;
        let x: Vec<f64> = (0..20000)
            .map(|k| math::sin(math::TAU * f * k as f64 * dt))
            .collect();
        let y = lowpass_zero_phase(&x, dt, f).unwrap();
        let amp = (y[5000..15000].iter().map(|v| v * v).sum::<f64>() / 10000.0 * 2.0).sqrt();
        assert!((amp - 0.5).abs() < 0.01, "{amp}");
    }

    #[test]
    fn refuses_cutoff_above_nyquist() {
        assert!(lowpass_zero_phase(&[0.0; 10], 1e-3, 600.0).is_err());
        assert!(lowpass_zero_phase(&[0.0; 10], 1e-3, -1.0).is_err());
    }

    #[test]
    fn moving_average_of_ramp_is_ramp_inside() {
        let x: Vec<f64> = (0..100).map(|k| k as f64).collect();
        let y = moving_average(&x, 5);
        assert!((y[50] - 50.0).abs() < 1e-12);
        assert!((y[0] - 2.5).abs() < 1e-12);
    }
}
