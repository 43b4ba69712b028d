//! PID / PI / PD synthesis by Bode's method (handout §3.2, eqs. 44-52) and the real derivative
//! of eq. 53. Pure formulas, no heap.

use super::{c_abs, c_arg, deg, Complex, DesignError, FixHint, LoopSpec};
use crate::math;

/// Controller structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerKind {
    /// K_P (1 + 1/(T_I s) + T_D s) with T_I = alpha T_D (eqs. 47-50).
    Pid,
    /// K_P + K_I/s (eq. 52).
    Pi,
    /// K_P + K_D s (eq. 51).
    Pd,
}

impl ControllerKind {
    /// "pid", "pi" or "pd".
    pub fn name(&self) -> &'static str {
        match self {
            ControllerKind::Pid => "pid",
            ControllerKind::Pi => "pi",
            ControllerKind::Pd => "pd",
        }
    }
}

/// The gains of C(s) = K_P + K_I/s + K_D s/(T_L s + 1) [V/rad, V/(rad s), V s/rad, s]: the same
/// type the discrete controller (`control::pid`) runs.
pub use crate::control::pid::PidGains;

impl PidGains {
    /// Integral time T_I = K_P / K_I [s] (infinite without integral action).
    pub fn ti_s(&self) -> f64 {
        if self.ki == 0.0 {
            f64::INFINITY
        } else {
            self.kp / self.ki
        }
    }
    /// Derivative time T_D = K_D / K_P [s].
    pub fn td_s(&self) -> f64 {
        self.kd / self.kp
    }
    /// C(s) at a complex s, with the real derivative of eq. 53.
    pub fn eval(&self, s: Complex<f64>) -> Complex<f64> {
        let mut c = Complex::new(self.kp, 0.0);
        if self.ki != 0.0 {
            c += Complex::new(self.ki, 0.0) / s;
        }
        if self.kd != 0.0 {
            c += s * self.kd / (s * self.tl_s + 1.0);
        }
        c
    }
    /// C(jw), w [rad/s].
    pub fn response(&self, omega: f64) -> Complex<f64> {
        self.eval(Complex::new(0.0, omega))
    }
}

/// How T_L of the real derivative (eq. 53) is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DerivativeFilter {
    /// 1/T_L = factor * w_gc (handout: 2..5; default 5).
    Factor(f64),
    /// T_L given in seconds (0 = ideal derivative).
    TimeConstant(f64),
}

impl DerivativeFilter {
    /// T_L [s] for a crossover w_gc [rad/s].
    pub fn tl_s(&self, omega_gc: f64) -> Result<f64, DesignError> {
        match *self {
            DerivativeFilter::Factor(f) if f.is_finite() && f > 0.0 => Ok(1.0 / (f * omega_gc)),
            DerivativeFilter::Factor(f) => Err(DesignError::OutOfRange {
                name: "--tl-factor",
                value: f,
                why: "1/T_L must be a positive multiple of w_gc (handout: 2..5)",
            }),
            DerivativeFilter::TimeConstant(t) if t.is_finite() && t >= 0.0 => Ok(t),
            DerivativeFilter::TimeConstant(t) => Err(DesignError::OutOfRange {
                name: "--tl [s]",
                value: t,
                why: "T_L must be >= 0 s",
            }),
        }
    }
}

/// The phase the controller must add at w_gc (eq. 44): (Delta K, Delta phi [rad] in (-pi, pi]).
pub fn required_compensation(spec: &LoopSpec, p_gc: Complex<f64>) -> (f64, f64) {
    let delta_k = 1.0 / c_abs(p_gc);
    let delta_phi = wrap_pi(-math::PI + spec.phase_margin - c_arg(p_gc));
    (delta_k, delta_phi)
}

/// Wraps an angle into (-pi, pi].
pub fn wrap_pi(x: f64) -> f64 {
    let r = math::rem_euclid(x + math::PI, math::TAU) - math::PI;
    if r <= -math::PI {
        r + math::TAU
    } else {
        r
    }
}

