//! Linear least squares by QR with the statistics of every estimate.
//!
//! Solves min ||y - Phi theta||^2 with Householder QR on the column-scaled regression matrix
//! (each column divided by its 2-norm, so that the condition number measures collinearity and not
//! units). The covariance of theta is either
//! * `Iid`: sigma^2 (R^T R)^-1 with sigma^2 = RSS / (n - p) (white residuals, the classical formula), or
//! * `Blocks(b)`: the cluster-robust "sandwich" with `b` contiguous blocks as clusters,
//!   (R^T R)^-1 (sum_b g_b g_b^T) (R^T R)^-1 * b/(b-1), g_b = sum over the block of phi_k e_k.
//!   Use it for sample-level fits at 1 kHz, whose residuals are strongly autocorrelated: the
//!   classical formula would claim far too small an uncertainty.
//!
//! The 95 % interval is theta +- t_{0.975, dof} se, with dof = n - p (`Iid`) or b - 1 (`Blocks`).

use alloc::vec::Vec;
use nalgebra::{DMatrix, DVector};

use super::student_t::t95;
use super::IdentError;

/// How the covariance of the estimate is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Covariance {
    /// Independent residuals with constant variance.
    Iid,
    /// Autocorrelated residuals: cluster-robust covariance over this many contiguous blocks.
    Blocks(usize),
}

/// Result of a least-squares fit.
#[derive(Debug, Clone, PartialEq)]
pub struct LsFit {
    /// Estimated parameters, in the order of the regressor columns.
    pub theta: Vec<f64>,
    /// Standard errors of `theta`.
    pub std_err: Vec<f64>,
    /// 95 % confidence intervals (lo, hi).
    pub ci95: Vec<(f64, f64)>,
    /// Degrees of freedom used for the t quantile.
    pub dof: usize,
    /// Number of rows (observations).
    pub n: usize,
    /// RMS of the residuals y - Phi theta (units of y).
    pub residual_rms: f64,
    /// 2-norm condition number of the column-scaled regression matrix.
    pub cond: f64,
    /// Covariance matrix of `theta`, row-major p x p.
    pub cov: Vec<f64>,
}

/// Above this condition number (column-scaled) the regressors are treated as collinear.
pub const MAX_COND: f64 = 1e8;

