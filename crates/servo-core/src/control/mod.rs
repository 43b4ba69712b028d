//! The controller: discrete PID, feedforward compensation and reference generators.
//!
//! Everything here is `no_std` and allocation-free, so the same code runs on the simulator, in the
//! `servo run` loop and on a microcontroller.
//!
//! * [`pid`]: discrete PID in parallel form with a real derivative, anti-windup, bumpless gain
//!   change and per-term output.
//! * [`feedforward`]: inertia and friction compensation from the reference's speed and
//!   acceleration (handout eqs. 1-9, 54), converted to driver volts.
//! * [`reference`]: reference generators on the load angle (step, ramp, trapezoid, sine, chirp,
//!   square, PRBS) with analytic speed and acceleration, and their `--ref` text syntax.
//! * [`sequence`]: sequences of references (segments with durations, absolute or chained).
//! * [`speed`]: the speed estimate from the encoder angle (tracking loop) and the load-speed PI
//!   of the identification experiments.
//! * `program` (alloc): what a run applies over time: a position reference, a sequence of
//!   position and voltage segments, or a load-speed profile.

pub mod compensation;
pub mod feedforward;
pub mod loop_compensation;
pub mod pid;
#[cfg(feature = "alloc")]
pub mod program;
pub mod reference;
mod reference_parse;
pub mod sequence;
pub mod speed;

pub use compensation::{EffectCompensator, EffectSelect};
pub use feedforward::{
    Feedforward, FeedforwardConfig, FeedforwardParams, FeedforwardTerms, SmoothSign,
};
pub use loop_compensation::{CompensationTerms, LoopCompensation};
pub use pid::{AntiWindup, DerivativeOn, Discretization, Pid, PidConfig, PidGains, PidOutput};
#[cfg(feature = "alloc")]
pub use program::{Aliased, Program, ProgramError, SpeedPiece, SpeedProfile};
pub use reference::{ChirpMode, RefParseError, RefSample, Reference, Shape, Snippet};
pub use sequence::{
    PlacedSegment, Segment, SegmentMode, Sequence, SequenceError, Setpoint, Target,
};
pub use speed::{SpeedEstimator, SpeedLoop, SpeedLoopConfig, SpeedLoopError, SpeedLoopOutput};

/// Why a controller could not be built or reconfigured.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ControlError {
    /// A parameter is NaN or infinite where a finite value is needed.
    #[error("`{key}` must be a finite number, got {value}")]
    NotFinite { key: &'static str, value: f64 },
    /// A parameter that must be non-negative is negative.
    #[error("`{key}` must be >= 0 {unit}, got {value}")]
    Negative {
        key: &'static str,
        unit: &'static str,
        value: f64,
    },
    /// A parameter that must be strictly positive is not.
    #[error("`{key}` must be > 0 {unit}, got {value}")]
    NotPositive {
        key: &'static str,
        unit: &'static str,
        value: f64,
    },
    /// The output limits are NaN or not ordered.
    #[error(
        "output limits must satisfy u_min_v < u_max_v (infinite allowed), got [{min}, {max}] V"
    )]
    BadLimits { min: f64, max: f64 },
}

/// Checks `value` is finite and >= 0.
pub(crate) fn check_non_negative(
    key: &'static str,
    unit: &'static str,
    value: f64,
) -> Result<(), ControlError> {
    if !value.is_finite() {
        return Err(ControlError::NotFinite { key, value });
    }
    if value < 0.0 {
        return Err(ControlError::Negative { key, unit, value });
    }
    Ok(())
}

/// Checks `value` is finite and > 0.
pub(crate) fn check_positive(
    key: &'static str,
    unit: &'static str,
    value: f64,
) -> Result<(), ControlError> {
    if !value.is_finite() {
        return Err(ControlError::NotFinite { key, value });
    }
    if value <= 0.0 {
        return Err(ControlError::NotPositive { key, unit, value });
    }
    Ok(())
}
