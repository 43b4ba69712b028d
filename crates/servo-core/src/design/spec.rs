//! Translation of time-domain specs into loop specs (handout §3.1, eqs. 33, 36, 39-41), valid
//! under the second-order dominant-pole approximation (eq. 31).

use super::{deg, DesignError};
use crate::math;

/// A specification on the loop transfer function L(s): gain crossover and phase margin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopSpec {
    /// Gain crossover frequency w_gc [rad/s].
    pub omega_gc: f64,
    /// Phase margin phi_m [rad].
    pub phase_margin: f64,
}

impl LoopSpec {
    /// Checks w_gc > 0 and phi_m in (0, 90) deg.
    pub fn validate(&self) -> Result<(), DesignError> {
        if !(self.omega_gc.is_finite() && self.omega_gc > 0.0) {
            return Err(DesignError::OutOfRange {
                name: "w_gc [rad/s]",
                value: self.omega_gc,
                why: "the gain crossover frequency must be a finite number > 0 (e.g. --wc 30)",
            });
        }
        let pm = deg(self.phase_margin);
        if !(pm.is_finite() && pm > 0.0 && pm < 90.0) {
            return Err(DesignError::OutOfRange {
                name: "phase margin [deg]",
                value: pm,
                why: "it must lie in (0, 90) deg: <= 0 is unstable, >= 90 needs a loop flatter than an integrator \
                      (typical choices 45..70 deg, e.g. --pm 60)",
            });
        }
        Ok(())
    }
}

/// How fast the closed loop must be: one of eqs. 39, 40, or w_gc directly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpeedSpec {
    /// Gain crossover frequency [rad/s].
    OmegaGc(f64),
    /// 10-90 % rise time t_r [s] (eq. 39: w_gc = 1.8 / t_r).
    RiseTime(f64),
    /// 5 % settling time t_s,5% [s] (eq. 40: w_gc = 3 / (delta t_s,5%)).
    Settling5(f64),
    /// 1 % settling time t_s,1% [s] (eq. 40: w_gc = 4.6 / (delta t_s,1%)).
    Settling1(f64),
}

/// How damped the closed loop must be.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DampingSpec {
    /// Step overshoot M_p as a fraction (0.1 = 10 %), through eqs. 36 and 41.
    Overshoot(f64),
    /// Phase margin directly [rad]; delta from the inverse of eq. 41 when a settling time needs it.
    PhaseMargin(f64),
}

/// The result of the translation, with the intermediate damping factor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Translation {
    /// Damping factor delta of the dominant poles [-].
    pub delta: f64,
    /// Loop spec (w_gc, phi_m).
    pub spec: LoopSpec,
    /// Overshoot M_p [fraction] implied by delta (eq. 33).
    pub overshoot: f64,
}

/// Damping factor from overshoot (eq. 36), M_p in (0, 1).
pub fn damping_from_overshoot(overshoot: f64) -> Result<f64, DesignError> {
    if !(overshoot.is_finite() && overshoot > 0.0 && overshoot < 1.0) {
        return Err(DesignError::OutOfRange {
            name: "overshoot M_p [fraction]",
            value: overshoot,
            why: "it must lie in (0, 1): 0.1 means 10 % (eq. 36 has no solution for 0 or >= 100 %)",
        });
    }
    let l = math::ln(1.0 / overshoot);
    Ok(l / math::sqrt(math::PI * math::PI + l * l))
}

/// Overshoot M_p [fraction] of the second-order step response (eq. 33), 0 <= delta < 1.
pub fn overshoot_from_damping(delta: f64) -> f64 {
    if delta >= 1.0 {
        return 0.0;
    }
    math::exp(-math::PI * delta / math::sqrt(1.0 - delta * delta))
}

/// Phase margin [rad] from the damping factor (eq. 41).
pub fn phase_margin_from_damping(delta: f64) -> f64 {
    let d2 = delta * delta;
    math::atan(2.0 * delta / math::sqrt(math::sqrt(1.0 + 4.0 * d2 * d2) - 2.0 * d2))
}

