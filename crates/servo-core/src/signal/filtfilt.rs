//! Zero-phase low-pass filtering: a second-order Butterworth biquad run forwards and backwards
//! (like MATLAB's and SciPy's `filtfilt`).
//!
//! Forward-backward filtering squares the magnitude response (|H|^2 = 1/(1 + (w/wc)^4) with
//! w = tan(pi f T_s): -6 dB at the cut-off, a fourth-order roll-off) and has zero phase, so
//! filtered speed, acceleration, current and torque stay aligned in time and every regressor
//! filtered with the same [`ZeroPhase`] keeps the equation it belongs to consistent. Both ends are
//! padded with an odd reflection (value and slope continuous, so a ramp passes through: within
//! 3e-8 of a 3 /s ramp at 25 Hz and 1 kHz) and each pass starts in the steady state of its first
//! sample, which removes the start-up transients.
//!
//! The padding is three time constants of the cut-off, 3 / (fc T_s) samples (at least 3, at most
//! n - 1). Longer padding changes nothing measurable: on a random walk, 3 extra samples moved the
//! output by at most 2e-9 (1e-7 of its standard deviation), and 6 or 10 time constants left the
//! edge error of ramps, sines and parabolas unchanged to three digits (the edge error comes from
//! the reflection, not from the padding length).

use alloc::vec::Vec;

use super::derivative;
use crate::math;

/// Highest cut-off, as a fraction of the sample rate 1/T_s (0.9 x the Nyquist frequency; the
/// bilinear transform warps frequencies without bound towards Nyquist).
pub const MAX_CUTOFF_PER_RATE: f64 = 0.45;
/// Lowest cut-off, as a fraction of the sample rate: the sum 1 + a1 + a2 ~ 4 (pi fc T_s)^2 that
/// sets the DC gain loses ever more digits to rounding as the cut-off falls (11 of 16 here).
pub const MIN_CUTOFF_PER_RATE: f64 = 1e-6;

/// A filter that cannot be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// The sample period is not a positive finite number.
    #[error("sample period {dt_s} s must be > 0 and finite")]
    BadSamplePeriod { dt_s: f64 },
    /// The cut-off lies outside [MIN_CUTOFF_PER_RATE, MAX_CUTOFF_PER_RATE] x the sample rate.
    #[error(
        "filter cut-off {cutoff_hz} Hz must lie between {min_hz} Hz and {max_hz} Hz \
         (0.9 x the Nyquist frequency) for a sample period of {dt_s} s"
    )]
    BadCutoff {
        cutoff_hz: f64,
        min_hz: f64,
        max_hz: f64,
        dt_s: f64,
    },
}

/// A second-order Butterworth low-pass biquad (bilinear transform with pre-warping), direct form
/// II transposed: y = b0 x + z1, z1' = b1 x - a1 y + z2, z2' = b2 x - a2 y.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Butter2 {
    b: [f64; 3],
    a: [f64; 2],
}

impl Butter2 {
    /// Low-pass with cut-off `cutoff_hz` (-3 dB) for the sample period `dt_s`; the caller keeps
    /// the cut-off inside (0, 0.5 / dt_s).
    fn lowpass(cutoff_hz: f64, dt_s: f64) -> Butter2 {
        let k = math::tan(math::PI * cutoff_hz * dt_s);
        let s2 = core::f64::consts::SQRT_2;
        let norm = 1.0 / (1.0 + s2 * k + k * k);
        let b0 = k * k * norm;
        Butter2 {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - s2 * k + k * k) * norm],
        }
    }

    /// The identity (y = x).
    const PASS: Butter2 = Butter2 {
        b: [1.0, 0.0, 0.0],
        a: [0.0, 0.0],
    };

    /// Filters `L` signals of one length in place, interleaved (sample k of signal l at
    /// `x[k][l]`), forwards (or, `backwards`, last sample first), each from the steady state of
    /// its first sample (unit DC gain: a constant input leaves the filter in that state). Each
    /// lane gets the same operations in the same order as alone; the lanes' independent
    /// recursions overlap (one recursion alone leaves most of a core idle).
    fn run_lanes<const L: usize>(&self, x: &mut [[f64; L]], backwards: bool) {
        let first = if backwards { x.last() } else { x.first() };
        let Some(&x0) = first else { return };
        let [b0, b1, b2] = self.b;
        let [a1, a2] = self.a;
        let mut z1: [f64; L] = core::array::from_fn(|l| x0[l] - b0 * x0[l]);
        let mut z2: [f64; L] = core::array::from_fn(|l| b2 * x0[l] - a2 * x0[l]);
        let mut step = |v: &mut [f64; L]| {
            for l in 0..L {
                let xin = v[l];
                let y = b0 * xin + z1[l];
                z1[l] = b1 * xin - a1 * y + z2[l];
                z2[l] = b2 * xin - a2 * y;
                v[l] = y;
            }
        };
        if backwards {
            x.iter_mut().rev().for_each(&mut step);
        } else {
            x.iter_mut().for_each(&mut step);
        }
    }
}

