//! The controller as implemented: continuous C(s) with the real derivative (eq. 53) and its
//! discrete version C(z) at T_s, in the state-space form used to close the loop.
//!
//! Discrete PID (derivative on the error, as in the loop analysis):
//! u[k] = K_P e[k] + K_I I[k] + K_D D[k], where the integral and the filtered derivative
//! s/(T_L s + 1) are discretised with backward Euler (s <- (z - 1)/(T_s z)) or Tustin
//! (s <- 2/T_s (z - 1)/(z + 1)), exactly as `control::pid::Pid` does. The output is applied at
//! once and held (ZOH) for one period.

use super::{c_expj, Complex, PidGains};

/// Discretisation of the integral and the filtered derivative: the rule the discrete controller
/// (`control::pid`) implements, so the verification analyses the controller that will run.
pub use crate::control::pid::Discretization;

impl Discretization {
    /// "backward-euler" or "tustin".
    pub fn name(&self) -> &'static str {
        match self {
            Discretization::BackwardEuler => "backward-euler",
            Discretization::Tustin => "tustin",
        }
    }
}

/// Controller realisation u = Dc e + Cc xc, xc' = Ac xc + Bc e (continuous) or
/// xc[k+1] = Ac xc[k] + Bc e[k] (discrete). Ac is diagonal: at most an integrator and a filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerRealisation {
    /// Number of states (0..=2).
    pub order: usize,
    /// Diagonal of Ac.
    pub a: [f64; 2],
    pub b: [f64; 2],
    pub c: [f64; 2],
    pub d: f64,
}

impl ControllerRealisation {
    fn push(&mut self, a: f64, b: f64, c: f64) {
        self.a[self.order] = a;
        self.b[self.order] = b;
        self.c[self.order] = c;
        self.order += 1;
    }

    /// Continuous realisation of C(s) = K_P + K_I/s + K_D s/(T_L s + 1); requires T_L > 0 when
    /// K_D != 0 (an ideal derivative has no state space).
    pub fn continuous(g: &PidGains) -> Option<ControllerRealisation> {
        let mut r = ControllerRealisation {
            order: 0,
            a: [0.0; 2],
            b: [0.0; 2],
            c: [0.0; 2],
            d: g.kp,
        };
        if g.ki != 0.0 {
            r.push(0.0, 1.0, g.ki);
        }
        if g.kd != 0.0 {
            if g.tl_s <= 0.0 {
                return None;
            }
            // K_D s/(T_L s + 1) = K_D/T_L (1 - 1/(T_L s + 1)); x_f' = (e - x_f)/T_L
            r.push(-1.0 / g.tl_s, 1.0 / g.tl_s, -g.kd / g.tl_s);
            r.d += g.kd / g.tl_s;
        }
        Some(r)
    }

    /// Discrete realisation of C(z) at T_s [s].
    pub fn discrete(g: &PidGains, ts_s: f64, method: Discretization) -> ControllerRealisation {
        let mut r = ControllerRealisation {
            order: 0,
            a: [0.0; 2],
            b: [0.0; 2],
            c: [0.0; 2],
            d: g.kp,
        };
        if g.ki != 0.0 {
            // s_next = s + T_s e; I = s + c_i T_s e, c_i = 1 (BE) or 1/2 (Tustin)
            let ci = match method {
                Discretization::BackwardEuler => 1.0,
                Discretization::Tustin => 0.5,
            };
            r.push(1.0, ts_s, g.ki);
            r.d += g.ki * ci * ts_s;
        }
        if g.kd != 0.0 {
            // H(z) = gain (z - 1)/(z - p) = gain (1 + (p - 1)/(z - p)); w_next = p w + e
            let (gain, p) = match method {
                Discretization::BackwardEuler => (1.0 / (g.tl_s + ts_s), g.tl_s / (g.tl_s + ts_s)),
                Discretization::Tustin => (
                    2.0 / (2.0 * g.tl_s + ts_s),
                    (2.0 * g.tl_s - ts_s) / (2.0 * g.tl_s + ts_s),
                ),
            };
            r.push(p, 1.0, g.kd * gain * (p - 1.0));
            r.d += g.kd * gain;
        }
        r
    }

    /// Transfer value at s (continuous) or z (discrete): Dc + sum c_i b_i / (x - a_i).
    pub fn eval(&self, x: Complex<f64>) -> Complex<f64> {
        let mut v = Complex::new(self.d, 0.0);
        for i in 0..self.order {
            v += Complex::new(self.c[i] * self.b[i], 0.0) / (x - self.a[i]);
        }
        v
    }
}

