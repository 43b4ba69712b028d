//! How many samples one signal lags another: the whole shift that makes them differ least
//! (mean squared difference over the same samples for every shift), to a fraction of a sample
//! by a parabola through the least and its neighbours (exact for smooth signals, whose squared
//! difference grows as the square of the shift error). Used to tell a speed *estimate* logged
//! by a causal filter (it lags the derivative of the angle it was computed from by the filter's
//! group delay, 1 / (2 pi f_c) for a first-order filter: 3.2 ms at 50 Hz) from a speed measured
//! without lag.

/// A logged speed lagging the derivative of the logged angle by more than this many samples is
/// a causal estimate (servo's own runs log a 50 Hz first-order estimate: 3.2 samples at 1 kHz),
/// and the angle's derivative, which has no lag, is used instead: a lagged speed against an
/// unlagged torque biases J_eq and B_eq (+17 % and +10 % on a drive whose mechanical time
/// constant is 18 ms), and against a model's speed it inflates the comparison's speed error
/// (fit 85 % for the true model of a run). Half a sample: below it, the shift is within the
/// estimate's resolution, and a speed measured without lag (a tachometer) is kept.
pub const MAX_SPEED_LAG_SAMPLES: f64 = 0.5;

/// Largest shift searched between a logged speed and the angle's derivative [samples].
pub const SPEED_LAG_SEARCH_SAMPLES: usize = 50;

/// The lag [samples] of a `logged` speed behind `derived`, the derivative of the logged angle
/// (the same unit and side), when it exceeds [`MAX_SPEED_LAG_SAMPLES`]: the logged speed is a
/// causal estimate and `derived` should be used. `None`: keep the logged speed (no lag, or it
/// cannot be measured).
pub fn lagging_speed(derived: &[f64], logged: &[f64]) -> Option<f64> {
    lag_samples(derived, logged, SPEED_LAG_SEARCH_SAMPLES)
        .filter(|lag| *lag > MAX_SPEED_LAG_SAMPLES)
}

/// The lag of `delayed` behind `reference` in samples, over shifts -`max_lag`..=`max_lag`:
/// positive when `delayed[k]` follows `reference[k - lag]`. `None` when the signals are shorter
/// than 4 `max_lag` samples, `reference` is constant, or a value is not finite. O(n max_lag).
pub fn lag_samples(reference: &[f64], delayed: &[f64], max_lag: usize) -> Option<f64> {
    let n = reference.len().min(delayed.len());
    if max_lag == 0 || n < 4 * max_lag {
        return None;
    }
    let (a, b) = (&reference[..n], &delayed[..n]);
    if a.iter().chain(b).any(|v| !v.is_finite()) {
        return None;
    }
    if a.iter().all(|v| *v == a[0]) {
        return None;
    }
    // The same samples for every shift: k in [max_lag, n - max_lag).
    let window = max_lag..n - max_lag;
    let msd = |s: isize| -> f64 {
        window
            .clone()
            .map(|k| {
                let d = b[k] - a[(k as isize - s) as usize];
                d * d
            })
            .sum::<f64>()
    };
    let m = max_lag as isize;
    let c: alloc::vec::Vec<f64> = (-m..=m).map(msd).collect();
    let (best, _) = c.iter().enumerate().min_by(|x, y| x.1.total_cmp(y.1))?;
    let shift = best as f64 - m as f64;
    if best == 0 || best == c.len() - 1 {
        return Some(shift);
    }
    // The vertex of the parabola through the least and its neighbours.
    let (l, p, r) = (c[best - 1], c[best], c[best + 1]);
    let den = l - 2.0 * p + r;
    let frac = if den > 0.0 { 0.5 * (l - r) / den } else { 0.0 };
    Some(shift + frac.clamp(-0.5, 0.5))
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec::Vec;

    /// A sum of sines, and the same through a first-order low-pass (3.2 samples of group delay
    /// at low frequency) or shifted by whole samples.
    #[test]
    fn a_causal_filter_lags_by_its_group_delay() {
        let x: Vec<f64> = (0..4000)
            .map(|k| {
                let t = k as f64 * 1e-3;
                libm::sin(2.0 * core::f64::consts::PI * 1.3 * t)
                    + 0.5 * libm::sin(2.0 * core::f64::consts::PI * 3.7 * t + 1.0)
            })
            .collect();
        let shifted: Vec<f64> = (0..4000usize).map(|k| x[k.saturating_sub(5)]).collect();
        let lag = lag_samples(&x, &shifted, 20).unwrap();
        assert!((lag - 5.0).abs() < 0.05, "{lag}");
        let back = lag_samples(&shifted, &x, 20).unwrap();
        assert!((back + 5.0).abs() < 0.05, "{back}");
        // First order at 50 Hz, 1 kHz: tau = 3.18 ms.
        let a = 1.0 - libm::exp(-2.0 * core::f64::consts::PI * 50.0 * 1e-3);
        let mut y = 0.0;
        let filtered: Vec<f64> = x
            .iter()
            .map(|v| {
                y += a * (v - y);
                y
            })
            .collect();
        let lag = lag_samples(&x, &filtered, 20).unwrap();
        assert!((2.3..4.0).contains(&lag), "{lag}");
        assert!(lag_samples(&x, &x, 20).unwrap().abs() < 0.01);
        assert!(lag_samples(&[1.0; 4000], &x, 20).is_none());
        assert!(lag_samples(&x[..50], &x[..50], 20).is_none());
    }
}