/// Fits y = Phi theta. `columns` are the regressor columns (each of the length of `y`).
pub fn fit(columns: &[&[f64]], y: &[f64], cov: Covariance) -> Result<LsFit, IdentError> {
    let p = columns.len();
    let n = y.len();
    if p == 0 || columns.iter().any(|c| c.len() != n) {
        return Err(IdentError::Internal(
            "regressor columns and observations differ in length",
        ));
    }
    if n <= p {
        return Err(IdentError::TooFewData {
            needed: p + 1,
            got: n,
        });
    }
    if let Covariance::Blocks(b) = cov {
        if b < 2 || n < 2 * b {
            return Err(IdentError::Internal(
                "block covariance needs >= 2 blocks of >= 2 rows",
            ));
        }
    }
    // Column scaling.
    let mut scale = Vec::with_capacity(p);
    let mut data = Vec::with_capacity(n * p);
    for c in columns {
        let norm = crate::math::sqrt(c.iter().map(|v| v * v).sum::<f64>());
        if !(norm > 0.0) || !norm.is_finite() {
            return Err(IdentError::RankDeficient {
                cond: f64::INFINITY,
            });
        }
        scale.push(norm);
        data.extend(c.iter().map(|v| v / norm));
    }
    let phi = DMatrix::from_vec(n, p, data);
    let qr = phi.clone().qr();
    let r = qr.r();
    let sv = r.clone().singular_values();
    let (smax, smin) = sv
        .iter()
        .fold((0.0_f64, f64::INFINITY), |(a, b), &s| (a.max(s), b.min(s)));
    let cond = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    if !(cond < MAX_COND) {
        return Err(IdentError::RankDeficient { cond });
    }
    let mut qty = DVector::from_column_slice(y);
    qr.q_tr_mul(&mut qty);
    let qty_p = qty.rows(0, p).into_owned();
    let theta_s = r
        .solve_upper_triangular(&qty_p)
        .ok_or(IdentError::RankDeficient { cond })?;
    let r_inv = r
        .clone()
        .try_inverse()
        .ok_or(IdentError::RankDeficient { cond })?;
    let bread = &r_inv * r_inv.transpose(); // (R^T R)^-1 in scaled coordinates
                                            // Residuals.
    let fitted = &phi * &theta_s;
    let resid: Vec<f64> = y.iter().zip(fitted.iter()).map(|(a, b)| a - b).collect();
    let rss: f64 = resid.iter().map(|e| e * e).sum();
    let residual_rms = crate::math::sqrt(rss / n as f64);
    let (cov_s, dof) = match cov {
        Covariance::Iid => {
            let dof = n - p;
            (bread * (rss / dof as f64), dof)
        }
        Covariance::Blocks(b) => {
            let mut meat = DMatrix::<f64>::zeros(p, p);
            let mut g = DVector::<f64>::zeros(p);
            for k in 0..b {
                let (s, e) = (k * n / b, (k + 1) * n / b);
                g.fill(0.0);
                for (j, gj) in g.iter_mut().enumerate() {
                    let col = phi.column(j);
                    *gj = (s..e).map(|i| col[i] * resid[i]).sum();
                }
                meat += &g * g.transpose();
            }
            let c = b as f64 / (b as f64 - 1.0);
            (&bread * meat * &bread * c, b - 1)
        }
    };
    let t = t95(dof as f64);
    let mut theta = Vec::with_capacity(p);
    let mut std_err = Vec::with_capacity(p);
    let mut ci95 = Vec::with_capacity(p);
    let mut cov_out = Vec::with_capacity(p * p);
    for i in 0..p {
        for j in 0..p {
            cov_out.push(cov_s[(i, j)] / (scale[i] * scale[j]));
        }
    }
    for j in 0..p {
        let v = theta_s[j] / scale[j];
        let se = crate::math::sqrt(cov_s[(j, j)].max(0.0)) / scale[j];
        theta.push(v);
        std_err.push(se);
        ci95.push((v - t * se, v + t * se));
    }
    Ok(LsFit {
        theta,
        std_err,
        ci95,
        dof,
        n,
        residual_rms,
        cond,
        cov: cov_out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::sensors::SplitMix64;

    #[test]
    fn exact_fit_recovers_parameters() {
        let x: Vec<f64> = (0..20).map(|i| i as f64).collect();
        let one = alloc::vec![1.0; 20];
        let y: Vec<f64> = x.iter().map(|x| 3.0 * x - 2.0).collect();
        let f = fit(&[&x, &one], &y, Covariance::Iid).unwrap();
        assert!((f.theta[0] - 3.0).abs() < 1e-12 && (f.theta[1] + 2.0).abs() < 1e-12);
        assert!(f.residual_rms < 1e-12);
        assert_eq!(f.dof, 18);
    }

    #[test]
    fn straight_line_statistics_match_closed_form() {
        // Simple regression y = a + b x: se(b) = sigma / sqrt(sum (x - xbar)^2).
        let mut rng = SplitMix64(7);
        let x: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let one = alloc::vec![1.0; 50];
        let y: Vec<f64> = x
            .iter()
            .map(|x| 1.0 + 0.5 * x + 0.1 * rng.normal())
            .collect();
        let f = fit(&[&x, &one], &y, Covariance::Iid).unwrap();
        let xbar = x.iter().sum::<f64>() / 50.0;
        let sxx: f64 = x.iter().map(|v| (v - xbar) * (v - xbar)).sum();
        let rss: f64 = x
            .iter()
            .zip(&y)
            .map(|(x, y)| (y - f.theta[1] - f.theta[0] * x).powi(2))
            .sum();
        let se_b = (rss / 48.0).sqrt() / sxx.sqrt();
        assert!(
            (f.std_err[0] - se_b).abs() < 1e-12 * se_b.max(1.0),
            "{} vs {se_b}",
            f.std_err[0]
        );
        let t = t95(48.0);
        assert!((f.ci95[0].1 - f.theta[0] - t * se_b).abs() < 1e-12);
        assert!(f.cond > 1.0 && f.cond < 10.0);
    }

    #[test]
    fn coverage_of_intervals_is_about_95_percent() {
        let mut rng = SplitMix64(11);
        let x: Vec<f64> = (0..12).map(|i| i as f64).collect();
        let one = alloc::vec![1.0; 12];
        let mut hits = 0;
        for _ in 0..1000 {
            let y: Vec<f64> = x.iter().map(|x| 2.0 * x + 1.0 + rng.normal()).collect();
            let f = fit(&[&x, &one], &y, Covariance::Iid).unwrap();
            if f.ci95[0].0 <= 2.0 && 2.0 <= f.ci95[0].1 {
                hits += 1;
            }
        }
        assert!((920..=975).contains(&hits), "coverage {hits}/1000");
    }

    #[test]
    fn block_covariance_widens_for_correlated_noise() {
        // AR(1) noise with strong correlation: the iid formula understates the uncertainty.
        let mut rng = SplitMix64(3);
        let n = 4000;
        let x: Vec<f64> = (0..n).map(|i| crate::math::sin(i as f64 * 0.001)).collect();
        let mut e = 0.0;
        let y: Vec<f64> = x
            .iter()
            .map(|x| {
                e = 0.99 * e + 0.1 * rng.normal();
                x + e
            })
            .collect();
        let iid = fit(&[&x], &y, Covariance::Iid).unwrap();
        let blk = fit(&[&x], &y, Covariance::Blocks(20)).unwrap();
        assert!(
            blk.std_err[0] > 3.0 * iid.std_err[0],
            "{} vs {}",
            blk.std_err[0],
            iid.std_err[0]
        );
        assert_eq!(blk.dof, 19);
    }

    #[test]
    fn collinear_columns_are_refused() {
        let x: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let x2: Vec<f64> = x.iter().map(|v| 2.0 * v).collect();
        let y = x.clone();
        assert!(matches!(
            fit(&[&x, &x2], &y, Covariance::Iid),
            Err(IdentError::RankDeficient { .. })
        ));
        assert!(matches!(
            fit(&[&x], &y[..1], Covariance::Iid),
            Err(IdentError::Internal(_))
        ));
        assert!(matches!(
            fit(&[&x[..1]], &y[..1], Covariance::Iid),
            Err(IdentError::TooFewData { .. })
        ));
    }
}
