//! Friction estimation (handout 4.1, eqs. 57-66): at constant speed the motor torque balances the
//! friction, k_t i_a = B_eq w_m + (tau_sf / N) sign(w_m). The constant-speed segments are found
//! automatically ([`find_plateaus`]); the LS uses the per-plateau means of torque and speed (one
//! equation per plateau, as the published Padova estimates) or every plateau sample.

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

use super::ls::{self, Covariance};
use super::plateaus::{find_plateaus, PlateauConfig};
use super::{mean, Estimate, Experiment, IdentError};
use crate::math;

/// Settings of the friction estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionConfig {
    /// Plateau detection.
    pub plateau: PlateauConfig,
    /// Plateaus slower than this fraction of the largest |w_m| count as "at rest" and are
    /// excluded (the sign of the speed is undefined there and stiction dominates) [-].
    pub min_speed_frac: f64,
    /// Fit every plateau sample instead of the plateau means (covariance robust to
    /// autocorrelation, one block per plateau).
    pub samples: bool,
}

impl Default for FrictionConfig {
    fn default() -> Self {
        FrictionConfig {
            plateau: PlateauConfig::default(),
            min_speed_frac: 0.02,
            samples: false,
        }
    }
}

/// One constant-speed segment used by the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FrictionPoint {
    /// Index of the experiment it came from.
    pub experiment: usize,
    /// Start and end of the (trimmed) segment [s].
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Mean motor speed [rad/s].
    pub omega_m_rad_s: f64,
    /// Mean motor torque k_t i_a [N m].
    pub tau_m_nm: f64,
    /// Sample range in the experiment.
    pub start: usize,
    pub end: usize,
}

/// Result of the friction estimation.
#[derive(Debug, Clone, PartialEq)]
pub struct FrictionFit {
    /// Viscous friction at motor side B_eq [N m s/rad].
    pub b_eq: Estimate,
    /// Coulomb friction at load side tau_sf [N m].
    pub tau_sf: Estimate,
    /// Gear ratio used for the sign regressor (1/N) sign(w_m).
    pub n: f64,
    /// The constant-speed segments.
    pub points: Vec<FrictionPoint>,
    /// Remarks on what the data can and cannot show.
    pub notes: Vec<String>,
}

impl FrictionFit {
    /// Friction torque at motor side (eq. 66) at motor speed `w` [rad/s] -> [N m].
    pub fn torque_nm(&self, omega_m_rad_s: f64) -> f64 {
        self.b_eq.value * omega_m_rad_s + self.tau_sf.value / self.n * math::sign(omega_m_rad_s)
    }
}

/// Finds the constant-speed segments of every experiment that has a torque signal.
pub fn friction_points(
    exps: &[Experiment],
    cfg: &FrictionConfig,
) -> Result<Vec<FrictionPoint>, IdentError> {
    let mut points = Vec::new();
    for (k, e) in exps.iter().enumerate() {
        let tau = e.torque("friction")?;
        let plats = find_plateaus(&e.time_s, &e.omega_m_rad_s, &cfg.plateau)?;
        let wmax = e.omega_m_rad_s.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
        for p in plats {
            if p.omega_mean.abs() <= cfg.min_speed_frac * wmax {
                continue;
            }
            points.push(FrictionPoint {
                experiment: k,
                t_start_s: e.time_s[p.start],
                t_end_s: e.time_s[p.end - 1],
                omega_m_rad_s: p.omega_mean,
                tau_m_nm: mean(&tau[p.start..p.end]),
                start: p.start,
                end: p.end,
            });
        }
    }
    Ok(points)
}

