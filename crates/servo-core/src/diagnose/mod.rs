//! Which physical effect is the model missing?
//!
//! Every catalogue effect the model lacks is fitted to the data (nonlinear parameters by search,
//! base parameters refitted with it, see [`crate::fit`]) on the fit blocks of the logs, and judged
//! on three guards against overfitting, all of which must pass for `significant`:
//!
//! 1. information criterion: the BIC gain of its own equation, computed with the effective number
//!    of independent rows (lag-1 autocorrelation of the residual) and charged for the parameters
//!    added plus the search over each nonlinear parameter;
//! 2. a minimum relative drop of its own equation's residual on the held-out blocks;
//! 3. a minimum drop of the output-error (simulation) cost on the held-out blocks, against the
//!    model without the effect with its J_eq and tau_sf tuned on the simulation (the same
//!    reference for every candidate, so that drops compare and a candidate that tunes base
//!    parameters on the simulation, as a gear play does, is not credited for the tuning).
//!
//! Candidates are ranked significant first, then by error reduction. One effect is accepted at a
//! time ([`diagnose_loop`]): accepting several at once produces false effects. A candidate whose
//! fitted torque is below the current-noise torque is reported as not resolvable with this data,
//! with the experiment that would resolve it.
//!
//! The diagnosis is a pipeline of named stages, one file each, read top to bottom in
//! [`diagnose_dataset`]: [`base`] (the base fit and the noise floors), [`kinds`] (what to try),
//! [`survey`] (every candidate fitted, the simulation reference, the balances analysed),
//! [`judge`] (the guards and the mimic checks), [`vetoes`] (the electrical veto),
//! [`consistent`] (agreement across halves of the data), [`rank`], [`change`] (a plant
//! that changes during a log), [`presliding`] (the regime near reversals, judged apart), [`search`] (the joint search
//! when nothing passes alone) and [`conclude`] (status, leads and verdict). Every threshold is in
//! one table, [`thresholds::Thresholds`], printed with every verdict ([`bars`]).

mod backward;
pub mod bars;
mod base;
pub mod cancel;
pub mod change;
pub mod checks;
mod conclude;
mod consistent;
mod diagnosis;
pub mod evidence;
pub mod friction_curve;
pub mod joint;
mod judge;
pub mod kinds;
pub mod neighbours;
mod options;
pub mod outside;
pub mod phrase;
pub mod presliding;
mod rank;
pub mod regimes;
pub mod resonance;
mod search;
pub mod sliding_lead;
pub mod structure;
mod survey;
pub mod thresholds;
pub mod timing;
mod tuner;
pub mod user_effects;
mod vetoes;

pub use crate::verdict::Candidate;
pub use diagnosis::{BaseSummary, Diagnosis, Status, Unresolvable};
pub use kinds::candidate_kinds;
pub use options::DiagnoseOptions;
pub use structure::{BalanceKind, BalanceReport, Signature};
pub use thresholds::Thresholds;

pub(crate) use crate::par::{join, par_map};
pub use kinds::on_simulation;

use crate::effects::EffectKind;
use crate::fit::model::Equation;
use crate::fit::{Dataset, FitError};
use crate::plant::Plant;
use crate::record::Record;
use alloc::vec::Vec;

/// Diagnoses `model` against `records`.
///
/// The winner is the catalogue effect that explains the residual best, when it is significant:
///
/// ```
/// # use servo_core::{record::Record, sim::{PlantSim, SensorConfig, Sensors}, Plant, PlantParams};
/// # fn simulate(plant: &Plant, seconds: f64) -> Record {
/// #     let (mut sim, mut sensors) = (PlantSim::new(plant, 1e-3).unwrap(), Sensors::new(SensorConfig::default()));
/// #     let mut rec = Record::default();
/// #     let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
/// #     for k in 0..(seconds * 1e3) as usize {
/// #         let u = [6.0, -3.0, 2.0, -7.0, 4.0][(k / 300) % 5];
/// #         let m = sensors.measure(sim.state());
/// #         rec.time_s.push(k as f64 * 1e-3);
/// #         th.push(m.theta_l_rad); ia.push(m.i_a_a); uv.push(u);
/// #         sim.step(u);
/// #     }
/// #     (rec.theta_l_rad, rec.i_a_a, rec.u_v) = (Some(th), Some(ia), Some(uv));
/// #     rec
/// # }
/// use servo_core::diagnose::{diagnose, DiagnoseOptions};
/// use servo_core::effects::{Effect, EffectKind};
/// let mut truth = Plant::from_params(PlantParams::TABLE2)?;
/// truth.effects.insert(Effect::new(EffectKind::Deadzone, &[0.8])?);
/// let logs = [simulate(&truth, 6.0)];
/// let d = diagnose(&logs, &Plant::from_params(PlantParams::TABLE2)?, &DiagnoseOptions::default())?;
/// assert_eq!(d.winner().map(|c| c.effect), Some(EffectKind::Deadzone));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn diagnose(
    records: &[Record],
    model: &Plant,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis, FitError> {
    timing::timed(
        || "whole diagnosis".into(),
        || {
            let ds = Dataset::new(records, &model.params, &opts.fit)?;
            diagnose_dataset(&ds, model, opts)
        },
    )
}

