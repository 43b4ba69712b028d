//! One-dimensional minimisation: a grid scan followed by golden-section refinement.

/// Minimises `f` over `grid` (sorted ascending), then refines between the neighbours of the best
/// grid point by golden-section search. Returns (argmin, min). `None` when the grid is empty or `f`
/// is never finite.
pub fn grid_then_golden(
    grid: &[f64],
    mut f: impl FnMut(f64) -> f64,
    iters: usize,
) -> Option<(f64, f64)> {
    grid_then_golden_bounded(grid, |x, _| f(x), iters)
}

/// As [`grid_then_golden`] for a costly `f(x, bound)` that may stop early: when it can tell that
/// its value exceeds `bound`, it may return any value above `bound` (e.g. infinity). Every
/// comparison the search makes is against such a bound (the best grid value so far; in the
/// golden section, the other interior point), so the result is the one of the full evaluations.
///
/// When every grid value is the same (a parameter `f` does not see there), the first grid point
/// is returned without a golden section: it could only find that value again.
pub fn grid_then_golden_bounded(
    grid: &[f64],
    mut f: impl FnMut(f64, f64) -> f64,
    iters: usize,
) -> Option<(f64, f64)> {
    let mut scan = GridScan::default();
    for (i, &x) in grid.iter().enumerate() {
        let v = f(x, scan.bound());
        scan.push(i, v);
    }
    golden_from(grid, scan, f, iters)
}

/// As [`grid_then_golden`], the grid's values all computed first by `on_grid` (in grid order:
/// e.g. on two threads, [`crate::par::join`]), then the golden section with `f`. The same
/// result as [`grid_then_golden`] when `on_grid` returns `f` at each grid point.
pub fn grid_then_golden_batched(
    grid: &[f64],
    on_grid: impl FnOnce(&[f64]) -> alloc::vec::Vec<f64>,
    mut f: impl FnMut(f64) -> f64,
    iters: usize,
) -> Option<(f64, f64)> {
    let values = on_grid(grid);
    if values.len() != grid.len() {
        return None;
    }
    let mut scan = GridScan::default();
    for (i, &v) in values.iter().enumerate() {
        scan.push(i, v);
    }
    golden_from(grid, scan, |x, _| f(x), iters)
}

/// The scan of a grid's values in grid order: the best (index, value) and whether every value
/// was the same.
struct GridScan {
    best: Option<(usize, f64)>,
    flat: bool,
}

impl Default for GridScan {
    fn default() -> Self {
        GridScan {
            best: None,
            flat: true,
        }
    }
}

impl GridScan {
    /// The best value so far (infinity before any): the bound of the next evaluation.
    fn bound(&self) -> f64 {
        self.best.map_or(f64::INFINITY, |b| b.1)
    }

    /// Grid point `i` of value `v`.
    fn push(&mut self, i: usize, v: f64) {
        self.flat &= v.is_finite() && self.best.is_none_or(|b| v == b.1);
        // Strictly lower: the first of equal values wins, as a scan of every value would.
        if v.is_finite() && self.best.is_none_or(|b| v < b.1) {
            self.best = Some((i, v));
        }
    }
}

/// The golden-section refinement of the grid scans: between the neighbours of the best grid
/// point of `scan`, unless the grid was flat; `f` against a bound as in
/// [`grid_then_golden_bounded`].
fn golden_from(
    grid: &[f64],
    scan: GridScan,
    mut f: impl FnMut(f64, f64) -> f64,
    iters: usize,
) -> Option<(f64, f64)> {
    let (ib, fb) = scan.best?;
    if scan.flat && grid.len() > 1 {
        return Some((grid[ib], fb));
    }
    let lo = grid[ib.saturating_sub(1)];
    let hi = grid[(ib + 1).min(grid.len() - 1)];
    let (mut best_x, mut best_f) = (grid[ib], fb);
    if hi > lo && iters > 0 {
        let g = 0.618_033_988_749_894_9;
        let (mut a, mut b) = (lo, hi);
        let mut c = b - g * (b - a);
        let mut d = a + g * (b - a);
        let mut fc = f(c, f64::INFINITY);
        let mut fd = f(d, fc);
        for _ in 0..iters {
            if fc < fd {
                b = d;
                d = c;
                fd = fc;
                c = b - g * (b - a);
                // Compared with fd next (fc < fd): only its exceeding fd matters.
                fc = f(c, fd);
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + g * (b - a);
                fd = f(d, fc);
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

// The grids live beside the scalar maths (the effects' grids use them too): one path for both.
pub use crate::math::{linspace, logspace};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flat_grid_is_not_refined() {
        let mut calls = 0;
        let r = grid_then_golden(
            &[1.0, 2.0, 3.0],
            |_| {
                calls += 1;
                5.0
            },
            8,
        );
        assert_eq!(r, Some((1.0, 5.0)));
        assert_eq!(calls, 3);
    }

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

    /// Stopping early above the bound changes nothing.
    #[test]
    fn bounded_search_matches_the_full_one() {
        let f = |x: f64| (x - 2.71).powi(2) + 0.1 * (7.0 * x).sin() + 1.0;
        let grid = linspace(0.0, 10.0, 16);
        let full = grid_then_golden(&grid, f, 20).unwrap();
        let mut calls_cut = 0;
        let bounded = grid_then_golden_bounded(
            &grid,
            |x, bound| {
                let v = f(x);
                if v > bound {
                    calls_cut += 1;
                    f64::INFINITY
                } else {
                    v
                }
            },
            20,
        )
        .unwrap();
        assert_eq!(full, bounded);
        assert!(calls_cut > 10, "{calls_cut}");
    }
}
