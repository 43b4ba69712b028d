//! Identification of the gearmotor's mechanical and electrical constants (handout section 4).
//!
//! * [`friction`] (4.1): constant-speed segments found automatically ([`plateaus`]), then LS on
//!   k_t i_a = B_eq w_m + (tau_sf / N) sign(w_m) (eqs. 57-66).
//! * [`inertia`] (4.2): constant acceleration/deceleration phases ([`phases`]), eqs. 67-70
//!   averaged over phase pairs; or LS on the samples with |dw_m/dt| above a threshold.
//! * [`combined`] (4.3): one LS over the whole record (eqs. 71-76) with zero-phase filtered
//!   differentiation ([`crate::signal`]), the same filter on every regressor.
//! * [`electrical`]: u = (R_eq / k_drv) i_a + (k_e / k_drv) w_m at steady state gives k_drv, R_eq.
//!
//! All fits go through [`ls::fit`] (QR, standard errors, 95 % intervals with the Student t
//! quantile of [`student_t`], residual RMS, condition number). Data that cannot identify a
//! parameter is refused with [`IdentError::NotIdentifiable`], whose message says what experiment
//! is missing.
//!
//! Units: SI. B_eq [N m s/rad] and J_eq [kg m^2] at motor side, tau_sf [N m] at load side.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN. Index loops walk parallel slices.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod auto;
pub mod combined;
pub mod electrical;
pub mod friction;
pub mod inertia;
pub mod ls;
pub mod phases;
pub mod plateaus;
pub mod student_t;

use alloc::string::String;
use alloc::vec::Vec;

use crate::params::PlantParams;
use crate::record::Record;
use crate::signal::{derivative_at, FilterError};

/// Why an identification was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentError {
    /// A signal the method needs is not in the log.
    #[error("{log}: no {signal} signal: {why}")]
    MissingSignal {
        log: String,
        signal: &'static str,
        why: &'static str,
    },
    /// A signal holds NaN or infinity.
    #[error("{log}: signal {signal} is not finite at row {row} (t = {time_s} s)")]
    NotFinite {
        log: String,
        signal: &'static str,
        row: usize,
        time_s: f64,
    },
    /// Time is not strictly increasing.
    #[error("{log}: time is not strictly increasing at row {row}")]
    BadTime { log: String, row: usize },
    /// The data cannot separate the parameters; the message says which experiment is missing.
    #[error("{0}")]
    NotIdentifiable(String),
    /// Too few observations for the fit and its uncertainty.
    #[error("too few data: need at least {needed} observations, got {got}")]
    TooFewData { needed: usize, got: usize },
    /// The regressors are (nearly) collinear.
    #[error("the regressors are collinear (condition number {cond:.3e}): the parameters cannot be separated")]
    RankDeficient { cond: f64 },
    /// A bad configuration value.
    #[error("invalid setting: {0}")]
    BadConfig(String),
    /// The low-pass filter cannot be built with the configured cut-off.
    #[error("invalid setting: {0}")]
    Filter(#[from] FilterError),
    /// An internal inconsistency (a bug).
    #[error("internal error: {0}")]
    Internal(&'static str),
}

/// How the current of a voltage-driven log was sampled, for the torque's part in the
/// acceleration balance. The board samples i_a at the end of each period, just before the next
/// command is held (zero-order hold). Within a period the current first follows the new command
/// (within `lag_s` = T_drv + L_a / R_eq) and then falls as the back-EMF k_e w_m rises with the
/// speed: under an acceleration a the samples sit (k_e / R_eq) a (T_s / 2 - lag_s) below the
/// period's mean current. Taken as sampled, J_eq would come out low by
/// [`CurrentSampling::inertia_offset_kg_m2`] (k_t k_e / R_eq) (T_s / 2 - T_e), 0.8 % of the lab's
/// J_eq at 1 kHz, in every method that sees accelerations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentSampling {
    /// T_drv + L_a / R_eq [s].
    pub lag_s: f64,
    /// k_t k_e / R_eq [N m s/rad].
    pub back_emf_nm_s_rad: f64,
}

impl CurrentSampling {
    /// For a voltage drive with the constants of `p`.
    pub fn from_params(p: &PlantParams) -> CurrentSampling {
        CurrentSampling {
            lag_s: p.t_drv() + p.t_a(),
            back_emf_nm_s_rad: p.k_t * p.k_e / p.r_eq(),
        }
    }
    /// The standard uncertainty of that correction [kg m^2]: 10 % of it, for what the log
    /// does not tell (the current sensor's own lag, a drive that is not quite first order).
    pub fn inertia_offset_se_kg_m2(&self, dt_s: f64) -> f64 {
        0.1 * self.inertia_offset_kg_m2(dt_s)
    }
    /// The inertia offset [kg m^2] and its standard error for the logs `exps` (their first log's
    /// sample period), none when the sampling is not known.
    pub fn offsets_for(sampling: Option<CurrentSampling>, exps: &[Experiment]) -> (f64, f64) {
        let dt = exps.first().map_or(f64::NAN, |e| e.sample_period_s());
        sampling.map_or((0.0, 0.0), |cs| {
            (cs.inertia_offset_kg_m2(dt), cs.inertia_offset_se_kg_m2(dt))
        })
    }
    /// The inertia missing from a fit on the sampled current at sample period `dt_s` [kg m^2].
    pub fn inertia_offset_kg_m2(&self, dt_s: f64) -> f64 {
        let d = self.back_emf_nm_s_rad * (0.5 * dt_s - self.lag_s).max(0.0);
        if d.is_finite() {
            d
        } else {
            0.0
        }
    }
}

