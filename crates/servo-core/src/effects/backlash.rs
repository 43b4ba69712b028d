//! `backlash`: gear play. Motor and load separate inside a gap and meet through a stiff
//! spring-damper contact at the load; the mechanics splits into two bodies (motor side J_eq (1 -
//! f), load J_eq f, f = `load_inertia_fraction`).
//!
//! It has no regressor (the torque balance cannot see a gap): the fit sizes the gap, with J_eq
//! and the Coulomb level, on the output error of short simulations, and the diagnosis judges it
//! on the simulation alone.

use super::{spec, ActsOn, Contact, EffectModel, ParamSpec, Regime, SimRole};

/// The `backlash` effect.
#[derive(Debug, Clone, Copy)]
pub struct Backlash;

const PARAMS: [ParamSpec; 4] = [
    spec("gap", "rad", "total play seen at the load", None, 0.0, true),
    spec(
        "stiffness",
        "N m/rad",
        "contact stiffness at the load",
        Some(20.0),
        1e-9,
        true,
    ),
    spec(
        "damping",
        "N m s/rad",
        "contact damping at the load",
        Some(0.02),
        0.0,
        true,
    ),
    spec(
        "load_inertia_fraction",
        "-",
        "share of J_eq on the load side of the gap (0..1)",
        Some(0.3),
        0.0,
        true,
    ),
];

/// Largest gap searched [rad].
#[cfg(feature = "alloc")]
const GAP_MAX_RAD: f64 = 0.2;

/// Horizon of the long prediction segments that size a gap [s].
#[cfg(feature = "alloc")]
const LONG_HORIZON_S: f64 = 0.75;

/// Penetration [rad], load side: how far the motor side, reflected to the load (theta_m / N), is
/// past the edge of the play relative to the load angle. `delta_l = theta_m / N - theta_l`;
/// positive result: contact on the driving (+) flank, negative: on the (-) flank, 0 inside the
/// gap. `gap` [rad] is the total play.
#[inline]
pub fn penetration_l(gap: f64, delta_l: f64) -> f64 {
    let half = 0.5 * gap;
    if delta_l > half {
        delta_l - half
    } else if delta_l < -half {
        delta_l + half
    } else {
        0.0
    }
}

/// Contact torque [N m] transmitted to the load (and -1/N of it to the motor): a spring-damper
/// that acts only in contact and never pulls the flanks together.
///
/// `gap` [rad], `stiffness` [N m/rad], `damping` [N m s/rad], `delta_l` = theta_m / N - theta_l
/// [rad], `delta_dot_l` its rate [rad/s].
#[inline]
pub fn torque_l(gap: f64, stiffness: f64, damping: f64, delta_l: f64, delta_dot_l: f64) -> f64 {
    let p = penetration_l(gap, delta_l);
    if p > 0.0 {
        (stiffness * p + damping * delta_dot_l).max(0.0)
    } else if p < 0.0 {
        (stiffness * p + damping * delta_dot_l).min(0.0)
    } else {
        0.0
    }
}

impl EffectModel for Backlash {
    fn name(&self) -> &str {
        "backlash"
    }
    fn description(&self) -> &str {
        "gear play: motor and load separate inside a gap, contact through a stiff spring"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::LoadTorque
    }
    fn sim_role(&self) -> SimRole {
        SimRole::Contact
    }
    fn contact(&self, v: &[f64]) -> Option<Contact> {
        Some(Contact {
            gap_rad: *v.first()?,
            stiffness_nm_per_rad: *v.get(1)?,
            damping_nms_per_rad: *v.get(2)?,
            load_inertia_fraction: *v.get(3)?,
        })
    }
    fn contact_torque_l(&self, c: &Contact, delta_l: f64, delta_dot_l: f64) -> f64 {
        torque_l(
            c.gap_rad,
            c.stiffness_nm_per_rad,
            c.damping_nms_per_rad,
            delta_l,
            delta_dot_l,
        )
    }
    fn contact_penetration_l(&self, c: &Contact, delta_l: f64) -> f64 {
        penetration_l(c.gap_rad, delta_l)
    }
    fn fittable(&self, key: &str) -> bool {
        // The contact stiffness, damping and inertia split keep their defaults unless asked.
        key == "gap"
    }
    #[cfg(feature = "alloc")]
    fn search_grid(&self, _key: &str, _ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        Some(crate::fit::search::linspace(0.0, GAP_MAX_RAD, 16))
    }
    fn experiment(&self) -> &str {
        "run small position reversals (a 1-2 Hz sine of a few degrees) and log both motor and load angles"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::Reversal, Regime::Acceleration]
    }
    fn suspect_phrase(&self) -> &str {
        "backlash (gear play)"
    }
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn super::FitHooks> {
        Some(self)
    }
}

