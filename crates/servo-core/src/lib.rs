//! servo-core: the physics and the algorithms of the servo toolchain.
//!
//! * [`params`]: the gearmotor parameters of the handout's Table 2 and the derived quantities
//!   (eqs. 10, 22, 30).
//! * [`effects`]: the effect catalogue, the one definition of every physical mechanism that the
//!   simulator, the model fit and the diagnosis use.
//! * [`custom`]: user-defined effects (an expression of the signals and parameters), their fit
//!   and the discovery of a term outside the catalogue.
//! * [`drive`]: the drive between command and motor (voltage amplifier, current drive, PWM
//!   duty on a supply) and its equivalent voltage chain.
//! * [`plant`]: a parameter set together with its active effects: the model of one gearmotor.
//! * [`control`]: discrete PID, feedforward compensation, reference generators and sequences.
//! * [`board`]: the servo board firmware core (protocol state machine over a small HAL trait).
//! * `frf` (std): frequency-response estimates from logs (Welch/H1, coherence, bounds), the
//!   margins a measured loop achieved and the model's errors by frequency.
//! * `metrics` (alloc): figures of merit of a run (tracking error, overshoot and settling of each
//!   reference step, saturation time), computed while it runs.
//! * [`sim`]: integration of the plant with its effects (truth for the simulator, model for
//!   `compare`).
//! * [`transmission`]: gear, screw or belt between motor and load, the encoder's place, and the
//!   conversions of a linear axis (m, N, kg) to the equivalent rotation the core computes in.
//! * `trend` (alloc): a parameter's estimates over many logs: its linear trend with a 95 %
//!   interval, a step test, the verdict and the forecast of a limit crossing (`servo trend`).
//!
//! The crate is `no_std` without the default `std` feature; modules that need a heap are behind
//! the `alloc` feature. Units are SI unless a name says otherwise; "motor side" and "load side"
//! are as in the handout (omega_l = omega_m / N).
#![cfg_attr(not(feature = "std"), no_std)]

#[cfg(feature = "alloc")]
extern crate alloc;

pub mod board;
#[cfg(feature = "alloc")]
pub mod compare;
pub mod control;
pub mod custom;
pub mod design;
#[cfg(feature = "alloc")]
pub mod diagnose;
pub mod drive;
pub mod effects;
#[cfg(feature = "alloc")]
pub mod fit;
#[cfg(feature = "std")]
pub mod frf;
#[cfg(feature = "alloc")]
pub mod ident;
pub mod linalg;
pub mod math;
#[cfg(feature = "alloc")]
pub mod metrics;
#[cfg(feature = "alloc")]
mod par;
pub mod params;
pub mod plant;
pub mod protocol;
#[cfg(feature = "alloc")]
pub mod record;
pub mod safety;
#[cfg(feature = "alloc")]
pub mod signal;
pub mod sim;
#[cfg(feature = "alloc")]
pub mod smart;
pub mod stiffness;
pub mod transmission;
#[cfg(feature = "alloc")]
pub mod trend;
#[cfg(feature = "alloc")]
pub mod verdict;

pub use design::DesignError;
pub use effects::{Effect, EffectKind, Effects};
pub use params::{ParamError, PlantParams};
pub use plant::Plant;
pub use transmission::Transmission;
