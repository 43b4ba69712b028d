//! Several effects found together: backward elimination from a joint simulation fit.
//!
//! The forward search adds one effect at a time. Effects that interact are missed: a gear play
//! and a breakaway friction both live at the low speeds around reversals, and neither passes
//! alone (each only helps once the other is in the model); an input delay named first absorbs
//! the lag the play adds after each reversal and comes out too long. The standard remedy
//! (stepwise regression) is backward elimination from a joint fit:
//!
//! 1. **Joint fit.** When no single candidate passes and a balance is still above its noise
//!    floor, the effects already in the model beyond friction (named by earlier steps), the
//!    best candidates by held-out simulation drop ([`super::DiagnoseOptions::joint_candidates`]
//!    of them, none whose fit makes its own balance clearly worse held out, [`joint::seeds`]),
//!    those with clear evidence in their own balance and those acting where a play
//!    acts ([`partners`]) are fitted together: first by the usual equation-error fit (base refitted), then
//!    on the simulation cost of the fit blocks over long segments (several reversals each),
//!    where the motion shows every one of them, trimmed of its worst fifth ([`trimmed`]: a few
//!    segments start from a state no measurement fixes and carry most of the plain cost). A
//!    coarse grid over two nonlinear parameters of different members (e.g. a play's gap and a
//!    breakaway's speed scale, the pair that trades off at low speed), the linear ones
//!    re-solved by least squares at each point (simulated with a search's coarser sub-steps,
//!    [`Tuner::grid_cost`]: the grid only chooses the starts), then a coordinate refinement from
//!    the best points (its first pass from each, its second from the best of them,
//!    [`refine_best`]): the base first (the Coulomb level, B_eq, R_a, J_eq), then every
//!    member's parameters; then restarts with the play's gap at half and 0.7 times its value
//!    ([`narrower`]). The effects named earlier are re-estimated too (a delay sized without the
//!    play).
//! 2. **Drop-one test.** Each new member is judged given all the others, against the joint
//!    model without it (re-tuned on the simulation): every check of a single candidate (the
//!    information criterion of its balance (for a play, judged on the motion alone, that of
//!    the trimmed cost it was tuned on, [`on_tuned_cost`]), held-out residual and simulation
//!    drops, its noise
//!    floor and structured share, its physical constraints, "explains the structure it fits",
//!    agreement across both halves of the data with the others in the model). The member with
//!    the smallest held-out simulation contribution among those that fail is removed, the
//!    others are re-tuned, and the test is repeated, until every survivor passes (or none is
//!    left). When several fail, they are first removed together if together they are
//!    immaterial too ([`drop_group`], a group test: one round instead of one per member); when
//!    some of them make the held-out simulation worse given the others, those alone are the
//!    group (a harmful member's negative share would hide the others' in the group's sum). A
//!    lone survivor (no effect named earlier either) is left to the single candidates'
//!    verdict: it hid nothing.
//! 3. **Guard.** The survivors together must cut the held-out simulation error materially
//!    against the model holding none of them.
//!
//! The survivors are named together, with their jointly fitted parameters. A set of mimics (effects
//! bending together to soak up a mechanism outside the catalogue) must pass every guard, each
//! given the others.

use super::judge::{simulation_bic, Simulated};
use super::survey::Reference;
use super::thresholds::frac;
use super::tuner::{get, targets, with, Target, Tuner, GRID_POINTS, STARTS};
use super::{joint, on_simulation, par_map, Candidate};
use crate::effects::EffectKind;
use crate::fit::model::Config;
use crate::fit::oe::{self, Part};
use crate::fit::{search, set_effect, to_plant, Dataset, EffectToFit, FitError, Solved};
use crate::math;
use crate::plant::Plant;
use alloc::vec::Vec;

/// How the backward elimination ended.
pub(super) enum Outcome {
    /// The survivors (best first), judged each given the others, every one carrying the joint
    /// model in its `plant`.
    Found(Vec<Candidate>),
    /// The elimination ran to its end and no set passes: every member failed given the others,
    /// a lone survivor was left to the single candidates' verdict, or the survivors together
    /// are immaterial.
    Refused,
    /// The elimination did not run (fewer than two members) or could not finish (a fit or a
    /// cost that could not be computed).
    NotRun,
}

