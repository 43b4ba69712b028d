//! Combined friction and inertia estimation (handout 4.3, eqs. 71-76): one LS over the whole
//! record of tau_m = J_eq dw_m/dt + B_eq w_m + (tau_sf / N) sign(w_m).
//!
//! Speed, torque and the sign regressor all pass through the SAME zero-phase low-pass filter F
//! (the model is linear in the parameters, so F(tau_m) = J_eq F(dw_m/dt) + B_eq F(w_m) +
//! tau_sf/N F(sign w_m) holds exactly); the acceleration is the derivative of F(w_m). Samples
//! near zero speed are excluded: there the sign is undefined and stiction, not Coulomb friction,
//! holds the motor. Works on any sufficiently exciting record (staircases, ramps, open-loop
//! voltage sweeps or steps), and on several records together.

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

use super::ls::{self, Covariance};
use super::{Estimate, Experiment, IdentError};
use crate::math;
use crate::signal::{derivative_at, lowpass_zero_phase};

/// Settings of the combined estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CombinedConfig {
    /// Cut-off of the zero-phase low-pass applied to every signal [Hz].
    pub cutoff_hz: f64,
    /// Samples with |F(w_m)| below this fraction of the largest |F(w_m)| are excluded [-].
    pub min_speed_frac: f64,
    /// Samples within this time of the record's ends are excluded (filter edges) [s].
    pub edge_s: f64,
    /// How the current was sampled (voltage drive, zero-order hold): when set, the torque is
    /// aligned with the speed's derivative ([`aligned_torque`]) and J_eq corrected for the
    /// samples' place in each period; `None`: taken as sampled.
    pub current_sampling: Option<super::CurrentSampling>,
}

impl Default for CombinedConfig {
    fn default() -> Self {
        CombinedConfig {
            cutoff_hz: 10.0,
            min_speed_frac: 0.05,
            edge_s: 0.05,
            current_sampling: None,
        }
    }
}

/// Result of the combined estimation.
#[derive(Debug, Clone, PartialEq)]
pub struct CombinedFit {
    /// J_eq [kg m^2] at motor side.
    pub j_eq: Estimate,
    /// B_eq [N m s/rad] at motor side.
    pub b_eq: Estimate,
    /// tau_sf [N m] at load side.
    pub tau_sf: Estimate,
    /// Rows used (after excluding near-zero speeds and edges).
    pub rows: usize,
    /// Remarks.
    pub notes: Vec<String>,
}

/// J_eq, B_eq and tau_sf from one LS over `exps`; `n` is the gear ratio N.
pub fn identify_combined(
    exps: &[Experiment],
    n: f64,
    cfg: &CombinedConfig,
) -> Result<CombinedFit, IdentError> {
    if !(cfg.min_speed_frac >= 0.0 && cfg.min_speed_frac < 1.0 && cfg.edge_s >= 0.0) {
        return Err(IdentError::BadConfig(format!(
            "combined-fit settings out of range: {cfg:?}"
        )));
    }
    let (mut ca, mut cw, mut cs, mut y) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for e in exps {
        let tau = e.torque("combined")?;
        let dt = e.sample_period_s();
        let wf = lowpass_zero_phase(&e.omega_m_rad_s, dt, cfg.cutoff_hz)?;
        // Sign from the filtered speed (raw encoder speed chatters near zero), then filtered.
        let sgn: Vec<f64> = wf.iter().map(|w| math::sign(*w) / n).collect();
        let sf = lowpass_zero_phase(&sgn, dt, cfg.cutoff_hz)?;
        let aligned;
        let tau = match cfg.current_sampling {
            Some(cs) => {
                aligned = aligned_torque(tau, cs.lag_s / dt);
                &aligned[..]
            }
            None => tau,
        };
        let tf = lowpass_zero_phase(tau, dt, cfg.cutoff_hz)?;
        let a = derivative_at(&e.time_s, &wf);
        let wmax = wf.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
        let (t0, t1) = (
            e.time_s[0] + cfg.edge_s,
            e.time_s[e.time_s.len() - 1] - cfg.edge_s,
        );
        // Exclude whole neighbourhoods of zero crossings: the filtered sign is smeared there.
        let guard = (1.0 / (cfg.cutoff_hz * dt)) as usize;
        let mut near_zero = alloc::vec![false; wf.len()];
        for k in 0..wf.len() {
            if wf[k].abs() <= cfg.min_speed_frac * wmax {
                let lo = k.saturating_sub(guard);
                let hi = (k + guard + 1).min(wf.len());
                for z in &mut near_zero[lo..hi] {
                    *z = true;
                }
            }
        }
        for k in 0..wf.len() {
            let t = e.time_s[k];
            if near_zero[k] || t < t0 || t > t1 {
                continue;
            }
            ca.push(a[k]);
            cw.push(wf[k]);
            cs.push(sf[k]);
            y.push(tf[k]);
        }
    }
    let rows = y.len();
    if rows < 100 {
        return Err(IdentError::NotIdentifiable(format!(
            "combined: only {rows} samples away from rest; the record must keep the motor turning (|w_m| above {:.0} % of \
             its maximum) for a substantial time",
            cfg.min_speed_frac * 100.0
        )));
    }
    check_excitation(&ca, &cw, &cs)?;
    let blocks = (rows / 500).clamp(2, 40);
    let fit = ls::fit(&[&ca, &cw, &cs], &y, Covariance::Blocks(blocks))?;
    let (j_offset, j_offset_se) = super::CurrentSampling::offsets_for(cfg.current_sampling, exps);
    let mut j_eq = Estimate::from_fit(&fit, 0).shifted(j_offset);
    let mut b_eq = Estimate::from_fit(&fit, 1);
    let mut tau_sf = Estimate::from_fit(&fit, 2);
    // The disagreement of the two halves of the rows, fitted apart, folded in: a model or
    // sampling error that changes along the record (speed range, excitation) shows there even
    // when the block sandwich, which trusts the model, does not see it. For halves of equal
    // information (theta_1 - theta_2)^2 / 4 estimates the variance of the whole fit; the larger
    // of the two variances is used.
    let half = rows / 2;
    if half >= 1000 {
        let part = |a: usize, z: usize| {
            ls::fit(
                &[&ca[a..z], &cw[a..z], &cs[a..z]],
                &y[a..z],
                Covariance::Blocks(((z - a) / 500).clamp(2, 40)),
            )
        };
        if let (Ok(f1), Ok(f2)) = (part(0, half), part(half, rows)) {
            let t = super::student_t::t95(fit.dof as f64);
            for (j, e) in [&mut j_eq, &mut b_eq, &mut tau_sf].into_iter().enumerate() {
                let d = 0.5 * (f1.theta[j] - f2.theta[j]).abs();
                if d > e.std_err {
                    e.std_err = d;
                    e.ci95 = (e.value - t * d, e.value + t * d);
                }
            }
        }
    }
    let j_eq = j_eq.widened(j_offset_se);
    let mut notes = Vec::new();
    for (name, e) in [("J_eq", &j_eq), ("B_eq", &b_eq), ("tau_sf", &tau_sf)] {
        if e.ci95.0 <= 0.0 && e.ci95.1 >= 0.0 {
            notes.push(format!(
                "{name}: the 95 % interval contains zero; the record barely excites this term (see the experiment advice of \
                 `--method friction`/`inertia`)"
            ));
        }
    }
    Ok(CombinedFit {
        j_eq,
        b_eq,
        tau_sf,
        rows,
        notes,
    })
}

