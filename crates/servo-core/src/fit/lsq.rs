//! Linear least squares by QR with standard errors and sign constraints.
//!
//! Columns are scaled to unit norm before the Householder QR (nalgebra) so that regressors of very
//! different magnitudes (accelerations of 1e4 rad/s^2 next to unit sign functions) stay well
//! conditioned. Sign constraints are enforced by an active set: a coefficient that comes out with
//! the wrong sign is fixed at zero and the rest refitted, until every sign is physical.

use crate::math;
use alloc::vec::Vec;
use nalgebra::{DMatrix, DVector};

/// Sign constraint of one coefficient.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sign {
    Free,
    NonNegative,
}

/// A least-squares solution.
#[derive(Debug, Clone, PartialEq)]
pub struct LsSolution {
    /// Coefficients, one per column (0 for columns held at zero by a constraint).
    pub theta: Vec<f64>,
    /// Standard errors (0 for constrained-out columns).
    pub std_err: Vec<f64>,
    /// Residual sum of squares.
    pub rss: f64,
    /// Rows used.
    pub n: usize,
    /// Free coefficients actually estimated.
    pub p: usize,
}

/// [`solve`] on the rows `rows` of full-length columns `cols` and `y`, every coefficient free.
pub fn solve_on(cols: &[&Vec<f64>], y: &[f64], rows: &[usize]) -> Option<LsSolution> {
    let c: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| rows.iter().map(|&i| c[i]).collect())
        .collect();
    let yy: Vec<f64> = rows.iter().map(|&i| y[i]).collect();
    solve(&c, &yy, &alloc::vec![Sign::Free; c.len()])
}

/// Residual sum of squares of coefficients `theta` on the rows `rows` of full-length columns
/// `cols` and `y` (e.g. held-out rows of a [`solve_on`] fit).
pub fn rss_on(cols: &[&Vec<f64>], theta: &[f64], y: &[f64], rows: &[usize]) -> f64 {
    rows.iter()
        .map(|&i| {
            let r = y[i] - cols.iter().zip(theta).map(|(c, t)| c[i] * t).sum::<f64>();
            r * r
        })
        .sum()
}

/// Solves min |y - X theta|^2 with `x` given column-major as `cols` (each of length `y.len()`).
///
/// Returns `None` when the problem is empty or singular.
pub fn solve(cols: &[Vec<f64>], y: &[f64], signs: &[Sign]) -> Option<LsSolution> {
    let n = y.len();
    let p_all = cols.len();
    let mut active: Vec<bool> = alloc::vec![true; p_all];
    for _ in 0..=p_all {
        let idx: Vec<usize> = (0..p_all).filter(|&j| active[j]).collect();
        let (theta_a, se_a, rss) = solve_unconstrained(cols, y, &idx)?;
        let mut worst: Option<(usize, f64)> = None;
        for (t, &j) in theta_a.iter().zip(&idx) {
            if signs.get(j) == Some(&Sign::NonNegative) && *t < 0.0 {
                // Scale-free badness: t relative to its standard error.
                let bad = -*t / se_a[idx.iter().position(|&q| q == j).unwrap_or(0)].max(1e-300);
                if worst.is_none_or(|(_, b)| bad > b) {
                    worst = Some((j, bad));
                }
            }
        }
        match worst {
            Some((j, _)) => active[j] = false,
            None => {
                let mut theta = alloc::vec![0.0; p_all];
                let mut std_err = alloc::vec![0.0; p_all];
                for (q, &j) in idx.iter().enumerate() {
                    theta[j] = theta_a[q];
                    std_err[j] = se_a[q];
                }
                return Some(LsSolution {
                    theta,
                    std_err,
                    rss,
                    n,
                    p: idx.len(),
                });
            }
        }
    }
    None
}

fn solve_unconstrained(
    cols: &[Vec<f64>],
    y: &[f64],
    idx: &[usize],
) -> Option<(Vec<f64>, Vec<f64>, f64)> {
    let n = y.len();
    let p = idx.len();
    if p == 0 {
        let rss = y.iter().map(|v| v * v).sum();
        return Some((Vec::new(), Vec::new(), rss));
    }
    if n <= p {
        return None;
    }
    let mut scale = Vec::with_capacity(p);
    let mut x = DMatrix::<f64>::zeros(n, p);
    for (q, &j) in idx.iter().enumerate() {
        let c = &cols[j];
        let s = math::sqrt(c.iter().map(|v| v * v).sum::<f64>());
        let s = if s > 0.0 { s } else { 1.0 };
        scale.push(s);
        for (i, v) in c.iter().enumerate() {
            x[(i, q)] = v / s;
        }
    }
    let yv = DVector::from_column_slice(y);
    let qr = x.clone().qr();
    let r = qr.r();
    // Rank check on the diagonal of R (columns have unit norm).
    if (0..p).any(|i| r[(i, i)].abs() < 1e-10) {
        return None;
    }
    let qty = qr.q().transpose() * &yv;
    let beta = r.solve_upper_triangular(&qty)?;
    let resid = &yv - &x * &beta;
    let rss = resid.norm_squared();
    let sigma2 = rss / (n - p) as f64;
    let rinv = r.solve_upper_triangular(&DMatrix::identity(p, p))?;
    let mut theta = Vec::with_capacity(p);
    let mut se = Vec::with_capacity(p);
    for q in 0..p {
        let var = sigma2 * rinv.row(q).norm_squared();
        theta.push(beta[q] / scale[q]);
        se.push(math::sqrt(var) / scale[q]);
    }
    Some((theta, se, rss))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_coefficients_and_respects_signs() {
        let n = 200;
        let x1: Vec<f64> = (0..n).map(|k| k as f64 * 1e3).collect();
        let x2: Vec<f64> = (0..n)
            .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let y: Vec<f64> = (0..n).map(|k| 2e-6 * x1[k] + 0.5 * x2[k]).collect();
        let s = solve(
            &[x1.clone(), x2.clone()],
            &y,
            &[Sign::Free, Sign::NonNegative],
        )
        .unwrap();
        assert!((s.theta[0] - 2e-6).abs() < 1e-12 && (s.theta[1] - 0.5).abs() < 1e-9);
        let y: Vec<f64> = (0..n).map(|k| 2e-6 * x1[k] - 0.5 * x2[k]).collect();
        let s = solve(&[x1, x2], &y, &[Sign::Free, Sign::NonNegative]).unwrap();
        assert_eq!(s.theta[1], 0.0);
        assert_eq!(s.p, 1);
    }
}