/// The backward elimination ([`Outcome`]).
pub(super) fn search(
    cx: &joint::Context,
    fits: &[(EffectKind, Result<Solved, FitError>)],
    ranking: &[Candidate],
) -> Outcome {
    let ds = cx.ds;
    let mut fresh: Vec<EffectKind> = joint::seeds(cx, fits, ranking)
        .into_iter()
        .map(|(k, _)| k)
        .collect();
    // Also the candidates with clear evidence in their own balance that failed only the
    // simulation (an input delay whose motion another missing effect spoils): the information
    // criterion, the held-out residual drop and the noise floor of their balance pass.
    let th = &cx.opts.thresholds;
    let min_red = th.min_eq_rms_drop_pct();
    join_from(
        ranking,
        fits,
        &mut fresh,
        cx.opts.joint_candidates + 2,
        |c| {
            !on_simulation(c.effect)
                && c.bic_gain > th.min_bic_gain
                && c.error_reduction_pct >= min_red
                && c.noise_ratio >= th.min_noise_ratio
        },
    );
    // And the effects that act where a member judged on the simulation acts (a gear play: at
    // reversals and in accelerations), whatever their own drop: alone, a breakaway friction
    // beside an unmodelled play and delay makes the simulation worse (-14 % and below on two
    // seeds of the three-effect test) and ranks below a periodic-torque mimic, yet it is the
    // play's natural partner (each hides the other at the reversals).
    let plays: Vec<EffectKind> = fresh
        .iter()
        .copied()
        .filter(|k| on_simulation(*k))
        .collect();
    join_from(
        ranking,
        fits,
        &mut fresh,
        cx.opts.joint_candidates + 2,
        |c| plays.iter().any(|p| partners(*p, c.effect)),
    );
    if fresh.len() < 2 {
        return Outcome::NotRun;
    }
    let named: Vec<EffectKind> = cx
        .model
        .effects
        .iter()
        .map(|e| e.kind)
        .filter(|k| !matches!(*k, EffectKind::Viscous | EffectKind::Coulomb))
        .filter(|k| k.params().iter().any(|p| k.model().fittable(p.key)))
        .collect();
    // The effects named earlier are searched again in their balances with the new ones in the
    // model (with a gear play, the rows where the motor crosses the gap get no weight there).
    let to_fit: Vec<EffectToFit> = named
        .iter()
        .chain(&fresh)
        .map(|&k| EffectToFit::all(k))
        .collect();
    let Ok(start) = super::timing::timed(
        || "backward: equation-error start".into(),
        || ds.fit_config(cx.model, &to_fit),
    ) else {
        return Outcome::NotRun;
    };
    let tuner = Tuner::new(ds);
    let gridded = super::timing::timed(
        || "backward: grid".into(),
        || grid_stage(cx, &tuner, &start, &fresh),
    );
    let all: Vec<EffectKind> = named.iter().chain(&fresh).copied().collect();
    trace(|| {
        alloc::format!(
            "named {named:?} fresh {fresh:?}; start {} cost {:.4e} ({} long segments kept)",
            show(&start.plant, &all),
            tuner.cost(&start.plant),
            tuner.kept()
        )
    });
    let Some((full, c_full)) = super::timing::timed(
        || "backward: joint refinement".into(),
        || {
            for g in &gridded {
                trace(|| alloc::format!("grid start {} cost {:.4e}", show(g, &all), tuner.cost(g)));
            }
            refine_best(cx, &tuner, &gridded, &all, "start")
        },
    ) else {
        return Outcome::NotRun;
    };
    trace(|| {
        alloc::format!(
            "joint {} r_a {} b_eq {:e} cost {c_full:.4e}",
            show(&full, &all),
            full.params.r_a,
            full.params.b_eq()
        )
    });
    let (mut full, c_full) = super::timing::timed(
        || "backward: narrower restarts".into(),
        || narrower(cx, &tuner, (full, c_full), &all),
    );
    trace(|| {
        alloc::format!(
            "after the narrower restarts {} cost {c_full:.4e}",
            show(&full, &all)
        )
    });
    let mut survivors = fresh.clone();
    loop {
        if survivors.is_empty() {
            return Outcome::Refused;
        }
        if named.is_empty() && survivors.len() == 1 {
            // A lone survivor hid nothing and was hidden by nothing: whether it passes given
            // nothing or not, it is judged as a single candidate (a delay re-tuned on the motion
            // soaked up a compliant shaft's lag there, passing where the single candidate had
            // failed).
            trace(|| {
                alloc::format!("a lone survivor {survivors:?}: left to the single candidates")
            });
            return Outcome::Refused;
        }
        let members: Vec<EffectKind> = named.iter().chain(&survivors).copied().collect();
        // The joint model's solution and held-out cost: the same in every member's test, the
        // group test and the guard below.
        let Some(j_solved) = solved_at(ds, &full) else {
            trace(|| "the joint model could not be solved".into());
            return Outcome::NotRun;
        };
        let joint_now = Simulated::new(ds, &j_solved);
        let (mut judged, reduced): (Vec<(Candidate, f64)>, Vec<Plant>) = super::timing::timed(
            || alloc::format!("backward: drop-one tests of {survivors:?}"),
            || {
                par_map(&survivors, cx.opts.parallel, |&m| {
                    drop_one(cx, &tuner, &joint_now, &members, m)
                })
            },
        )
        .into_iter()
        .flatten()
        .map(|(c, d, r)| ((c, d), r))
        .unzip();
        if judged.len() < survivors.len() {
            trace(|| "a drop-one test could not be computed".into());
            return Outcome::NotRun;
        }
        // The agreement across halves of the members that pass (each refitted on both halves
        // of the data: a drop-one test's cost again) only when this round's decision can
        // depend on it (see [`halves_decide`]).
        let halves_checked = halves_decide(&judged);
        if halves_checked {
            check_halves(cx, &mut judged, &reduced);
        }
        for (c, d) in &judged {
            trace(|| {
                alloc::format!("drop {}: significant {} contribution {d:.1} % eq {:.1} % bic {:.1} failed {:?}{}", c.effect, c.significant, c.error_reduction_pct, c.bic_gain, c.failed_check().map(|k| (k.name, &k.detail)), if halves_checked { "" } else { " (halves not checked)" })
            });
        }
        let failing: Vec<EffectKind> = judged
            .iter()
            .filter(|(c, _)| !c.significant)
            .map(|(c, _)| c.effect)
            .collect();
        if failing.len() >= 2 {
            // The group tested: the failing members that make the held-out simulation worse
            // given the others when there are such, else every failing member. A harmful member
            // in the group hides the others' contributions in the group's sum: on seed 24 of
            // the three-effect test a periodic-torque mimic (-170 %) and the gear play (+6 %, at
            // a gap 7 % narrower than the play's best) came out immaterial together (+7.4 %),
            // and the play went with the mimic; dropped alone first, the mimic left a play that
            // passed.
            let harmful: Vec<EffectKind> = judged
                .iter()
                .filter(|(c, d)| !c.significant && *d < 0.0)
                .map(|(c, _)| c.effect)
                .collect();
            let group = if harmful.is_empty() { failing } else { harmful };
            let reduced = super::timing::timed(
                || alloc::format!("backward: group drop of {group:?}"),
                || drop_group(cx, &tuner, &joint_now, &named, &survivors, &group),
            );
            if let Some(reduced) = reduced {
                survivors.retain(|k| !group.contains(k));
                full = reduced;
                continue;
            }
        }
        if !halves_checked {
            check_halves(cx, &mut judged, &reduced);
        }
        // A member its own data refute (a play the motor never crosses) goes first, whatever
        // it adds to the simulation: it adds it as a mimic (on seed 65 of the two-mass drive
        // train with soft LuGre bristles and a hump, such a play contributed 78 % and outlived
        // the breakaway friction it stood in for). Then the one that adds least.
        let weakest = judged
            .iter()
            .filter(|(c, _)| !c.significant)
            .map(|(c, d)| (c.effect, *d, refuted(cx, c, &full)))
            .min_by(|a, b| b.2.cmp(&a.2).then(a.1.total_cmp(&b.1)))
            .map(|(k, _, _)| k);
        match weakest {
            Some(w) => {
                survivors.retain(|k| *k != w);
                if ends_here(&named, &survivors) {
                    // No model is judged after this round: the refinement would be thrown away
                    // (0.9 s of a 25 s diagnosis of a torque ripple outside the catalogue).
                    continue;
                }
                if let Some(p) = without(&full, w) {
                    let left: Vec<EffectKind> = named.iter().chain(&survivors).copied().collect();
                    // The full refinement again: the members left had bent to the one
                    // removed (a gap tuned beside a periodic-torque mimic came out 0.052 rad
                    // for 0.030, and one pass at half the span left it at 0.043).
                    full = tuner.refine(&p, &targets(&p, &left), &[1.0, 0.5]).0;
                }
            }
            None => {
                let (Some(with_them), Some(without_them)) =
                    (joint_now.oe_holdout_rad, cx.reference.oe_holdout)
                else {
                    return Outcome::NotRun;
                };
                let total = 1.0 - with_them / without_them.max(1e-300);
                let need = frac(if survivors.iter().any(|k| on_simulation(*k)) {
                    cx.opts.thresholds.min_simulation_oe_drop_pct
                } else {
                    cx.opts.thresholds.min_oe_drop_pct
                });
                trace(|| {
                    alloc::format!(
                        "survivors {survivors:?} total held-out drop {:.1} % (needs {:.1} %)",
                        100.0 * total,
                        100.0 * need
                    )
                });
                if total < need {
                    return Outcome::Refused;
                }
                let mut out: Vec<(Candidate, f64)> = judged;
                out.sort_by(|a, b| b.1.total_cmp(&a.1));
                let names: Vec<EffectKind> = out.iter().map(|(c, _)| c.effect).collect();
                return Outcome::Found(
                    out.into_iter()
                        .map(|(mut c, _)| {
                            c.joint_with = names.iter().copied().find(|k| *k != c.effect);
                            c.plant = full;
                            c.evidence =
                                note(cx, &full, &named, &names, c.effect, total, &c.evidence);
                            c
                        })
                        .collect(),
                );
            }
        }
    }
}