#[cfg(feature = "alloc")]
mod fit {
    use super::{Backlash, GAP_MAX_RAD, LONG_HORIZON_S};
    use crate::diagnose::checks::{get, Check};
    use crate::diagnose::Candidate;
    use crate::effects::{EffectKind, FitHooks};
    use crate::fit::{
        oe, search, set_effect as set, to_plant, Dataset, EffectToFit, FitError, ParamEstimate,
        Solved,
    };
    use crate::plant::Plant;
    use alloc::string::String;
    use alloc::vec::Vec;

    impl FitHooks for Backlash {
        fn constraints(
            &self,
            ds: &Dataset,
            params: &[ParamEstimate],
            _cand: &Plant,
            _base: &Plant,
        ) -> Vec<Check> {
            let g = get(params, "gap").unwrap_or(f64::NAN);
            let q = ds
                .recs
                .iter()
                .filter_map(|r| crate::compare::quantum::encoder_quantum(&r.theta_m_rad))
                .fold(0.0f64, f64::max)
                / ds.gear_ratio;
            alloc::vec![Check {
                name: "gap > 0",
                passed: g > (2.0 * q).max(1e-4),
                detail: alloc::format!(
                    "gap {g:.4} rad against the load-angle resolution {q:.2e} rad (needs more than twice it: a gap at zero is a compliance without play)"
                ),
            }]
        }
        fn judged_on_simulation(&self) -> bool {
            true
        }
        fn refine_on_simulation(
            &self,
            ds: &Dataset,
            solved: &mut Solved,
            i: usize,
            fit_main: bool,
            fit_j: bool,
        ) -> Result<(), FitError> {
            refine(ds, solved, i, fit_main, fit_j)
        }
        fn candidate_note(&self, ds: &Dataset, model: &Plant, c: &Candidate) -> Option<String> {
            stiffness_note(ds, model, c)
        }
    }

