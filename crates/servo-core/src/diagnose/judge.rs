//! Stage 4 of a diagnosis: every candidate judged against the base and the simulation reference:
//! the three statistical guards (information criterion, held-out residual drop, held-out
//! simulation drop), the practical checks (noise floor, share of the structured error), the
//! effect's own constraints, and the two mimic checks (the structure it fits is gone; a
//! resonance is not left ringing). The joint search ([`super::search`]) judges its members with
//! the same [`judge`].

use super::evidence;
use super::kinds::{nonlinear_searched, on_simulation};
use super::structure::{self, BalanceReport};
use super::survey::{Reference, Survey};
use super::thresholds::{frac, Thresholds};
use super::{checks, par_map, Candidate, DiagnoseOptions};
use super::{regimes, resonance};
use crate::effects::EffectKind;
use crate::fit::model::{EqSolution, Equation};
use crate::fit::oe::{self, Part};
use crate::fit::{self, Dataset, FitError, ParamEstimate, Solved};
use crate::math;
use alloc::string::String;
use alloc::vec::Vec;

/// Name of the check that what a candidate explains stands above its balance's noise floor.
pub(super) const FLOOR_CHECK: &str = "above the noise floor";
/// Name of the check that a candidate explains a material share of its balance's structured
/// (above-noise) error: an effect below the floor fails it too when little stands above it.
pub(super) const STRUCTURED_CHECK: &str = "material share of the structured error";

/// Judges every fitted candidate of `survey` (in parallel): [`judge`], then the mimic checks
/// ([`structure_check`], [`resonance_check`]) of those that pass.
///
/// `base`: the base model re-solved in its balances, `noise_a` the current-sensor noise [A] and
/// `floors` each balance's noise floor ([`super::base`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn all(
    ds: &Dataset,
    labels: &regimes::Labels,
    base: &Solved,
    noise_a: Option<f64>,
    floors: &[(Equation, f64)],
    survey: &Survey,
    curve: Option<&super::friction_curve::FrictionCurve>,
    opts: &DiagnoseOptions,
) -> Vec<Candidate> {
    let th = &opts.thresholds;
    let floor_of = |eq: Equation| structure::floor_in(floors, eq);
    let sols: Vec<&EqSolution> = core::iter::once(&base.mech)
        .chain(base.elec.as_ref())
        .collect();
    par_map(&survey.fits, opts.parallel, |(kind, res)| {
        let kind = *kind;
        let solved = match res {
            Ok(s) => s,
            Err(e) => return failed(base, kind, e),
        };
        let eq = fit::model::Config::equation_of(kind, ds.has_current);
        let bal = survey.balances.iter().find(|b| b.equation == eq);
        let mut c = judge(
            ds,
            labels,
            base,
            &survey.reference,
            noise_a,
            floor_of(eq),
            bal.map_or(0.0, |b| b.rms),
            kind,
            &Simulated::new(ds, solved),
            opts,
            false,
            curve,
        );
        // A mimic leaves the structure it was meant to explain: the shape that carried the
        // balance's residual is still there, above the noise floor, after adding it.
        if c.significant && !on_simulation(kind) && kind != EffectKind::Coulomb {
            if let (Some(b), Some(sol)) = (bal, solved.equation(eq)) {
                if let Some(k) = structure_check(ds, b, sol, floor_of(eq), th) {
                    let still = !k.passed;
                    c.checks.push(k);
                    if still {
                        demote(&mut c);
                    }
                }
            }
        }
        if c.significant {
            let base_sol = sols.iter().copied().find(|s| s.equation == eq);
            if let Some(k) = bal.and_then(|b| resonance_check(ds, b, base_sol, solved, th)) {
                let passed = k.passed;
                c.checks.push(k);
                if !passed {
                    demote(&mut c);
                }
            }
        }
        c
    })
}

/// Refuses candidate `c` after a check it failed (already pushed to `c.checks`): not
/// significant, the experiment that would settle it, the failed checks in its evidence.
pub(super) fn demote(c: &mut Candidate) {
    c.significant = false;
    c.experiment = Some(String::from(evidence::experiment(c.effect)));
    evidence::append_failed(c);
}