/// Stages 1-7 of a diagnosis on `ds`: the base, the candidates fitted and judged, best first.
struct Screened {
    base: base::Base,
    kinds: Vec<EffectKind>,
    survey: survey::Survey,
    labels: regimes::Labels,
    ranking: Vec<Candidate>,
    electrical_broken: bool,
    /// The measured friction curve of the torque (or u-driven) balance's sliding rows.
    curve: Option<friction_curve::FrictionCurve>,
}

fn screen(ds: &Dataset, model: &Plant, opts: &DiagnoseOptions) -> Result<Screened, FitError> {
    let th = &opts.thresholds;
    // 1. The base model refitted, the current noise, every balance's noise floor.
    let base = base::fit(ds, model)?;
    // 2. The candidates worth trying on these data.
    let kinds = kinds::for_dataset(ds, model, opts);
    // 3. Every candidate fitted, the simulation reference, every balance analysed (in parallel).
    let mut survey = survey::run(ds, model, &base, &kinds, opts);
    opts.cancel.check()?;
    // 4. Each candidate judged: statistical guards, practical checks, constraints, mimic checks
    //    (a friction against the measured friction curve of the sliding rows, whose shape is a
    //    signature of the torque balance).
    let labels = regimes::Labels::new(ds);
    let curve = timing::timed(
        || "measured friction curve".into(),
        || {
            friction_curve::measure(
                ds,
                &base.solved.mech,
                &base.solved.plant,
                labels.of(base.solved.mech.equation),
                th,
            )
        },
    );
    if let Some(sig) = curve.as_ref().and_then(|c| c.signature()) {
        if let Some(b) = survey
            .balances
            .iter_mut()
            .find(|b| b.equation == base.solved.mech.equation)
        {
            friction_curve::attach(b, sig, th);
        }
    }
    let mut ranking = judge::all(
        ds,
        &labels,
        &base.solved,
        base.noise_a,
        &base.floors,
        &survey,
        curve.as_ref(),
        opts,
    );
    opts.cancel.check()?;
    // 5. No torque named while the electrical balance is inconsistent.
    let electrical_broken = vetoes::electrical(&survey.balances, &mut ranking, th).is_some();
    // 6. Physical consistency across independent parts of the data.
    consistent::check(ds, model, &mut ranking, th);
    // 7. Best first.
    rank::sort(&mut ranking, th);
    Ok(Screened {
        base,
        kinds,
        survey,
        labels,
        ranking,
        electrical_broken,
        curve,
    })
}

