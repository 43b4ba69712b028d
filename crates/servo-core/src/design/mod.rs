//! Bode-method PID design (handout §3) and its verification.
//!
//! * [`model`]: the full (eq. 27) and reduced (eq. 29) gearmotor models, frequency response
//!   P(jw), and (with `alloc`) their transfer functions and state-space realisations.
//! * [`spec`]: translation of time-domain specs into loop specs (eqs. 33, 36, 39-41).
//! * [`bode`]: the PID/PI/PD synthesis of eqs. 44-52 and the real derivative of eq. 53.
//! * [`controller`]: the controller C(s) with real derivative and its discrete version C(z).
//! * [`margins`]: gain/phase margins and crossovers of a loop by a frequency sweep.
//! * `tf`, `ss` (alloc): rational transfer functions and state space with exact ZOH
//!   discretisation.
//! * `closed_loop`, `step` (alloc): closed-loop poles, stability and step metrics.
//! * `exact` (alloc): gains whose achieved crossover and phase margin, with derivative filter and
//!   ZOH, equal the spec.
//! * `step_range` (alloc): step responses of the loop that runs (discrete PID, ZOH plant, voltage
//!   limit, anti-windup) over a range of step sizes, against time-domain specs.
//! * `meet` (alloc): `--meet-specs`, the search for a design whose step responses meet them.
//! * `verify` (alloc): the whole design + verification pipeline used by `servo design`.
//!
//! Angles in the public API are in radians unless the name ends in `_deg`; frequencies in rad/s.

pub mod bode;
pub mod controller;
pub mod margins;
pub mod model;
pub mod spec;

#[cfg(feature = "alloc")]
pub mod closed_loop;
#[cfg(feature = "alloc")]
pub mod exact;
#[cfg(feature = "alloc")]
pub mod meet;
#[cfg(feature = "alloc")]
pub mod ss;
#[cfg(feature = "alloc")]
pub mod step;
#[cfg(feature = "alloc")]
pub mod step_range;
#[cfg(feature = "alloc")]
pub mod tf;
#[cfg(feature = "alloc")]
pub mod verify;

pub use bode::{synthesize, ControllerKind, PidGains};
pub use model::PlantModel;
pub use nalgebra::Complex;
pub use spec::LoopSpec;

use crate::math;

/// Why a design request was rejected or could not be met.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// A number in the request is meaningless (non-finite, out of range); the message says which
    /// and what would be valid.
    #[error("{0}")]
    Invalid(&'static str),
    /// A quantity is out of its valid range.
    #[error("{name} = {} is invalid: {why}", math::Num(*.value))]
    OutOfRange {
        name: &'static str,
        value: f64,
        why: &'static str,
    },
    /// The chosen controller structure cannot provide the phase the spec needs at w_gc.
    #[error(
        "a {controller} cannot meet phase margin {pm_deg:.2} deg at w_gc = {omega_gc:.4} rad/s: the plant phase there is \
         {plant_phase_deg:.2} deg, so the controller must add {needed_deg:.2} deg of phase ({why}); {fix}"
    )]
    Infeasible {
        controller: &'static str,
        pm_deg: f64,
        omega_gc: f64,
        plant_phase_deg: f64,
        needed_deg: f64,
        why: &'static str,
        fix: FixHint,
    },
    /// A numerical solve (`--exact`) did not converge.
    #[error("{0}")]
    NoSolution(&'static str),
}

/// What would make an infeasible request feasible (printed after the error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixHint {
    /// Feasible phase margins at the requested w_gc [deg], as (min, max); NaN when none.
    pub pm_range_deg: (f64, f64),
    /// Suggested controller structure, if another would work.
    pub other_controller: Option<&'static str>,
}

impl core::fmt::Display for FixHint {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let (lo, hi) = self.pm_range_deg;
        if lo.is_finite() && hi.is_finite() && hi > lo {
            write!(
                f,
                "at this w_gc it can give phase margins between {lo:.2} and {hi:.2} deg"
            )?;
        } else {
            write!(
                f,
                "no phase margin in (0, 90) deg is reachable at this w_gc"
            )?;
        }
        if let Some(c) = self.other_controller {
            write!(f, "; or use --controller {c}")?;
        }
        write!(f, "; or choose another w_gc")
    }
}

/// |c|.
#[inline]
pub fn c_abs(c: Complex<f64>) -> f64 {
    math::hypot(c.re, c.im)
}

/// Principal argument of c [rad] in (-pi, pi].
#[inline]
pub fn c_arg(c: Complex<f64>) -> f64 {
    math::atan2(c.im, c.re)
}

/// e^{j phi}.
#[inline]
pub fn c_expj(phi: f64) -> Complex<f64> {
    Complex::new(math::cos(phi), math::sin(phi))
}

/// Degrees from radians.
#[inline]
pub fn deg(rad: f64) -> f64 {
    rad * 180.0 / math::PI
}

/// Radians from degrees.
#[inline]
pub fn rad(deg: f64) -> f64 {
    deg * math::PI / 180.0
}
