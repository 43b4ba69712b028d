//! Linear least squares by QR with standard errors and sign constraints.
//!
//! Columns are scaled to unit norm before the Householder QR (nalgebra) so that regressors of very
//! different magnitudes (accelerations of 1e4 rad/s^2 next to unit sign functions) stay well
//! conditioned. Sign constraints are enforced by an active set: a coefficient that comes out with
//! the wrong sign is fixed at zero and the rest refitted, until every sign is physical.
//!
//! Besides the classical standard errors (white residuals), every solution carries robust ones
//! ([`LsSolution::std_err_robust`]): the cluster-robust sandwich over contiguous blocks of rows
//! (the rows of a log are in time order, and the residuals of filtered signals at a 100 Hz row
//! rate are correlated over many rows), at least the classical ones, and scaled so that
//! +/- 1.96 of them is the Student-t 95 % interval on the blocks' degrees of freedom.

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
    /// Standard errors (0 for constrained-out columns), residuals taken as white.
    pub std_err: Vec<f64>,
    /// Standard errors robust to correlated residuals (block sandwich, see the module's doc),
    /// at least `std_err`, as a 1.96-sigma half-width of the 95 % interval.
    pub std_err_robust: Vec<f64>,
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
        let (theta_a, se_a, rob_a, rss) = solve_unconstrained(cols, y, &idx)?;
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
                let mut std_err_robust = alloc::vec![0.0; p_all];
                for (q, &j) in idx.iter().enumerate() {
                    theta[j] = theta_a[q];
                    std_err[j] = se_a[q];
                    std_err_robust[j] = rob_a[q].max(se_a[q]);
                }
                return Some(LsSolution {
                    theta,
                    std_err,
                    std_err_robust,
                    rss,
                    n,
                    p: idx.len(),
                });
            }
        }
    }
    None
}

/// Rows per block of the robust covariance (half a second at the fits' 100 Hz row rate).
pub const ROWS_PER_BLOCK: usize = 50;
/// Most blocks of the robust covariance.
pub const MAX_BLOCKS: usize = 40;

/// Two-sided 95 % normal quantile.
pub const Z95: f64 = 1.959_964;

/// Two-sided 95 % Student-t quantile on `dof` degrees of freedom (within 0.5 % from 3 on).
pub fn t95(dof: usize) -> f64 {
    match dof {
        0 => f64::INFINITY,
        1 => 12.706,
        2 => 4.303,
        d => {
            let d = d as f64;
            Z95 + 2.37 / d + 2.8 / (d * d)
        }
    }
}

/// (theta, classical se, robust se, RSS) of the columns `idx`.
type Unconstrained = (Vec<f64>, Vec<f64>, Vec<f64>, f64);

fn solve_unconstrained(cols: &[Vec<f64>], y: &[f64], idx: &[usize]) -> Option<Unconstrained> {
    let n = y.len();
    let p = idx.len();
    if p == 0 {
        let rss = y.iter().map(|v| v * v).sum();
        return Some((Vec::new(), Vec::new(), Vec::new(), rss));
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
    // Block sandwich: (R^T R)^-1 (sum_b g_b g_b^T) (R^T R)^-1 b/(b-1), g_b = X_b^T e_b.
    let b = (n / ROWS_PER_BLOCK).clamp(2, MAX_BLOCKS);
    let mut rob = alloc::vec![0.0; p];
    if n >= 2 * b {
        let mut meat = DMatrix::<f64>::zeros(p, p);
        for k in 0..b {
            let (s, e) = (k * n / b, (k + 1) * n / b);
            let g = x.rows(s, e - s).transpose() * resid.rows(s, e - s);
            meat += &g * g.transpose();
        }
        let bread = &rinv * rinv.transpose();
        let cov = &bread * meat * &bread * (b as f64 / (b as f64 - 1.0));
        let widen = t95(b - 1) / Z95;
        for (q, r) in rob.iter_mut().enumerate() {
            *r = math::sqrt(cov[(q, q)].max(0.0)) / scale[q] * widen;
        }
    }
    let mut theta = Vec::with_capacity(p);
    let mut se = Vec::with_capacity(p);
    for q in 0..p {
        let var = sigma2 * rinv.row(q).norm_squared();
        theta.push(beta[q] / scale[q]);
        se.push(math::sqrt(var) / scale[q]);
    }
    Some((theta, se, rob, rss))
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
