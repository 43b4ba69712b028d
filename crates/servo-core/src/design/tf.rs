//! Rational transfer functions N(s)/D(s) with real coefficients in ASCENDING powers of s
//! (`num[k]` multiplies s^k), as used for the plant, the controller and the loop.

use super::Complex;
use alloc::vec::Vec;

/// N(s)/D(s), coefficients in ascending powers.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    /// Numerator coefficients, ascending powers of s.
    pub num: Vec<f64>,
    /// Denominator coefficients, ascending powers of s.
    pub den: Vec<f64>,
}

impl TransferFunction {
    /// Builds N(s)/D(s).
    pub fn new(num: Vec<f64>, den: Vec<f64>) -> TransferFunction {
        TransferFunction { num, den }
    }

    /// Product of two polynomials (ascending coefficients).
    pub fn poly_mul(a: &[f64], b: &[f64]) -> Vec<f64> {
        let mut out = alloc::vec![0.0; a.len() + b.len() - 1];
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                out[i + j] += x * y;
            }
        }
        out
    }

    /// Sum of two polynomials.
    pub fn poly_add(a: &[f64], b: &[f64]) -> Vec<f64> {
        let mut out = alloc::vec![0.0; a.len().max(b.len())];
        for (i, x) in a.iter().enumerate() {
            out[i] += x;
        }
        for (i, y) in b.iter().enumerate() {
            out[i] += y;
        }
        out
    }

    /// Evaluates a polynomial at s (Horner).
    pub fn poly_eval(p: &[f64], s: Complex<f64>) -> Complex<f64> {
        p.iter()
            .rev()
            .fold(Complex::new(0.0, 0.0), |acc, &c| acc * s + c)
    }

    /// G(s).
    pub fn eval(&self, s: Complex<f64>) -> Complex<f64> {
        Self::poly_eval(&self.num, s) / Self::poly_eval(&self.den, s)
    }

    /// Series connection G1 G2.
    pub fn series(&self, other: &TransferFunction) -> TransferFunction {
        TransferFunction::new(
            Self::poly_mul(&self.num, &other.num),
            Self::poly_mul(&self.den, &other.den),
        )
    }

    /// Coefficients of `p` (ascending) in DESCENDING powers, leading zeros dropped (the order of
    /// MATLAB's `tf` and python-control's `tf`; `[0.0]` for the zero polynomial).
    pub fn descending(p: &[f64]) -> Vec<f64> {
        let top = p.iter().rposition(|&c| c != 0.0).unwrap_or(0);
        p[..=top.min(p.len().saturating_sub(1))]
            .iter()
            .rev()
            .copied()
            .collect()
    }

    /// Unity negative feedback T = G / (1 + G) and the characteristic polynomial D + N.
    pub fn feedback_unity(&self) -> TransferFunction {
        TransferFunction::new(self.num.clone(), Self::poly_add(&self.den, &self.num))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn algebra() {
        // (1 + s)(2 + s) = 2 + 3 s + s^2
        assert_eq!(
            TransferFunction::poly_mul(&[1.0, 1.0], &[2.0, 1.0]),
            alloc::vec![2.0, 3.0, 1.0]
        );
        let g = TransferFunction::new(alloc::vec![2.0], alloc::vec![0.0, 1.0]); // 2/s
        let t = g.feedback_unity(); // 2/(s + 2)
        assert_eq!(t.den, alloc::vec![2.0, 1.0]);
        assert_eq!(
            TransferFunction::descending(&[0.0, 1.0, 2.0, 0.0]),
            alloc::vec![2.0, 1.0, 0.0]
        );
        assert_eq!(TransferFunction::descending(&[0.0, 0.0]), alloc::vec![0.0]);
        let v = t.eval(Complex::new(0.0, 2.0)); // 2/(2 + 2j) = 0.5 - 0.5j
        assert!((v.re - 0.5).abs() < 1e-15 && (v.im + 0.5).abs() < 1e-15);
    }
}
