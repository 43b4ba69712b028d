//! Inertia estimation (handout 4.2, eqs. 67-70).
//!
//! In each constant acceleration (a_m+ > 0) or deceleration (a_m- < 0) phase the inertial torque
//! is tau_i = k_t i_a - tau_f'(w_m) with the friction of 4.1 (eq. 67). Each acceleration phase is
//! paired with the deceleration phase next to it: J_eq,n = (tau_i+ - tau_i-) / (a_m+ - a_m-)
//! (eq. 70), and J_eq is the mean over the pairs (eq. 69), with the standard error of that mean.
//!
//! [`identify_inertia_ls`] is the alternative used in some reports: LS of tau_i = J_eq dw_m/dt
//! on every sample with |dw_m/dt| above a threshold (filtered derivative, same filter on torque).

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

use super::friction::FrictionFit;
use super::ls::{self, Covariance};
use super::phases::{accel_threshold, find_phases, PhaseConfig};
use super::student_t::t95;
use super::{mean, Estimate, Experiment, IdentError};
use crate::math;
use crate::signal::{derivative_at, lowpass_zero_phase};

/// One acceleration or deceleration phase used by the estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct InertiaPhase {
    /// Index of the experiment.
    pub experiment: usize,
    /// Sample range (trimmed).
    pub start: usize,
    pub end: usize,
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Acceleration a_m (slope of the speed) [rad/s^2].
    pub accel_rad_s2: f64,
    /// Mean inertial torque tau_i = k_t i_a - tau_f' [N m].
    pub tau_i_nm: f64,
}

/// Result of the inertia estimation.
#[derive(Debug, Clone, PartialEq)]
pub struct InertiaFit {
    /// Total inertia at motor side J_eq [kg m^2].
    pub j_eq: Estimate,
    /// The phases found.
    pub phases: Vec<InertiaPhase>,
    /// Pairs (acceleration phase index, deceleration phase index, J_eq,n) of eq. 70.
    pub pairs: Vec<(usize, usize, f64)>,
    /// Remarks.
    pub notes: Vec<String>,
}

fn friction_torque(f: Option<&FrictionFit>, w: f64) -> f64 {
    f.map(|f| f.torque_nm(w)).unwrap_or(0.0)
}

/// Finds the phases of every experiment and their mean inertial torque.
pub fn inertia_phases(
    exps: &[Experiment],
    friction: Option<&FrictionFit>,
    cfg: &PhaseConfig,
) -> Result<Vec<InertiaPhase>, IdentError> {
    let mut out = Vec::new();
    for (k, e) in exps.iter().enumerate() {
        let tau = e.torque("inertia")?;
        let w = &e.omega_m_rad_s;
        let wmax = w.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
        for p in find_phases(&e.time_s, w, cfg)? {
            // A phase through or near rest is left out: the friction there (stiction, the
            // turn of the sign) is not the fitted one, and eq. 67 would carry its error into J.
            let w0 = w[p.start];
            if w[p.start..p.end]
                .iter()
                .any(|v| v * w0 <= 0.0 || v.abs() < REST_FRAC * wmax)
            {
                continue;
            }
            let tau_i: Vec<f64> = (p.start..p.end)
                .map(|i| tau[i] - friction_torque(friction, w[i]))
                .collect();
            out.push(InertiaPhase {
                experiment: k,
                start: p.start,
                end: p.end,
                t_start_s: e.time_s[p.start],
                t_end_s: e.time_s[p.end - 1],
                accel_rad_s2: p.accel_rad_s2,
                tau_i_nm: slope_weighted_mean(&e.time_s[p.start..p.end], &tau_i),
            });
        }
    }
    Ok(out)
}

/// Phases with a speed below this fraction of the log's largest |w_m| are left out [-].
const REST_FRAC: f64 = 0.02;

/// The mean of `x` (sampled at `t`) weighted as the straight-line slope of the phase weights the
/// acceleration: the slope of a line fitted to w(t) is sum_j W_j (w_{j+1} - w_j) / (t_{j+1} - t_j)
/// with parabolic weights W_j >= 0, sum W_j = 1 (largest mid-phase). The torque that causes that
/// acceleration is the same W-weighted mean, so eq. 70 stays exact when the acceleration is not
/// constant over the phase (a speed loop catching up with its ramp, a sine).
pub(crate) fn slope_weighted_mean(t: &[f64], x: &[f64]) -> f64 {
    let m = t.len().min(x.len());
    if m < 3 {
        return mean(&x[..m]);
    }
    let tm = mean(&t[..m]);
    let sxx: f64 = t[..m].iter().map(|t| (t - tm) * (t - tm)).sum();
    if !(sxx > 0.0) {
        return mean(&x[..m]);
    }
    let (mut c, mut acc, mut wsum) = (0.0, 0.0, 0.0);
    for j in 0..m - 1 {
        c += (t[j] - tm) / sxx;
        let wj = -c * (t[j + 1] - t[j]);
        acc += wj * 0.5 * (x[j] + x[j + 1]);
        wsum += wj;
    }
    if wsum > 0.0 {
        acc / wsum
    } else {
        mean(&x[..m])
    }
}

fn no_phase_error() -> IdentError {
    IdentError::NotIdentifiable(String::from(
        "inertia: no constant acceleration/deceleration phase found (each must last at least 0.2 s); J_eq multiplies \
         dw_m/dt only, so a test at constant speeds cannot show it. Run speed ramps up and down at a constant \
         acceleration (handout 4.2, `servo identify --ramp`), repeated at least twice",
    ))
}

