//! Stage 1 of a diagnosis: the base model refitted on the logs, the current-sensor noise and the
//! noise floor of every balance.

use super::kinds::on_simulation;
use super::structure;
use super::tuner;
use crate::fit::model::{EqSolution, Equation};
use crate::fit::{Dataset, FitError, Solved};
use crate::math;
use crate::plant::Plant;
use alloc::vec::Vec;

/// The base model of a diagnosis and the floors its balances are judged against.
pub(super) struct Base {
    /// The base model re-solved in its balances ([`base_fit`]).
    pub solved: Solved,
    /// The fitted inertia J_eq [kg m^2] when it was not positive (the base then keeps the
    /// model's inertia, and each candidate refits it).
    pub unphysical_j_eq: Option<f64>,
    /// White current-sensor noise [A] (current logged).
    pub noise_a: Option<f64>,
    /// Noise floor per balance of the base model [unit of the balance].
    pub floors: Vec<(Equation, f64)>,
}

impl Base {
    /// The base model's balances: the torque balance, then the electrical one when the current is
    /// logged.
    pub fn solutions(&self) -> Vec<&EqSolution> {
        core::iter::once(&self.solved.mech)
            .chain(self.solved.elec.as_ref())
            .collect()
    }

    /// The noise floor of balance `eq` (0 when it has none).
    pub fn floor_of(&self, eq: Equation) -> f64 {
        structure::floor_in(&self.floors, eq)
    }
}

/// Fits the base model of `model` on `ds` and measures the noise floors of its balances.
pub(super) fn fit(ds: &Dataset, model: &Plant) -> Result<Base, FitError> {
    let (solved, unphysical_j_eq) =
        super::timing::timed(|| "base fit".into(), || base_fit(ds, model))?;
    let noise_a = current_noise(ds);
    let floors = core::iter::once(&solved.mech)
        .chain(solved.elec.as_ref())
        .map(|sol| {
            (
                sol.equation,
                structure::noise_floor(ds, sol.equation, &solved.plant, noise_a),
            )
        })
        .collect();
    Ok(Base {
        solved,
        unphysical_j_eq,
        noise_a,
        floors,
    })
}

/// The base model of a diagnosis: `model` with its linear parameters (base and effects)
/// re-solved in their balances, its nonlinear ones kept.
///
/// When `model` holds an effect judged on the simulation (a gear play), those balances leave
/// out the rows around torque reversals, where the motor crosses the gap and the load angle
/// says nothing of it, and they cannot see the play itself: the values `model` was given, tuned
/// on the simulation with the play (by its refinement or a joint fit, [`super::backward`]), are then
/// kept when they predict the motion of the fit blocks better (on the cost the joint fit is
/// tuned on, [`super::tuner::motion_costs`]) than the re-solved ones. A breakaway friction found
/// beside a play at tau_s 0.017 N m (0.020 true) came back from the torque balance at 0.012,
/// and one at 0.020 at 0.026 (the breakaway lives at the reversals the balance leaves out).
/// The balances' residuals are those of the re-solved model either way.
///
/// When the re-solved inertia is not positive (a large torque the model lacks: an arm's
/// gravity), the base keeps `model`'s inertia and the fitted value is returned beside it: the
/// candidates, each refitting the base, are still tried ([`Dataset::fit_base_tolerant`]).
fn base_fit(ds: &Dataset, model: &Plant) -> Result<(Solved, Option<f64>), FitError> {
    let (mut s, unphysical) = ds.fit_base_tolerant(model)?;
    if unphysical.is_some() {
        return Ok((s, unphysical));
    }
    if ds.has_input && model.effects.iter().any(|e| on_simulation(e.kind)) {
        if let [Some(a), Some(b)] = tuner::motion_costs(ds, [&s.plant, model]) {
            if b < a {
                s.plant = *model;
            }
        }
    }
    Ok((s, None))
}

/// Robust estimate of the white current-sensor noise [A]: MAD of first differences / sqrt(2).
fn current_noise(ds: &Dataset) -> Option<f64> {
    let mut d: Vec<f64> = Vec::new();
    for r in &ds.recs {
        let i = r.i_raw.as_ref()?;
        d.extend(i.windows(2).map(|w| (w[1] - w[0]).abs()));
    }
    if d.is_empty() {
        return None;
    }
    let mid = d.len() / 2;
    let median = math::order_statistic(&mut d, mid)?;
    Some(median / 0.6745 / core::f64::consts::SQRT_2)
}
