//! One-dimensional minimisation: a grid scan followed by golden-section refinement.

use alloc::vec::Vec;

/// Minimises `f` over `grid` (sorted ascending), then refines between the neighbours of the best
/// grid point by golden-section search. Returns (argmin, min). `None` when the grid is empty or `f`
/// is never finite.
pub fn grid_then_golden(
    grid: &[f64],
    mut f: impl FnMut(f64) -> f64,
    iters: usize,
) -> Option<(f64, f64)> {
    let vals: Vec<f64> = grid.iter().map(|&x| f(x)).collect();
    let (ib, fb) = vals
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, v)| (i, *v))?;
    let lo = grid[ib.saturating_sub(1)];
    let hi = grid[(ib + 1).min(grid.len() - 1)];
    let (mut best_x, mut best_f) = (grid[ib], fb);
    if hi > lo && iters > 0 {
        let g = 0.618_033_988_749_894_9;
        let (mut a, mut b) = (lo, hi);
        let mut c = b - g * (b - a);
        let mut d = a + g * (b - a);
        let (mut fc, mut fd) = (f(c), f(d));
        for _ in 0..iters {
            if fc < fd {
                b = d;
                d = c;
                fd = fc;
                c = b - g * (b - a);
                fc = f(c);
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + g * (b - a);
                fd = f(d);
            }
        }
        for (x, v) in [(c, fc), (d, fd)] {
            if v.is_finite() && v < best_f {
                best_x = x;
                best_f = v;
            }
        }
    }
    Some((best_x, best_f))
}

/// `n` points from `a` to `b` inclusive, spaced evenly.
pub fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    if n < 2 {
        return alloc::vec![a];
    }
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .collect()
}

/// `n` points from `a` to `b` inclusive, spaced evenly on a log scale (a, b > 0).
pub fn logspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    linspace(crate::math::ln(a), crate::math::ln(b), n)
        .into_iter()
        .map(crate::math::exp)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_minimum_between_grid_points() {
        let (x, f) = grid_then_golden(
            &linspace(0.0, 10.0, 11),
            |x| (x - 3.3) * (x - 3.3) + 1.0,
            40,
        )
        .unwrap();
        assert!((x - 3.3).abs() < 1e-6 && (f - 1.0).abs() < 1e-9);
    }
}
