//! Two effects judged together, when neither passes alone.
//!
//! The diagnosis accepts one effect at a time: adding several at once produces false effects.
//! But two missing effects can hide each other so that neither passes alone. A gear play and a
//! breakaway friction both live at the low speeds around reversals: without the play in the
//! model, the torque balance near every reversal holds the play's unmodelled impacts, which
//! dominate its residual, and the breakaway friction fails the information criterion there
//! (it cuts the simulation error by 15-31 % but explains too little of a torque residual the
//! play pollutes); without the stiction, the simulated load sticks and slips at the wrong times
//! and the play's own simulation drop stays at 2-3 %. Each is material only once the other is in
//! the model.
//!
//! So when no single candidate passes and some balance is still above its noise floor, the
//! candidates with the largest held-out simulation drops ([`super::DiagnoseOptions::joint_candidates`] of them) are fitted in
//! pairs, jointly (base refitted, nonlinear parameters searched together, see
//! [`crate::fit::Dataset::fit_config`]). A pair is accepted only if *each* member passes every
//! check of a single candidate *given the other* (a drop-one test, like a partial F-test): the
//! pair is judged against the model holding the other member alone, fitted and with its inertia
//! and Coulomb level tuned on the simulation exactly as the single candidate's reference is, on
//! the information criterion of the member's own balance, its held-out residual and simulation
//! drops, its noise floor and structured share, its physical constraints, "explains the
//! structure it fits", and its agreement across both halves of the data (refitted with the other
//! member in the model). A mimic pair (two effects bending together to soak up a mechanism
//! outside the catalogue) must therefore pass every guard twice over.

use super::judge::{judge, resonance_check, structure_check, Simulated};
use super::survey::Reference;
use super::thresholds::frac;
use super::{checks, on_simulation, par_map, structure, Candidate, DiagnoseOptions};
use crate::effects::EffectKind;
use crate::fit::model::{Config, Equation};
use crate::fit::oe::{self, Part};
use crate::fit::{Dataset, EffectToFit, FitError, Solved};
use crate::plant::Plant;
use alloc::vec::Vec;

/// What a pair search needs from the diagnosis.
pub(super) struct Context<'a> {
    pub ds: &'a Dataset,
    pub model: &'a Plant,
    pub noise_a: Option<f64>,
    /// Noise floor per balance of the base model.
    pub floors: &'a [(Equation, f64)],
    /// The electrical balance is itself far above its noise floor and no drive-side effect
    /// explains it (no torque may be named).
    pub electrical_broken: bool,
    /// The simulation reference of the diagnosis (the model holding neither member).
    pub reference: &'a Reference,
    /// The regime labels of both balances' rows.
    pub labels: &'a super::regimes::Labels,
    pub opts: &'a DiagnoseOptions,
}

impl Context<'_> {
    pub(super) fn floor_of(&self, eq: Equation) -> f64 {
        structure::floor_in(self.floors, eq)
    }
}

/// The candidates worth pairing: not significant alone, fitted, with a held-out simulation drop
/// of at least the minimum and (judged in a balance of their own) a held-out residual no worse
/// than the drop a candidate must show there, best first, at most
/// [`super::DiagnoseOptions::joint_candidates`].
pub(super) fn seeds<'a>(
    cx: &Context,
    fits: &'a [(EffectKind, Result<Solved, FitError>)],
    ranking: &[Candidate],
) -> Vec<(EffectKind, &'a Solved)> {
    let th = &cx.opts.thresholds;
    let mut top: Vec<(f64, EffectKind, &Solved)> = ranking
        .iter()
        .filter_map(|c| {
            let drop = seed_rank(c, th)?;
            let (_, r) = fits.iter().find(|(k, _)| *k == c.effect)?;
            Some((drop, c.effect, r.as_ref().ok()?))
        })
        .collect();
    top.sort_by(|a, b| b.0.total_cmp(&a.0));
    top.truncate(cx.opts.joint_candidates);
    top.into_iter().map(|(_, k, s)| (k, s)).collect()
}