/// A mimic leaves the structure it was meant to explain: the shape that carried the balance's
/// residual (`before`) is still there, above the noise floor `floor`, in the residual `after` the
/// candidate was added. `None` when the balance was not above its noise floor or had no shape.
pub(super) fn structure_check(
    ds: &Dataset,
    before: &BalanceReport,
    after: &EqSolution,
    floor: f64,
    th: &Thresholds,
) -> Option<checks::Check> {
    let b = before;
    let eq = after.equation;
    // The first shape the analysis re-measures (the friction curve's is measured apart).
    let top = b
        .signatures
        .iter()
        .find(|s| s.kind != super::friction_curve::KIND)
        .filter(|_| b.above_noise)?;
    let after = structure::analyse(ds, after, floor, th, ds.gear_ratio);
    let left = after.signatures.iter().find(|s| s.kind == top.kind);
    // Still there: above the noise floor and at least half its size before (a true effect
    // removes most of the shape it fits, whatever another missing effect leaves of it; a mimic
    // bends to it and leaves most of it).
    let still = after.above_noise
        && left.is_some_and(|s| {
            s.explained_rms >= th.min_noise_ratio * floor
                && s.explained_rms >= frac(th.structure_left_pct) * top.explained_rms
        });
    Some(checks::Check {
        name: "explains the structure it fits",
        passed: !still,
        detail: alloc::format!(
            "before it, the {} residual was {:.1} times its noise floor, carried by a shape that {} ({:.2e} {unit} RMS); with it, {:.1} times, and that shape still carries {:.0} % of it ({:.2e} {unit} RMS; a shape is still there above the noise floor and at half its size before)",
            eq.name(),
            b.ratio_to_noise,
            top.description,
            top.explained_rms,
            after.ratio_to_noise,
            100.0 * left.map_or(0.0, |s| s.share),
            left.map_or(0.0, |s| s.explained_rms),
            unit = eq.unit()
        ),
    })
}

/// A candidate that leaves the resonance ringing in the balance it is judged on is a mimic: a
/// resonance is a second mass on a spring, which no catalogue effect of the rigid model holds
/// (a gear play bends to it through its contact stiffness but does not ring at a fixed
/// frequency). The check fails when the candidate's residual keeps at least half the base
/// residual's power in the resonance band, both measured on the held-out rows that both models
/// weigh (see [`structure::resonance_kept`]). `None` when the balance shows no resonance, or one
/// too weak to refuse a candidate ([`Thresholds::resonance_refuse_prominence`]).
pub(super) fn resonance_check(
    ds: &Dataset,
    b: &BalanceReport,
    base: Option<&EqSolution>,
    cand: &Solved,
    th: &Thresholds,
) -> Option<checks::Check> {
    let res = b
        .resonance
        .as_ref()
        .filter(|r| b.above_noise && r.prominence >= th.resonance_refuse_prominence)?;
    let sol = cand.equation(b.equation)?;
    let contact = cand
        .cfg
        .slots
        .iter()
        .any(|s| s.kind.sim_role() == crate::effects::SimRole::Contact);
    let kept = structure::resonance_kept(ds, base?, sol, contact, res);
    let max_kept = frac(th.max_resonance_kept_pct);
    Some(checks::Check {
        name: "explains the resonance",
        passed: kept < max_kept,
        detail: alloc::format!(
            "the {} residual rings near {:.1} Hz ({}, {:.0} % of it); with this effect {:.0} % of that band's power is still there on the rows both models weigh (needs under {:.0} %){}",
            b.equation.name(),
            res.freq_hz,
            resonance::damping_phrase(res),
            100.0 * res.share,
            100.0 * kept,
            th.max_resonance_kept_pct,
            if kept < max_kept {
                ""
            } else {
                ": a resonance (e.g. a compliant shaft or coupling) that this effect does not explain"
            }
        ),
    })
}

/// The information criterion of `kind` judged on the simulation alone (a gear play): the
/// simulation cost `x` [rad] without it against `y` with it over `n` independent terms, each
/// nonlinear parameter searched costing [`Thresholds::bic_search_charge`] (as in the equation's criterion).
/// `-inf` when `y` is not positive.
pub(super) fn simulation_bic(x: f64, y: f64, n: f64, kind: EffectKind, th: &Thresholds) -> f64 {
    if y <= 0.0 {
        return f64::NEG_INFINITY;
    }
    let q = nonlinear_searched(kind) as f64;
    n * math::ln(x * x / (y * y)) - th.bic_search_charge * q * math::ln(n)
}

/// A fitted model and its held-out simulation cost [rad] ([`oe::prediction_cost`] on the
/// held-out blocks), computed once for every judgement of it: the joint model of a round of
/// drop-one tests is judged once per member.
pub(super) struct Simulated<'a> {
    pub solved: &'a Solved,
    pub oe_holdout_rad: Option<f64>,
}

impl<'a> Simulated<'a> {
    /// `solved` with its held-out simulation cost.
    pub(super) fn new(ds: &Dataset, solved: &'a Solved) -> Self {
        Simulated {
            solved,
            oe_holdout_rad: oe::prediction_cost(ds, &solved.plant, Part::Holdout),
        }
    }
}