/// The joint model (`joint_now`, with its held-out cost) without every member of `failing` (each
/// failed its drop-one test given the others), re-tuned, when together they are immaterial too:
/// their held-out simulation contribution (the joint model against the model without them) stays
/// below the bar a single member must clear ([`super::Thresholds::min_oe_drop_pct`], or
/// [`super::Thresholds::min_simulation_oe_drop_pct`] with a member judged on the simulation).
/// `None` when the group is material (two mimics of one mechanism each redundant given the
/// other): the members are then dropped one at a time.
///
/// Backward elimination with a group test (a block of regressors dropped by one F-test): one
/// round instead of one per failing member, which is most of a joint search that ends with
/// nothing (five members, five rounds: 60 % of a 70 s diagnosis of the real Padova friction
/// logs).
fn drop_group(
    cx: &joint::Context,
    tuner: &Tuner,
    joint_now: &Simulated,
    named: &[EffectKind],
    survivors: &[EffectKind],
    failing: &[EffectKind],
) -> Option<Plant> {
    let full = &joint_now.solved.plant;
    let mut reduced = *full;
    for &k in failing {
        reduced.effects.remove(k)?;
    }
    let left: Vec<EffectKind> = named
        .iter()
        .chain(survivors)
        .copied()
        .filter(|k| !failing.contains(k))
        .collect();
    let reduced = if left.is_empty() {
        reduced
    } else {
        tuner
            .refine(&reduced, &targets(&reduced, &left), &[1.0, 0.5])
            .0
    };
    let th = &cx.opts.thresholds;
    let need = frac(if failing.iter().any(|k| on_simulation(*k)) {
        th.min_simulation_oe_drop_pct
    } else {
        th.min_oe_drop_pct
    });
    let with_them = joint_now.oe_holdout_rad?;
    let without_them = if left.is_empty() {
        cx.reference.oe_holdout?
    } else {
        oe::prediction_cost(cx.ds, &reduced, Part::Holdout)?
    };
    let contribution = 1.0 - with_them / without_them.max(1e-300);
    trace(|| {
        alloc::format!(
            "drop {failing:?} together: held-out {without_them:.4e} -> {with_them:.4e} rad, contribution {:.1} % (a member needs {:.1} %)",
            100.0 * contribution,
            100.0 * need
        )
    });
    (contribution < need).then_some(reduced)
}