/// Where candidate `c` ranks among the seeds of a joint search (its held-out simulation drop
/// [%], infinite for an effect judged on the simulation alone), or `None` when it is no seed:
/// significant alone, or a drop below [`super::Thresholds::min_oe_drop_pct`], or (judged in a
/// balance of its own) a held-out residual worse by more than a candidate must make it better
/// ([`super::Thresholds::min_eq_rms_drop_pct`]).
fn seed_rank(c: &Candidate, th: &super::Thresholds) -> Option<f64> {
    if c.significant {
        return None;
    }
    let drop = c.oe_reduction_pct?;
    if on_simulation(c.effect) {
        // An effect judged on the simulation alone (a gear play) has no balance of its own to
        // show in: its only evidence, the simulation, is the one another missing effect spoils
        // most. It is always a seed.
        return Some(f64::INFINITY);
    }
    // A candidate whose fit makes its own balance worse on the held-out rows, by as much as a
    // candidate must make it better, does not generalise: what it bends to fit is not its
    // structure (a torque locked to a harmonic of the motor angle, beside a torque ripple at no
    // harmonic of it: -5 to -6 %). Another missing effect can hide how much it explains, not
    // turn its fit into a clearly worse prediction than none. Each simulation holding such a
    // mimic runs in sub-steps: it was two thirds of an "unexplained" diagnosis (28 s of 41 s).
    (drop >= th.min_oe_drop_pct && c.error_reduction_pct >= -th.min_eq_rms_drop_pct())
        .then_some(drop)
}

/// The best accepted pair (largest joint held-out simulation drop), its two members as
/// candidates, the first with the larger drop given the other; `None` when no pair passes.
pub(super) fn best_pair(
    cx: &Context,
    fits: &[(EffectKind, Result<Solved, FitError>)],
    ranking: &[Candidate],
) -> Option<[Candidate; 2]> {
    let top = seeds(cx, fits, ranking);
    if top.len() < 2 {
        return None;
    }
    let mut pairs = Vec::new();
    for i in 0..top.len() {
        for j in i + 1..top.len() {
            pairs.push((i, j));
        }
    }
    // The independent work first, as one even load on the cores: each member judged against the
    // model holding the other alone, tuned on the simulation as the single candidates' reference
    // is; and every start of every pair's joint fit ([`joint_start`]).
    enum Task {
        Reference(usize),
        Start(usize, usize),
    }
    enum Done {
        Reference(alloc::boxed::Box<Reference>),
        Start(Option<alloc::boxed::Box<(f64, Solved)>>),
    }
    let tasks: Vec<Task> = (0..top.len())
        .map(Task::Reference)
        .chain((0..pairs.len()).flat_map(|p| (0..START_COUNT).map(move |k| Task::Start(p, k))))
        .collect();
    let done = par_map(&tasks, cx.opts.parallel, |t| match *t {
        Task::Reference(i) => {
            let plant = cx.ds.refine_rigid_on_simulation(&top[i].1.plant);
            Done::Reference(alloc::boxed::Box::new(Reference {
                oe_holdout: oe::prediction_cost(cx.ds, &plant, Part::Holdout),
                plant,
            }))
        }
        Task::Start(p, k) => {
            let (i, j) = pairs[p];
            Done::Start(joint_start(cx, top[i], top[j], k).map(alloc::boxed::Box::new))
        }
    });
    let mut refs = Vec::new();
    let mut starts: Vec<Vec<Option<(f64, Solved)>>> = pairs.iter().map(|_| Vec::new()).collect();
    for (t, d) in tasks.iter().zip(done) {
        match (t, d) {
            (Task::Reference(_), Done::Reference(r)) => refs.push(*r),
            (Task::Start(p, _), Done::Start(s)) => starts[*p].push(s.map(|b| *b)),
            _ => return None,
        }
    }
    // Each pair's joint fit: the start with the lowest cost (the first of equal ones).
    let joints: Vec<(usize, usize, Solved)> = pairs
        .iter()
        .zip(starts)
        .filter_map(|(&(i, j), s)| {
            let best = s.into_iter().flatten().min_by(|x, y| x.0.total_cmp(&y.0))?;
            Some((i, j, best.1))
        })
        .collect();
    let judged = par_map(&joints, cx.opts.parallel, |(i, j, joint)| {
        judge_pair(
            cx,
            (top[*i].0, top[*i].1, &refs[*i]),
            (top[*j].0, top[*j].1, &refs[*j]),
            joint,
        )
    });
    judged
        .into_iter()
        .flatten()
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, pair)| pair)
}

