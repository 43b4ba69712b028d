//! Identification from logs of u and the angle alone (no current sensor: a smart servo, a
//! gearmotor without a shunt) with the effects a params file declares, and with a large
//! position-dependent load torque (an arm's gravity m g L sin(theta_l + phi)) found when it
//! dominates the balance.
//!
//! The u-driven balance k_drv k_t u / R_eq = J_eq dw/dt + (B_eq + k_t k_e / R_eq) w +
//! tau_sf/N sign(w) + tau_effects/N holds every mechanical effect. A declared effect is fitted
//! with the base from the start (its linear parameters re-estimated, its nonlinear ones kept as
//! declared). Without a declaration, a gravity torque tens of times the friction is absorbed by
//! the base's terms (the classic symptom: a negative inertia, J_eq -87 %, B_eq -78 %,
//! tau_sf +605 % on a pendulum): each registered effect that can dominate a balance
//! ([`crate::effects::EffectModel::dominant_load_candidate`]) is fitted with the base, and when
//! it explains at least [`DOMINANT_SHARE`] of the bare fit's squared residual it is kept and
//! reported, never silently.

use super::model::Coef;
use super::{
    Dataset, EffectToFit, FitError, FitOptions, ParamEstimate, Solved, UDrivenEstimate,
    DRIVE_CONSTANT_TOLERANCE,
};
use crate::effects::EffectKind;
use crate::math;
use crate::params::PlantParams;
use crate::plant::Plant;
use crate::record::Record;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

/// Share of the bare base fit's squared residual (fit rows) a position-dependent load torque
/// must explain to count as dominating the balance.
pub const DOMINANT_SHARE: f64 = 0.5;

/// A position-dependent load torque found to dominate the balance (not declared).
#[derive(Debug, Clone, PartialEq)]
pub struct DominantTorque {
    pub effect: EffectKind,
    /// Share of the bare base fit's squared residual it explains (0..1).
    pub share: f64,
    /// What the bare base fit gave: J_eq [kg m^2] and B_eq [N m s/rad] (motor side), before
    /// any clamping.
    pub bare_j_eq_kg_m2: f64,
    pub bare_b_eq_n_m_s_rad: f64,
}

/// What [`identify_without_current_model`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct UDrivenIdentification {
    /// J_eq, B_eq and tau_sf, then the parameters of every effect fitted with them (`effect`
    /// set), each with its statistical and drive-tolerance-widened standard errors.
    pub estimates: Vec<UDrivenEstimate>,
    /// Effects of the given model (the params file) fitted with the base.
    pub declared: Vec<EffectKind>,
    /// A position-dependent torque found to dominate the balance and fitted with the base.
    pub dominant: Option<DominantTorque>,
    /// The identified model (the base and the effects fitted with it; B_eq and tau_sf at 0 when
    /// they came out negative, see `clamped`).
    pub plant: Plant,
    /// Base parameters that came out negative and were set to 0: (key, fitted value).
    pub clamped: Vec<(&'static str, f64)>,
}

/// The model `base` with the parameters `p` (a Coulomb level to start from when `p` has none),
/// keeping `base`'s effects beyond the linear base friction and its user effects.
fn with_params(base: &Plant, p: PlantParams) -> Result<Plant, FitError> {
    let mut plant = Plant::from_params(PlantParams {
        tau_sf: Some(p.tau_sf.unwrap_or(0.005)),
        ..p
    })
    .map_err(|e| FitError::BadModel(format!("{e}")))?;
    for e in base.effects.iter() {
        if !matches!(e.kind, EffectKind::Viscous | EffectKind::Coulomb) {
            plant.effects.insert(*e);
        }
    }
    plant.custom = base.custom;
    Ok(plant)
}

/// B_eq as the balance fitted it (before the plant clamps it at 0).
fn raw_b_eq(s: &Solved) -> Option<f64> {
    s.mech.coef(Coef::BEq).map(|c| c.0)
}