    /// Sizes the backlash gap of slot `i` on the simulation (output-error) cost of the fit blocks.
    ///
    /// Backlash lives outside the equation-error regressors, and a gap biases the rigid-body
    /// estimates of the torque balance: while the motor crosses the gap the measured load does not
    /// follow the motor torque, and least squares answers with a smaller J_eq (about 3 % for a
    /// 0.03 rad gap). A gap sized with that biased inertia comes out too wide (0.045 rad for 0.03),
    /// so the gap and J_eq are refined together on the simulation cost:
    ///
    /// 1. on the usual short prediction segments: a grid over the gap, then J_eq (within +-15 %
    ///    of its equation-error value) and the gap again by golden-section search;
    /// 2. on long overlapping segments (0.75 s, a new one every 0.25 s): J_eq and the gap once
    ///    more. A gap shows as an offset after each reversal, which short segments started from an
    ///    uncertain contact state blur; long segments hold several reversals each. Over 5 seeds
    ///    and gaps of 0.015, 0.03 and 0.06 rad this brings every estimate within 12 % (short
    ///    segments alone: within 35 %).
    ///
    /// With `fit_gap` false the gap keeps its value and only J_eq is refined; with `fit_j` false
    /// J_eq keeps its equation-error value.
    fn refine(
        ds: &Dataset,
        solved: &mut Solved,
        i: usize,
        fit_gap: bool,
        fit_j: bool,
    ) -> Result<(), FitError> {
        let hi = search::linspace(0.0, GAP_MAX_RAD, 16)
            .last()
            .copied()
            .unwrap_or(0.1);
        let base = to_plant(&solved.cfg, &solved.mech, solved.elec.as_ref())?;
        let j0 = base.params.j_eq();
        let short = oe::segments(ds, oe::Part::Fit);
        let long_h = LONG_HORIZON_S.max(ds.opts.oe_horizon_s);
        let long = oe::segments_with(ds, oe::Part::Fit, long_h, 3, 90);
        let tau0 = base.tau_sf();
        let plant_with = |gap: f64, j_eq: f64, tau_sf: f64| -> Option<Plant> {
            let mut c = solved.cfg.clone();
            c.slots[i].set("gap", gap);
            let mut p = to_plant(&c, &solved.mech, solved.elec.as_ref()).ok()?;
            p.params.j_eq = Some(j_eq);
            if tau_sf != tau0 {
                p.params.tau_sf = Some(tau_sf);
                set(&mut p, EffectKind::Coulomb, &[tau_sf]).ok()?;
            }
            Some(p)
        };
        let tau_cell = core::cell::Cell::new(tau0);
        let cost = |segs: &[(usize, usize)], h: f64, gap: f64, j_eq: f64| -> f64 {
            plant_with(gap, j_eq, tau_cell.get())
                .and_then(|p| oe::prediction_cost_over(ds, &p, segs, h))
                .unwrap_or(f64::INFINITY)
        };
        let h0 = ds.opts.oe_horizon_s;
        // J_eq that best goes with a gap on the short segments (+-15 % of its equation-error
        // value): gap and inertia trade off along a ridge (a heavier motor side crosses the gap
        // later, which looks like a wider gap), so each gap of the grid gets its own J_eq.
        let best_j = |gap: f64| -> (f64, f64) {
            if !fit_j {
                return (j0, cost(&short, h0, gap, j0));
            }
            search::grid_then_golden(
                &search::linspace(0.85, 1.15, 4),
                |s| cost(&short, h0, gap, j0 * s),
                5,
            )
            .map_or((j0, f64::INFINITY), |(s, c)| (j0 * s, c))
        };
        let (mut gap, mut j_eq) = if fit_gap {
            let mut best = (f64::NAN, j0, f64::INFINITY);
            for g in search::linspace(0.0, hi, 16) {
                let (j, c) = best_j(g);
                if c < best.2 {
                    best = (g, j, c);
                }
            }
            if !best.2.is_finite() {
                return Err(FitError::Singular(String::from(
                    "backlash: the simulation failed for every gap",
                )));
            }
            (best.0, best.1)
        } else {
            (solved.cfg.slots[i].get("gap"), j0)
        };
        let step = hi / 15.0;
        for (segs, h, j_span, iters) in [(&short, h0, 0.15, 8), (&long, long_h, 0.05, 8)] {
            if segs.is_empty() {
                continue;
            }
            if fit_j {
                let grid = search::linspace(1.0 - j_span, 1.0 + j_span, 5);
                let jc = j_eq;
                if let Some((s, _)) =
                    search::grid_then_golden(&grid, |s| cost(segs, h, gap, jc * s), iters)
                {
                    j_eq = jc * s;
                }
            }
            if fit_j && base.effects.contains(EffectKind::Coulomb) {
                // The Coulomb level decides how far the load coasts once the motor leaves it.
                let tc = tau_cell.get();
                let grid = search::linspace(0.9, 1.1, 5);
                let f = |s: f64| {
                    tau_cell.set(tc * s);
                    let c = cost(segs, h, gap, j_eq);
                    tau_cell.set(tc);
                    c
                };
                if let Some((s, _)) = search::grid_then_golden(&grid, f, iters) {
                    tau_cell.set(tc * s);
                }
            }
            if fit_gap {
                let grid = search::linspace((gap - step).max(0.0), gap + step, 5);
                if let Some((g, _)) =
                    search::grid_then_golden(&grid, |g| cost(segs, h, g, j_eq), iters)
                {
                    gap = g;
                }
            }
        }
        let refined = plant_with(gap, j_eq, tau_cell.get()).ok_or_else(|| {
            FitError::BadModel(String::from("backlash: the refined model is not valid"))
        })?;
        solved.cfg.slots[i].set("gap", gap);
        solved.plant = refined;
        Ok(())
    }