/// Synthesises the controller so that C(j w_gc) P(j w_gc) = e^{j(-pi + phi_m)} (eq. 43), ideal
/// derivative (eqs. 44-52), then attaches the real derivative time constant `tl_s` (eq. 53).
///
/// `p_gc` is the plant response P(j w_gc); `alpha` = T_I / T_D (PID only).
pub fn synthesize(
    kind: ControllerKind,
    spec: &LoopSpec,
    alpha: f64,
    p_gc: Complex<f64>,
    tl_s: f64,
) -> Result<PidGains, DesignError> {
    spec.validate()?;
    if !(p_gc.re.is_finite() && p_gc.im.is_finite()) || c_abs(p_gc) == 0.0 {
        return Err(DesignError::Invalid(
            "the plant response at w_gc is zero or not finite",
        ));
    }
    let w = spec.omega_gc;
    let (delta_k, delta_phi) = required_compensation(spec, p_gc);
    let (lo, hi) = match kind {
        ControllerKind::Pid => (-math::PI / 2.0, math::PI / 2.0),
        ControllerKind::Pi => (-math::PI / 2.0, 0.0),
        ControllerKind::Pd => (0.0, math::PI / 2.0),
    };
    let strict_ok = delta_phi > lo && delta_phi < hi;
    let edge_ok = delta_phi == 0.0 && kind != ControllerKind::Pid;
    if !(strict_ok || edge_ok) {
        return Err(infeasible(kind, spec, p_gc, delta_phi, lo, hi));
    }
    let kp = delta_k * math::cos(delta_phi);
    let g = match kind {
        ControllerKind::Pid => {
            if !(alpha.is_finite() && alpha > 0.0) {
                return Err(DesignError::OutOfRange {
                    name: "--alpha (T_I/T_D)",
                    value: alpha,
                    why: "alpha must be > 0 (handout: alpha >= 4 gives real PID zeros)",
                });
            }
            let t = math::tan(delta_phi);
            let td = (t + math::sqrt(t * t + 4.0 / alpha)) / (2.0 * w);
            let ti = alpha * td;
            PidGains {
                kp,
                ki: kp / ti,
                kd: kp * td,
                tl_s,
            }
        }
        ControllerKind::Pd => PidGains {
            kp,
            ki: 0.0,
            kd: delta_k * math::sin(delta_phi) / w,
            tl_s,
        },
        ControllerKind::Pi => PidGains {
            kp,
            ki: -w * delta_k * math::sin(delta_phi),
            kd: 0.0,
            tl_s: 0.0,
        },
    };
    Ok(g)
}