/// A zero-phase low-pass filter for signals sampled every `dt_s`: a second-order Butterworth
/// biquad forwards and backwards with odd-reflection padding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZeroPhase {
    biquad: Butter2,
    /// Sample period T_s [s].
    dt_s: f64,
    /// Reflection padding at each end [samples] (before the n - 1 limit of a short signal).
    pad: usize,
}

impl ZeroPhase {
    /// A filter with cut-off `cutoff_hz` (-3 dB of one pass, -6 dB of the pair) for samples every
    /// `dt_s`; the cut-off must lie in [`MIN_CUTOFF_PER_RATE`, `MAX_CUTOFF_PER_RATE`] / `dt_s`.
    pub fn new(cutoff_hz: f64, dt_s: f64) -> Result<ZeroPhase, FilterError> {
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(FilterError::BadSamplePeriod { dt_s });
        }
        let (min_hz, max_hz) = (MIN_CUTOFF_PER_RATE / dt_s, MAX_CUTOFF_PER_RATE / dt_s);
        if !(cutoff_hz >= min_hz && cutoff_hz <= max_hz) {
            return Err(FilterError::BadCutoff {
                cutoff_hz,
                min_hz,
                max_hz,
                dt_s,
            });
        }
        Ok(ZeroPhase::design(cutoff_hz, dt_s))
    }

    /// Like [`ZeroPhase::new`], but a cut-off outside the range is moved to its nearest end, and
    /// a non-positive (or NaN) cut-off or sample period gives the identity (no filtering). For
    /// derived cut-offs (a multiple of a user's) and for options where "0" means "off".
    pub fn clamped(cutoff_hz: f64, dt_s: f64) -> ZeroPhase {
        if !(cutoff_hz > 0.0 && dt_s > 0.0 && dt_s.is_finite()) {
            return ZeroPhase {
                biquad: Butter2::PASS,
                dt_s,
                pad: 0,
            };
        }
        let fc = cutoff_hz.clamp(MIN_CUTOFF_PER_RATE / dt_s, MAX_CUTOFF_PER_RATE / dt_s);
        ZeroPhase::design(fc, dt_s)
    }

    /// The filter for a cut-off and sample period already checked to be in range.
    fn design(cutoff_hz: f64, dt_s: f64) -> ZeroPhase {
        ZeroPhase {
            biquad: Butter2::lowpass(cutoff_hz, dt_s),
            dt_s,
            pad: ((3.0 / (cutoff_hz * dt_s)) as usize).max(3),
        }
    }

    /// Sample period T_s [s] the filter was designed for.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Power gain |H(f)|^2 of the forward-backward pair at `f_hz` [1]: the biquad's squared
    /// magnitude squared again (each pass filters once; the pair has no phase). A white input
    /// comes out with this spectral shape; dividing a filtered signal's spectrum by it gives the
    /// spectrum of what went in.
    pub fn power_gain(&self, f_hz: f64) -> f64 {
        let w = core::f64::consts::TAU * f_hz * self.dt_s;
        let (c1, s1, c2, s2) = (
            math::cos(w),
            math::sin(w),
            math::cos(2.0 * w),
            math::sin(2.0 * w),
        );
        let [b0, b1, b2] = self.biquad.b;
        let [a1, a2] = self.biquad.a;
        // H(e^{jw}) = (b0 + b1 e^{-jw} + b2 e^{-2jw}) / (1 + a1 e^{-jw} + a2 e^{-2jw}).
        let (nr, ni) = (b0 + b1 * c1 + b2 * c2, -(b1 * s1 + b2 * s2));
        let (dr, di) = (1.0 + a1 * c1 + a2 * c2, -(a1 * s1 + a2 * s2));
        let den = dr * dr + di * di;
        if den.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            return 0.0;
        }
        let mag2 = (nr * nr + ni * ni) / den;
        mag2 * mag2
    }

    /// Filters `x` forwards and backwards; returns a signal of the same length (a copy of `x`
    /// when it has fewer than 3 samples).
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        match self.apply_lanes([x]) {
            Some([y]) => y,
            None => x.to_vec(),
        }
    }

    /// [`Self::apply`] to two signals: the same values, the two filtered in lockstep (about
    /// twice as fast as one after the other: each recursion alone leaves a core mostly idle).
    pub fn apply_pair(&self, x: &[f64], y: &[f64]) -> (Vec<f64>, Vec<f64>) {
        match self.apply_lanes([x, y]) {
            Some([a, b]) => (a, b),
            None => (self.apply(x), self.apply(y)),
        }
    }

    /// [`Self::apply`] to `L` signals of one length (at least 3 samples), interleaved and
    /// filtered in lockstep ([`Butter2::run_lanes`]): the values of each filtered alone, about
    /// `L` times as fast as one after the other. `None` when the lengths differ or are below 3.
    pub fn apply_lanes<const L: usize>(&self, xs: [&[f64]; L]) -> Option<[Vec<f64>; L]> {
        let n = xs.first()?.len();
        if n < 3 || xs.iter().any(|x| x.len() != n) {
            return None;
        }
        let pad = self.pad.min(n - 1);
        let mut buf: Vec<[f64; L]> = Vec::with_capacity(n + 2 * pad);
        // Odd reflection about the end points keeps value and slope continuous.
        for k in (1..=pad).rev() {
            buf.push(core::array::from_fn(|l| 2.0 * xs[l][0] - xs[l][k]));
        }
        buf.extend((0..n).map(|k| core::array::from_fn(|l| xs[l][k])));
        for k in 1..=pad {
            buf.push(core::array::from_fn(|l| {
                2.0 * xs[l][n - 1] - xs[l][n - 1 - k]
            }));
        }
        self.biquad.run_lanes(&mut buf, false);
        self.biquad.run_lanes(&mut buf, true);
        let middle = &buf[pad..pad + n];
        Some(core::array::from_fn(|l| {
            middle.iter().map(|v| v[l]).collect()
        }))
    }

    /// The derivative of the filtered `x` per second (central differences of [`ZeroPhase::apply`]),
    /// e.g. speed [rad/s] from position [rad].
    pub fn derivative(&self, x: &[f64]) -> Vec<f64> {
        derivative(&self.apply(x), self.dt_s)
    }
}

