//! Stage 3 of a diagnosis: the independent work, on two threads: every candidate fitted with the
//! base refitted beside it, the simulation reference every candidate is judged against, and the
//! analysis of each balance's residual (its noise floor, ratio and shapes).

use super::base::Base;
use super::kinds::cost_rank;
use super::structure::{self, BalanceReport};
use super::{par_map, timing, DiagnoseOptions};
use crate::effects::EffectKind;
use crate::fit::oe::{self, Part};
use crate::fit::{Dataset, EffectToFit, FitError, Solved};
use crate::plant::Plant;
use alloc::boxed::Box;
use alloc::vec::Vec;

/// The simulation reference of a diagnosis (see [`super::diagnose_dataset`]).
pub(super) struct Reference {
    /// The model without the candidates, J_eq and tau_sf tuned on the simulation.
    pub plant: Plant,
    /// Its held-out output-error cost [rad].
    pub oe_holdout: Option<f64>,
}

/// What the survey found.
pub(super) struct Survey {
    /// Every candidate's fit, in the order of the kinds tried (the ranking's ties keep it).
    pub fits: Vec<(EffectKind, Result<Solved, FitError>)>,
    /// The simulation reference: the model without the candidates, J_eq and tau_sf tuned on the
    /// simulation.
    pub reference: Reference,
    /// Every balance's residual of the base model, in the base's order.
    pub balances: Vec<BalanceReport>,
}

/// Independent work of a diagnosis, run in parallel.
enum Task {
    /// Fit a candidate kind.
    Fit(EffectKind),
    /// The simulation reference (J_eq and tau_sf tuned on the simulation).
    Reference,
    /// Analyse the residual of the base model's i-th balance.
    Balance(usize),
}

// One per task, moved once through the queue: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
enum Done {
    Fit(EffectKind, Box<Result<Solved, FitError>>),
    Reference(Plant),
    Balance(usize, BalanceReport),
}

/// Runs the survey of `kinds` on `ds` (the tasks not started are skipped once cancelled; the
/// caller checks the cancel hook).
pub(super) fn run(
    ds: &Dataset,
    model: &Plant,
    base: &Base,
    kinds: &[EffectKind],
    opts: &DiagnoseOptions,
) -> Survey {
    let th = opts.thresholds;
    let sols = base.solutions();
    // The independent work, costliest first (a shared queue on two threads then ends together):
    // the candidates' fits, the simulation reference and the analyses of the balances.
    let mut tasks: Vec<Task> = kinds.iter().map(|&k| Task::Fit(k)).collect();
    tasks.sort_by_key(|t| match t {
        Task::Fit(k) => cost_rank(*k),
        _ => 0,
    });
    let at = tasks.len().min(1);
    tasks.insert(at, Task::Reference);
    for i in 0..sols.len() {
        tasks.insert(at + 1 + i, Task::Balance(i));
    }
    let mut fits: Vec<(EffectKind, Result<Solved, FitError>)> = Vec::new();
    let mut rigid = base.solved.plant;
    let mut analysed: Vec<(usize, BalanceReport)> = Vec::new();
    for done in par_map(&tasks, opts.parallel, |t| match *t {
        // Cancelled: the tasks not started are skipped (the error is returned below).
        Task::Fit(k) if opts.cancel.requested() => Done::Fit(k, Box::new(Err(FitError::Cancelled))),
        Task::Fit(k) => Done::Fit(
            k,
            Box::new(timing::timed(
                || alloc::format!("fit {k}"),
                || ds.fit_config(model, &[EffectToFit::all(k)]),
            )),
        ),
        // The simulation reference every candidate is judged against: the model without it,
        // its inertia and Coulomb level tuned on the simulation (fit blocks). Candidates that
        // refine parameters on the simulation (a gear play with J_eq and tau_sf) would otherwise
        // win on the tuning alone, and the ranking would compare drops from different
        // references.
        Task::Reference => Done::Reference(timing::timed(
            || "simulation reference".into(),
            || ds.refine_rigid_on_simulation(&base.solved.plant),
        )),
        Task::Balance(i) => Done::Balance(
            i,
            timing::timed(
                || alloc::format!("analyse the {}", sols[i].equation.name()),
                || {
                    structure::analyse(
                        ds,
                        sols[i],
                        base.floor_of(sols[i].equation),
                        &th,
                        ds.gear_ratio,
                    )
                },
            ),
        ),
    }) {
        match done {
            Done::Fit(k, r) => fits.push((k, *r)),
            Done::Reference(p) => rigid = p,
            Done::Balance(i, b) => analysed.push((i, b)),
        }
    }
    analysed.sort_by_key(|(i, _)| *i);
    let balances = analysed.into_iter().map(|(_, b)| b).collect();
    // Candidates in catalogue order (the ranking's ties keep it).
    fits.sort_by_key(|(k, _)| kinds.iter().position(|x| x == k));
    let reference = Reference {
        oe_holdout: oe::prediction_cost(ds, &rigid, Part::Holdout),
        plant: rigid,
    };
    Survey {
        fits,
        reference,
        balances,
    }
}