/// Starts of a pair's joint fit ([`joint_start`]).
const START_COUNT: usize = 3;

/// Start `k` (< [`START_COUNT`]) of the joint fit of `a` and `b`, with its simulation cost on the
/// fit blocks: both searched together (0), and each searched with the other held at its own
/// single fit (1: `a` held, 2: `b` held; its nonlinear parameters kept, its linear ones
/// refitted). The joint problem is not convex: a breakaway friction fitted beside a play whose
/// gap is still unknown can settle on a narrow spike at low speed that the play then
/// compensates with a wide gap. The start with the lowest simulation cost on the fit blocks
/// (never the held-out ones) is kept.
fn joint_start(
    cx: &Context,
    (a, a_alone): (EffectKind, &Solved),
    (b, b_alone): (EffectKind, &Solved),
    k: usize,
) -> Option<(f64, Solved)> {
    let both = [EffectToFit::all(a), EffectToFit::all(b)];
    let (from, fit) = match k {
        0 => (*cx.model, &both[..]),
        1 => (a_alone.plant, &both[1..]),
        _ => (b_alone.plant, &both[..1]),
    };
    let s = cx.ds.fit_config(&from, fit).ok()?;
    let cost = oe::prediction_cost(cx.ds, &s.plant, Part::Fit)?;
    Some((cost, s))
}

/// Judges each of `a` and `b` given the other in their joint fit `joint`. `Some((joint held-out
/// simulation drop against the model holding neither, [members]))` when both pass.
fn judge_pair(
    cx: &Context,
    a: (EffectKind, &Solved, &Reference),
    b: (EffectKind, &Solved, &Reference),
    joint: &Solved,
) -> Option<(f64, [Candidate; 2])> {
    let ca = judge_member(cx, a.0, (b.0, b.1, b.2), joint);
    let cb = judge_member(cx, b.0, (a.0, a.1, a.2), joint);
    let (mut ca, mut cb) = (ca.filter(|c| c.significant)?, cb.filter(|c| c.significant)?);
    // The pair against the model holding neither.
    let joint_oe = oe::prediction_cost(cx.ds, &joint.plant, Part::Holdout)?;
    let base_oe = cx.reference.oe_holdout?;
    let total = 1.0 - joint_oe / base_oe.max(1e-300);
    if total < frac(cx.opts.thresholds.min_oe_drop_pct) {
        return None;
    }
    if !(confirm_member(cx, &mut ca, joint) && confirm_member(cx, &mut cb, joint)) {
        return None;
    }
    let drop = |c: &Candidate| c.oe_reduction_pct.unwrap_or(f64::NEG_INFINITY);
    Some((
        total,
        if drop(&ca) >= drop(&cb) {
            [ca, cb]
        } else {
            [cb, ca]
        },
    ))
}

/// Judges `m` in the joint fit against the model holding only the other member `o` (fitted
/// alone, `o_alone`, and its simulation reference `o_ref`): every check of a single candidate but
/// the agreement across parts of the data ([`confirm_member`]). `None` when a balance is
/// missing.
fn judge_member(
    cx: &Context,
    m: EffectKind,
    (o, o_alone, o_ref): (EffectKind, &Solved, &Reference),
    joint: &Solved,
) -> Option<Candidate> {
    let (mut c, _) = judge_given(cx, m, o_alone, o_ref, &Simulated::new(cx.ds, joint))?;
    c.joint_with = Some(o);
    Some(c)
}

