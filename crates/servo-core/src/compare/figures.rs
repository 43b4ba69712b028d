//! Goodness-of-fit figures of one signal: fit %, RMSE, maximum error.
//!
//! The fit percentage is the normalised root-mean-square figure of MATLAB's `compare` (System
//! Identification Toolbox, `goodnessOfFit(..., 'NRMSE')` expressed as a percentage):
//!
//! fit = 100 (1 - ||y - y_hat|| / ||y - mean(y)||)
//!
//! 100 % is a perfect match, 0 % is no better than the mean of the measurement, and it is negative
//! when the model is worse than that constant.

use crate::math;

/// Figures of one compared signal (units of the signal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// Fit [%] as MATLAB's `compare` defines it (NaN when the measurement is constant).
    pub fit_percent: f64,
    /// Root-mean-square error, in the unit of the signal.
    pub rmse: f64,
    /// Largest absolute error, in the unit of the signal.
    pub max_abs_error: f64,
    /// Index of the sample where the largest error occurs.
    pub max_error_index: usize,
    /// Mean error (measurement minus model): a bias.
    pub mean_error: f64,
    /// Number of samples used.
    pub samples: usize,
}

/// Fit [%] = 100 (1 - ||y - y_hat|| / ||y - mean(y)||); NaN when y is constant or the slices are
/// empty or of different lengths.
pub fn fit_percent(y: &[f64], y_hat: &[f64]) -> f64 {
    if y.is_empty() || y.len() != y_hat.len() {
        return f64::NAN;
    }
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let (mut num, mut den) = (0.0, 0.0);
    for (a, b) in y.iter().zip(y_hat) {
        num += (a - b) * (a - b);
        den += (a - mean) * (a - mean);
    }
    if den <= 0.0 {
        return f64::NAN;
    }
    100.0 * (1.0 - math::sqrt(num) / math::sqrt(den))
}

/// Root-mean-square of `y - y_hat` (NaN when empty or of different lengths).
pub fn rmse(y: &[f64], y_hat: &[f64]) -> f64 {
    if y.is_empty() || y.len() != y_hat.len() {
        return f64::NAN;
    }
    let s: f64 = y.iter().zip(y_hat).map(|(a, b)| (a - b) * (a - b)).sum();
    math::sqrt(s / y.len() as f64)
}

impl Figures {
    /// All figures of measurement `y` against model `y_hat`.
    pub fn of(y: &[f64], y_hat: &[f64]) -> Figures {
        let n = y.len().min(y_hat.len());
        let (mut max_abs_error, mut max_error_index, mut sum) = (0.0f64, 0usize, 0.0);
        for (i, (a, b)) in y.iter().zip(y_hat).enumerate() {
            let e = a - b;
            sum += e;
            let ae = libm::fabs(e);
            if ae > max_abs_error {
                max_abs_error = ae;
                max_error_index = i;
            }
        }
        Figures {
            fit_percent: fit_percent(&y[..n], &y_hat[..n]),
            rmse: rmse(&y[..n], &y_hat[..n]),
            max_abs_error,
            max_error_index,
            mean_error: if n > 0 { sum / n as f64 } else { f64::NAN },
            samples: n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_percent_by_hand() {
        // y = [1, 2, 3, 4], mean 2.5, ||y - mean|| = sqrt(2.25 + 0.25 + 0.25 + 2.25) = sqrt(5)
        // y_hat = [1, 2, 3, 3]: ||e|| = 1 -> fit = 100 (1 - 1/sqrt(5)) = 55.27864045...
        let y = [1.0, 2.0, 3.0, 4.0];
        let f = fit_percent(&y, &[1.0, 2.0, 3.0, 3.0]);
        assert!((f - 55.278_640_450_004_2).abs() < 1e-9, "{f}");
        assert!((fit_percent(&y, &y) - 100.0).abs() < 1e-12);
        // The mean itself scores 0 %; worse than the mean is negative.
        assert!(fit_percent(&y, &[2.5; 4]).abs() < 1e-12);
        assert!(fit_percent(&y, &[4.0, 3.0, 2.0, 1.0]) < 0.0);
        assert!(fit_percent(&[1.0; 3], &[1.0; 3]).is_nan());
        assert!(fit_percent(&y, &[1.0]).is_nan());
    }

    #[test]
    fn rmse_and_max_error_by_hand() {
        let f = Figures::of(&[0.0, 1.0, 2.0], &[0.0, 0.0, 5.0]);
        // errors 0, 1, -3: rmse = sqrt(10/3)
        assert!((f.rmse - (10.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(f.max_abs_error, 3.0);
        assert_eq!(f.max_error_index, 2);
        assert!((f.mean_error + 2.0 / 3.0).abs() < 1e-12);
    }
}
