//! The closed position loop (unity feedback, controller on the error r - theta_l) as a state-space
//! model, its poles and a stability verdict, in continuous time and at T_s with the ZOH plant.

use super::controller::{ControllerRealisation, Discretization};
use super::ss::{DiscreteStateSpace, StateSpace};
use super::{c_abs, Complex, PidGains};
use alloc::vec::Vec;
use nalgebra::{DMatrix, DVector};

/// Closed loop r -> theta_l: x+ = A x + B r (x' in continuous time), y = C x.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedLoop {
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    pub c: DVector<f64>,
    /// `None`: continuous time; `Some(T_s)`: discrete time at T_s [s].
    pub ts_s: Option<f64>,
}

/// Stability verdict from the closed-loop poles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stability {
    /// All poles strictly inside the stability region.
    Stable,
    /// A pole on the boundary (Re s = 0 or |z| = 1, within 1e-9 relative).
    Marginal,
    Unstable,
}

fn close(
    pa: &DMatrix<f64>,
    pb: &DVector<f64>,
    pc: &DVector<f64>,
    k: &ControllerRealisation,
    ts_s: Option<f64>,
) -> ClosedLoop {
    let n = pa.nrows();
    let m = k.order;
    let mut a = DMatrix::<f64>::zeros(n + m, n + m);
    let mut b = DVector::<f64>::zeros(n + m);
    // plant: x+ = pa x + pb (d e + Cc xc), e = r - pc x
    a.view_mut((0, 0), (n, n))
        .copy_from(&(pa - pb * pc.transpose() * k.d));
    for j in 0..m {
        for i in 0..n {
            a[(i, n + j)] = pb[i] * k.c[j];
        }
    }
    for i in 0..n {
        b[i] = pb[i] * k.d;
    }
    // controller: xc+ = ac xc + bc (r - pc x)
    for j in 0..m {
        for i in 0..n {
            a[(n + j, i)] = -k.b[j] * pc[i];
        }
        a[(n + j, n + j)] = k.a[j];
        b[n + j] = k.b[j];
    }
    let mut c = DVector::<f64>::zeros(n + m);
    c.rows_mut(0, n).copy_from(pc);
    ClosedLoop { a, b, c, ts_s }
}

impl ClosedLoop {
    /// Continuous loop of a plant and the controller with real derivative (needs T_L > 0 if K_D != 0).
    pub fn continuous(plant: &StateSpace, gains: &PidGains) -> Option<ClosedLoop> {
        let k = ControllerRealisation::continuous(gains)?;
        Some(close(&plant.a, &plant.b, &plant.c, &k, None))
    }

    /// Discrete loop: ZOH plant and the discrete PID at the same T_s.
    pub fn discrete(
        plant: &DiscreteStateSpace,
        gains: &PidGains,
        method: Discretization,
    ) -> ClosedLoop {
        let k = ControllerRealisation::discrete(gains, plant.ts_s, method);
        close(&plant.phi, &plant.gamma, &plant.c, &k, Some(plant.ts_s))
    }

    /// Closed-loop poles (eigenvalues of A): s [rad/s] or z [-].
    pub fn poles(&self) -> Vec<Complex<f64>> {
        self.a.complex_eigenvalues().iter().copied().collect()
    }

    /// Stability verdict from the poles.
    pub fn stability(&self) -> Stability {
        classify(&self.poles(), self.ts_s.is_some())
    }
}

/// Stable / marginal / unstable from poles (continuous: real parts; discrete: moduli).
pub fn classify(poles: &[Complex<f64>], discrete: bool) -> Stability {
    let mut verdict = Stability::Stable;
    for p in poles {
        let margin = if discrete { 1.0 - c_abs(*p) } else { -p.re };
        let tol = if discrete {
            1e-9
        } else {
            1e-9 * c_abs(*p).max(1e-6)
        };
        if margin < -tol {
            return Stability::Unstable;
        }
        if margin <= tol {
            verdict = Stability::Marginal;
        }
    }
    verdict
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::tf::TransferFunction;
    use crate::design::PlantModel;
    use crate::params::PlantParams;

    /// The closed-loop poles are the roots of D_L + N_L of the loop transfer function, checked by
    /// evaluating that polynomial at each pole.
    #[test]
    fn poles_are_roots_of_characteristic_polynomial() {
        let g = PidGains {
            kp: 7.0476,
            ki: 86.121,
            kd: 0.14418,
            tl_s: 1.0 / 150.0,
        };
        for model in [
            PlantModel::reduced(&PlantParams::TABLE2),
            PlantModel::full(&PlantParams::TABLE2),
        ] {
            let cl = ClosedLoop::continuous(&model.state_space(), &g).unwrap();
            // C(s) = (kp s (tl s + 1) + ki (tl s + 1) + kd s^2) / (s (tl s + 1))
            let cnum = alloc::vec![g.ki, g.kp + g.ki * g.tl_s, g.kp * g.tl_s + g.kd];
            let cden = alloc::vec![0.0, 1.0, g.tl_s];
            let l = TransferFunction::new(cnum, cden).series(&model.transfer_function());
            let ch = l.feedback_unity().den;
            let poles = cl.poles();
            assert_eq!(poles.len(), ch.len() - 1);
            let scale: f64 = ch.iter().map(|c| c.abs()).fold(0.0, f64::max);
            for p in &poles {
                let v = TransferFunction::poly_eval(&ch, *p);
                let mag = ch
                    .iter()
                    .enumerate()
                    .map(|(k, c)| c.abs() * c_abs(*p).powi(k as i32))
                    .sum::<f64>();
                assert!(
                    c_abs(v) < 1e-8 * mag.max(scale),
                    "{} pole {p}",
                    model.name()
                );
            }
            assert_eq!(cl.stability(), Stability::Stable);
        }
    }

    #[test]
    fn too_much_gain_is_unstable_in_discrete_time() {
        let model = PlantModel::full(&PlantParams::TABLE2);
        let g = PidGains {
            kp: 2000.0,
            ki: 0.0,
            kd: 0.0,
            tl_s: 0.0,
        };
        let d = model.state_space().discretize_zoh(1e-3);
        assert_eq!(
            ClosedLoop::discrete(&d, &g, Discretization::Tustin).stability(),
            Stability::Unstable
        );
        let g = PidGains { kp: 5.0, ..g };
        assert_eq!(
            ClosedLoop::discrete(&d, &g, Discretization::Tustin).stability(),
            Stability::Stable
        );
    }
}