/// Judges `m` in the joint fit `sim` (with its held-out simulation cost) against the model
/// without it (`o_alone`, its simulation reference `o_ref`): every check of a single candidate
/// but the agreement across parts of the data ([`confirm_given`]). Shared by the pairs and the
/// backward elimination. `None` when a balance is missing.
pub(super) fn judge_given(
    cx: &Context,
    m: EffectKind,
    o_alone: &Solved,
    o_ref: &Reference,
    sim: &Simulated,
) -> Option<(Candidate, structure::BalanceReport)> {
    let joint = sim.solved;
    let ds = cx.ds;
    let th = &cx.opts.thresholds;
    let eq = Config::equation_of(m, ds.has_current);
    let floor = cx.floor_of(eq);
    let before = structure::analyse(ds, o_alone.equation(eq)?, floor, th, ds.gear_ratio);
    let mut c = judge(
        ds, cx.labels, o_alone, o_ref, cx.noise_a, floor, before.rms, m, sim, cx.opts, true, None,
    );
    if c.significant && !on_simulation(m) && m != EffectKind::Coulomb {
        if let Some(k) = structure_check(ds, &before, joint.equation(eq)?, floor, th) {
            c.significant &= k.passed;
            c.checks.push(k);
        }
    }
    // No torque is named while the electrical balance is itself inconsistent, judged in the
    // joint model: a drive-side member re-sized there (a delay named before a play was in the
    // model absorbed the play's lag) may account for what the model before it left.
    if c.significant && m.is_mechanical() && !on_simulation(m) {
        if let Some(k) = electrical_consistent(cx, joint) {
            c.significant = k.passed;
            c.checks.push(k);
        }
    }
    resonance_given(ds, &mut c, &before, o_alone, joint, &cx.opts.thresholds);
    Some((c, before))
}

/// The check of a single candidate that it explains the resonance its balance rings with
/// ([`super::judge::resonance_check`]), for member `c` of `joint` judged against `o_alone` (the joint
/// model without it; `before`, that model's balance): a play bends to a compliant shaft's ringing
/// through its contact stiffness beside other members as it does alone (with the joint search
/// on, seed 50 of the compliant-shaft test named one without this check). Applied once, to a
/// member still significant.
pub(super) fn resonance_given(
    ds: &Dataset,
    c: &mut Candidate,
    before: &structure::BalanceReport,
    o_alone: &Solved,
    joint: &Solved,
    th: &super::Thresholds,
) {
    const NAME: &str = "explains the resonance";
    if !c.significant || c.checks.iter().any(|k| k.name == NAME) {
        return;
    }
    if let Some(k) = resonance_check(ds, before, o_alone.equation(before.equation), joint, th) {
        c.significant = k.passed;
        c.checks.push(k);
    }
}

/// The check that no torque is named while the electrical balance, which holds no mechanical
/// effect, is itself inconsistent: `None` when the diagnosis found it consistent, else the
/// balance's residual in `joint` against its noise floor (it fails at
/// [`super::Thresholds::electrical_block_ratio`] times the floor).
fn electrical_consistent(cx: &Context, joint: &Solved) -> Option<checks::Check> {
    if !cx.electrical_broken {
        return None;
    }
    let floor = cx.floor_of(Equation::Electrical);
    let ratio = joint
        .equation(Equation::Electrical)
        .filter(|_| floor > 0.0)
        .map_or(f64::INFINITY, |s| s.rms() / floor);
    let block = cx.opts.thresholds.electrical_block_ratio;
    Some(checks::Check {
        name: "electrical balance consistent",
        passed: ratio < block,
        detail: alloc::format!(
            "the electrical balance, which holds no mechanical effect, is {ratio:.1} times its noise floor in the joint model (no torque is named at {block:.0} times or more: the current or speed measurement would be inconsistent)"
        ),
    })
}

/// The agreement of `c` (a member of a joint fit, with the other member `c.joint_with`) across
/// independent parts of the data, refitted with the other member in the model, then its notes.
/// Returns whether it passed.
fn confirm_member(cx: &Context, c: &mut Candidate, joint: &Solved) -> bool {
    let Some(o) = c.joint_with else {
        return false;
    };
    let Some(other) = joint.plant.effects.get(o) else {
        return false;
    };
    let mut given = *cx.model;
    given.effects.insert(*other);
    if !confirm_given(cx, c, &given) {
        return false;
    }
    let m = c.effect;
    c.evidence = alloc::format!(
        "Found together with {o}: no single effect passed, and {m} is material once {o} is in the model (judged against the model with {o} alone, fitted jointly with it). {}",
        c.evidence
    );
    c.experiment = None;
    true
}