/// Zero-phase low-pass of `x` sampled every `dt_s` with cut-off `cutoff_hz` (see [`ZeroPhase::new`]
/// for the valid range).
pub fn lowpass_zero_phase(x: &[f64], dt_s: f64, cutoff_hz: f64) -> Result<Vec<f64>, FilterError> {
    Ok(ZeroPhase::new(cutoff_hz, dt_s)?.apply(x))
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 1e-3;

    fn sine(f_hz: f64, phase_rad: f64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| math::sin(math::TAU * f_hz * k as f64 * DT + phase_rad))
            .collect()
    }

    /// Amplitude of the sine in y[lo..hi] by correlation with sin and cos at `f_hz`, and its phase
    /// [rad] relative to sin(2 pi f t).
    fn amplitude_and_phase(y: &[f64], f_hz: f64, lo: usize, hi: usize) -> (f64, f64) {
        let (mut s, mut c) = (0.0, 0.0);
        for (k, v) in y.iter().enumerate().take(hi).skip(lo) {
            let w = math::TAU * f_hz * k as f64 * DT;
            s += v * math::sin(w);
            c += v * math::cos(w);
        }
        let m = (hi - lo) as f64 / 2.0;
        (math::hypot(s / m, c / m), math::atan2(c, s))
    }

    /// Two signals filtered in lockstep get exactly the values each gets alone.
    #[test]
    fn a_pair_is_filtered_exactly_as_each_alone() {
        let f = ZeroPhase::new(20.0, DT).unwrap();
        let x = sine(3.0, 0.2, 2000);
        let y: Vec<f64> = sine(11.0, 1.0, 2000).iter().map(|v| v * v).collect();
        let (fx, fy) = f.apply_pair(&x, &y);
        assert_eq!(fx, f.apply(&x));
        assert_eq!(fy, f.apply(&y));
    }

    /// Four signals filtered in lockstep get exactly the values each gets alone, short ones
    /// (padding cut to n - 1) too; lengths that differ are refused.
    #[test]
    fn lanes_are_filtered_exactly_as_each_alone() {
        let f = ZeroPhase::new(20.0, DT).unwrap();
        for n in [3, 7, 2000] {
            let s: Vec<Vec<f64>> = (0..4)
                .map(|i| sine(2.0 + 3.0 * i as f64, 0.3 * i as f64, n))
                .map(|v| {
                    v.iter()
                        .enumerate()
                        .map(|(k, x)| x + 1e-3 * k as f64)
                        .collect()
                })
                .collect();
            let got = f
                .apply_lanes([&s[0][..], &s[1][..], &s[2][..], &s[3][..]])
                .unwrap();
            for (g, x) in got.iter().zip(&s) {
                assert_eq!(*g, f.apply(x), "n = {n}");
            }
        }
        let (a, b) = (sine(3.0, 0.0, 100), sine(3.0, 0.0, 101));
        assert!(f.apply_lanes([&a[..], &b[..]]).is_none());
        assert!(f.apply_lanes([&a[..2], &a[..2]]).is_none());
    }

    #[test]
    fn dc_passes_with_unit_gain_everywhere() {
        let x = [2.5; 500];
        let y = lowpass_zero_phase(&x, DT, 20.0).unwrap();
        // The steady-state start makes a constant pass exactly, ends included.
        assert!(y.iter().all(|v| (v - 2.5).abs() < 1e-12), "{:?}", &y[..3]);
    }

    #[test]
    fn gain_is_minus_3db_per_pass_and_minus_6db_forward_backward_at_the_cutoff() {
        // What is checked, on a 10 Hz sine at 1 kHz, over whole periods away from the ends:
        // one Butterworth pass is -3 dB (|H| = 1/sqrt 2) with -90 degrees of phase at the cut-off;
        // forwards and backwards square the gain, |H|^2 = 1/2 (-6.02 dB), with zero phase.
        // (Measured: 0.5 - 7e-15 and 3e-14 rad.)
        let fc = 10.0;
        let x = sine(fc, 0.3, 20_000);
        let mut lane: Vec<[f64; 1]> = x.iter().map(|v| [*v]).collect();
        Butter2::lowpass(fc, DT).run_lanes(&mut lane, false);
        let one_pass: Vec<f64> = lane.iter().map(|v| v[0]).collect();
        let (amp, phase) = amplitude_and_phase(&one_pass, fc, 5_000, 15_000);
        assert!(
            (amp - core::f64::consts::FRAC_1_SQRT_2).abs() < 1e-9,
            "one pass {amp}"
        );
        assert!(
            (phase - (0.3 - math::PI / 2.0)).abs() < 1e-9,
            "one pass {phase} rad"
        );
        let y = lowpass_zero_phase(&x, DT, fc).unwrap();
        let (amp, phase) = amplitude_and_phase(&y, fc, 5_000, 15_000);
        assert!((amp - 0.5).abs() < 1e-9, "amplitude {amp}");
        assert!((phase - 0.3).abs() < 1e-9, "phase {phase} rad");
        // Around it, the pair follows the squared digital Butterworth response
        // 1/(1 + (tan(pi f T_s)/tan(pi fc T_s))^4), still with zero phase (measured within 4e-14).
        let warp = |f: f64| math::tan(math::PI * f * DT);
        for f in [2.0, 5.0, 20.0, 40.0] {
            let x = sine(f, 1.0, 20_000);
            let y = lowpass_zero_phase(&x, DT, fc).unwrap();
            let (amp, phase) = amplitude_and_phase(&y, f, 5_000, 15_000);
            let expected = 1.0 / (1.0 + math::pow(warp(f) / warp(fc), 4.0));
            assert!((amp - expected).abs() < 1e-9, "{f} Hz: {amp} vs {expected}");
            assert!((phase - 1.0).abs() < 1e-9, "{f} Hz: phase {phase} rad");
        }
    }

    /// The pair's power gain is the square of the amplitude a sine keeps through it, measured on
    /// filtered sines: 1 at DC, 1/4 at the cut-off, and the digital Butterworth curve around it.
    #[test]
    fn power_gain_is_the_square_of_a_sines_amplitude_through_the_pair() {
        let fc = 10.0;
        let f = ZeroPhase::new(fc, DT).unwrap();
        assert!((f.power_gain(0.0) - 1.0).abs() < 1e-12);
        assert!((f.power_gain(fc) - 0.25).abs() < 1e-12);
        for hz in [2.0, 5.0, 20.0, 40.0] {
            let y = f.apply(&sine(hz, 1.0, 20_000));
            let (amp, _) = amplitude_and_phase(&y, hz, 5_000, 15_000);
            assert!(
                (f.power_gain(hz) / (amp * amp) - 1.0).abs() < 1e-6,
                "{hz} Hz: {} vs {}",
                f.power_gain(hz),
                amp * amp
            );
        }
        assert_eq!(ZeroPhase::clamped(0.0, DT).power_gain(30.0), 1.0);
    }

    #[test]
    fn slow_sine_passes_without_delay_and_fast_one_is_removed() {
        let slow = sine(1.0, 0.0, 5_000);
        let y = lowpass_zero_phase(&slow, DT, 20.0).unwrap();
        // Away from the ends every sample matches: no lag at all.
        for k in 500..4_500 {
            assert!(
                (y[k] - slow[k]).abs() < 2e-3,
                "k {k}: {} vs {}",
                y[k],
                slow[k]
            );
        }
        let fast = sine(200.0, 0.0, 5_000);
        let y = lowpass_zero_phase(&fast, DT, 10.0).unwrap();
        // |H|^2 at 20 x the cut-off is 1/(1 + 20^4) ~ 6e-6.
        assert!(y[500..4_500].iter().all(|v| v.abs() < 1e-4));
        // The Nyquist alternation is gone too.
        let alt: Vec<f64> = (0..2_000)
            .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let y = lowpass_zero_phase(&alt, DT, 20.0).unwrap();
        assert!(y[100..1_900].iter().all(|v| v.abs() < 1e-3));
    }

    #[test]
    fn ramp_passes_unchanged_up_to_the_ends_and_its_slope_is_exact() {
        // The odd reflection continues a ramp as the same ramp, so nothing bends at the edges:
        // all that is left is the start-up of each pass (it starts in the steady state of a
        // constant, not of a ramp), decayed over three time constants of padding (~3e-8).
        let f = ZeroPhase::new(25.0, DT).unwrap();
        let ramp: Vec<f64> = (0..4_000).map(|k| 3.0 * k as f64 * DT - 1.0).collect();
        let y = f.apply(&ramp);
        let err: Vec<f64> = y.iter().zip(&ramp).map(|(a, b)| (a - b).abs()).collect();
        let worst = |e: &[f64]| e.iter().fold(0.0f64, |m, v| m.max(*v));
        assert!(worst(&err[..50]) < 1e-7, "start {}", worst(&err[..50]));
        assert!(worst(&err[3_950..]) < 1e-7, "end {}", worst(&err[3_950..]));
        assert!(worst(&err) < 1e-7, "{}", worst(&err));
        let slope = f.derivative(&ramp);
        assert!(slope.iter().all(|v| (v - 3.0).abs() < 1e-5));
    }

    #[test]
    fn speed_of_a_sine_keeps_amplitude_and_phase() {
        let f = 2.0;
        let th = sine(f, 0.0, 3_000);
        let w = ZeroPhase::new(30.0, DT).unwrap().derivative(&th);
        for (k, wk) in w.iter().enumerate().take(2_500).skip(500) {
            let exact = math::TAU * f * math::cos(math::TAU * f * k as f64 * DT);
            assert!(
                (wk - exact).abs() < 0.02 * math::TAU * f,
                "{k}: {wk} vs {exact}"
            );
        }
    }

    #[test]
    fn short_signals_come_back_unchanged() {
        let f = ZeroPhase::new(20.0, DT).unwrap();
        assert!(f.apply(&[]).is_empty());
        assert_eq!(f.apply(&[1.0, 4.0]), [1.0, 4.0]);
    }

    #[test]
    fn refuses_cutoffs_outside_the_range_and_bad_periods() {
        assert!(lowpass_zero_phase(&[0.0; 10], DT, 460.0).is_err());
        assert!(lowpass_zero_phase(&[0.0; 10], DT, -1.0).is_err());
        assert!(lowpass_zero_phase(&[0.0; 10], DT, f64::NAN).is_err());
        assert!(lowpass_zero_phase(&[0.0; 10], 0.0, 10.0).is_err());
        assert!(lowpass_zero_phase(&[0.0; 10], DT, 450.0).is_ok());
    }

    #[test]
    fn clamped_moves_the_cutoff_into_range_or_switches_off() {
        assert_eq!(
            ZeroPhase::clamped(1_000.0, DT),
            ZeroPhase::new(450.0, DT).unwrap()
        );
        assert_eq!(
            ZeroPhase::clamped(1e-9, DT),
            ZeroPhase::new(1e-3, DT).unwrap()
        );
        let x = sine(200.0, 0.0, 100);
        for off in [
            ZeroPhase::clamped(0.0, DT),
            ZeroPhase::clamped(f64::NAN, DT),
            ZeroPhase::clamped(10.0, 0.0),
        ] {
            assert_eq!(off.apply(&x), x);
        }
    }
}
