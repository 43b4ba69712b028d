//! Single-input single-output state space x' = A x + B u, y = C x + D u, its frequency response
//! and its exact zero-order-hold discretisation.

use super::Complex;
use crate::linalg::expm;
use alloc::vec::Vec;
use nalgebra::{DMatrix, DVector};

/// SISO state-space model.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace {
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    pub c: DVector<f64>,
    pub d: f64,
}

/// Exact ZOH discretisation: x[k+1] = phi x[k] + gamma u[k], y[k] = C x[k] + D u[k].
#[derive(Debug, Clone, PartialEq)]
pub struct DiscreteStateSpace {
    pub phi: DMatrix<f64>,
    pub gamma: DVector<f64>,
    pub c: DVector<f64>,
    pub d: f64,
    /// Sample period T_s [s].
    pub ts_s: f64,
}

impl StateSpace {
    /// From row-major A (n x n), B and C (length n), D = 0.
    pub fn from_rows(n: usize, a: &[f64], b: &[f64], c: &[f64]) -> StateSpace {
        StateSpace {
            a: DMatrix::from_row_slice(n, n, a),
            b: DVector::from_column_slice(b),
            c: DVector::from_column_slice(c),
            d: 0.0,
        }
    }

    /// Number of states.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// G(s) = C (sI - A)^-1 B + D.
    pub fn eval(&self, s: Complex<f64>) -> Complex<f64> {
        resolvent_gain(&self.a, &self.b, &self.c, self.d, s)
    }

    /// Exact ZOH discretisation at T_s [s] via the exponential of [[A, B], [0, 0]] T_s.
    pub fn discretize_zoh(&self, ts_s: f64) -> DiscreteStateSpace {
        let n = self.order();
        let mut m = DMatrix::<f64>::zeros(n + 1, n + 1);
        m.view_mut((0, 0), (n, n)).copy_from(&(&self.a * ts_s));
        m.view_mut((0, n), (n, 1)).copy_from(&(&self.b * ts_s));
        let e = expm(&m);
        DiscreteStateSpace {
            phi: e.view((0, 0), (n, n)).into_owned(),
            gamma: e.view((0, n), (n, 1)).column(0).into_owned(),
            c: self.c.clone(),
            d: self.d,
            ts_s,
        }
    }
}

impl DiscreteStateSpace {
    /// G(z) = C (zI - phi)^-1 gamma + D.
    pub fn eval(&self, z: Complex<f64>) -> Complex<f64> {
        resolvent_gain(&self.phi, &self.gamma, &self.c, self.d, z)
    }

    /// Frequency response G(e^{j w T_s}), w [rad/s].
    pub fn response(&self, omega: f64) -> Complex<f64> {
        self.eval(super::c_expj(omega * self.ts_s))
    }
}

/// C (sI - A)^-1 B + D by Gaussian elimination with partial pivoting on the complex system.
fn resolvent_gain(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    c: &DVector<f64>,
    d: f64,
    s: Complex<f64>,
) -> Complex<f64> {
    let n = a.nrows();
    let mut m: Vec<Complex<f64>> = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            let diag = if i == j { s } else { Complex::new(0.0, 0.0) };
            m.push(diag - a[(i, j)]);
        }
    }
    let mut x: Vec<Complex<f64>> = b.iter().map(|&v| Complex::new(v, 0.0)).collect();
    for col in 0..n {
        let mut piv = col;
        for r in col + 1..n {
            if super::c_abs(m[r * n + col]) > super::c_abs(m[piv * n + col]) {
                piv = r;
            }
        }
        if piv != col {
            for j in 0..n {
                m.swap(col * n + j, piv * n + j);
            }
            x.swap(col, piv);
        }
        let p = m[col * n + col];
        if super::c_abs(p) == 0.0 {
            return Complex::new(f64::INFINITY, 0.0);
        }
        for r in col + 1..n {
            let f = m[r * n + col] / p;
            if f.re == 0.0 && f.im == 0.0 {
                continue;
            }
            for j in col..n {
                let v = m[col * n + j];
                m[r * n + j] -= f * v;
            }
            let xv = x[col];
            x[r] -= f * xv;
        }
    }
    for col in (0..n).rev() {
        let mut acc = x[col];
        for j in col + 1..n {
            acc -= m[col * n + j] * x[j];
        }
        x[col] = acc / m[col * n + col];
    }
    x.iter()
        .zip(c.iter())
        .fold(Complex::new(d, 0.0), |acc, (xi, &ci)| acc + xi * ci)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zoh_of_first_order_lag() {
        // x' = -x/T + u/T: phi = e^{-Ts/T}, gamma = 1 - e^{-Ts/T}
        let ss = StateSpace::from_rows(1, &[-10.0], &[10.0], &[1.0]);
        let d = ss.discretize_zoh(0.01);
        let e = (-0.1f64).exp();
        assert!((d.phi[(0, 0)] - e).abs() < 1e-14);
        assert!((d.gamma[0] - (1.0 - e)).abs() < 1e-14);
    }

    #[test]
    fn zoh_of_integrator_chain() {
        // double integrator: phi = [[1, 0], [Ts, 1]], gamma = [Ts, Ts^2/2] (x1' = u, x2' = x1)
        let ss = StateSpace::from_rows(2, &[0.0, 0.0, 1.0, 0.0], &[1.0, 0.0], &[0.0, 1.0]);
        let d = ss.discretize_zoh(0.1);
        assert!((d.phi[(1, 0)] - 0.1).abs() < 1e-14);
        assert!((d.gamma[1] - 0.005).abs() < 1e-14);
    }
}