/// How member `c` of a joint model is refitted on parts of the data ([`confirm_given`]): in
/// full, except a torque-balance member beside an effect judged on the simulation (a gear play),
/// whose nonlinear parameters keep their joint values and only its levels are refitted. The
/// torque balance leaves out the rows around reversals when the model has a play, and there a
/// breakaway's speed scale is free: searched again on each half it settled on a narrow spike on
/// one (tau_s 0.070 against 0.021 N m on the other, seed 27 of the three-effect test), while the
/// joint fit had tuned it on the motion.
fn halves_fit(c: &Candidate, given: &Plant) -> EffectToFit {
    let all = EffectToFit::all(c.effect);
    let beside_play = given.effects.iter().any(|e| on_simulation(e.kind));
    c.plant
        .effects
        .get(c.effect)
        .filter(|_| beside_play && c.effect.is_mechanical() && !on_simulation(c.effect))
        .and_then(|member| all.levels_of(*member))
        .unwrap_or(all)
}

/// The agreement of `c` across independent parts of the data, refitted on `given` (the joint
/// model without `c`), then its effect's notes. Marks `c` not significant and returns false when
/// a part disagrees.
pub(super) fn confirm_given(cx: &Context, c: &mut Candidate, given: &Plant) -> bool {
    let ds = cx.ds;
    let cons = checks::consistency_with(ds, given, c, &cx.opts.thresholds, halves_fit(c, given));
    let ok = cons.iter().all(|k| k.passed);
    c.checks.extend(cons);
    if !ok {
        c.significant = false;
        return false;
    }
    let hooks = c.effect.model().fit_hooks();
    if let Some(note) = hooks.and_then(|h| h.candidate_note(ds, given, c)) {
        c.evidence.push_str(&note);
    }
    if let Some((cond, note)) = hooks.and_then(|h| h.conditional(ds, given, c)) {
        c.evidence.push_str(&note);
        c.conditional = Some(cond);
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::model::Equation;
    use crate::PlantParams;
    use alloc::string::String;

    /// A candidate of `effect` that failed alone, with held-out residual drop `eq_pct` and
    /// simulation drop `oe_pct` [%].
    fn candidate(effect: EffectKind, eq_pct: f64, oe_pct: f64) -> Candidate {
        Candidate {
            effect,
            significant: false,
            resolvable: true,
            error_reduction_pct: eq_pct,
            oe_reduction_pct: Some(oe_pct),
            bic_gain: -10.0,
            equation: Equation::Torque,
            params: Vec::new(),
            plant: Plant::from_params(PlantParams::TABLE2).unwrap(),
            evidence: String::new(),
            experiment: None,
            noise_ratio: 1.0,
            structured_share: 0.1,
            checks: Vec::new(),
            conditional: None,
            joint_with: None,
        }
    }

    #[test]
    fn a_candidate_that_worsens_its_own_held_out_balance_is_no_seed() {
        let th = super::super::Thresholds::default();
        let bar = th.min_eq_rms_drop_pct();
        assert!((bar - 1.005).abs() < 1e-3, "{bar}");
        // Every effect judged in a balance of its own (named through the registry).
        for k in EffectKind::ALL.into_iter().filter(|k| !on_simulation(*k)) {
            // A mimic: a large simulation drop, its own balance 5 % worse on the held-out rows.
            assert_eq!(seed_rank(&candidate(k, -5.3, 21.0), &th), None, "{k}");
            // Within the bar either way it is noise: a seed, ranked by its simulation drop.
            assert_eq!(seed_rank(&candidate(k, -0.5, 11.5), &th), Some(11.5), "{k}");
            assert_eq!(seed_rank(&candidate(k, 1.8, 15.3), &th), Some(15.3), "{k}");
            // Too small a simulation drop, or significant alone: no seed.
            assert_eq!(seed_rank(&candidate(k, 3.0, 0.5), &th), None, "{k}");
            let mut alone = candidate(k, 30.0, 40.0);
            alone.significant = true;
            assert_eq!(seed_rank(&alone, &th), None, "{k}");
        }
        // An effect judged on the simulation alone (a gear play) has no balance of its own:
        // always a seed, first, whatever its figures.
        let plays: Vec<EffectKind> = EffectKind::ALL
            .into_iter()
            .filter(|k| on_simulation(*k))
            .collect();
        assert!(!plays.is_empty());
        for k in plays {
            assert_eq!(
                seed_rank(&candidate(k, -8.0, -3.0), &th),
                Some(f64::INFINITY),
                "{k}"
            );
        }
    }
}
