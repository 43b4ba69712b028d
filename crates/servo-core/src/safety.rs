//! Safety limits of a position loop, checked in one place by the host (serial backend) and by the
//! board firmware (virtual board): voltage limit, soft position limits, over-current trip.
//!
//! Defaults are safe for the SRV-02 of the handout's Table 2: the driver input is limited to
//! ±10 V; the stall current at that limit is k_drv·10 V / R_eq = 0.6·10/3.1 ≈ 1.9 A, so the
//! 2.5 A trip only fires on a fault (or a wrong plant), never on a normal step; the load may turn
//! at most two revolutions either way from where the run started.

use crate::math;

/// Configurable safety limits (see the module doc for the defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields, default))]
pub struct SafetyLimits {
    /// Largest |driver input| [V]; larger commands are clipped.
    pub voltage_limit_v: f64,
    /// Soft lower limit of the load angle [rad].
    pub theta_min_rad: f64,
    /// Soft upper limit of the load angle [rad].
    pub theta_max_rad: f64,
    /// Over-current trip level on |i_a| [A].
    pub i_trip_a: f64,
}

impl Default for SafetyLimits {
    fn default() -> Self {
        SafetyLimits {
            voltage_limit_v: 10.0,
            theta_min_rad: -2.0 * math::TAU,
            theta_max_rad: 2.0 * math::TAU,
            i_trip_a: 2.5,
        }
    }
}

/// Why the limits themselves are unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LimitsError {
    #[error("voltage limit must be > 0 and finite, got {0} V")]
    VoltageLimit(f64),
    #[error("position limits must satisfy min < max, got [{0}, {1}] rad")]
    PositionLimits(f64, f64),
    #[error("over-current trip must be > 0, got {0} A")]
    CurrentTrip(f64),
}

/// A tripped limit: the loop must go to 0 V.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Trip {
    #[error("over-current: |i_a| = {i_a_a:.3} A > trip level {i_trip_a:.3} A")]
    OverCurrent { i_a_a: f64, i_trip_a: f64 },
    #[error(
        "position limit: theta_l = {theta_l_rad:.3} rad outside [{min_rad:.3}, {max_rad:.3}] rad"
    )]
    PositionLimit {
        theta_l_rad: f64,
        min_rad: f64,
        max_rad: f64,
    },
    #[error("non-finite measurement")]
    NonFinite,
}

impl SafetyLimits {
    /// Checks that the limits make sense.
    pub fn validate(&self) -> Result<(), LimitsError> {
        if !(self.voltage_limit_v > 0.0 && self.voltage_limit_v.is_finite()) {
            return Err(LimitsError::VoltageLimit(self.voltage_limit_v));
        }
        if self.theta_min_rad.is_nan()
            || self.theta_max_rad.is_nan()
            || self.theta_min_rad >= self.theta_max_rad
        {
            return Err(LimitsError::PositionLimits(
                self.theta_min_rad,
                self.theta_max_rad,
            ));
        }
        if self.i_trip_a.is_nan() || self.i_trip_a <= 0.0 {
            return Err(LimitsError::CurrentTrip(self.i_trip_a));
        }
        Ok(())
    }

    /// Clips `u_v` to the voltage limit; a non-finite command becomes 0 V. Returns the voltage to
    /// apply [V] and whether it was changed.
    pub fn clamp_voltage(&self, u_v: f64) -> (f64, bool) {
        if !u_v.is_finite() {
            return (0.0, true);
        }
        let c = u_v.clamp(-self.voltage_limit_v, self.voltage_limit_v);
        (c, c != u_v)
    }

    /// Checks one measurement of the load angle [rad] and the armature current [A].
    pub fn check(&self, theta_l_rad: f64, i_a_a: f64) -> Result<(), Trip> {
        if !theta_l_rad.is_finite() || !i_a_a.is_finite() {
            return Err(Trip::NonFinite);
        }
        if i_a_a > self.i_trip_a || i_a_a < -self.i_trip_a {
            return Err(Trip::OverCurrent {
                i_a_a,
                i_trip_a: self.i_trip_a,
            });
        }
        if theta_l_rad < self.theta_min_rad || theta_l_rad > self.theta_max_rad {
            return Err(Trip::PositionLimit {
                theta_l_rad,
                min_rad: self.theta_min_rad,
                max_rad: self.theta_max_rad,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_trip_where_documented() {
        let l = SafetyLimits::default();
        l.validate().unwrap();
        assert_eq!(l.clamp_voltage(12.0), (10.0, true));
        assert_eq!(l.clamp_voltage(-3.0), (-3.0, false));
        assert_eq!(l.clamp_voltage(f64::NAN), (0.0, true));
        assert!(l.check(1.0, 1.9).is_ok());
        assert!(matches!(l.check(1.0, -2.6), Err(Trip::OverCurrent { .. })));
        assert!(matches!(
            l.check(13.0, 0.0),
            Err(Trip::PositionLimit { .. })
        ));
        assert_eq!(l.check(f64::NAN, 0.0), Err(Trip::NonFinite));
        let bad = SafetyLimits {
            theta_min_rad: 1.0,
            theta_max_rad: 0.0,
            ..l
        };
        assert!(bad.validate().is_err());
    }
}