/// The torque of a log sampled before each zero-order-hold command, moved onto the sample
/// instants of the speed's central derivative. Sample i_k is taken at the end of period k-1,
/// whose driver input the current has followed within `lag` (in samples, T_drv + L_a / R_eq):
/// the mean torque over period k is tau_{k+1} - lag (tau_{k+1} - tau_k), and the derivative of
/// the speed at t_k sees the mean of periods k-1 and k. Taken as sampled, the torque would lag
/// by half a period less the electrical lag, and J_eq would come out low by about that time
/// over the mechanical time constant (0.5-1 % at 1 kHz).
pub fn aligned_torque(tau: &[f64], lag: f64) -> Vec<f64> {
    let n = tau.len();
    if n < 3 || !lag.is_finite() {
        return tau.to_vec();
    }
    let r = lag.clamp(0.0, 1.0);
    let period = |k: usize| tau[k + 1] - r * (tau[k + 1] - tau[k]);
    (0..n)
        .map(|k| {
            if k == 0 || k + 1 >= n {
                tau[k]
            } else {
                0.5 * (period(k - 1) + period(k))
            }
        })
        .collect()
}

/// Refuses records that cannot separate J_eq, B_eq and tau_sf, saying what is missing.
fn check_excitation(a: &[f64], w: &[f64], s: &[f64]) -> Result<(), IdentError> {
    let rms = |x: &[f64]| math::sqrt(x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64);
    let wabs: Vec<f64> = w.iter().map(|w| w.abs()).collect();
    let wmax = wabs.iter().cloned().fold(0.0, f64::max);
    let wmean = wabs.iter().sum::<f64>() / wabs.len() as f64;
    let wsd =
        math::sqrt(wabs.iter().map(|v| (v - wmean) * (v - wmean)).sum::<f64>() / wabs.len() as f64);
    if wsd < 0.03 * wmax {
        return Err(IdentError::NotIdentifiable(format!(
            "combined: the speed magnitude hardly varies (|w_m| = {wmean:.1} +- {wsd:.1} rad/s), so B_eq |w_m| and the \
             Coulomb term tau_sf/N cannot be told apart; the record needs several speed levels"
        )));
    }
    // Acceleration must be visible: compare with the speed scale over one mechanical time scale.
    let a_rms = rms(a);
    if a_rms * 0.05 < 0.01 * rms(w) {
        return Err(IdentError::NotIdentifiable(format!(
            "combined: the record has almost no acceleration (rms dw_m/dt = {a_rms:.2} rad/s^2), so J_eq is not \
             identifiable; include speed changes (steps, ramps or a voltage sweep)"
        )));
    }
    let _ = s;
    Ok(())
}