/// Inverse of eq. 41 by bisection: the damping factor whose phase margin is `phase_margin` [rad].
pub fn damping_from_phase_margin(phase_margin: f64) -> Result<f64, DesignError> {
    let pm = deg(phase_margin);
    if !(pm > 0.0 && pm < 90.0) {
        return Err(DesignError::OutOfRange {
            name: "phase margin [deg]",
            value: pm,
            why: "it must lie in (0, 90) deg",
        });
    }
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    while phase_margin_from_damping(hi) < phase_margin {
        hi *= 2.0;
        if hi > 1e6 {
            return Err(DesignError::NoSolution(
                "phase margin too close to 90 deg to invert eq. 41",
            ));
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if phase_margin_from_damping(mid) < phase_margin {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(0.5 * (lo + hi))
}

/// Translates a damping spec and a speed spec into a loop spec (eqs. 36, 39-41).
pub fn translate(damping: DampingSpec, speed: SpeedSpec) -> Result<Translation, DesignError> {
    let (delta, phase_margin) = match damping {
        DampingSpec::Overshoot(mp) => {
            let d = damping_from_overshoot(mp)?;
            (d, phase_margin_from_damping(d))
        }
        DampingSpec::PhaseMargin(pm) => (damping_from_phase_margin(pm)?, pm),
    };
    let positive = |name: &'static str, v: f64| -> Result<f64, DesignError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(DesignError::OutOfRange {
                name,
                value: v,
                why: "a time spec must be a finite number of seconds > 0",
            })
        }
    };
    let omega_gc = match speed {
        SpeedSpec::OmegaGc(w) => w,
        SpeedSpec::RiseTime(t) => 1.8 / positive("rise time [s]", t)?,
        SpeedSpec::Settling5(t) => 3.0 / (delta * positive("5 % settling time [s]", t)?),
        SpeedSpec::Settling1(t) => 4.6 / (delta * positive("1 % settling time [s]", t)?),
    };
    let spec = LoopSpec {
        omega_gc,
        phase_margin,
    };
    spec.validate()?;
    Ok(Translation {
        delta,
        spec,
        overshoot: overshoot_from_damping(delta),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::rad;

    #[test]
    fn savian_translation() {
        // Published: M_p = 0.1, t_s,5% = 0.15 s -> delta = 0.59116, phi_m = 1.02264 rad, w_gc = 33.8321.
        let t = translate(DampingSpec::Overshoot(0.1), SpeedSpec::Settling5(0.15)).unwrap();
        assert!((t.delta - 0.59116).abs() < 1e-5, "{}", t.delta);
        assert!((t.spec.phase_margin - 1.02264).abs() < 1e-5);
        assert!((t.spec.omega_gc - 33.8321).abs() < 1e-3);
    }

    #[test]
    fn independent_values() {
        // delta for 5 % overshoot: ln(20) / sqrt(pi^2 + ln(20)^2) = 2.995732 / 4.340970 = 0.690107
        assert!((damping_from_overshoot(0.05).unwrap() - 0.690_107).abs() < 1e-6);
        // eq. 33 inverts eq. 36
        for mp in [0.01, 0.05, 0.2, 0.5] {
            let d = damping_from_overshoot(mp).unwrap();
            assert!((overshoot_from_damping(d) - mp).abs() < 1e-12);
        }
        // eq. 41 at delta = 1: atan(2 / sqrt(sqrt(5) - 2)) = 76.345 deg
        assert!((deg(phase_margin_from_damping(1.0)) - 76.345).abs() < 1e-3);
        // handout rule of thumb delta ~ phi_m / 100 below 70 deg
        let d = damping_from_phase_margin(rad(50.0)).unwrap();
        assert!((d - 0.5).abs() < 0.05, "{d}");
        assert!((phase_margin_from_damping(d) - rad(50.0)).abs() < 1e-12);
        // rise time (eq. 39) and 1 % settling (eq. 40)
        let t = translate(
            DampingSpec::PhaseMargin(rad(60.0)),
            SpeedSpec::RiseTime(0.06),
        )
        .unwrap();
        assert!((t.spec.omega_gc - 30.0).abs() < 1e-12);
        let t = translate(DampingSpec::Overshoot(0.1), SpeedSpec::Settling1(0.2)).unwrap();
        assert!((t.spec.omega_gc - 4.6 / (0.591_155 * 0.2)).abs() < 1e-3);
    }

    #[test]
    fn rejects_meaningless() {
        assert!(damping_from_overshoot(0.0).is_err());
        assert!(damping_from_overshoot(1.5).is_err());
        assert!(translate(
            DampingSpec::PhaseMargin(rad(95.0)),
            SpeedSpec::OmegaGc(30.0)
        )
        .is_err());
        assert!(translate(
            DampingSpec::PhaseMargin(rad(60.0)),
            SpeedSpec::OmegaGc(-1.0)
        )
        .is_err());
        assert!(translate(DampingSpec::Overshoot(0.1), SpeedSpec::Settling5(0.0)).is_err());
    }
}