#[cfg(feature = "alloc")]
impl ControllerRealisation {
    /// The rational transfer function of the realisation in s or z (coefficients ASCENDING):
    /// D prod(x - a_i) + sum_i c_i b_i prod_{j != i}(x - a_j) over prod(x - a_i).
    pub fn transfer_function(&self) -> super::tf::TransferFunction {
        use super::tf::TransferFunction as Tf;
        let mut den = alloc::vec![1.0];
        for i in 0..self.order {
            den = Tf::poly_mul(&den, &[-self.a[i], 1.0]);
        }
        let mut num: alloc::vec::Vec<f64> = den.iter().map(|c| c * self.d).collect();
        for i in 0..self.order {
            let mut term = alloc::vec![self.c[i] * self.b[i]];
            for j in 0..self.order {
                if j != i {
                    term = Tf::poly_mul(&term, &[-self.a[j], 1.0]);
                }
            }
            num = Tf::poly_add(&num, &term);
        }
        Tf::new(num, den)
    }
}

/// C(s) = K_P + K_I/s + K_D s/(T_L s + 1) as a rational function of s (ascending coefficients):
/// ((K_P T_L + K_D) s^2 + (K_P + K_I T_L) s + K_I) / (T_L s^2 + s), reduced when K_I, K_D or
/// T_L is zero.
#[cfg(feature = "alloc")]
pub fn controller_tf_s(g: &PidGains) -> super::tf::TransferFunction {
    use super::tf::TransferFunction as Tf;
    let mut num = alloc::vec![g.kp];
    let mut den = alloc::vec![1.0];
    let mut add = |n: &[f64], d: &[f64]| {
        // num/den + n/d
        let new_num = Tf::poly_add(&Tf::poly_mul(&num, d), &Tf::poly_mul(n, &den));
        den = Tf::poly_mul(&den, d);
        num = new_num;
    };
    if g.ki != 0.0 {
        add(&[g.ki], &[0.0, 1.0]);
    }
    if g.kd != 0.0 {
        add(&[0.0, g.kd], &[1.0, g.tl_s]);
    }
    Tf::new(num, den)
}

/// C(z) of the discrete PID at T_s [s] (ascending powers of z), from the realisation that
/// [`crate::control::pid::Pid`] runs.
#[cfg(feature = "alloc")]
pub fn controller_tf_z(
    g: &PidGains,
    ts_s: f64,
    method: Discretization,
) -> super::tf::TransferFunction {
    ControllerRealisation::discrete(g, ts_s, method).transfer_function()
}

/// Discrete controller response C(e^{j w T_s}), w [rad/s].
pub fn discrete_response(
    g: &PidGains,
    ts_s: f64,
    method: Discretization,
    omega: f64,
) -> Complex<f64> {
    ControllerRealisation::discrete(g, ts_s, method).eval(c_expj(omega * ts_s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::c_abs;

    const G: PidGains = PidGains {
        kp: 7.0,
        ki: 86.0,
        kd: 0.144,
        tl_s: 1.0 / 150.0,
    };

    #[test]
    fn continuous_realisation_matches_formula() {
        let r = ControllerRealisation::continuous(&G).unwrap();
        for w in [0.3, 30.0, 3000.0] {
            let s = Complex::new(0.0, w);
            assert!(c_abs(r.eval(s) - G.eval(s)) < 1e-12 * c_abs(G.eval(s)));
        }
        assert!(ControllerRealisation::continuous(&PidGains { tl_s: 0.0, ..G }).is_none());
    }

    #[test]
    fn transfer_functions_match_the_responses() {
        let ts = 1e-3;
        for g in [
            G,
            PidGains {
                kd: 0.0,
                tl_s: 0.0,
                ..G
            },
            PidGains { ki: 0.0, ..G },
        ] {
            let cs = controller_tf_s(&g);
            for method in [Discretization::BackwardEuler, Discretization::Tustin] {
                let cz = controller_tf_z(&g, ts, method);
                for w in [0.5, 30.0, 1000.0] {
                    let s = Complex::new(0.0, w);
                    assert!(c_abs(cs.eval(s) - g.eval(s)) < 1e-9 * c_abs(g.eval(s)));
                    let d = discrete_response(&g, ts, method, w);
                    assert!(
                        c_abs(cz.eval(c_expj(w * ts)) - d) < 1e-9 * c_abs(d),
                        "{method:?} {w}"
                    );
                }
            }
        }
        // PID: second order over s (T_L s + 1)
        let cs = controller_tf_s(&G);
        assert_eq!(cs.den.len(), 3);
        assert!((cs.num[2] - (G.kp * G.tl_s + G.kd)).abs() < 1e-12);
    }

    #[test]
    fn discrete_matches_substitution() {
        let ts = 1e-3;
        for w in [0.5, 30.0, 1000.0] {
            let z = c_expj(w * ts);
            let one = Complex::new(1.0, 0.0);
            // backward Euler: s = (z - 1)/(Ts z)
            let s_be = (z - one) / (z * ts);
            let be = discrete_response(&G, ts, Discretization::BackwardEuler, w);
            assert!(c_abs(be - G.eval(s_be)) < 1e-9 * c_abs(be), "BE w={w}");
            let s_tu = (z - one) / (z + one) * (2.0 / ts);
            let tu = discrete_response(&G, ts, Discretization::Tustin, w);
            assert!(c_abs(tu - G.eval(s_tu)) < 1e-9 * c_abs(tu), "Tustin w={w}");
        }
    }
}
