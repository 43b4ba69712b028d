//! Processing of sampled signals shared by identification, model fit and comparison: the
//! zero-phase low-pass ([`filtfilt`]), central-difference derivatives, a moving average and the
//! lag of one signal behind another ([`lag`]).

pub mod filtfilt;
pub mod lag;
pub mod quantum;

use alloc::vec::Vec;

pub use filtfilt::{lowpass_zero_phase, FilterError, ZeroPhase};

/// Central-difference derivative of `x` sampled every `dt_s` (one-sided at the ends), per second.
pub fn derivative(x: &[f64], dt_s: f64) -> Vec<f64> {
    central_difference(x, |lo, hi| (hi - lo) as f64 * dt_s)
}

/// Central-difference derivative of `x` sampled at the times `t` [s] (possibly non-uniform;
/// one-sided at the ends), per second. Uses the first min(len) samples of both.
pub fn derivative_at(t: &[f64], x: &[f64]) -> Vec<f64> {
    let n = x.len().min(t.len());
    central_difference(&x[..n], |lo, hi| t[hi] - t[lo])
}

/// (x[k+1] - x[k-1]) / span(k-1, k+1) inside, one-sided differences at the ends; `span(lo, hi)`
/// is the time from sample lo to sample hi [s].
fn central_difference(x: &[f64], span: impl Fn(usize, usize) -> f64) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return alloc::vec![0.0; n];
    }
    (0..n)
        .map(|k| {
            let (lo, hi) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (x[hi] - x[lo]) / span(lo, hi)
        })
        .collect()
}

/// Centred moving average over `half` samples each side (the window shrinks at the ends). O(n).
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
    fn derivative_is_exact_on_a_parabola_inside_and_one_sided_at_the_ends() {
        // Central differences are exact on a parabola; the ends see a one-sided difference,
        // which is off by half a step of the second derivative: 2 a dt / 2.
        let dt = 0.01;
        let x: Vec<f64> = (0..50)
            .map(|k| {
                let t = k as f64 * dt;
                4.0 * t * t
            })
            .collect();
        let d = derivative(&x, dt);
        for (k, v) in d.iter().enumerate().take(49).skip(1) {
            assert!((v - 8.0 * k as f64 * dt).abs() < 1e-9, "{k}: {v}");
        }
        assert!((d[0] - 4.0 * dt).abs() < 1e-9);
        assert!((d[49] - (8.0 * 49.0 * dt - 4.0 * dt)).abs() < 1e-9);
        assert_eq!(derivative(&[1.0], dt), [0.0]);
    }

    #[test]
    fn derivative_on_a_time_base_handles_uneven_steps_and_matches_the_uniform_one() {
        let t = [0.0, 0.1, 0.3, 0.6, 1.0];
        let x: Vec<f64> = t.iter().map(|s| 2.0 * s + 1.0).collect();
        assert!(derivative_at(&t, &x)
            .iter()
            .all(|v| (v - 2.0).abs() < 1e-12));
        let x: Vec<f64> = (0..20).map(|k| libm::sin(0.3 * k as f64)).collect();
        let t: Vec<f64> = (0..20).map(|k| 0.05 * k as f64).collect();
        let (a, b) = (derivative_at(&t, &x), derivative(&x, 0.05));
        assert!(a.iter().zip(&b).all(|(p, q)| (p - q).abs() < 1e-9));
    }

    #[test]
    fn moving_average_of_ramp_is_ramp_inside() {
        let x: Vec<f64> = (0..100).map(|k| k as f64).collect();
        let y = moving_average(&x, 5);
        assert!((y[50] - 50.0).abs() < 1e-12);
        // At the ends the window is one-sided: mean of 0..=5.
        assert!((y[0] - 2.5).abs() < 1e-12);
    }
}