/// Estimates B_eq and tau_sf from the constant-speed segments of `exps`; `n` is the gear ratio N.
pub fn identify_friction(
    exps: &[Experiment],
    n: f64,
    cfg: &FrictionConfig,
) -> Result<FrictionFit, IdentError> {
    if !(n > 0.0 && n.is_finite()) {
        return Err(IdentError::BadConfig(format!(
            "gear ratio N must be > 0, got {n}"
        )));
    }
    if exps.is_empty() {
        return Err(IdentError::TooFewData { needed: 1, got: 0 });
    }
    let points = friction_points(exps, cfg)?;
    check_friction_points(&points)?;
    let mut notes = Vec::new();
    let pos = points.iter().filter(|p| p.omega_m_rad_s > 0.0).count();
    let neg = points.len() - pos;
    if pos == 0 || neg == 0 {
        notes.push(String::from(
            "only one direction of rotation: B_eq and tau_sf are separated by the different speed levels, but a \
             current-sensor offset is indistinguishable from Coulomb friction and direction asymmetry cannot be seen; \
             repeat the staircase in the other direction",
        ));
    }
    let fit = if cfg.samples {
        let mut w = Vec::new();
        let mut s = Vec::new();
        let mut y = Vec::new();
        for p in &points {
            let e = &exps[p.experiment];
            let tau = e.torque("friction")?;
            for k in p.start..p.end {
                w.push(e.omega_m_rad_s[k]);
                s.push(math::sign(p.omega_m_rad_s) / n);
                y.push(tau[k]);
            }
        }
        ls::fit(&[&w, &s], &y, Covariance::Blocks(points.len()))?
    } else {
        let w: Vec<f64> = points.iter().map(|p| p.omega_m_rad_s).collect();
        let s: Vec<f64> = points
            .iter()
            .map(|p| math::sign(p.omega_m_rad_s) / n)
            .collect();
        let y: Vec<f64> = points.iter().map(|p| p.tau_m_nm).collect();
        ls::fit(&[&w, &s], &y, Covariance::Iid)?
    };
    let b_eq = Estimate::from_fit(&fit, 0);
    let tau_sf = Estimate::from_fit(&fit, 1);
    if b_eq.value < 0.0 {
        notes.push(format!(
            "B_eq came out negative ({:.3e} N m s/rad): torque falls with speed, which the viscous model cannot \
             describe (stiction decaying with speed, or a drifting current offset?)",
            b_eq.value
        ));
    }
    if tau_sf.value < 0.0 {
        notes.push(format!(
            "tau_sf came out negative ({:.3e} N m): check the sign convention of the current and the speed",
            tau_sf.value
        ));
    }
    Ok(FrictionFit {
        b_eq,
        tau_sf,
        n,
        points,
        notes,
    })
}

/// Refuses segment sets that cannot separate B_eq and tau_sf, saying which experiment is missing.
pub fn check_friction_points(points: &[FrictionPoint]) -> Result<(), IdentError> {
    if points.is_empty() {
        return Err(IdentError::NotIdentifiable(String::from(
            "friction: no constant-speed segment found (each must hold its speed for at least 0.5 s away from rest); \
             run a speed staircase or position ramps at several constant speeds (handout 4.1, `servo identify --ramp`)",
        )));
    }
    // The friction model is odd in w_m: only the speed magnitudes matter for separability.
    let mags: Vec<f64> = points.iter().map(|p| p.omega_m_rad_s.abs()).collect();
    let lo = mags.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = mags.iter().cloned().fold(0.0, f64::max);
    if hi - lo < 0.1 * hi {
        return Err(IdentError::NotIdentifiable(format!(
            "friction: every constant-speed segment runs at the same speed magnitude (|w_m| = {lo:.1}..{hi:.1} rad/s). \
             There the torque is B_eq |w_m| + tau_sf/N, one number for two unknowns, and the opposite direction at \
             the same speed adds nothing because the model is odd in w_m. Add segments at other speed levels \
             (at least two clearly different speeds, better 5-10 spread over the range)"
        )));
    }
    if points.len() < 3 {
        return Err(IdentError::NotIdentifiable(format!(
            "friction: only {} constant-speed segments: two parameters fit them exactly and leave no degree of freedom \
             for an uncertainty; add at least one more speed level",
            points.len()
        )));
    }
    Ok(())
}
