//! The gearmotor as a linear plant from driver input u [V] to load angle theta_l [rad]:
//! the full model of eq. 27 (driver low-pass, armature R-L, mechanics, integrator) and the
//! reduced model of eq. 29, P(s) = k_m / ((T_m s + 1) N s).

use super::Complex;
use crate::params::PlantParams;
use crate::DesignError;

/// A linear plant model u [V] -> theta_l [rad].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlantModel {
    /// Eq. 29: P(s) = k_m / ((T_m s + 1) N s).
    Reduced {
        /// Static gain k_m [rad/(V s)] at motor side (eq. 30).
        k_m: f64,
        /// Mechanical time constant T_m [s] (eq. 30).
        t_m: f64,
        /// Gear ratio N [-].
        n: f64,
    },
    /// Eq. 27: P(s) = k_drv/(T_drv s + 1) * k_t/((L_a s + R_eq)(J_eq s + B_eq) + k_t k_e) * 1/(N s).
    Full {
        /// Driver gain k_drv [V/V].
        k_drv: f64,
        /// Driver time constant T_drv [s].
        t_drv: f64,
        /// Armature inductance L_a [H].
        l_a: f64,
        /// R_a + R_s [ohm].
        r_eq: f64,
        /// Torque constant k_t [N m/A].
        k_t: f64,
        /// BEMF constant k_e [V s/rad].
        k_e: f64,
        /// Total inertia at motor side J_eq [kg m^2].
        j_eq: f64,
        /// Total viscous friction at motor side B_eq [N m s/rad].
        b_eq: f64,
        /// Gear ratio N [-].
        n: f64,
    },
}

impl PlantModel {
    /// Reduced model (eq. 29) of a parameter set.
    pub fn reduced(p: &PlantParams) -> PlantModel {
        PlantModel::Reduced {
            k_m: p.k_m(),
            t_m: p.t_m(),
            n: p.n,
        }
    }

    /// Reduced model given directly by k_m [rad/(V s)], T_m [s] and N.
    pub fn reduced_from(k_m: f64, t_m: f64, n: f64) -> Result<PlantModel, DesignError> {
        for (name, v) in [("k_m [rad/(V s)]", k_m), ("T_m [s]", t_m), ("N [-]", n)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(DesignError::OutOfRange {
                    name,
                    value: v,
                    why: "a plant constant must be finite and > 0",
                });
            }
        }
        Ok(PlantModel::Reduced { k_m, t_m, n })
    }

    /// Full model (eq. 27) of a parameter set.
    pub fn full(p: &PlantParams) -> PlantModel {
        PlantModel::Full {
            k_drv: p.k_drv,
            t_drv: p.t_drv(),
            l_a: p.l_a,
            r_eq: p.r_eq(),
            k_t: p.k_t,
            k_e: p.k_e,
            j_eq: p.j_eq(),
            b_eq: p.b_eq(),
            n: p.n,
        }
    }

    /// Short name: "reduced" or "full".
    pub fn name(&self) -> &'static str {
        match self {
            PlantModel::Reduced { .. } => "reduced",
            PlantModel::Full { .. } => "full",
        }
    }

    /// Evaluates P(s) at a complex s.
    pub fn eval(&self, s: Complex<f64>) -> Complex<f64> {
        let one = Complex::new(1.0, 0.0);
        match *self {
            PlantModel::Reduced { k_m, t_m, n } => {
                Complex::new(k_m, 0.0) / ((s * t_m + one) * s * n)
            }
            PlantModel::Full {
                k_drv,
                t_drv,
                l_a,
                r_eq,
                k_t,
                k_e,
                j_eq,
                b_eq,
                n,
            } => {
                let elec_mech = (s * l_a + r_eq) * (s * j_eq + b_eq) + k_t * k_e;
                Complex::new(k_drv * k_t, 0.0) / ((s * t_drv + one) * elec_mech * s * n)
            }
        }
    }

    /// Frequency response P(jw), w [rad/s].
    pub fn response(&self, omega: f64) -> Complex<f64> {
        self.eval(Complex::new(0.0, omega))
    }

    /// The fastest pole magnitude [rad/s] (to size frequency sweeps).
    pub fn fastest_pole(&self) -> f64 {
        match *self {
            PlantModel::Reduced { t_m, .. } => 1.0 / t_m,
            PlantModel::Full {
                t_drv, l_a, r_eq, ..
            } => (1.0 / t_drv).max(r_eq / l_a),
        }
    }
}

#[cfg(feature = "alloc")]
mod realisations {
    use super::PlantModel;
    use crate::design::ss::StateSpace;
    use crate::design::tf::TransferFunction;
    use alloc::vec;