/// J_eq by eqs. 67-70 from the phases of `exps`, with the friction `friction` removed (eq. 67).
pub fn identify_inertia(
    exps: &[Experiment],
    friction: Option<&FrictionFit>,
    cfg: &PhaseConfig,
) -> Result<InertiaFit, IdentError> {
    let phases = inertia_phases(exps, friction, cfg)?;
    if phases.is_empty() {
        return Err(no_phase_error());
    }
    // Pair each phase with the next one of opposite sign in the same experiment.
    let mut pairs = Vec::new();
    let mut k = 0;
    while k + 1 < phases.len() {
        let (a, b) = (&phases[k], &phases[k + 1]);
        if a.experiment == b.experiment && a.accel_rad_s2 * b.accel_rad_s2 < 0.0 {
            let (p, m) = if a.accel_rad_s2 > 0.0 {
                (k, k + 1)
            } else {
                (k + 1, k)
            };
            let (pp, pm) = (&phases[p], &phases[m]);
            let j = (pp.tau_i_nm - pm.tau_i_nm) / (pp.accel_rad_s2 - pm.accel_rad_s2);
            pairs.push((p, m, j));
            k += 2;
        } else {
            k += 1;
        }
    }
    let m = pairs.len();
    if m < 2 {
        let (np, nn) = (
            phases.iter().filter(|p| p.accel_rad_s2 > 0.0).count(),
            phases.iter().filter(|p| p.accel_rad_s2 < 0.0).count(),
        );
        return Err(IdentError::NotIdentifiable(format!(
            "inertia: found {np} acceleration and {nn} deceleration phases forming {m} acceleration/deceleration pair(s); \
             eq. 70 needs an acceleration next to a deceleration (so that friction cancels), and the uncertainty needs \
             at least two such pairs: repeat the up/down ramp cycle"
        )));
    }
    let js: Vec<f64> = pairs.iter().map(|p| p.2).collect();
    let j_mean = mean(&js);
    let var = js.iter().map(|j| (j - j_mean) * (j - j_mean)).sum::<f64>() / (m - 1) as f64;
    let se = math::sqrt(var / m as f64);
    let t = t95((m - 1) as f64);
    // Residual of tau_i = J a over the samples of the paired phases.
    let mut ss = 0.0;
    let mut cnt = 0usize;
    for &(p, q, _) in &pairs {
        for ph in [&phases[p], &phases[q]] {
            let e = &exps[ph.experiment];
            let tau = e.torque("inertia")?;
            for i in ph.start..ph.end {
                let r = tau[i]
                    - friction_torque(friction, e.omega_m_rad_s[i])
                    - j_mean * ph.accel_rad_s2;
                ss += r * r;
                cnt += 1;
            }
        }
    }
    let mut notes = Vec::new();
    if friction.is_none() {
        notes.push(String::from(
            "no friction estimate given: the friction cancels in eq. 68 only as far as the acceleration and deceleration \
             phases sweep the same speeds; add the friction runs for eq. 67",
        ));
    }
    let (j_offset, j_offset_se) = super::CurrentSampling::offsets_for(cfg.current_sampling, exps);
    let j_eq = Estimate {
        value: j_mean,
        std_err: se,
        ci95: (j_mean - t * se, j_mean + t * se),
        residual_rms: math::sqrt(ss / cnt.max(1) as f64),
        cond: 1.0,
        dof: m - 1,
        n: m,
    }
    .shifted(j_offset)
    .widened(j_offset_se);
    Ok(InertiaFit {
        j_eq,
        phases,
        pairs,
        notes,
    })
}

/// J_eq by LS of tau_i = J_eq dw_m/dt over the samples with |dw_m/dt| above the phase threshold.
/// Torque and speed are low-passed by the same zero-phase filter; the covariance is robust to the
/// autocorrelation of the residuals.
pub fn identify_inertia_ls(
    exps: &[Experiment],
    friction: Option<&FrictionFit>,
    cfg: &PhaseConfig,
) -> Result<InertiaFit, IdentError> {
    let mut a_rows = Vec::new();
    let mut y = Vec::new();
    for e in exps {
        let tau = e.torque("inertia")?;
        let dt = e.sample_period_s();
        let wf = lowpass_zero_phase(&e.omega_m_rad_s, dt, cfg.cutoff_hz)?;
        let tf = lowpass_zero_phase(tau, dt, cfg.cutoff_hz)?;
        let a = derivative_at(&e.time_s, &wf);
        let thr = accel_threshold(&a, cfg);
        let wmax = wf.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
        for k in 0..a.len() {
            if a[k].abs() > thr && wf[k].abs() > 0.02 * wmax {
                a_rows.push(a[k]);
                y.push(tf[k] - friction_torque(friction, wf[k]));
            }
        }
    }
    if a_rows.len() < 100 {
        return Err(no_phase_error());
    }
    let blocks = (a_rows.len() / 200).clamp(2, 40);
    let fit = ls::fit(&[&a_rows], &y, Covariance::Blocks(blocks))?;
    let mut notes = Vec::new();
    if friction.is_none() {
        notes.push(String::from(
            "no friction estimate given: the LS attributes all torque to inertia",
        ));
    }
    Ok(InertiaFit {
        j_eq: Estimate::from_fit(&fit, 0),
        phases: Vec::new(),
        pairs: Vec::new(),
        notes,
    })
}