/// One identified parameter with its uncertainty and the quality of the fit it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Estimated value (SI).
    pub value: f64,
    /// Standard error.
    pub std_err: f64,
    /// 95 % confidence interval (lo, hi).
    pub ci95: (f64, f64),
    /// Residual RMS of the fit (units of its left-hand side, usually N m).
    pub residual_rms: f64,
    /// Condition number of the column-scaled regression.
    pub cond: f64,
    /// Degrees of freedom of the t quantile.
    pub dof: usize,
    /// Number of observations of the fit.
    pub n: usize,
}

impl Estimate {
    /// The `j`-th parameter of a least-squares fit.
    pub fn from_fit(fit: &ls::LsFit, j: usize) -> Estimate {
        Estimate {
            value: fit.theta[j],
            std_err: fit.std_err[j],
            ci95: fit.ci95[j],
            residual_rms: fit.residual_rms,
            cond: fit.cond,
            dof: fit.dof,
            n: fit.n,
        }
    }
    /// True when `x` lies in the 95 % interval.
    pub fn contains(&self, x: f64) -> bool {
        self.ci95.0 <= x && x <= self.ci95.1
    }
    /// Relative standard error |se / value|.
    pub fn rel_err(&self) -> f64 {
        (self.std_err / self.value).abs()
    }
    /// The same estimate with a further independent standard uncertainty `se` folded in (the
    /// interval widened with the same t quantile).
    pub fn widened(self, se: f64) -> Estimate {
        if !(se > 0.0) || !(self.std_err > 0.0) {
            return self;
        }
        let t = (self.ci95.1 - self.value) / self.std_err;
        let s = crate::math::sqrt(self.std_err * self.std_err + se * se);
        Estimate {
            std_err: s,
            ci95: (self.value - t * s, self.value + t * s),
            ..self
        }
    }
    /// The same estimate moved by `d` (a known bias removed).
    pub fn shifted(self, d: f64) -> Estimate {
        Estimate {
            value: self.value + d,
            ci95: (self.ci95.0 + d, self.ci95.1 + d),
            ..self
        }
    }
}

/// The signals of one experiment, in the form the estimators use: motor side, SI.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    /// Where the data came from (for messages and provenance).
    pub source: String,
    /// Sample times [s].
    pub time_s: Vec<f64>,
    /// Motor speed omega_m [rad/s] (from omega_m, N omega_l, or differentiated angles).
    pub omega_m_rad_s: Vec<f64>,
    /// Motor torque tau_m = k_t i_a [N m], if the current was logged.
    pub tau_m_nm: Option<Vec<f64>>,
    /// Armature current i_a [A], if logged.
    pub i_a_a: Option<Vec<f64>>,
    /// Driver input voltage u [V], if logged.
    pub u_v: Option<Vec<f64>>,
    /// Why the speed is not the logged one, when it is not: a logged speed that lags the
    /// angle's derivative (a causal estimate) is replaced by that derivative.
    pub speed_note: Option<String>,
}

pub use crate::signal::lag::MAX_SPEED_LAG_SAMPLES;