/// Restarts the joint refinement from the tuned model `full` (cost `c_full`) with the first
/// nonlinear parameter of each member judged on the simulation (a gear play's gap) at half and
/// at 0.7 times its value ([`refine_best`]: the best restart after one pass gets the second),
/// and returns the model of lowest cost.
///
/// A wide gap beside a spiked breakaway friction is a local optimum of the joint cost that the
/// grid's starts can all fall into: the refinement moves a gap by at most half again per pass.
/// On seeds 26 and 29 of the three-effect test the joint model settled at a gap of 0.061 and
/// 0.067 rad (0.030 true), trimmed cost 0.21 and 0.24 rad, where the refinement started from
/// the true model ends at 0.064 and 0.069 rad.
fn narrower(
    cx: &joint::Context,
    tuner: &Tuner,
    (full, c_full): (Plant, f64),
    members: &[EffectKind],
) -> (Plant, f64) {
    let mut starts = Vec::new();
    for &k in members.iter().filter(|k| on_simulation(**k)) {
        let Some(spec) = k
            .params()
            .iter()
            .find(|p| p.nonlinear && k.model().fittable(p.key))
        else {
            continue;
        };
        let t = Target::Effect(k, spec.key);
        let Some(x) = get(&full, t).filter(|x| *x > 0.0) else {
            continue;
        };
        starts.extend([0.5, 0.7].iter().filter_map(|f| with(&full, t, f * x)));
    }
    let Some(r) = refine_best(cx, tuner, &starts, members, "restart") else {
        return (full, c_full);
    };
    if r.1 < c_full {
        r
    } else {
        (full, c_full)
    }
}