/// Diagnoses on a prepared dataset (reuse it across the loop): the stages in order.
pub fn diagnose_dataset(
    ds: &Dataset,
    model: &Plant,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis, FitError> {
    let th = &opts.thresholds;
    opts.cancel.check()?;
    // 1-7. The base, every candidate fitted and judged, best first.
    let mut s = screen(ds, model, opts)?;
    // A plant that changes during a log: the base refitted on each side of a change point.
    let changes = timing::timed(
        || "change points".into(),
        || {
            let mech = &s.base.solved.mech;
            change::find(
                ds,
                &s.base.solved.plant,
                mech,
                s.base.floor_of(mech.equation),
                th,
            )
        },
    );
    // The pre-sliding regime: when nothing passes and the torque balance's residual lives in
    // the rows near reversals (a dynamic friction's bristles), the candidates are judged again
    // on the sliding rows, and that judgement is kept when a candidate passes there.
    // Only a friction shape is named this way (the regime hides the sliding curve, nothing
    // else), and not where a gear play shows: its crossings of the gap live at the same
    // reversals, and the joint search sizes it with what hides it.
    let mut sliding: Option<(Dataset, presliding::Extent)> = None;
    // A friction the sliding rows show that only the simulation refuses (the pre-sliding
    // regime's dynamics): reported, not named ([`sliding_lead`]).
    let mut lead: Option<sliding_lead::SlidingFit> = None;
    let passed = |s: &Screened| s.ranking.first().is_some_and(|c| c.significant);
    let friction_passed = |s: &Screened| {
        s.ranking.first().is_some_and(|c| {
            c.significant
                && c.joint_with.is_none()
                && c.effect.sim_role() == crate::effects::SimRole::DryFriction
        })
    };
    // A play the data refute (the motor never crosses its gap) shows nowhere but as a mimic.
    let play = model.effects.iter().any(|e| on_simulation(e.kind))
        || s.ranking.iter().any(|c| {
            on_simulation(c.effect)
                && c.oe_reduction_pct
                    .is_some_and(|d| d >= th.min_simulation_oe_drop_pct)
                && c.effect
                    .model()
                    .fit_hooks()
                    .is_none_or(|h| h.refuted(ds, &c.params, model).is_none())
        });
    if changes.is_empty() && !passed(&s) && !play && s.survey.balances.iter().any(|b| b.above_noise)
    {
        let mech = &s.base.solved.mech;
        if let Some(ext) = presliding::extent(ds, mech, s.base.floor_of(mech.equation), th) {
            if let Some(ds2) = ds.without_presliding(ext.counts) {
                opts.cancel.check()?;
                let s2 = timing::timed(
                    || "judged on the sliding rows".into(),
                    || screen(&ds2, model, opts),
                )?;
                if friction_passed(&s2) {
                    s = s2;
                    sliding = Some((ds2, ext));
                } else {
                    lead = sliding_lead::find(&ds2, &s2, ext, th);
                }
            }
        }
    }
    let ds = sliding.as_ref().map_or(ds, |(d, _)| d);
    // 8. Effects that hide each other: the joint search, when nothing passes alone (not on a
    // plant that changed: no model of the catalogue holds on both sides of the change).
    opts.cancel.check()?;
    let searched_first = !passed(&s);
    let outside = outside::why_not_searched(
        s.curve.as_ref(),
        &s.survey.balances,
        &outside::catalogue_orders(&ds.grid_context()),
        th,
    )
    .filter(|_| searched_first);
    // A dynamic friction carries the residual (the lead above): what is missing is not a set of
    // catalogue effects, whose simulation has no bristles either.
    if changes.is_empty() && lead.is_none() {
        search::run(
            ds,
            model,
            &s.base,
            &s.survey,
            &s.labels,
            s.electrical_broken,
            &mut s.ranking,
            opts,
            outside.is_some(),
        );
    }
    opts.cancel.check()?;
    // 9. Status, leads beyond the catalogue, the verdict.
    let Screened {
        base,
        kinds,
        survey,
        labels,
        ranking,
        curve,
        ..
    } = s;
    let mut d = conclude::run(
        ds, model, base, survey, &labels, &kinds, ranking, changes, opts,
    );
    d.friction_curve = curve;
    let hump = d
        .friction_curve
        .as_ref()
        .and_then(|c| friction_curve::hump_refusal(c, ds, &d.ranking, th));
    conclude::regimes(
        &mut d,
        outside.as_deref(),
        sliding.map(|(_, ext)| ext),
        lead,
        hump,
    );
    Ok(d)
}

pub struct Rung {
    /// The effect added at this rung (`None` for the starting model).
    pub added: Option<EffectKind>,
    /// The effect added together with `added` at this rung, when the two passed only together
    /// ([`Candidate::joint_with`]).
    pub added_with: Option<EffectKind>,
    /// Further effects added together at this rung, beyond `added` and `added_with`, when
    /// several passed only together (backward elimination from a joint fit).
    pub added_also: Vec<EffectKind>,
    /// The model after this rung (base and effects refitted on the fit blocks).
    pub plant: Plant,
    /// RMS residual per equation.
    pub equations: Vec<(Equation, f64)>,
    /// Held-out output-error cost [rad].
    pub oe_cost_rad: Option<f64>,
}

/// The loop: diagnose, add the winner (with the base refitted), diagnose again,
/// until nothing is significant or `max_steps` effects were added.
pub fn diagnose_loop(
    records: &[Record],
    model: &Plant,
    opts: &DiagnoseOptions,
    max_steps: usize,
) -> Result<(Vec<Rung>, Vec<Diagnosis>), FitError> {
    let ds = timing::timed(
        || "prepare the data set".into(),
        || Dataset::new(records, &model.params, &opts.fit),
    )?;
    let mut plant = *model;
    let mut ladder = Vec::new();
    let mut diags = Vec::new();
    let mut added: Option<EffectKind> = None;
    let mut added_with: Option<EffectKind> = None;
    let mut added_also: Vec<EffectKind> = Vec::new();
    for step in 0..=max_steps {
        opts.cancel.check()?;
        let d = timing::timed(
            || alloc::format!("whole diagnosis, step {step}"),
            || diagnose_dataset(&ds, &plant, opts),
        )?;
        ladder.push(Rung {
            added,
            added_with,
            added_also: core::mem::take(&mut added_also),
            plant: d.base.plant,
            equations: d.base.equations.iter().map(|e| (e.0, e.1)).collect(),
            oe_cost_rad: d.base.oe_cost_rad,
        });
        let next = d.winner().map(|w| (w.effect, w.joint_with, w.plant));
        // The rest of a set found together: the significant candidates after the winner that
        // carry its joint model.
        let also: Vec<EffectKind> = d
            .winner()
            .map(|w| {
                d.ranking
                    .iter()
                    .skip(1)
                    .take_while(|c| c.significant && c.joint_with.is_some() && c.plant == w.plant)
                    .map(|c| c.effect)
                    .filter(|k| Some(*k) != w.joint_with)
                    .collect()
            })
            .unwrap_or_default();
        diags.push(d);
        match next {
            Some((kind, with, cand_plant)) if step < max_steps => {
                // Keep the candidate's nonlinear parameters; the next diagnosis refits the linear
                // ones. A pair found together ([`joint`]) is added together.
                plant = cand_plant;
                added = Some(kind);
                added_with = with;
                added_also = also;
            }
            _ => break,
        }
    }
    Ok((ladder, diags))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::tests::{open_loop_log, truth, without_coulomb};

    fn print_ranking(d: &Diagnosis) {
        for c in &d.ranking {
            std::eprintln!(
                "{} sig={} red={:.1}% oe={:?} bic={:.1}\n   {}",
                c.effect,
                c.significant,
                c.error_reduction_pct,
                c.oe_reduction_pct,
                c.bic_gain,
                c.evidence
            );
        }
        std::eprintln!("{}", d.verdict);
    }

    /// A log without the input voltage (current and motion only): the torque balance alone
    /// names the missing Coulomb friction; drive-side effects and effects judged on the
    /// simulation are not tried.
    #[test]
    fn logs_without_voltage_are_judged_on_the_torque_balance() {
        let truth = truth();
        let mut log = open_loop_log(&truth, 12.0, 5, true);
        log.u_v = None;
        let lacking = without_coulomb();
        let d = diagnose(&[log.clone()], &lacking, &DiagnoseOptions::default()).unwrap();
        print_ranking(&d);
        let w = d.winner().expect("a significant candidate");
        assert_eq!(w.effect, EffectKind::Coulomb);
        assert!(w.oe_reduction_pct.is_none());
        let tau = w.params.iter().find(|p| p.key == "tau_sf").unwrap().value;
        assert!((tau / 0.01 - 1.0).abs() < 0.15, "tau_sf {tau}");
        assert!(d
            .ranking
            .iter()
            .all(|c| c.effect.is_mechanical() && !on_simulation(c.effect)));
        assert!(d.verdict.contains("No log records the input voltage u"));
        // Nothing left on the complete model.
        let d = diagnose(&[log.clone()], &truth, &DiagnoseOptions::default()).unwrap();
        assert!(d.winner().is_none(), "false positive: {}", d.verdict);
        // Without u and without the current there is nothing to fit.
        log.i_a_a = None;
        let e = diagnose(&[log], &lacking, &DiagnoseOptions::default()).unwrap_err();
        assert!(
            e.to_string()
                .contains("neither the input voltage u nor the armature current"),
            "{e}"
        );
    }

    #[test]
    fn names_missing_coulomb_and_nothing_on_a_complete_model() {
        let truth = truth();
        let logs = [open_loop_log(&truth, 12.0, 5, true)];
        // Model without Coulomb friction.
        let lacking = without_coulomb();
        let d = diagnose(&logs, &lacking, &DiagnoseOptions::default()).unwrap();
        print_ranking(&d);
        let w = d.winner().expect("a significant candidate");
        assert_eq!(w.effect, EffectKind::Coulomb);
        let tau = w.params.iter().find(|p| p.key == "tau_sf").unwrap().value;
        assert!((tau / 0.01 - 1.0).abs() < 0.15, "tau_sf {tau}");
        // The complete model.
        let d = diagnose(&logs, &truth, &DiagnoseOptions::default()).unwrap();
        print_ranking(&d);
        assert!(d.winner().is_none(), "false positive: {}", d.verdict);
    }
}