impl Experiment {
    /// Prepares a record: checks finiteness and time, derives the motor speed from whatever the
    /// log has (omega_m, omega_l, theta_m or theta_l, in that order) and the torque k_t i_a.
    pub fn from_record(rec: &Record, params: &PlantParams) -> Result<Experiment, IdentError> {
        let source = if rec.source.is_empty() {
            String::from("record")
        } else {
            rec.source.clone()
        };
        let t = &rec.time_s;
        if t.len() < 3 {
            return Err(IdentError::TooFewData {
                needed: 3,
                got: t.len(),
            });
        }
        check_finite(&source, "time", t, t)?;
        for k in 1..t.len() {
            if !(t[k] > t[k - 1]) {
                return Err(IdentError::BadTime {
                    log: source,
                    row: k,
                });
            }
        }
        let n = params.n;
        let logged = if let Some(w) = &rec.omega_m_rad_s {
            check_finite(&source, "omega_m", w, t)?;
            Some((w.clone(), "omega_m"))
        } else if let Some(w) = &rec.omega_l_rad_s {
            check_finite(&source, "omega_l", w, t)?;
            Some((w.iter().map(|w| w * n).collect(), "omega_l"))
        } else {
            None
        };
        let angle = match (&rec.theta_m_rad, &rec.theta_l_rad) {
            (Some(th), _) => Some((th, 1.0, "theta_m")),
            (None, Some(th)) => Some((th, n, "theta_l")),
            (None, None) => None,
        };
        let mut speed_note = None;
        let omega_m_rad_s = if let Some((w, name)) = logged {
            match angle.filter(|(th, _, _)| th.iter().all(|v| v.is_finite())) {
                Some((th, scale, angle_name)) => {
                    let d: Vec<f64> = derivative_at(t, th)
                        .into_iter()
                        .map(|w| w * scale)
                        .collect();
                    match crate::signal::lag::lagging_speed(&d, &w) {
                        Some(lag) => {
                            speed_note = Some(alloc::format!(
                                "{source}: the logged {name} lags the derivative of {angle_name} by \
                                 {lag:.1} samples (a causal estimate, more than \
                                 {MAX_SPEED_LAG_SAMPLES} samples): the speed is taken from \
                                 {angle_name}"
                            ));
                            d
                        }
                        _ => w,
                    }
                }
                None => w,
            }
        } else if let Some(th) = &rec.theta_m_rad {
            check_finite(&source, "theta_m", th, t)?;
            derivative_at(t, th)
        } else if let Some(th) = &rec.theta_l_rad {
            check_finite(&source, "theta_l", th, t)?;
            derivative_at(t, th).into_iter().map(|w| w * n).collect()
        } else {
            return Err(IdentError::MissingSignal {
                log: source,
                signal: "speed or angle",
                why: "every method needs the motor speed; log omega_m, omega_l, theta_m or theta_l",
            });
        };
        let i_a_a = match &rec.i_a_a {
            Some(i) => {
                check_finite(&source, "i_a", i, t)?;
                Some(i.clone())
            }
            None => None,
        };
        let u_v = match &rec.u_v {
            Some(u) => {
                check_finite(&source, "u", u, t)?;
                Some(u.clone())
            }
            None => None,
        };
        let tau_m_nm = i_a_a
            .as_ref()
            .map(|i| i.iter().map(|i| params.k_t * i).collect());
        Ok(Experiment {
            source,
            time_s: t.clone(),
            omega_m_rad_s,
            tau_m_nm,
            i_a_a,
            u_v,
            speed_note,
        })
    }

    /// The motor torque, or the explanation why the method needs the current.
    pub fn torque(&self, method: &'static str) -> Result<&[f64], IdentError> {
        let _ = method;
        self.tau_m_nm.as_deref().ok_or_else(|| IdentError::MissingSignal {
            log: self.source.clone(),
            signal: "armature current i_a",
            why: "the motor torque tau_m = k_t i_a is the left-hand side of eqs. 57, 67 and 71; log the current (shunt voltage / R_s)",
        })
    }

    /// Median sample period [s].
    pub fn sample_period_s(&self) -> f64 {
        median_dt(&self.time_s)
    }
}

fn check_finite(
    source: &str,
    signal: &'static str,
    x: &[f64],
    t: &[f64],
) -> Result<(), IdentError> {
    match x.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(row) => Err(IdentError::NotFinite {
            log: String::from(source),
            signal,
            row,
            time_s: t.get(row).copied().unwrap_or(f64::NAN),
        }),
    }
}

/// Median of the sample periods [s].
pub(crate) fn median_dt(t: &[f64]) -> f64 {
    if t.len() < 2 {
        return f64::NAN;
    }
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(|a, b| a.total_cmp(b));
    d[d.len() / 2]
}

/// Mean of a slice (NaN when empty).
pub(crate) fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A load angle and its speed logged beside it: kept when it does not lag the angle's
    /// derivative (a tachometer), replaced by that derivative, with a note, when it lags by
    /// more than [`MAX_SPEED_LAG_SAMPLES`] (a causal estimate).
    #[test]
    fn a_lagging_logged_speed_gives_way_to_the_angle() {
        let n = 3000;
        let time_s: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let w = |t: f64| libm::sin(7.0 * t) + 0.4 * libm::sin(23.0 * t);
        let theta = |t: f64| -libm::cos(7.0 * t) / 7.0 - 0.4 * libm::cos(23.0 * t) / 23.0;
        let theta_l: Vec<f64> = time_s.iter().map(|&t| theta(t)).collect();
        let exact: Vec<f64> = time_s.iter().map(|&t| w(t)).collect();
        let late: Vec<f64> = time_s.iter().map(|&t| w(t - 4e-3)).collect();
        let p = PlantParams::TABLE2;
        let rec = |omega: &[f64]| Record {
            source: "log".into(),
            time_s: time_s.clone(),
            theta_l_rad: Some(theta_l.clone()),
            omega_l_rad_s: Some(omega.to_vec()),
            i_a_a: Some(alloc::vec![0.1; n]),
            ..Record::default()
        };
        let kept = Experiment::from_record(&rec(&exact), &p).unwrap();
        assert!(kept.speed_note.is_none());
        assert_eq!(kept.omega_m_rad_s[100], exact[100] * p.n);
        let replaced = Experiment::from_record(&rec(&late), &p).unwrap();
        let note = replaced.speed_note.unwrap();
        assert!(
            note.contains("omega_l") && note.contains("4.0 samples"),
            "{note}"
        );
        let d = derivative_at(&time_s, &theta_l);
        assert_eq!(replaced.omega_m_rad_s[100], d[100] * p.n);
    }
}
