//! Electrical check: at steady state (L_a di_a/dt = 0, driver settled) the armature equation gives
//! u = (R_eq / k_drv) i_a + (k_e / k_drv) w_m. With k_e from the datasheet, the LS coefficients
//! a = R_eq/k_drv [V/A] and b = k_e/k_drv [V s/rad] on the constant-speed segments give
//! k_drv = k_e / b and R_eq = k_e a / b (uncertainties by the delta method), which are compared
//! with the nominal values.

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

use super::friction::{check_friction_points, friction_points, FrictionConfig};
use super::ls::{self, Covariance};
use super::student_t::t95;
use super::{mean, Estimate, Experiment, IdentError};
use crate::math;
use crate::params::PlantParams;

/// Result of the electrical check.
#[derive(Debug, Clone, PartialEq)]
pub struct ElectricalFit {
    /// a = R_eq / k_drv [V/A].
    pub a_v_per_a: Estimate,
    /// b = k_e / k_drv [V s/rad].
    pub b_v_s_per_rad: Estimate,
    /// Driver gain k_drv [V/V].
    pub k_drv: Estimate,
    /// Armature-circuit resistance R_eq = R_a + R_s [ohm].
    pub r_eq: Estimate,
    /// Nominal values compared against (k_drv, R_eq).
    pub nominal_k_drv: f64,
    pub nominal_r_eq: f64,
    /// Disagreements with the datasheet (empty when consistent).
    pub warnings: Vec<String>,
}

/// Relative deviation from the datasheet that is flagged when also outside the 95 % interval.
pub const FLAG_REL: f64 = 0.05;

/// k_drv and R_eq from the constant-speed segments of experiments logging u, i_a and speed.
pub fn identify_electrical(
    exps: &[Experiment],
    params: &PlantParams,
    cfg: &FrictionConfig,
) -> Result<ElectricalFit, IdentError> {
    let with_u: Vec<Experiment> = exps.iter().filter(|e| e.u_v.is_some()).cloned().collect();
    if with_u.is_empty() {
        return Err(IdentError::NotIdentifiable(String::from(
            "electrical: no log has the driver input voltage u; the check needs u, i_a and the speed at constant speeds",
        )));
    }
    let points = friction_points(&with_u, cfg)?;
    check_friction_points(&points)?;
    let mut ia = Vec::new();
    let mut w = Vec::new();
    let mut u = Vec::new();
    for p in &points {
        let e = &with_u[p.experiment];
        let (Some(uu), Some(ii)) = (&e.u_v, &e.i_a_a) else {
            return Err(IdentError::Internal("experiment lost its signals"));
        };
        ia.push(mean(&ii[p.start..p.end]));
        w.push(p.omega_m_rad_s);
        u.push(mean(&uu[p.start..p.end]));
    }
    let fit = ls::fit(&[&ia, &w], &u, Covariance::Iid)?;
    let (a, b) = (fit.theta[0], fit.theta[1]);
    let (vaa, vab, vbb) = (fit.cov[0], fit.cov[1], fit.cov[3]);
    let k_e = params.k_e;
    let t = t95(fit.dof as f64);
    let k_drv = k_e / b;
    let se_k = k_e / (b * b) * math::sqrt(vbb);
    let r_eq = k_e * a / b;
    // Gradient of R_eq = k_e a / b: (k_e / b, -k_e a / b^2).
    let (ga, gb) = (k_e / b, -k_e * a / (b * b));
    let se_r = math::sqrt((ga * ga * vaa + 2.0 * ga * gb * vab + gb * gb * vbb).max(0.0));
    let mk = |v: f64, se: f64| Estimate {
        value: v,
        std_err: se,
        ci95: (v - t * se, v + t * se),
        residual_rms: fit.residual_rms,
        cond: fit.cond,
        dof: fit.dof,
        n: fit.n,
    };
    let k_drv = mk(k_drv, se_k);
    let r_eq = mk(r_eq, se_r);
    let mut warnings = Vec::new();
    for (name, key, est, nom, unit) in [
        ("k_drv", "k_drv", &k_drv, params.k_drv, "V/V"),
        ("R_eq", "r_eq", &r_eq, params.r_eq(), "ohm"),
    ] {
        let rel = (est.value - nom) / nom;
        if rel.abs() > FLAG_REL && !est.contains(nom) {
            warnings.push(format!(
                "{name} = {:.4} {unit} (95 % CI {:.4}..{:.4}) disagrees with the datasheet value {nom:.4} {unit} by {:+.1} %; the model keeps {nom:.4} {unit} unless told: `--keep-fitted {key}` writes the fitted value (with -o)",
                est.value,
                est.ci95.0,
                est.ci95.1,
                rel * 100.0
            ));
        }
    }
    Ok(ElectricalFit {
        a_v_per_a: Estimate::from_fit(&fit, 0),
        b_v_s_per_rad: Estimate::from_fit(&fit, 1),
        k_drv,
        r_eq,
        nominal_k_drv: params.k_drv,
        nominal_r_eq: params.r_eq(),
        warnings,
    })
}
