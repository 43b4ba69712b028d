//! Stage 9 of a diagnosis: the conclusion. The base model's residual summary per balance and
//! regime, the status (missing when a candidate passes, unexplained when a balance is left above
//! its floor, complete otherwise), the leads beyond the catalogue for an unexplained status
//! ([`super::neighbours`]), and the verdict in words ([`super::evidence::verdict`]).

use super::base::Base;
use super::change::Change;
use super::judge::{FLOOR_CHECK, STRUCTURED_CHECK};
use super::presliding::Extent;
use super::sliding_lead::SlidingFit;
use super::structure::BalanceReport;
use super::survey::Survey;
use super::{evidence, neighbours, regimes, timing, BaseSummary, Candidate, DiagnoseOptions};
use super::{on_simulation, phrase, Diagnosis, Status, Thresholds, Unresolvable};
use crate::effects::EffectKind;
use crate::fit::Dataset;
use crate::math;
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

/// What the verdict of `d` adds on the regimes the diagnosis judged apart: `outside`, why no
/// set of catalogue effects was searched (a shape no catalogue effect makes, [`super::outside`]),
/// when the status is "unexplained"; `presliding`, the pre-sliding rows left out (the candidates were
/// judged on the sliding rows), kept in `d.presliding`; `lead`, a friction the sliding rows
/// show that only the simulation refuses, when the status is "unexplained", kept in
/// `d.sliding_fit`; otherwise `hump`, why the breakaway friction a hump of the measured
/// friction curve calls for was refused ([`super::friction_curve::hump_refusal`]), when the
/// status is "unexplained".
pub(super) fn regimes(
    d: &mut Diagnosis,
    outside: Option<&str>,
    presliding: Option<Extent>,
    lead: Option<SlidingFit>,
    hump: Option<String>,
) {
    if let (Some(why), Status::Unexplained) = (outside, d.status) {
        d.verdict.push_str(why);
    }
    if let Some(ext) = presliding {
        d.verdict.push_str(&alloc::format!(
            " Judged on the sliding rows: the {} torque-balance rows within {:.0} encoder counts of travel since a reversal of the motion carry {:.1} times the residual of the sliding rows ({:.2e} {} RMS), a pre-sliding regime of their own (a dynamic friction's bristles winding up like a spring, outside the catalogue), and were left out.",
            ext.rows,
            ext.counts,
            ext.ratio,
            ext.rms,
            d.base.equations.first().map_or("", |e| e.0.unit())
        ));
        d.presliding = Some(ext);
    }
    if d.status != Status::Unexplained {
        return;
    }
    if let Some(l) = lead {
        d.verdict.push_str(&l.sentence());
        d.sliding_fit = Some(l);
    } else if let Some(h) = hump {
        d.verdict.push_str(&h);
    }
}

/// Concludes the diagnosis of `model` on `ds` from the stages before.
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    ds: &Dataset,
    model: &Plant,
    base: Base,
    survey: Survey,
    labels: &regimes::Labels,
    kinds: &[EffectKind],
    ranking: Vec<Candidate>,
    changes: Vec<Change>,
    opts: &DiagnoseOptions,
) -> Diagnosis {
    let mut equations = Vec::new();
    for sol in base.solutions() {
        let reg = labels.of(sol.equation);
        let sq: Vec<f64> = sol.resid.iter().map(|r| r * r).collect();
        equations.push((
            sol.equation,
            sol.rms(),
            regimes::shares(reg, &sq),
            regimes::occupancy(reg),
        ));
    }
    let Survey {
        reference,
        mut balances,
        ..
    } = survey;
    let summary = BaseSummary {
        plant: base.solved.plant,
        equations,
        oe_cost_rad: reference.oe_holdout,
        current_noise_a: base.noise_a,
    };
    let winner = ranking.first().filter(|c| c.significant).is_some();
    attach_changes(&mut balances, &changes);
    attach_partial(&mut balances, &ranking, &opts.thresholds);
    let mut unexplained: Vec<BalanceReport> = if winner {
        Vec::new()
    } else {
        balances.iter().filter(|b| b.above_noise).cloned().collect()
    };
    let status = if winner {
        Status::Missing
    } else if unexplained.is_empty() {
        Status::Complete
    } else {
        Status::Unexplained
    };
    let mut leads = Vec::new();
    if status == Status::Unexplained {
        // Leads beyond the catalogue: a mechanism the candidates' own machinery sizes (a gear
        // play's contact without play: a shaft) that predicts the motion materially better.
        if let (Some(c0), true) = (reference.oe_holdout, ds.has_input) {
            let found = timing::timed(
                || "neighbours outside the catalogue".into(),
                || neighbours::find(ds, kinds, &[model, &reference.plant], c0, opts),
            );
            neighbours::attach(&mut unexplained, &found, &opts.thresholds);
            neighbours::attach(&mut balances, &found, &opts.thresholds);
            leads = found.into_iter().map(|(n, _)| n).collect();
        }
    }
    let unresolvable = unresolvable(&ranking, &balances, &opts.thresholds);
    let mut verdict = evidence::verdict(
        status,
        &ranking,
        &unexplained,
        &balances,
        &unresolvable,
        &opts.thresholds,
    );
    if let Some(j) = base.unphysical_j_eq {
        verdict.push_str(&alloc::format!(
            " The bare base model was unphysical on these logs (the fitted inertia J_eq = {} kg m^2 is not positive: a large torque it lacks, such as an arm's gravity, was absorbed into it); each candidate was fitted with the base refitted beside it.",
            math::Num(j)
        ));
    }
    if !ds.has_input {
        verdict.push_str(" No log records the input voltage u: judged on the torque balance alone (information criterion and held-out residual), without a simulation check; input effects and effects judged on the simulation were not tried.");
    }
    Diagnosis {
        ranking,
        verdict,
        base: summary,
        status,
        balances,
        unexplained,
        neighbours: leads,
        unresolvable,
        friction_curve: None,
        changes,
        presliding: None,
        sliding_fit: None,
    }
}