    /// The backlash gap against the contact stiffness it was sized with: the gap is refitted with
    /// the stiffness halved and doubled (the default is a guess unless both angles are logged). When
    /// one stiffness predicts the held-out motion clearly best (5 % lower simulation error than
    /// both others) it is reported as estimated; otherwise the gap is reported as conditional on
    /// the assumed stiffness, with the range of gaps over the plausible range.
    fn stiffness_note(ds: &Dataset, model: &Plant, c: &Candidate) -> Option<String> {
        use oe::{prediction_cost, Part};
        let k0 = c.plant.effects.value(EffectKind::Backlash, "stiffness")?;
        let g0 = c.plant.effects.value(EffectKind::Backlash, "gap")?;
        let mut rows: Vec<(f64, f64, f64)> = Vec::new();
        let c0 = prediction_cost(ds, &c.plant, Part::Holdout)?;
        rows.push((k0, g0, c0));
        for f in [0.5, 2.0] {
            let spec = alloc::format!("backlash:stiffness={}", k0 * f);
            let t = EffectToFit::parse(&spec).ok()?;
            let solved = ds.fit_config(model, &[t]).ok()?;
            let g = solved.plant.effects.value(EffectKind::Backlash, "gap")?;
            let cost = prediction_cost(ds, &solved.plant, Part::Holdout)?;
            rows.push((k0 * f, g, cost));
        }
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        let best = rows.iter().min_by(|a, b| a.2.total_cmp(&b.2))?;
        let clear = rows
            .iter()
            .filter(|r| r.0 != best.0)
            .all(|r| best.2 < 0.95 * r.2);
        let (gmin, gmax) = rows
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
                (a.min(r.1), b.max(r.1))
            });
        let table: Vec<String> = rows
            .iter()
            .map(|r| {
                alloc::format!(
                    "{:.0} N m/rad: gap {:.4} rad, held-out simulation error {:.3e} rad",
                    r.0,
                    r.1,
                    r.2
                )
            })
            .collect();
        Some(if clear {
            alloc::format!(
                " Contact stiffness estimated with the gap: {:.0} N m/rad predicts the held-out motion best (gap {:.4} rad; {}).",
                best.0,
                best.1,
                table.join("; ")
            )
        } else {
            alloc::format!(
                " The gap is conditional on the assumed contact stiffness {k0:.0} N m/rad, which these data do not pin down: over {:.0}-{:.0} N m/rad the gap ranges {gmin:.4}-{gmax:.4} rad ({}). Log both motor and load angles to measure it.",
                rows[0].0,
                rows[rows.len() - 1].0,
                table.join("; ")
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contact_torques_by_hand() {
        assert_eq!(penetration_l(0.04, 0.01), 0.0);
        assert!((penetration_l(0.04, 0.03) - 0.01).abs() < 1e-15);
        assert!((penetration_l(0.04, -0.03) + 0.01).abs() < 1e-15);
        assert!((torque_l(0.04, 20.0, 0.0, 0.03, 0.0) - 0.2).abs() < 1e-12);
        // Separating fast: the damper would pull, the contact does not.
        assert_eq!(torque_l(0.04, 20.0, 0.02, 0.021, -100.0), 0.0);
        assert_eq!(torque_l(0.04, 20.0, 0.02, 0.0, 5.0), 0.0);
    }
}