/// Judges candidate `kind` fitted as `sim` against `base` (its balance: `balance_rms` over the
/// noise floor `balance_floor`) and the simulation `reference`: the information criterion, the
/// held-out residual and simulation drops, then the practical-significance checks and the
/// effect's constraints. `given_others`: `kind` is a member of a joint model judged given the
/// other members (its share of the structured error may be measured in the motion).
#[allow(clippy::too_many_arguments)]
pub(super) fn judge(
    ds: &Dataset,
    labels: &regimes::Labels,
    base: &Solved,
    reference: &Reference,
    noise_a: Option<f64>,
    balance_floor: f64,
    balance_rms: f64,
    kind: EffectKind,
    sim: &Simulated,
    opts: &DiagnoseOptions,
    given_others: bool,
    curve: Option<&super::friction_curve::FrictionCurve>,
) -> Candidate {
    let cand = sim.solved;
    let eq = fit::model::Config::equation_of(kind, ds.has_current);
    let params: Vec<ParamEstimate> = ds
        .estimates(cand)
        .into_iter()
        .filter(|p| p.effect == Some(kind) || (kind == EffectKind::Coulomb && p.key == "tau_sf"))
        .collect();
    let sim_only = on_simulation(kind);
    let base_oe = reference.oe_holdout;
    let cand_oe = sim.oe_holdout_rad;
    let oe_drop = match (base_oe, cand_oe) {
        (Some(b), Some(c)) if b > 0.0 => Some(1.0 - c / b),
        _ => None,
    };
    let (b, c) = match (base.equation(eq), cand.equation(eq)) {
        (Some(b), Some(c)) => (b, c),
        _ => {
            return failed(
                base,
                kind,
                &FitError::BadModel(String::from("equation missing")),
            )
        }
    };
    // Information criterion on the fit rows, over the effective number of independent rows of
    // the noise. When the candidate explains most of the base's residual (a dominant torque such
    // as an arm's gravity), that residual is the effect's own smooth shape, whose lag-1
    // correlation near 1 would count a whole log as a handful of rows (a gravity torque 70 times
    // the Coulomb level refused at a gain of 9.9): the candidate's residual then measures the
    // noise's correlation.
    let th = &opts.thresholds;
    let rho = if c.rss_fit < frac(th.dominant_residual_pct) * b.rss_fit {
        math::lag1(&c.resid)
    } else {
        math::lag1(&b.resid)
    };
    let n_eff = (b.n_fit as f64 * (1.0 - rho) / (1.0 + rho)).max(1.0);
    let q_lin = c.p.saturating_sub(b.p) as f64;
    let q_nl = nonlinear_searched(kind) as f64;
    let bic_gain = if sim_only {
        // No equation-error regressors (a gear play): judged on the simulation cost.
        let fit_b = oe::prediction_cost(ds, &reference.plant, Part::Fit);
        let fit_c = oe::prediction_cost(ds, &cand.plant, Part::Fit);
        match (fit_b, fit_c) {
            (Some(x), Some(y)) => simulation_bic(x, y, n_eff, kind, th),
            _ => f64::NEG_INFINITY,
        }
    } else {
        n_eff * math::ln(b.rss_fit / c.rss_fit.max(1e-300))
            - (q_lin + th.bic_search_charge * q_nl) * math::ln(n_eff)
    };
    let (rss0, rss1) = if b.n_hold > 0 {
        (b.rss_hold, c.rss_hold)
    } else {
        (b.rss_fit, c.rss_fit)
    };
    let eq_drop = if sim_only {
        oe_drop.unwrap_or(0.0)
    } else {
        1.0 - rss1 / rss0.max(1e-300)
    };
    let error_reduction_pct = 100.0 * (1.0 - math::sqrt((1.0 - eq_drop).max(0.0)));
    // An effect judged on the simulation alone is judged on something less specific than an
    // equation residual (initial contact state, stick-slip transients): ask for a clear drop.
    let min_drop = frac(if sim_only {
        th.min_simulation_oe_drop_pct
    } else {
        th.min_eq_drop_pct
    });
    // Without a logged input nothing can be simulated: the two other guards decide.
    let oe_ok = match oe_drop {
        Some(d) => d >= frac(th.min_oe_drop_pct),
        None => !ds.has_input,
    };
    let statistically = bic_gain > th.min_bic_gain && eq_drop >= min_drop && oe_ok;
    // Detection floor: RMS of what the effect explains versus the sensor-noise torque/voltage.
    let explained: f64 = {
        let s: f64 = b
            .resid
            .iter()
            .zip(&c.resid)
            .map(|(x, y)| (x - y) * (x - y))
            .sum();
        math::sqrt(s / b.resid.len().max(1) as f64)
    };
    let floor = noise_a.map(|s| match eq {
        Equation::Electrical => s * base.plant.params.r_eq() / base.plant.params.k_drv,
        _ => s * base.plant.params.k_t,
    });
    let resolvable = floor.is_none_or(|f| explained >= f);
    // Practical significance: what it explains against the noise floor of its balance (sensor
    // noise and quantisation through the equation's filter and derivatives), and against the
    // structured error of that balance (the squared residual above the floor). An effect judged
    // on the simulation is held to its simulation drop.
    let noise_ratio = if balance_floor > 0.0 {
        explained / balance_floor
    } else {
        f64::INFINITY
    };
    let structured_sq = (balance_rms * balance_rms - balance_floor * balance_floor).max(0.0);
    let structured_share = if structured_sq > 0.0 {
        (explained * explained / structured_sq).min(1.0)
    } else {
        0.0
    };
    // A member of a joint model tuned on the simulation (`given_others`: judged given the other
    // members, [`backward`]) is found in the motion first: its share of the model's structured
    // error is also measured there, as its held-out simulation drop. Beside a gear play, whose
    // contact transients at every reversal stay in the torque balance (no regressor holds
    // them) and whose reversal rows that balance leaves out, a breakaway friction explains a
    // small share of the balance (23 % on seed 24 of the three-effect test) while removing 86 %
    // of the held-out simulation error.
    let motion_share = if given_others {
        oe_drop.unwrap_or(0.0).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut found: Vec<checks::Check> = Vec::new();
    if statistically {
        let unit = eq.unit();
        if !sim_only {
            found.push(checks::Check {
                name: FLOOR_CHECK,
                passed: noise_ratio >= th.min_noise_ratio,
                detail: alloc::format!(
                    "explains {explained:.2e} {unit} RMS, {noise_ratio:.2} times the {} noise floor {balance_floor:.2e} {unit} (needs {:.1})",
                    eq.name(),
                    th.min_noise_ratio
                ),
            });
            let in_motion = if given_others {
                alloc::format!(
                    ", or its held-out simulation drop given the other members, {:.0} %",
                    100.0 * motion_share
                )
            } else {
                String::new()
            };
            found.push(checks::Check {
                name: STRUCTURED_CHECK,
                passed: structured_share.max(motion_share) >= frac(th.min_structured_share_pct),
                detail: alloc::format!(
                    "explains {:.0} % of the structured (above-noise) error of the {}{in_motion} (needs {:.0} %)",
                    100.0 * structured_share,
                    eq.name(),
                    th.min_structured_share_pct
                ),
            });
        }
        found.extend(checks::constraints(
            ds,
            kind,
            &params,
            &cand.plant,
            &base.plant,
            th,
        ));
        // A friction is judged against the friction curve the logs show (sliding rows). Not a
        // member of a joint model: the curve is the base's, which the other members (a play's
        // impacts, a delay's lag) bend where they act.
        if !sim_only
            && !given_others
            && super::friction_curve::is_friction(kind)
            && eq != Equation::Electrical
        {
            if let Some(curve) = curve.filter(|c| c.equation == eq) {
                found.push(super::friction_curve::check(
                    curve,
                    b,
                    c,
                    &base.plant,
                    &cand.plant,
                    th,
                ));
            }
        }
    }
    let significant = statistically && found.iter().all(|c| c.passed);
    let ev = evidence::describe(
        ds,
        labels,
        kind,
        eq,
        b,
        c,
        &params,
        explained,
        floor,
        eq_drop,
        oe_drop,
        bic_gain,
        statistically,
    );
    let mut out = Candidate {
        effect: kind,
        significant,
        resolvable,
        error_reduction_pct,
        oe_reduction_pct: oe_drop.map(|d| 100.0 * d),
        bic_gain,
        equation: eq,
        params,
        plant: cand.plant,
        evidence: ev,
        experiment: if significant {
            None
        } else {
            Some(String::from(evidence::experiment(kind)))
        },
        noise_ratio,
        structured_share,
        checks: found,
        conditional: None,
        joint_with: None,
    };
    if statistically && !significant {
        evidence::append_failed(&mut out);
    }
    out
}

pub(super) fn failed(base: &Solved, kind: EffectKind, e: &FitError) -> Candidate {
    Candidate {
        effect: kind,
        significant: false,
        resolvable: false,
        error_reduction_pct: 0.0,
        oe_reduction_pct: None,
        bic_gain: f64::NEG_INFINITY,
        equation: Equation::Torque,
        params: Vec::new(),
        plant: base.plant,
        evidence: alloc::format!("could not be fitted to these logs ({e})"),
        experiment: Some(String::from(evidence::experiment(kind))),
        noise_ratio: 0.0,
        structured_share: 0.0,
        checks: Vec::new(),
        conditional: None,
        joint_with: None,
    }
}