/// A change of the plant is the first signature of its balance, which it makes incomplete,
/// with the experiment that confirms it (the first change's).
fn attach_changes(balances: &mut [BalanceReport], changes: &[Change]) {
    for b in balances.iter_mut() {
        let here: Vec<&Change> = changes
            .iter()
            .filter(|c| c.equation == b.equation)
            .collect();
        let Some(first) = here.first() else {
            continue;
        };
        let sigs: Vec<_> = here.iter().map(|c| c.signature()).collect();
        b.signatures.splice(0..0, sigs);
        b.above_noise = true;
        b.experiment = first.experiment();
    }
}

/// A catalogue effect that passes every check of its balance but the share of its structured
/// error (statistically significant on held-out rows, above the noise floor, physical) is a
/// shape that predicts the held-out residual: a balance above its incompleteness bar with such
/// a candidate is incomplete, whether or not any other shape was found there. What it explains
/// is real and above the floor, and what it leaves is larger still: the model misses more than
/// that effect (stop 45: a two-mass drive with bristles and a breakaway hump at twice the
/// Coulomb level, whose torque balance stood 3.4 times its floor, read "complete" although a
/// breakaway friction removed 18.5 % of its held-out residual and 41 % of the held-out
/// simulation error; the bristles' reversals held the rest).
fn attach_partial(balances: &mut [BalanceReport], ranking: &[Candidate], th: &Thresholds) {
    for c in ranking.iter().filter(|c| !c.significant) {
        // The share check failed, and only it.
        let Some(share_check) = c
            .checks
            .iter()
            .find(|k| k.name == STRUCTURED_CHECK && !k.passed)
        else {
            continue;
        };
        if !c
            .checks
            .iter()
            .all(|k| k.passed || k.name == STRUCTURED_CHECK)
        {
            continue;
        }
        let Some(b) = balances
            .iter_mut()
            .find(|b| b.equation == c.equation && b.ratio_to_noise >= th.unexplained_ratio)
        else {
            continue;
        };
        let share = phrase::squared_from_rms(c.error_reduction_pct) / 100.0;
        b.signatures.push(super::structure::Signature {
            kind: "partial_effect",
            description: alloc::format!(
                "{} predicts part of it: it removes {:.1} % of the held-out residual (RMS) and {}, so the model misses more than {}",
                c.effect,
                c.error_reduction_pct,
                share_check.detail,
                c.effect
            ),
            share,
            explained_rms: c.noise_ratio * b.floor,
            on_simulation: false,
            periodic: None,
            measured_on: alloc::format!(
                "the held-out rows of the {} (the candidate's own judgement)",
                c.equation.name()
            ),
        });
        b.signatures.sort_by(|x, y| y.share.total_cmp(&x.share));
        b.above_noise = true;
    }
}

/// The candidates the logs show but cannot resolve: not significant, yet their own balance
/// shows them (information criterion and held-out residual drop past their bars), while what
/// they explain there stays below that balance's noise floor (`min_noise_ratio`). Such an
/// effect is too small for its simulation drop to stand out of the other errors, or fails only
/// the floor and the share of the structured error (checked when the simulation drop passes). A
/// candidate refused by another check is a mimic, not a small effect, and one judged on the
/// simulation alone has no balance to be measured in: both are left out.
fn unresolvable(
    ranking: &[Candidate],
    balances: &[BalanceReport],
    th: &Thresholds,
) -> Vec<Unresolvable> {
    ranking
        .iter()
        .filter(|c| !c.significant && !on_simulation(c.effect))
        .filter(|c| {
            c.bic_gain > th.min_bic_gain
                && phrase::squared_from_rms(c.error_reduction_pct) >= th.min_eq_drop_pct
                && c.noise_ratio < th.min_noise_ratio
                && c.checks
                    .iter()
                    .all(|k| k.passed || k.name == FLOOR_CHECK || k.name == STRUCTURED_CHECK)
        })
        .filter_map(|c| {
            let floor = balances
                .iter()
                .find(|b| b.equation == c.equation)
                .map(|b| b.floor)?;
            let size = c.effect.main_param().and_then(|spec| {
                c.params
                    .iter()
                    .find(|p| p.effect == Some(c.effect) && p.key == spec.key)
                    .map(|p| (p.key, p.unit, p.value))
            });
            Some(Unresolvable {
                effect: c.effect,
                equation: c.equation,
                size,
                explained_rms: c.noise_ratio * floor,
                floor,
                experiment: evidence::experiment(c.effect),
            })
        })
        .collect()
}
