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
}

impl Default for CombinedConfig {
    fn default() -> Self {
        CombinedConfig {
            cutoff_hz: 10.0,
            min_speed_frac: 0.05,
            edge_s: 0.05,
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
    let j_eq = Estimate::from_fit(&fit, 0);
    let b_eq = Estimate::from_fit(&fit, 1);
    let tau_sf = Estimate::from_fit(&fit, 2);
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