/// Refines each of `starts` by one pass of the tuner's coordinate refinement over the parameters
/// of `members` ([`targets`]), then the best of them by a second pass at half the spans; `what`
/// names the starts in the trace. The starts end in their basins after one pass already (on seed
/// 24 of the three-effect test at 0.090, 0.105 and 0.225 rad after both), and the second pass
/// polishes within one: given to every start it was a third of the joint search's refinements.
/// `None` without a start.
fn refine_best(
    cx: &joint::Context,
    tuner: &Tuner,
    starts: &[Plant],
    members: &[EffectKind],
    what: &str,
) -> Option<(Plant, f64)> {
    let (first, _) = par_map(starts, cx.opts.parallel, |p| {
        let r = tuner.refine(p, &targets(p, members), &[1.0]);
        trace(|| alloc::format!("{what}, one pass: cost {:.6e} {}", r.1, show(&r.0, members)));
        r
    })
    .into_iter()
    .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let r = tuner.refine(&first, &targets(&first, members), &[0.5]);
    trace(|| {
        alloc::format!(
            "best {what} refined: cost {:.6e} {}",
            r.1,
            show(&r.0, members)
        )
    });
    Some(r)
}

/// Whether the elimination ends with `survivors` left beside the effects `named` earlier, before
/// any test: none left, or a lone survivor and none named (left to the single candidates'
/// verdict).
fn ends_here(named: &[EffectKind], survivors: &[EffectKind]) -> bool {
    survivors.is_empty() || (named.is_empty() && survivors.len() == 1)
}

/// Adds to `fresh`, in ranking order and while it holds fewer than `cap`, every candidate not
/// yet in it that failed alone, was fitted, and satisfies `pred`.
fn join_from(
    ranking: &[Candidate],
    fits: &[(EffectKind, Result<Solved, FitError>)],
    fresh: &mut Vec<EffectKind>,
    cap: usize,
    pred: impl Fn(&Candidate) -> bool,
) {
    for c in ranking {
        if fresh.len() >= cap {
            break;
        }
        let fitted = fits.iter().any(|(k, r)| *k == c.effect && r.is_ok());
        if !c.significant && fitted && !fresh.contains(&c.effect) && pred(c) {
            fresh.push(c.effect);
        }
    }
}

/// Whether `a` and `b` act in a common regime of the motion
/// ([`crate::effects::EffectModel::regimes`]: a gear play and a breakaway friction both at the
/// reversals), where each can hide the other.
fn partners(a: EffectKind, b: EffectKind) -> bool {
    let rb = b.model().regimes();
    a.model().regimes().iter().any(|r| rb.contains(r))
}

/// Whether member `c` of the joint model `full` is refuted by data no other member acts in
/// ([`crate::effects::FitHooks::refuted`]).
fn refuted(cx: &joint::Context, c: &Candidate, full: &Plant) -> bool {
    let Some(base) = without(full, c.effect) else {
        return false;
    };
    let found = c
        .effect
        .model()
        .fit_hooks()
        .and_then(|h| h.refuted(cx.ds, &c.params, &base));
    if let Some(k) = &found {
        trace(|| alloc::format!("{} refuted: {}", c.effect, k.detail));
    }
    found.is_some()
}

/// `p` without `kind`.
fn without(p: &Plant, kind: EffectKind) -> Option<Plant> {
    let mut q = *p;
    q.effects.remove(kind)?;
    Some(q)
}

