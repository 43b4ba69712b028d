//! Which candidates a diagnosis tries, in which order they are started, and how each is judged
//! (on its balance, or on the simulation alone).

use super::DiagnoseOptions;
use crate::effects::{EffectKind, SimRole};
use crate::fit::Dataset;
use crate::plant::Plant;
use alloc::vec::Vec;

/// Kinds worth trying on `model`.
pub fn candidate_kinds(model: &Plant, opts: &DiagnoseOptions) -> Vec<EffectKind> {
    let has = |k| model.effects.contains(k);
    let has_name = |name: &str| EffectKind::from_name(name).is_some_and(has);
    let pool: Vec<EffectKind> = if opts.candidates.is_empty() {
        EffectKind::ALL
            .into_iter()
            .chain(opts.extra_candidates.iter().copied())
            .collect()
    } else {
        // In registry order, whatever order they were given in.
        let mut c = opts.candidates.clone();
        c.sort();
        c
    };
    let mut out: Vec<EffectKind> = Vec::new();
    for k in pool {
        // Part of the linear base model (viscous friction) or already in the model: nothing
        // to try. Some effects need another one first (e.g. a breakaway decays to the Coulomb
        // level): [`crate::effects::EffectModel::applicable`].
        if k.sim_role() == SimRole::Linear || has(k) || out.contains(&k) {
            continue;
        }
        if k.model().applicable(&has_name) {
            out.push(k);
        }
    }
    out
}

/// The kinds tried on `ds`: [`candidate_kinds`], less those the data cannot judge. Without a
/// logged input the data say nothing of the drive (input effects), and nothing can be simulated
/// (effects judged on the simulation are left out).
pub fn for_dataset(ds: &Dataset, model: &Plant, opts: &DiagnoseOptions) -> Vec<EffectKind> {
    let mut kinds = candidate_kinds(model, opts);
    if !ds.has_input {
        kinds.retain(|k| k.is_mechanical() && !on_simulation(*k));
    }
    kinds
}

/// Order in which candidates are started: the costliest (most simulations) first
/// ([`crate::effects::EffectModel::schedule_rank`]).
pub(super) fn cost_rank(kind: EffectKind) -> usize {
    usize::from(kind.model().schedule_rank())
}

pub(super) fn nonlinear_searched(kind: EffectKind) -> usize {
    kind.params()
        .iter()
        .filter(|p| p.nonlinear && kind.model().fittable(p.key))
        .count()
}

/// Is `kind` judged on the simulation alone (no regressors; a gear play)?
pub fn on_simulation(kind: EffectKind) -> bool {
    kind.model()
        .fit_hooks()
        .is_some_and(|h| h.judged_on_simulation())
}