fn infeasible(
    kind: ControllerKind,
    spec: &LoopSpec,
    p_gc: Complex<f64>,
    delta_phi: f64,
    lo: f64,
    hi: f64,
) -> DesignError {
    // phi_m = delta_phi + pi + angle(P) (mod 2 pi): map the allowed delta_phi interval to phi_m.
    let base = wrap_pi(math::PI + c_arg(p_gc));
    let mut range = (f64::NAN, f64::NAN);
    for k in [-1.0, 0.0, 1.0] {
        let (a, b) = (lo + base + k * math::TAU, hi + base + k * math::TAU);
        let (a, b) = (a.max(0.0), b.min(math::PI / 2.0));
        if b > a {
            range = (deg(a), deg(b));
        }
    }
    let (why, other) = match kind {
        ControllerKind::Pi if delta_phi > 0.0 && delta_phi < math::PI / 2.0 => (
            "a PI can only add phase lag, here lead is needed",
            Some("pid"),
        ),
        ControllerKind::Pd if delta_phi < 0.0 && delta_phi > -math::PI / 2.0 => (
            "a PD can only add phase lead, here lag is needed",
            Some("pi"),
        ),
        _ => (
            "more than 90 deg of lead or lag would need a negative K_P",
            None,
        ),
    };
    DesignError::Infeasible {
        controller: match kind {
            ControllerKind::Pid => "PID",
            ControllerKind::Pi => "PI",
            ControllerKind::Pd => "PD",
        },
        pm_deg: deg(spec.phase_margin),
        omega_gc: spec.omega_gc,
        plant_phase_deg: deg(c_arg(p_gc)),
        needed_deg: deg(delta_phi),
        why,
        fix: FixHint {
            pm_range_deg: range,
            other_controller: other,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{rad, PlantModel};
    use crate::params::PlantParams;

    fn spec(w: f64, pm_deg: f64) -> LoopSpec {
        LoopSpec {
            omega_gc: w,
            phase_margin: rad(pm_deg),
        }
    }

    #[test]
    fn reference_point_table2() {
        let m = PlantModel::reduced(&PlantParams::TABLE2);
        let g = synthesize(
            ControllerKind::Pid,
            &spec(30.0, 60.0),
            4.0,
            m.response(30.0),
            0.0,
        )
        .unwrap();
        assert!((g.kp - 7.0476).abs() < 5e-4, "{g:?}");
        assert!((g.ki - 86.121).abs() < 5e-3);
        assert!((g.kd - 0.14418).abs() < 5e-5);
        assert!((g.td_s() - 0.020458).abs() < 5e-6);
        assert!((g.ti_s() - 0.081834).abs() < 5e-6);
    }

    /// Independent check: the ideal-derivative loop must satisfy eq. 43 exactly, and T_I = alpha T_D.
    #[test]
    fn loop_hits_spec_for_many_designs() {
        let p = PlantParams::TABLE2;
        for model in [PlantModel::reduced(&p), PlantModel::full(&p)] {
            for (w, pm, alpha) in [
                (10.0, 45.0, 4.0),
                (30.0, 60.0, 4.0),
                (50.0, 70.0, 6.0),
                (80.0, 50.0, 10.0),
                (20.0, 30.0, 4.0),
            ] {
                let s = spec(w, pm);
                let g = synthesize(ControllerKind::Pid, &s, alpha, model.response(w), 0.0).unwrap();
                let l = g.response(w) * model.response(w);
                assert!((c_abs(l) - 1.0).abs() < 1e-12, "|L| at w_gc");
                assert!(
                    (deg(c_arg(l)) - (pm - 180.0)).abs() < 1e-9,
                    "angle L at w_gc"
                );
                assert!((g.ti_s() / g.td_s() - alpha).abs() < 1e-9);
                assert!(g.kp > 0.0 && g.ki > 0.0 && g.kd > 0.0);
            }
        }
    }

    #[test]
    fn pi_and_pd() {
        let m = PlantModel::reduced(&PlantParams::TABLE2);
        // plant phase at w = 10: -90 - atan(0.2966) = -106.5 deg -> PI feasible for pm < 73.5 deg
        let g = synthesize(
            ControllerKind::Pi,
            &spec(10.0, 50.0),
            4.0,
            m.response(10.0),
            0.0,
        )
        .unwrap();
        let l = g.response(10.0) * m.response(10.0);
        assert!((c_abs(l) - 1.0).abs() < 1e-12 && (deg(c_arg(l)) + 130.0).abs() < 1e-9);
        assert_eq!(g.kd, 0.0);
        let g = synthesize(
            ControllerKind::Pd,
            &spec(40.0, 70.0),
            4.0,
            m.response(40.0),
            0.0,
        )
        .unwrap();
        let l = g.response(40.0) * m.response(40.0);
        assert!((c_abs(l) - 1.0).abs() < 1e-12 && (deg(c_arg(l)) + 110.0).abs() < 1e-9);
        assert_eq!(g.ki, 0.0);
        // PI cannot add lead: at w = 30 the plant has -131.7 deg, pm 60 needs +11.7 deg
        let e = synthesize(
            ControllerKind::Pi,
            &spec(30.0, 60.0),
            4.0,
            m.response(30.0),
            0.0,
        )
        .unwrap_err();
        match e {
            DesignError::Infeasible { fix, .. } => {
                assert!((fix.pm_range_deg.1 - 48.34).abs() < 0.05, "{fix:?}");
                assert_eq!(fix.other_controller, Some("pid"));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn real_derivative_tl() {
        assert!((DerivativeFilter::Factor(5.0).tl_s(30.0).unwrap() - 1.0 / 150.0).abs() < 1e-15);
        assert!(DerivativeFilter::Factor(0.0).tl_s(30.0).is_err());
        assert!(DerivativeFilter::TimeConstant(-1.0).tl_s(30.0).is_err());
    }
}