/// The coarse grid over two nonlinear parameters of different new members (a member judged on
/// the simulation first), the linear parameters re-solved by least squares at every point, J_eq
/// and the Coulomb level kept at their start values. Returns the [`STARTS`] best models (grid
/// points or the start), best first: the joint cost has local optima (a wide gap beside a
/// breakaway at the wrong speed), so the refinement starts from each.
fn grid_stage(
    cx: &joint::Context,
    tuner: &Tuner,
    start: &Solved,
    fresh: &[EffectKind],
) -> Vec<Plant> {
    let ds = cx.ds;
    // A member judged on the simulation first; an input effect last when the current is logged:
    // the electrical balance sizes it far more sharply than the motion does, and a grid over it
    // on the motion settled on a wrong basin (an 8.3 ms delay for 3.0 on seed 29 of the
    // three-effect test, which the refinement cannot leave).
    let rank = |k: &EffectKind| -> u8 {
        if on_simulation(*k) {
            0
        } else if k.is_mechanical() || !ds.has_current {
            1
        } else {
            2
        }
    };
    let mut order: Vec<EffectKind> = fresh.to_vec();
    order.sort_by_key(rank);
    let mut axes: Vec<(usize, &'static str)> = Vec::new();
    for k in order {
        if axes.len() == 2 {
            break;
        }
        let Some(i) = start.cfg.slots.iter().position(|s| s.kind == k) else {
            continue;
        };
        if let Some(p) = k
            .params()
            .iter()
            .find(|p| p.nonlinear && k.model().fittable(p.key))
        {
            axes.push((i, p.key));
        }
    }
    let c_start = tuner.grid_cost(&start.plant);
    if axes.len() < 2 {
        return alloc::vec![start.plant];
    }
    let values = |(i, key): (usize, &'static str)| -> Vec<f64> {
        let g: Vec<f64> = ds
            .grid(&start.cfg.slots[i], key)
            .into_iter()
            .filter(|v| *v > 0.0)
            .collect();
        if g.len() <= GRID_POINTS {
            return g;
        }
        // Evenly over the grid (log-spaced grids stay log-spaced).
        (0..GRID_POINTS)
            .map(|j| g[(j * (g.len() - 1)) / (GRID_POINTS - 1)])
            .collect()
    };
    let (ga, gb) = (values(axes[0]), values(axes[1]));
    let mut points = Vec::new();
    for &a in &ga {
        for &b in &gb {
            points.push((a, b));
        }
    }
    let keep = |plant: &mut Plant| {
        plant.params.j_eq = Some(start.plant.params.j_eq());
        let t = start.plant.tau_sf();
        plant.params.tau_sf = Some(t);
        if plant.effects.contains(EffectKind::Coulomb) {
            let _ = set_effect(plant, EffectKind::Coulomb, &[t]);
        }
    };
    // The members' parameters the motion is sensitive to (their polish list) other than the
    // grid's axes.
    let amplitudes: Vec<Target> = fresh
        .iter()
        .filter(|k| !on_simulation(**k))
        .flat_map(|&k| k.model().polish().iter().map(move |(key, _)| (k, *key)))
        .filter(|&(k, key)| {
            !axes
                .iter()
                .any(|&(i, a)| start.cfg.slots[i].kind == k && a == key)
        })
        .map(|(k, key)| Target::Effect(k, key))
        .collect();
    let costs = par_map(&points, cx.opts.parallel, |&(a, b)| {
        let mut cfg: Config = start.cfg.clone();
        cfg.slots[axes[0].0].set(axes[0].1, a);
        cfg.slots[axes[1].0].set(axes[1].1, b);
        let s = ds.solve_config(&cfg).ok()?;
        let mut p = to_plant(&s.cfg, &s.mech, s.elec.as_ref()).ok()?;
        // Nonlinear values of the effects named earlier: those of the start.
        for e in start.plant.effects.iter() {
            if !cfg.slots.iter().any(|s| s.kind == e.kind) || p.effects.contains(e.kind) {
                continue;
            }
            p.effects.insert(*e);
        }
        keep(&mut p);
        // The least-squares amplitude of a member beside a play still mis-sized is no guide
        // (a breakaway fitted as a narrow spike at low speed): the amplitudes the motion is
        // sensitive to are searched at each point, from a quarter to one and a half times it.
        let mut c = tuner.grid_cost(&p);
        for &t in &amplitudes {
            let Some(x0) = get(&p, t).filter(|x| *x > 0.0) else {
                continue;
            };
            let l0 = math::ln(x0);
            let grid = search::linspace(l0 - math::ln(4.0), l0 + math::ln(1.5), 4);
            let from = p;
            if let Some((l, cl)) = search::grid_then_golden_bounded(
                &grid,
                |l, _| with(&from, t, math::exp(l)).map_or(f64::INFINITY, |q| tuner.grid_cost(&q)),
                3,
            ) {
                if cl < c {
                    if let Some(q) = with(&from, t, math::exp(l)) {
                        p = q;
                        c = cl;
                    }
                }
            }
        }
        Some((c, p))
    });
    let mut best: Vec<(f64, Plant)> = costs
        .into_iter()
        .flatten()
        .filter(|(c, _)| c.is_finite())
        .collect();
    best.push((c_start, start.plant));
    best.sort_by(|a, b| a.0.total_cmp(&b.0));
    best.truncate(STARTS);
    // Starts of the same cost (to [`SAME_COST`]) are one start: the parameter they differ in
    // changed nothing the simulation shows.
    best.dedup_by(|a, b| (a.0 - b.0).abs() <= SAME_COST * b.0.abs());
    best.into_iter().map(|(_, p)| p).collect()
}

/// Relative difference below which two starts of the joint refinement have the same cost [-]:
/// they differ in a parameter the simulation barely sees, and refined they end in the same
/// place. On the Padova friction ramps (`padova2021-jacopisky`) the three best grid points differ
/// only in the gap (0.013, 0.040 and 0.080 rad, the motor seldom crosses it), their costs within
/// 3e-5 of each other; refined, each ends at the same parameters but the gap, costs within 1e-4,
/// the first the best: two of the three refinements (a tenth of the diagnosis) changed nothing.
/// The distinct starts of the tests' joint searches (16 searches: plays, breakaways, delays,
/// two-mass drive trains) differ by 9e-4 or more.
const SAME_COST: f64 = 1e-4;

/// The equation-error solution of `plant`'s configuration (its nonlinear parameters fixed, the
/// linear ones and the base re-solved) carrying `plant` itself as the model the simulation judges.
fn solved_at(ds: &Dataset, plant: &Plant) -> Option<Solved> {
    let cfg = ds.config(plant, &[], ds.opts.refit_base);
    let mut s = ds.solve_config(&cfg).ok()?;
    s.plant = *plant;
    Some(s)
}

/// Judges member `m` of the joint model `joint_now` ([`solved_at`] its plant, with its held-out
/// cost) given all the other `members`: against the joint model without `m`, re-tuned on the
/// simulation. Returns the candidate (every check but the agreement across halves,
/// [`check_halves`]), its held-out simulation drop [%] and the re-tuned model without `m`.
fn drop_one(
    cx: &joint::Context,
    tuner: &Tuner,
    joint_now: &Simulated,
    members: &[EffectKind],
    m: EffectKind,
) -> Option<(Candidate, f64, Plant)> {
    let ds = cx.ds;
    let full = &joint_now.solved.plant;
    let others: Vec<EffectKind> = members.iter().copied().filter(|k| *k != m).collect();
    let reduced = without(full, m)?;
    let (reduced, _) = tuner.refine(&reduced, &targets(&reduced, &others), &[0.5]);
    let reference = Reference {
        oe_holdout: oe::prediction_cost(ds, &reduced, Part::Holdout),
        plant: reduced,
    };
    trace(|| {
        alloc::format!("drop {m}: reduced {} | costs fit short {:?} vs {:?}, hold short {:?} vs {:?}, long fit {:.4e} vs {:.4e}", show(&reduced, &others), oe::prediction_cost(ds, &reduced, Part::Fit), oe::prediction_cost(ds, full, Part::Fit), oe::prediction_cost(ds, &reduced, Part::Holdout), oe::prediction_cost(ds, full, Part::Holdout), tuner.cost(&reduced), tuner.cost(full))
    });
    let o_solved = solved_at(ds, &reduced)?;
    let (mut c, before) = joint::judge_given(cx, m, &o_solved, &reference, joint_now)?;
    if on_simulation(m) && !c.significant && c.checks.is_empty() {
        on_tuned_cost(cx, tuner, &mut c, full, &reduced);
        joint::resonance_given(
            ds,
            &mut c,
            &before,
            &o_solved,
            joint_now.solved,
            &cx.opts.thresholds,
        );
    }
    let contribution = c.oe_reduction_pct.unwrap_or(f64::NEG_INFINITY);
    Some((c, contribution, reduced))
}

/// Whether the decision of a round of drop-one tests (`judged`: each member's candidate and
/// held-out simulation contribution [%], before the agreement across halves) can depend on that
/// agreement, which may only turn a passing member into a failing one.
///
/// It cannot when at least two members fail, some of them harmful (a negative contribution),
/// and every passing member helps (a non-negative contribution): the group tested is then the
/// harmful ones whatever the halves say (a passing member that failed there would fail with a
/// positive contribution). Only when that group is refused does the round go on to the weakest
/// member, and the agreement is checked then. On the real Padova friction ramps four of five
/// members were harmful and went together, leaving a lone survivor: its halves refit was
/// 0.67 s of work thrown away.
fn halves_decide(judged: &[(Candidate, f64)]) -> bool {
    let failing = judged.iter().filter(|(c, _)| !c.significant).count();
    let harmful = judged.iter().any(|(c, d)| !c.significant && *d < 0.0);
    let passing_help = judged.iter().all(|(c, d)| !c.significant || *d >= 0.0);
    !(failing >= 2 && harmful && passing_help)
}

/// The agreement across both halves of every passing member of `judged`, refitted with the
/// others in the model (`reduced`, in the same order: the joint model without it); a member
/// that disagrees fails ([`joint::confirm_given`]).
fn check_halves(cx: &joint::Context, judged: &mut [(Candidate, f64)], reduced: &[Plant]) {
    let passing: Vec<usize> = (0..judged.len())
        .filter(|&i| judged[i].0.significant)
        .collect();
    let checked = par_map(&passing, cx.opts.parallel, |&i| {
        let mut c = judged[i].0.clone();
        if joint::confirm_given(cx, &mut c, &reduced[i]) {
            c.experiment = None;
        }
        c
    });
    for (i, c) in passing.into_iter().zip(checked) {
        judged[i].0 = c;
    }
}

/// The information criterion of a member judged on the simulation alone (a gear play), on the
/// cost the joint model is tuned on: the trimmed simulation cost of the long fit segments
/// ([`trimmed`]), one term per segment kept, instead of the plain cost of the short ones.
///
/// A play's only evidence is the motion, and the plain cost of the fit blocks is carried by the
/// few segments no model predicts (on seed 24 of the three-effect test, the play leaves it
/// unchanged, 0.354 against 0.356 rad, while it halves the held-out error, 0.27 to 0.13 rad, and
/// the trimmed cost). When the held-out simulation drop passes and this criterion does, the
/// member gets the checks of a candidate that passed statistically (its physical constraints,
/// "play, not a compliance"); `c` is left as it was otherwise.
fn on_tuned_cost(
    cx: &joint::Context,
    tuner: &Tuner,
    c: &mut Candidate,
    full: &Plant,
    reduced: &Plant,
) {
    let opts = cx.opts;
    let held_out = c.oe_reduction_pct.is_some_and(|d| {
        d >= opts
            .thresholds
            .min_simulation_oe_drop_pct
            .max(opts.thresholds.min_oe_drop_pct)
    });
    let (x, y) = (tuner.cost(reduced), tuner.cost(full));
    if !(held_out && x.is_finite() && y > 0.0) {
        return;
    }
    let n = tuner.kept() as f64;
    let bic = simulation_bic(x, y, n, c.effect, &opts.thresholds);
    trace(|| {
        alloc::format!(
            "{} on the tuned cost: {x:.4e} -> {y:.4e} rad over {n} segments, criterion {bic:.1}",
            c.effect
        )
    });
    if bic <= opts.thresholds.min_bic_gain {
        return;
    }
    c.bic_gain = bic;
    let found =
        super::checks::constraints(cx.ds, c.effect, &c.params, full, reduced, &opts.thresholds);
    c.significant = found.iter().all(|k| k.passed);
    c.checks.extend(found);
}

/// The evidence of a survivor: found together with the others, how.
fn note(
    cx: &joint::Context,
    full: &Plant,
    named: &[EffectKind],
    survivors: &[EffectKind],
    m: EffectKind,
    total: f64,
    evidence: &str,
) -> alloc::string::String {
    use core::fmt::Write;
    let mut s = alloc::string::String::new();
    let others: Vec<&str> = survivors
        .iter()
        .filter(|k| **k != m)
        .map(|k| k.name())
        .collect();
    let _ = write!(
        s,
        "Found together with {}: no single effect passed; {m} is material given the others (judged against the joint model without it, backward elimination from a joint simulation fit).",
        if others.is_empty() { "the effects already in the model".into() } else { others.join(", ") }
    );
    if !named.is_empty() {
        let re: Vec<alloc::string::String> = named
            .iter()
            .filter_map(|k| {
                let p = re_estimated(cx, full, *k)?;
                Some(alloc::format!("{k} ({p})"))
            })
            .collect();
        if !re.is_empty() {
            let _ = write!(s, " Re-estimated with them: {}.", re.join(", "));
        }
    }
    let _ = write!(
        s,
        " Together they cut the held-out simulation error by {:.1} %. {evidence}",
        100.0 * total
    );
    s
}

/// The main parameter of an effect already in the model, before and after the joint fit.
fn re_estimated(cx: &joint::Context, full: &Plant, k: EffectKind) -> Option<alloc::string::String> {
    let spec = k.params().iter().find(|p| k.model().fittable(p.key))?;
    let before = cx.model.effects.value(k, spec.key)?;
    let after = full.effects.value(k, spec.key)?;
    Some(alloc::format!(
        "{} {before:.4e} -> {after:.4e} {}",
        spec.key,
        spec.unit
    ))
}

/// Prints a line of the search to stderr when `SERVO_DIAG_TRACE` is set (std builds).
#[cfg(feature = "std")]
fn trace(line: impl FnOnce() -> alloc::string::String) {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if *ON.get_or_init(|| std::env::var_os("SERVO_DIAG_TRACE").is_some()) {
        std::eprintln!("[backward] {}", line());
    }
}

#[cfg(not(feature = "std"))]
fn trace(_line: impl FnOnce() -> alloc::string::String) {}

/// The members' parameters in `p`, for the trace.
fn show(p: &Plant, members: &[EffectKind]) -> alloc::string::String {
    let mut s = alloc::format!("J_eq {:.4e} tau_sf {:.4e}", p.params.j_eq(), p.tau_sf());
    for &k in members {
        for spec in k.params() {
            if let Some(v) = p.effects.value(k, spec.key) {
                s.push_str(&alloc::format!(" {k}.{} {v:.4e}", spec.key));
            }
        }
    }
    s
}
