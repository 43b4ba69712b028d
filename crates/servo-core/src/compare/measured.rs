//! The measured side of a comparison: the signals of a [`Record`] in load-side SI units, checked.

use super::CompareError;
use crate::record::Record;
use crate::signal::ZeroPhase;
use alloc::vec::Vec;

/// Measured signals on a uniform time base (load side: theta_l, omega_l).
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// Sample times [s].
    pub time_s: Vec<f64>,
    /// Sample period [s] (median of the record).
    pub dt_s: f64,
    /// Driver input u [V], applied from row k to row k+1.
    pub u_v: Vec<f64>,
    /// Load angle theta_l [rad], if logged (directly or as theta_m / N).
    pub theta_l_rad: Option<Vec<f64>>,
    /// Load speed omega_l [rad/s]: logged, or derived from theta_l (see `speed_derived`).
    pub omega_l_rad_s: Vec<f64>,
    /// True when omega_l was derived from theta_l with the zero-phase filter.
    pub speed_derived: bool,
    /// The logged speed's lag behind the angle's derivative [samples] when it was a causal
    /// estimate and the speed was derived from the angle instead
    /// ([`crate::signal::lag::lagging_speed`]); `None` when no speed was logged or it was kept.
    pub logged_speed_lag_samples: Option<f64>,
    /// The logged speed's first sample omega_l [rad/s] when it was replaced so (the replay starts
    /// from it: a zero-phase derivative is unreliable at a log's first samples).
    pub logged_omega_l0_rad_s: Option<f64>,
    /// Armature current i_a [A], if logged.
    pub i_a_a: Option<Vec<f64>>,
    /// Position reference [rad], if logged.
    pub ref_rad: Option<Vec<f64>>,
}

fn check(name: &'static str, v: &[f64], n: usize) -> Result<(), CompareError> {
    if v.len() != n {
        return Err(CompareError::Length {
            signal: name,
            len: v.len(),
            expected: n,
        });
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(CompareError::NotFinite {
            signal: name,
            row: i,
        });
    }
    Ok(())
}

/// Speed from position: zero-phase low-pass at `fc_hz`, then central differences (a non-positive
/// `fc_hz` differentiates unfiltered; a cut-off above 0.45 / `dt_s` is lowered to it). The model's
/// position goes through the same when the measured speed is derived, so both sides see the same
/// filtering.
pub fn speed_from_position(theta: &[f64], dt_s: f64, fc_hz: f64) -> Vec<f64> {
    ZeroPhase::clamped(fc_hz, dt_s).derivative(theta)
}

impl Measured {
    /// Extracts and checks the signals of `rec`; `n_gear` is the gear ratio N (theta_l =
    /// theta_m / N); a speed derived from position uses the zero-phase filter at `speed_filter_hz`.
    pub fn from_record(
        rec: &Record,
        n_gear: f64,
        speed_filter_hz: f64,
    ) -> Result<Measured, CompareError> {
        let n = rec.len();
        if n < 10 {
            return Err(CompareError::TooShort { samples: n });
        }
        check("time", &rec.time_s, n)?;
        if let Some(i) = rec.time_s.windows(2).position(|w| w[1] <= w[0]) {
            return Err(CompareError::TimeNotIncreasing { row: i + 1 });
        }
        let dt_s = rec.sample_period_s();
        // Tolerate jitter, not gaps: the simulator advances a fixed period.
        if let Some(i) = rec
            .time_s
            .windows(2)
            .position(|w| (w[1] - w[0]) > 1.5 * dt_s || (w[1] - w[0]) < 0.5 * dt_s)
        {
            return Err(CompareError::NonUniform { row: i + 1, dt_s });
        }
        let u_v = rec
            .u_v
            .clone()
            .ok_or(CompareError::Missing("u (driver input voltage)"))?;
        check("u", &u_v, n)?;
        let theta_l_rad = match (&rec.theta_l_rad, &rec.theta_m_rad) {
            (Some(t), _) => Some(t.clone()),
            (None, Some(tm)) => Some(tm.iter().map(|v| v / n_gear).collect()),
            (None, None) => None,
        };
        if let Some(t) = &theta_l_rad {
            check("theta_l", t, n)?;
        }
        let logged = match (&rec.omega_l_rad_s, &rec.omega_m_rad_s) {
            (Some(w), _) => Some(w.clone()),
            (None, Some(wm)) => Some(wm.iter().map(|v| v / n_gear).collect::<Vec<f64>>()),
            (None, None) => None,
        };
        if let Some(w) = &logged {
            check("omega_l", w, n)?;
        }
        // A logged speed that lags the angle's derivative is a causal estimate: compared with
        // the model's speed it would count its own filter's lag as model error.
        let derived = theta_l_rad
            .as_ref()
            .map(|t| speed_from_position(t, dt_s, speed_filter_hz));
        let mut logged_speed_lag_samples = None;
        let mut logged_omega_l0_rad_s = None;
        let (omega_l_rad_s, speed_derived) = match (logged, derived) {
            (Some(w), Some(d)) => match crate::signal::lag::lagging_speed(&d, &w) {
                Some(lag) => {
                    logged_speed_lag_samples = Some(lag);
                    logged_omega_l0_rad_s = w.first().copied();
                    (d, true)
                }
                None => (w, false),
            },
            (Some(w), None) => (w, false),
            (None, Some(d)) => (d, true),
            (None, None) => {
                return Err(CompareError::Missing(
                    "a position or speed signal (theta_l, theta_m, omega_l or omega_m)",
                ))
            }
        };
        check("omega_l", &omega_l_rad_s, n)?;
        if let Some(i) = &rec.i_a_a {
            check("i_a", i, n)?;
        }
        if let Some(r) = &rec.ref_rad {
            check("ref", r, n)?;
        }
        Ok(Measured {
            time_s: rec.time_s.clone(),
            dt_s,
            u_v,
            theta_l_rad,
            omega_l_rad_s,
            speed_derived,
            logged_speed_lag_samples,
            logged_omega_l0_rad_s,
            i_a_a: rec.i_a_a.clone(),
            ref_rad: rec.ref_rad.clone(),
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }
    /// True when empty (never, after `from_record`).
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }
}
