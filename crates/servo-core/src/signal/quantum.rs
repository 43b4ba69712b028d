//! Detection of the position quantum of an encoder from a logged angle.
//!
//! A closed-loop replay feeds the model's controller the position it would have measured: the
//! model's angle rounded down to the same encoder grid (4096 counts/rev on the SRV-02), since the
//! quantisation shapes limit cycles and stick-slip of a PID with integral action.

use alloc::vec::Vec;

/// The grid spacing [rad] of `theta` if at least 98 % of the nonzero sample-to-sample changes are
/// integer multiples of the smallest one (within 2 %), and there are at least 20 such changes.
pub fn encoder_quantum(theta: &[f64]) -> Option<f64> {
    let d: Vec<f64> = theta
        .windows(2)
        .map(|w| libm::fabs(w[1] - w[0]))
        .filter(|v| *v > 1e-12)
        .collect();
    if d.len() < 20 {
        return None;
    }
    let q = d.iter().copied().fold(f64::INFINITY, f64::min);
    if !(q > 0.0 && q.is_finite()) {
        return None;
    }
    let on_grid = d
        .iter()
        .filter(|v| {
            let r = *v / q;
            libm::fabs(r - libm::round(r)) < 0.02
        })
        .count();
    // Only a true grid: a continuous signal has changes that are not multiples of the smallest.
    if (on_grid as f64) < 0.98 * d.len() as f64 {
        return None;
    }
    // Refine: least squares of |delta| = m q over the on-grid changes (m = round(|delta| / q)),
    // so that rounding in the log's text does not shift the grid over long travels.
    let (mut num, mut den) = (0.0, 0.0);
    for v in &d {
        let m = libm::round(*v / q);
        if m >= 1.0 && libm::fabs(*v / q - m) < 0.02 {
            num += m * v;
            den += m * m;
        }
    }
    Some(if den > 0.0 { num / den } else { q })
}

/// `x` rounded down to the grid of spacing `q` (as an incremental encoder counts).
pub fn quantize(x: f64, q: f64) -> f64 {
    libm::floor(x / q + 1e-9) * q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detects_grid_and_rejects_continuous() {
        let q = core::f64::consts::TAU / 4096.0;
        let th: Vec<f64> = (0..500)
            .map(|i| quantize(0.3 * (i as f64 * 0.01).sin(), q))
            .collect();
        let got = encoder_quantum(&th).unwrap();
        assert!((got - q).abs() < 1e-12, "{got}");
        let cont: Vec<f64> = (0..500).map(|i| 0.3 * (i as f64 * 0.01).sin()).collect();
        assert_eq!(encoder_quantum(&cont), None);
    }
}