    impl PlantModel {
        /// Rational transfer function (coefficients in ascending powers of s).
        pub fn transfer_function(&self) -> TransferFunction {
            match *self {
                PlantModel::Reduced { k_m, t_m, n } => {
                    TransferFunction::new(vec![k_m], vec![0.0, n, n * t_m])
                }
                PlantModel::Full {
                    k_drv,
                    t_drv,
                    l_a,
                    r_eq,
                    k_t,
                    k_e,
                    j_eq,
                    b_eq,
                    n,
                } => {
                    // (L s + R)(J s + B) + k_t k_e = L J s^2 + (L B + R J) s + (R B + k_t k_e)
                    let em = TransferFunction::poly_mul(
                        &[
                            r_eq * b_eq + k_t * k_e,
                            l_a * b_eq + r_eq * j_eq,
                            l_a * j_eq,
                        ],
                        &[1.0, t_drv],
                    );
                    let den = TransferFunction::poly_mul(&em, &[0.0, n]);
                    TransferFunction::new(vec![k_drv * k_t], den)
                }
            }
        }

        /// Physical state-space realisation, input u [V], output theta_l [rad].
        ///
        /// Reduced: x = [omega_m, theta_l]. Full: x = [u_drv, i_a, omega_m, theta_l].
        pub fn state_space(&self) -> StateSpace {
            match *self {
                PlantModel::Reduced { k_m, t_m, n } => StateSpace::from_rows(
                    2,
                    &[-1.0 / t_m, 0.0, 1.0 / n, 0.0],
                    &[k_m / t_m, 0.0],
                    &[0.0, 1.0],
                ),
                PlantModel::Full {
                    k_drv,
                    t_drv,
                    l_a,
                    r_eq,
                    k_t,
                    k_e,
                    j_eq,
                    b_eq,
                    n,
                } => StateSpace::from_rows(
                    4,
                    &[
                        -1.0 / t_drv,
                        0.0,
                        0.0,
                        0.0, //
                        1.0 / l_a,
                        -r_eq / l_a,
                        -k_e / l_a,
                        0.0, //
                        0.0,
                        k_t / j_eq,
                        -b_eq / j_eq,
                        0.0, //
                        0.0,
                        0.0,
                        1.0 / n,
                        0.0,
                    ],
                    &[k_drv / t_drv, 0.0, 0.0, 0.0],
                    &[0.0, 0.0, 0.0, 1.0],
                ),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{c_abs, c_arg, deg};

    #[test]
    fn reduced_response_by_hand() {
        let m = PlantModel::reduced(&PlantParams::TABLE2);
        let (k_m, t_m): (f64, f64) = (
            78.125,
            3.1 * 5.644_897_959_183_673e-7 / (7.682e-3 * 7.68e-3),
        );
        let p = m.response(30.0);
        // |P| = k_m / (N w sqrt(1 + (w T_m)^2)), angle = -90 - atan(w T_m)
        let mag = k_m / (14.0 * 30.0 * (1.0 + (30.0 * t_m) * (30.0 * t_m)).sqrt());
        assert!((c_abs(p) - mag).abs() < 1e-12);
        assert!((deg(c_arg(p)) - (-90.0 - (30.0 * t_m).atan().to_degrees())).abs() < 1e-9);
    }

    #[test]
    fn full_tends_to_reduced_at_low_frequency() {
        let p = PlantParams::TABLE2;
        let (r, f) = (PlantModel::reduced(&p), PlantModel::full(&p));
        for w in [0.1, 1.0, 10.0] {
            let (a, b) = (r.response(w), f.response(w));
            assert!(c_abs(a - b) / c_abs(a) < 2e-3 * w.max(1.0), "w = {w}");
        }
        // at high frequency the full model lags more (driver + armature poles)
        assert!(c_arg(f.response(2000.0) / r.response(2000.0)) < -0.2);
    }

    #[test]
    fn transfer_function_and_state_space_agree_with_response() {
        let p = PlantParams {
            b_l: 2e-4,
            ..PlantParams::TABLE2
        };
        for m in [PlantModel::reduced(&p), PlantModel::full(&p)] {
            let tf = m.transfer_function();
            let ss = m.state_space();
            for w in [0.5, 30.0, 900.0, 20_000.0] {
                let s = Complex::new(0.0, w);
                let (a, b, c) = (m.response(w), tf.eval(s), ss.eval(s));
                assert!(c_abs(a - b) <= 1e-9 * c_abs(a), "{} tf w={w}", m.name());
                assert!(c_abs(a - c) <= 1e-9 * c_abs(a), "{} ss w={w}", m.name());
            }
        }
    }
}