/// J_eq, B_eq, tau_sf and the effects of `base` (the params file's model) from logs of u and the
/// angle alone, the effects fitted with the base; a dominant position-dependent load torque is
/// found and fitted when `base` declares none (see the module). Each drive constant (k_drv,
/// R_a, k_e, k_t) is perturbed by [`DRIVE_CONSTANT_TOLERANCE`] and the shift of every estimate
/// is added to its interval. Refused when the inertia comes out not positive and no such torque
/// explains it.
pub fn identify_without_current_model(
    records: &[Record],
    base: &Plant,
    opts: &FitOptions,
) -> Result<UDrivenIdentification, FitError> {
    let strip: Vec<Record> = records
        .iter()
        .map(|r| Record {
            i_a_a: None,
            ..r.clone()
        })
        .collect();
    identify_with_model(&strip, base, opts)
}

/// [`identify_without_current_model`] on the records as they are: with the current logged in
/// every record the fit uses the torque and electrical balances (a params file that declares
/// effects on a rig with a current sensor), else the u-driven balance.
pub fn identify_with_model(
    strip: &[Record],
    base: &Plant,
    opts: &FitOptions,
) -> Result<UDrivenIdentification, FitError> {
    let params = base.params;
    let declared: Vec<EffectKind> = base
        .effects
        .iter()
        .map(|e| e.kind)
        .filter(|k| !matches!(*k, EffectKind::Viscous | EffectKind::Coulomb))
        .collect();
    let ds = Dataset::new(strip, &params, opts)?;
    let start = with_params(base, params)?;
    let (bare, bare_j) = ds.fit_base_tolerant(&start)?;
    let mut model = start;
    let mut dominant = None;
    let any_declared = declared.iter().any(|k| k.model().dominant_load_candidate());
    if !any_declared {
        let rss0 = bare.mech.rss_fit;
        let mut best: Option<(f64, Solved, EffectKind)> = None;
        for kind in EffectKind::ALL
            .into_iter()
            .filter(|k| k.model().dominant_load_candidate() && !start.effects.contains(*k))
        {
            if let Ok(s) = ds.fit_config(&start, &[EffectToFit::all(kind)]) {
                let share = 1.0 - s.mech.rss_fit / rss0.max(1e-300);
                if share >= DOMINANT_SHARE && best.as_ref().is_none_or(|b| share > b.0) {
                    best = Some((share, s, kind));
                }
            }
        }
        if let Some((share, s, kind)) = best {
            if let Some(e) = s.plant.effects.get(kind) {
                model.effects.insert(*e);
            }
            dominant = Some(DominantTorque {
                effect: kind,
                share,
                bare_j_eq_kg_m2: bare_j.unwrap_or(bare.plant.params.j_eq()),
                bare_b_eq_n_m_s_rad: raw_b_eq(&bare).unwrap_or(f64::NAN),
            });
        }
    }
    if let (Some(j), None) = (bare_j, &dominant) {
        if declared.is_empty() {
            return Err(FitError::BadModel(format!(
                "the fitted inertia J_eq = {} kg m^2 is not positive and no position-dependent load torque explains the balance (the best explains less than {:.0} % of its residual): the logs need accelerations, or the model lacks a large torque; declare it in the params file ([effects.NAME])",
                math::Num(j),
                100.0 * DOMINANT_SHARE
            )));
        }
    }
    let fit_with = |p: PlantParams| -> Result<(Vec<ParamEstimate>, Solved), FitError> {
        let ds = Dataset::new(strip, &p, opts)?;
        let s = ds.fit_config(&with_params(&model, p)?, &[])?;
        Ok((ds.estimates(&s), s))
    };
    let (nominal, solved) = fit_with(params).map_err(|e| match (&e, &dominant) {
        (FitError::BadModel(why), None) if !declared.is_empty() => FitError::BadModel(format!(
            "{why} (with the effects of the params file fitted beside the base: {})",
            declared
                .iter()
                .map(|k| k.name())
                .collect::<Vec<_>>()
                .join(", ")
        )),
        _ => e,
    })?;
    let tol = DRIVE_CONSTANT_TOLERANCE;
    let perturbed = [
        PlantParams {
            k_drv: params.k_drv * (1.0 + tol),
            ..params
        },
        PlantParams {
            r_a: params.r_a * (1.0 + tol),
            ..params
        },
        PlantParams {
            k_e: params.k_e * (1.0 + tol),
            ..params
        },
        PlantParams {
            k_t: params.k_t * (1.0 + tol),
            ..params
        },
    ];
    let same = |a: &ParamEstimate, b: &ParamEstimate| a.effect == b.effect && a.key == b.key;
    let mut shifts = alloc::vec![0.0f64; nominal.len()];
    for p in perturbed {
        let (est, _) = fit_with(p)?;
        for (j, a) in nominal.iter().enumerate() {
            if let Some(b) = est.iter().find(|b| same(a, b)) {
                shifts[j] += (b.value - a.value) * (b.value - a.value);
            }
        }
    }
    let raw_b = raw_b_eq(&solved);
    let mut clamped = Vec::new();
    let mut out = Vec::new();
    for (j, e) in nominal.iter().enumerate() {
        let base_key = matches!(e.key, "j_eq" | "b_eq" | "tau_sf");
        if !base_key && !e.fitted {
            continue;
        }
        let mut value = e.value;
        let raw = match e.key {
            "b_eq" => raw_b,
            "tau_sf" => solved.mech.coef(Coef::TauSf).map(|c| c.0),
            _ => None,
        };
        if let Some(v) = raw.filter(|v| *v < 0.0) {
            clamped.push((e.key, v));
            value = v;
        }
        let se = e.std_err.unwrap_or(f64::NAN);
        let se0 = if se.is_finite() { se } else { 0.0 };
        // An effect's parameter the least squares give no error for (a searched value, a
        // phase of a pair within its error of zero) has no interval: the drive constants'
        // tolerance alone would print a tight one.
        let total = if base_key || se.is_finite() {
            math::sqrt(se0 * se0 + shifts[j])
        } else {
            f64::NAN
        };
        out.push(UDrivenEstimate {
            effect: (!base_key).then_some(e.effect).flatten(),
            key: e.key,
            unit: e.unit,
            value,
            std_err: se,
            std_err_total: total,
        });
    }
    let mut declared_out = declared;
    declared_out.retain(|k| solved.plant.effects.contains(*k));
    Ok(UDrivenIdentification {
        estimates: out,
        declared: declared_out,
        dominant,
        plant: solved.plant,
        clamped,
    })
}

/// One line per effect fitted with the base, for reports: `NAME (declared|found): key = v +/- se
/// unit, ...`.
pub fn describe_effects(id: &UDrivenIdentification) -> Vec<String> {
    let mut kinds: Vec<(EffectKind, &str)> = id.declared.iter().map(|k| (*k, "declared")).collect();
    if let Some(d) = &id.dominant {
        kinds.push((d.effect, "found dominant"));
    }
    kinds
        .into_iter()
        .map(|(k, how)| {
            let parts: Vec<String> = id
                .estimates
                .iter()
                .filter(|e| e.effect == Some(k))
                .map(|e| {
                    if e.std_err_total.is_finite() {
                        format!(
                            "{} = {:.4e} +/- {:.2e} {}",
                            e.key, e.value, e.std_err_total, e.unit
                        )
                    } else {
                        format!(
                            "{} = {:.4e} {} (no interval: not determined by these logs)",
                            e.key, e.value, e.unit
                        )
                    }
                })
                .collect();
            format!("{} ({how}): {}", k.name(), parts.join(", "))
        })
        .collect()
}
