//! Model versus measurement (`servo compare`): replay a log on the model, measure how well it fits,
//! and locate where it fails.
//!
//! * [`replay`]: drive the model as the real motor was driven (closed loop with the logged
//!   controller, open-loop speed, k-step-ahead prediction or re-initialised segments).
//! * [`figures`]: fit % (as MATLAB's `compare`), RMSE and maximum error per signal.
//! * [`whiteness`] and [`chi2`]: residual autocorrelation, Ljung-Box test, residual-input
//!   cross-correlation (as MATLAB's `resid`).
//! * [`regimes`], [`periodic`], [`windows`]: where the error sits (operating regimes, position-
//!   periodic components, worst time windows).
//! * [`report`]: all of the above for one log, with plain-language findings.
//! * [`suspects`]: which effect a run compensated wrongly (the replay without it predicts the
//!   log better).
//! * [`measured`], [`quantum`]: the measured side (signals, speed from position through
//!   [`crate::signal::ZeroPhase`], encoder grid).

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod chi2;
pub mod controller_check;
pub mod figures;
pub mod gate;
pub mod ladder;
pub mod logs;
pub mod measured;
pub mod periodic;
pub use crate::signal::quantum;
pub mod regimes;
pub mod replay;
pub mod report;
pub mod suspects;
pub mod whiteness;
pub mod windows;

pub use figures::{fit_percent, rmse, Figures};
pub use ladder::{pooled, ModeChoice, ModelComparison, ReplayController};
pub use measured::Measured;
pub use regimes::{Regime, RegimeOptions, RegimeStats};
pub use replay::{replay, ClosedLoop, Controller, Replay, ReplayMode};
pub use report::{compare, CompareOptions, CompareReport, SignalComparison, SignalKind};

/// Why a comparison could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompareError {
    #[error("the log has {samples} samples; at least 10 are needed")]
    TooShort { samples: usize },
    #[error("signal `{signal}` has {len} samples but the time column has {expected}")]
    Length {
        signal: &'static str,
        len: usize,
        expected: usize,
    },
    #[error("signal `{signal}` is not a finite number at row {row}")]
    NotFinite { signal: &'static str, row: usize },
    #[error("time does not increase at row {row}")]
    TimeNotIncreasing { row: usize },
    #[error("the sampling is not uniform at row {row} (median period {dt_s} s): compare needs a gap-free log")]
    NonUniform { row: usize, dt_s: f64 },
    #[error("the log has no {0}")]
    Missing(&'static str),
    #[error("a closed-loop replay needs the controller (gains) and the reference")]
    NoController,
    #[error("the model's controller output is not finite at row {row}")]
    ControllerDiverged { row: usize },
    #[error("the model simulation diverged (non-finite state) at row {row}")]
    SimDiverged { row: usize },
    #[error("cannot simulate the model: {0}")]
    Sim(crate::sim::SimError),
}
