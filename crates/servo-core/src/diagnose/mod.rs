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

mod backward;
pub mod bars;
pub mod cancel;
pub mod checks;
pub mod evidence;
pub mod joint;
pub mod neighbours;
pub mod regimes;
pub mod resonance;
pub mod structure;
pub mod timing;
pub mod user_effects;

pub use crate::verdict::Candidate;
pub use structure::{BalanceKind, BalanceReport, Signature, Thresholds};

pub(crate) use crate::par::{join, par_map};

use crate::effects::{EffectKind, SimRole};
use crate::fit::model::{EqSolution, Equation};
use crate::fit::oe::{self, Part};
use crate::fit::{self, Dataset, EffectToFit, FitError, FitOptions, ParamEstimate, Solved};
use crate::math;
use crate::plant::Plant;
use crate::record::Record;
use alloc::string::String;
use alloc::vec::Vec;

/// Options of the diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseOptions {
    /// Fit options (the held-out split is set here: every `holdout_every`-th block).
    pub fit: FitOptions,
    /// Minimum BIC gain of the effect's own equation.
    pub min_bic_gain: f64,
    /// Minimum relative drop of the effect's own equation residual sum of squares on held-out
    /// data (0.02 = 2 %).
    pub min_eq_drop: f64,
    /// Minimum relative drop of the held-out output-error cost (0.01 = 1 %).
    pub min_oe_drop: f64,
    /// Minimum held-out output-error drop for an effect judged on the simulation alone (a gear
    /// play, [`crate::effects::FitHooks::judged_on_simulation`]) (0.08 = 8 %).
    pub min_simulation_oe_drop: f64,
    /// Kinds to try (catalogue or run-time); empty: every catalogue kind the model lacks, plus
    /// `extra_candidates`.
    pub candidates: Vec<EffectKind>,
    /// Run-time effects (e.g. user-defined ones) tried besides the catalogue when `candidates`
    /// is empty.
    pub extra_candidates: Vec<EffectKind>,
    /// Run candidates on two threads (std builds).
    pub parallel: bool,
    /// Practical-significance and "unexplained" thresholds.
    pub thresholds: Thresholds,
    /// When no single candidate passes and a balance is above its noise floor, how many of the
    /// best candidates (by held-out simulation drop) to fit jointly with the effects already
    /// named, then eliminate backward ([`backward`]; failing that, to try in pairs, [`joint`]);
    /// 0: none (2 at least otherwise). Default 3. The candidates acting where a gear play acts
    /// (sharing a regime with it) and those with clear evidence in their own balance join them.
    /// On a breakaway friction, a gear play and a delay hidden together (28 s of open- and
    /// closed-loop logs) it names all three with their main parameters within 25 % on 5 of 7
    /// seeds (on the other two the breakaway comes out 26 % and 38 % high); it adds 5-30 s to
    /// a diagnosis that ends "unexplained" on such logs, and 0.5-2 minutes when it finds a set.
    pub joint_candidates: usize,
    /// Optional cancel hook ([`cancel::Cancel`]): read between stages and candidates; once set,
    /// the diagnosis returns [`FitError::Cancelled`]. Default: none (never stops early).
    pub cancel: cancel::Cancel,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            fit: FitOptions {
                holdout_every: 3,
                ..FitOptions::default()
            },
            min_bic_gain: 10.0,
            min_eq_drop: 0.02,
            min_oe_drop: 0.01,
            min_simulation_oe_drop: 0.08,
            candidates: Vec::new(),
            extra_candidates: Vec::new(),
            parallel: true,
            thresholds: Thresholds::default(),
            joint_candidates: 3,
            cancel: cancel::Cancel::default(),
        }
    }
}

/// What the diagnosis concludes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Nothing material is left in any balance.
    Complete,
    /// A catalogue effect passes every check: it is `ranking[0]`.
    Missing,
    /// Structured error above the noise floor that no catalogue effect explains.
    Unexplained,
}

impl Status {
    pub const fn name(self) -> &'static str {
        match self {
            Status::Complete => "complete",
            Status::Missing => "missing",
            Status::Unexplained => "unexplained",
        }
    }
}

/// Residual summary of the model being diagnosed.
#[derive(Debug, Clone, PartialEq)]
pub struct BaseSummary {
    /// The model with its base parameters refitted (fit blocks).
    pub plant: Plant,
    /// Per equation: (equation, rms of the residual [unit], share of squared residual per regime).
    pub equations: Vec<(Equation, f64, [f64; 5], [f64; 5])>,
    /// Held-out output-error cost (RMS motor-angle prediction error [rad]) of the simulation
    /// reference: this model with J_eq and tau_sf tuned on the simulation (fit blocks).
    pub oe_cost_rad: Option<f64>,
    /// Current-noise floor [A] estimated from the logs (current logged).
    pub current_noise_a: Option<f64>,
}

/// The outcome of a diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnosis {
    /// Candidates, best first.
    pub ranking: Vec<Candidate>,
    /// One paragraph for the user.
    pub verdict: String,
    pub base: BaseSummary,
    /// complete / missing / unexplained.
    pub status: Status,
    /// Every balance's residual of the base model: noise floor, ratio and signatures.
    pub balances: Vec<BalanceReport>,
    /// The balances left unexplained (status `Unexplained`; empty otherwise).
    pub unexplained: Vec<BalanceReport>,
    /// Leads beyond the catalogue (status `Unexplained`): mechanisms outside it, fitted on the
    /// simulation, that predict the held-out motion materially better ([`neighbours`]); each is
    /// also a signature of its balance.
    pub neighbours: Vec<checks::Neighbour>,
}

impl Diagnosis {
    /// The best significant candidate.
    pub fn winner(&self) -> Option<&Candidate> {
        self.ranking.first().filter(|c| c.significant)
    }
}

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
    let ds = Dataset::new(records, &model.params, &opts.fit)?;
    diagnose_dataset(&ds, model, opts)
}

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

/// Diagnoses on a prepared dataset (reuse it across the loop).
pub fn diagnose_dataset(
    ds: &Dataset,
    model: &Plant,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis, FitError> {
    opts.cancel.check()?;
    let (base, base_j_unphysical) = timing::timed(|| "base fit".into(), || base_fit(ds, model))?;
    let noise = current_noise(ds);
    let th = opts.thresholds;
    let sols: Vec<&EqSolution> = core::iter::once(&base.mech)
        .chain(base.elec.as_ref())
        .collect();
    // Every balance of the base model: its noise floor (and, below, what structure is left).
    let floors: Vec<(Equation, f64)> = sols
        .iter()
        .map(|sol| {
            (
                sol.equation,
                structure::noise_floor(ds, sol.equation, &base.plant, noise),
            )
        })
        .collect();
    let floor_of = |eq: Equation| {
        floors
            .iter()
            .find(|(e, _)| *e == eq)
            .map_or(0.0, |(_, f)| *f)
    };
    let mut kinds = candidate_kinds(model, opts);
    if !ds.has_input {
        // Without a logged input the data say nothing of the drive (input effects), and nothing
        // can be simulated (effects judged on the simulation are left out).
        kinds.retain(|k| k.is_mechanical() && !on_simulation(*k));
    }
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
    let mut rigid = base.plant;
    let mut balances: Vec<BalanceReport> = Vec::new();
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
            || ds.refine_rigid_on_simulation(&base.plant),
        )),
        Task::Balance(i) => Done::Balance(
            i,
            timing::timed(
                || alloc::format!("analyse the {}", sols[i].equation.name()),
                || structure::analyse(ds, sols[i], floor_of(sols[i].equation), &th, ds.gear_ratio),
            ),
        ),
    }) {
        match done {
            Done::Fit(k, r) => fits.push((k, *r)),
            Done::Reference(p) => rigid = p,
            Done::Balance(i, b) => analysed.push((i, b)),
        }
    }
    opts.cancel.check()?;
    analysed.sort_by_key(|(i, _)| *i);
    balances.extend(analysed.into_iter().map(|(_, b)| b));
    // Candidates in catalogue order (the ranking's ties keep it).
    fits.sort_by_key(|(k, _)| kinds.iter().position(|x| x == k));
    let reference = Reference {
        oe_holdout: oe::prediction_cost(ds, &rigid, Part::Holdout),
        plant: rigid,
    };
    let base_oe = reference.oe_holdout;
    // The electrical balance holds no mechanical effect: when it is itself unexplained, the
    // current or the speed measurement is inconsistent and the torque balance (which uses
    // both) cannot be trusted to name a torque.
    let electrical_broken = balances.iter().find(|b| {
        b.equation == Equation::Electrical
            && b.above_noise
            && b.ratio_to_noise >= th.electrical_block_ratio
    });
    let labels = regimes::Labels::new(ds);
    let judged = par_map(&fits, opts.parallel, |(kind, res)| {
        let kind = *kind;
        let solved = match res {
            Ok(s) => s,
            Err(e) => return failed(&base, kind, e),
        };
        let eq = fit::model::Config::equation_of(kind, ds.has_current);
        let bal = balances.iter().find(|b| b.equation == eq);
        let mut c = judge(
            ds,
            &labels,
            &base,
            &reference,
            noise,
            floor_of(eq),
            bal.map_or(0.0, |b| b.rms),
            kind,
            solved,
            opts,
            false,
        );
        // A mimic leaves the structure it was meant to explain: the shape that carried the
        // balance's residual is still there, above the noise floor, after adding it.
        if c.significant && !on_simulation(kind) && kind != EffectKind::Coulomb {
            if let (Some(b), Some(sol)) = (bal, solved.equation(eq)) {
                if let Some(k) = structure_check(ds, b, sol, floor_of(eq), &th) {
                    let still = !k.passed;
                    c.checks.push(k);
                    if still {
                        c.significant = false;
                        c.experiment = Some(String::from(evidence::experiment(c.effect)));
                        evidence::append_failed(&mut c);
                    }
                }
            }
        }
        if c.significant {
            let base_sol = sols.iter().copied().find(|s| s.equation == eq);
            if let Some(k) = bal.and_then(|b| resonance_check(ds, b, base_sol, solved)) {
                c.significant = k.passed;
                c.checks.push(k);
                if !c.significant {
                    c.experiment = Some(String::from(evidence::experiment(c.effect)));
                    evidence::append_failed(&mut c);
                }
            }
        }
        c
    });
    opts.cancel.check()?;
    let mut ranking = judged;
    // A drive-side effect that explains most of the electrical residual (an input delay, a dead
    // zone) accounts for it: the measurements are then not suspect.
    let drive_explains = ranking
        .iter()
        .any(|c| c.equation == Equation::Electrical && c.error_reduction_pct >= 50.0);
    let electrical_broken = electrical_broken.filter(|_| !drive_explains);
    for c in ranking.iter_mut() {
        if let (true, true, Some(e)) = (
            c.significant,
            c.effect.is_mechanical() && !on_simulation(c.effect),
            electrical_broken,
        ) {
            c.checks.push(checks::Check {
                name: "electrical balance consistent",
                passed: false,
                detail: alloc::format!(
                    "the electrical balance, which holds no mechanical effect, is itself {:.1} times its noise floor and no drive-side effect explains it: the current or speed measurement is inconsistent, so no torque can be named from the torque balance",
                    e.ratio_to_noise
                ),
            });
            c.significant = false;
            c.experiment = Some(String::from(evidence::experiment(c.effect)));
            evidence::append_failed(c);
        }
    }
    // Physical consistency of the candidates that pass every other check: their parameters
    // must agree across independent parts of the data.
    for c in ranking.iter_mut().filter(|c| c.significant) {
        let cons = timing::timed(
            || alloc::format!("consistency of {}", c.effect),
            || checks::consistency(ds, model, c, &th),
        );
        if cons.iter().any(|k| !k.passed) {
            c.significant = false;
        }
        c.checks.extend(cons);
        if c.significant {
            let note = c
                .effect
                .model()
                .fit_hooks()
                .and_then(|h| h.candidate_note(ds, model, c));
            if let Some(note) = note {
                c.evidence.push_str(&note);
            }
            let cond = c.effect.model().fit_hooks().and_then(|h| {
                timing::timed(
                    || alloc::format!("conditional of {}", c.effect),
                    || h.conditional(ds, model, c),
                )
            });
            if let Some((cond, note)) = cond {
                c.evidence.push_str(&note);
                c.conditional = Some(cond);
            }
        }
        if !c.significant {
            c.experiment = Some(String::from(evidence::experiment(c.effect)));
            evidence::append_failed(c);
        }
    }
    ranking.sort_by(|a, b| {
        // Significant first; then by the held-out simulation error reduction, the one figure
        // comparable across equations, plus a tenth of the equation residual reduction: a
        // near tie in simulation (Coulomb friction and an input dead band both brake a
        // voltage-driven log, 74.2 % vs 74.4 % on the real jacopisky steps at 250 Hz) goes to
        // the effect that also explains its equation better (56.9 % vs 48.0 %).
        let score = |c: &Candidate| {
            c.oe_reduction_pct.unwrap_or(f64::NEG_INFINITY) + 0.1 * c.error_reduction_pct
        };
        b.significant
            .cmp(&a.significant)
            .then(score(b).total_cmp(&score(a)))
            .then(b.error_reduction_pct.total_cmp(&a.error_reduction_pct))
    });
    // The two best significant candidates explain the data alike (within 0.1 point of the
    // ranking's score: at N = 1 a torque periodic once per motor revolution is one periodic in
    // the load angle): the one with fewer searched parameters is named.
    if let [a, b, ..] = ranking.as_slice() {
        let score = |c: &Candidate| {
            c.oe_reduction_pct.unwrap_or(f64::NEG_INFINITY) + 0.1 * c.error_reduction_pct
        };
        if a.significant
            && b.significant
            && (score(a) - score(b)).abs() < 0.1
            && nonlinear_searched(b.effect) < nonlinear_searched(a.effect)
        {
            ranking.swap(0, 1);
        }
    }
    // No single effect passes but a balance is still above its noise floor: two missing effects
    // may hide each other; judge the best candidates in pairs ([`joint`]).
    if opts.joint_candidates >= 2
        && !ranking.first().is_some_and(|c| c.significant)
        && balances.iter().any(|b| b.above_noise)
    {
        let cx = joint::Context {
            ds,
            model,
            noise_a: noise,
            floors: &floors,
            electrical_broken: electrical_broken.is_some(),
            reference: &reference,
            labels: &labels,
            opts,
        };
        opts.cancel.check()?;
        // Backward elimination from a joint simulation fit of the effects already named and
        // the best candidates ([`backward`]); failing that, the pairs ([`joint`]).
        let found = timing::timed(
            || "backward elimination".into(),
            || backward::search(&cx, &fits, &ranking),
        )
        .or_else(|| joint::best_pair(&cx, &fits, &ranking).map(Vec::from));
        if let Some(set) = found {
            ranking.retain(|c| !set.iter().any(|m| m.effect == c.effect));
            ranking.splice(0..0, set);
        }
    }
    opts.cancel.check()?;
    let mut equations = Vec::new();
    for sol in core::iter::once(&base.mech).chain(base.elec.as_ref()) {
        let reg = labels.of(sol.equation);
        let sq: Vec<f64> = sol.resid.iter().map(|r| r * r).collect();
        equations.push((
            sol.equation,
            sol.rms(),
            regimes::shares(reg, &sq),
            regimes::occupancy(reg),
        ));
    }
    let summary = BaseSummary {
        plant: base.plant,
        equations,
        oe_cost_rad: base_oe,
        current_noise_a: noise,
    };
    let winner = ranking.first().filter(|c| c.significant).is_some();
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
                || neighbours::find(ds, &kinds, &[model, &reference.plant], c0, opts),
            );
            neighbours::attach(&mut unexplained, &found);
            neighbours::attach(&mut balances, &found);
            leads = found.into_iter().map(|(n, _)| n).collect();
        }
    }
    let mut verdict = evidence::verdict(status, &ranking, &unexplained, &th);
    if let Some(j) = base_j_unphysical {
        verdict.push_str(&alloc::format!(
            " The bare base model was unphysical on these logs (the fitted inertia J_eq = {} kg m^2 is not positive: a large torque it lacks, such as an arm's gravity, was absorbed into it); each candidate was fitted with the base refitted beside it.",
            math::Num(j)
        ));
    }
    if !ds.has_input {
        verdict.push_str(" No log records the input voltage u: judged on the torque balance alone (information criterion and held-out residual), without a simulation check; input effects and effects judged on the simulation were not tried.");
    }
    Ok(Diagnosis {
        ranking,
        verdict,
        base: summary,
        status,
        balances,
        unexplained,
        neighbours: leads,
    })
}

/// A mimic leaves the structure it was meant to explain: the shape that carried the balance's
/// residual (`before`) is still there, above the noise floor `floor`, in the residual `after` the
/// candidate was added. `None` when the balance was not above its noise floor or had no shape.
pub(crate) fn structure_check(
    ds: &Dataset,
    before: &BalanceReport,
    after: &EqSolution,
    floor: f64,
    th: &Thresholds,
) -> Option<checks::Check> {
    let b = before;
    let eq = after.equation;
    let top = b.signatures.first().filter(|_| b.above_noise)?;
    let after = structure::analyse(ds, after, floor, th, ds.gear_ratio);
    let left = after.signatures.iter().find(|s| s.kind == top.kind);
    // Still there: above the noise floor and at least half its size before (a true effect
    // removes most of the shape it fits, whatever another missing effect leaves of it; a mimic
    // bends to it and leaves most of it).
    let still = after.above_noise
        && left.is_some_and(|s| {
            s.explained_rms >= th.min_noise_ratio * floor
                && s.explained_rms >= 0.5 * top.explained_rms
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
/// too weak to refuse a candidate ([`resonance::REFUSE_PROMINENCE`]).
fn resonance_check(
    ds: &Dataset,
    b: &BalanceReport,
    base: Option<&EqSolution>,
    cand: &Solved,
) -> Option<checks::Check> {
    let res = b
        .resonance
        .as_ref()
        .filter(|r| b.above_noise && r.prominence >= resonance::REFUSE_PROMINENCE)?;
    let sol = cand.equation(b.equation)?;
    let contact = cand
        .cfg
        .slots
        .iter()
        .any(|s| s.kind.sim_role() == crate::effects::SimRole::Contact);
    let kept = structure::resonance_kept(ds, base?, sol, contact, res);
    Some(checks::Check {
        name: "explains the resonance",
        passed: kept < 0.5,
        detail: alloc::format!(
            "the {} residual rings near {:.1} Hz ({}, {:.0} % of it); with this effect {:.0} % of that band's power is still there on the rows both models weigh (needs under 50 %){}",
            b.equation.name(),
            res.freq_hz,
            resonance::damping_phrase(res),
            100.0 * res.share,
            100.0 * kept,
            if kept < 0.5 {
                ""
            } else {
                ": a resonance (e.g. a compliant shaft or coupling) that this effect does not explain"
            }
        ),
    })
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

/// Order in which candidates are started: the costliest (most simulations) first
/// ([`crate::effects::EffectModel::schedule_rank`]).
fn cost_rank(kind: EffectKind) -> usize {
    usize::from(kind.model().schedule_rank())
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

/// Lag-1 autocorrelation of a residual (rows in order).
fn lag1(r: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for w in r.windows(2) {
        num += w[0] * w[1];
    }
    for v in r {
        den += v * v;
    }
    if den > 0.0 {
        (num / den).clamp(0.0, 0.99)
    } else {
        0.0
    }
}

/// The information criterion of `kind` judged on the simulation alone (a gear play): the
/// simulation cost `x` [rad] without it against `y` with it over `n` independent terms, each
/// nonlinear parameter searched costing three (as in the equation's criterion).
/// `-inf` when `y` is not positive.
pub(crate) fn simulation_bic(x: f64, y: f64, n: f64, kind: EffectKind) -> f64 {
    if y <= 0.0 {
        return f64::NEG_INFINITY;
    }
    let q = nonlinear_searched(kind) as f64;
    n * math::ln(x * x / (y * y)) - 3.0 * q * math::ln(n)
}

fn nonlinear_searched(kind: EffectKind) -> usize {
    kind.params()
        .iter()
        .filter(|p| p.nonlinear && kind.model().fittable(p.key))
        .count()
}

/// The base model of a diagnosis: `model` with its linear parameters (base and effects)
/// re-solved in their balances, its nonlinear ones kept.
///
/// When `model` holds an effect judged on the simulation (a gear play), those balances leave
/// out the rows around torque reversals, where the motor crosses the gap and the load angle
/// says nothing of it, and they cannot see the play itself: the values `model` was given, tuned
/// on the simulation with the play (by its refinement or a joint fit, [`backward`]), are then
/// kept when they predict the motion of the fit blocks better (on the cost the joint fit is
/// tuned on, [`backward::motion_costs`]) than the re-solved ones. A breakaway friction found
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
        if let [Some(a), Some(b)] = backward::motion_costs(ds, [&s.plant, model]) {
            if b < a {
                s.plant = *model;
            }
        }
    }
    Ok((s, None))
}

/// Is `kind` judged on the simulation alone (no regressors; a gear play)?
pub(crate) fn on_simulation(kind: EffectKind) -> bool {
    kind.model()
        .fit_hooks()
        .is_some_and(|h| h.judged_on_simulation())
}

/// The simulation reference of a diagnosis (see [`diagnose_dataset`]).
struct Reference {
    /// The model without the candidates, J_eq and tau_sf tuned on the simulation.
    plant: Plant,
    /// Its held-out output-error cost [rad].
    oe_holdout: Option<f64>,
}

/// Judges candidate `kind` fitted as `cand` against `base` (its balance: `balance_rms` over the
/// noise floor `balance_floor`) and the simulation `reference`: the information criterion, the
/// held-out residual and simulation drops, then the practical-significance checks and the
/// effect's constraints. `given_others`: `kind` is a member of a joint model judged given the
/// other members (its share of the structured error may be measured in the motion).
#[allow(clippy::too_many_arguments)]
fn judge(
    ds: &Dataset,
    labels: &regimes::Labels,
    base: &Solved,
    reference: &Reference,
    noise_a: Option<f64>,
    balance_floor: f64,
    balance_rms: f64,
    kind: EffectKind,
    cand: &Solved,
    opts: &DiagnoseOptions,
    given_others: bool,
) -> Candidate {
    let eq = fit::model::Config::equation_of(kind, ds.has_current);
    let params: Vec<ParamEstimate> = ds
        .estimates(cand)
        .into_iter()
        .filter(|p| p.effect == Some(kind) || (kind == EffectKind::Coulomb && p.key == "tau_sf"))
        .collect();
    let sim_only = on_simulation(kind);
    let base_oe = reference.oe_holdout;
    let cand_oe = oe::prediction_cost(ds, &cand.plant, Part::Holdout);
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
    let rho = if c.rss_fit < 0.5 * b.rss_fit {
        lag1(&c.resid)
    } else {
        lag1(&b.resid)
    };
    let n_eff = (b.n_fit as f64 * (1.0 - rho) / (1.0 + rho)).max(1.0);
    let q_lin = c.p.saturating_sub(b.p) as f64;
    let q_nl = nonlinear_searched(kind) as f64;
    let bic_gain = if sim_only {
        // No equation-error regressors (a gear play): judged on the simulation cost.
        let fit_b = oe::prediction_cost(ds, &reference.plant, Part::Fit);
        let fit_c = oe::prediction_cost(ds, &cand.plant, Part::Fit);
        match (fit_b, fit_c) {
            (Some(x), Some(y)) => simulation_bic(x, y, n_eff, kind),
            _ => f64::NEG_INFINITY,
        }
    } else {
        n_eff * math::ln(b.rss_fit / c.rss_fit.max(1e-300)) - (q_lin + 3.0 * q_nl) * math::ln(n_eff)
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
    let min_drop = if sim_only {
        opts.min_simulation_oe_drop
    } else {
        opts.min_eq_drop
    };
    // Without a logged input nothing can be simulated: the two other guards decide.
    let oe_ok = match oe_drop {
        Some(d) => d >= opts.min_oe_drop,
        None => !ds.has_input,
    };
    let statistically = bic_gain > opts.min_bic_gain && eq_drop >= min_drop && oe_ok;
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
    let th = &opts.thresholds;
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
                name: "above the noise floor",
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
                name: "material share of the structured error",
                passed: structured_share.max(motion_share) >= th.min_structured_share,
                detail: alloc::format!(
                    "explains {:.0} % of the structured (above-noise) error of the {}{in_motion} (needs {:.0} %)",
                    100.0 * structured_share,
                    eq.name(),
                    100.0 * th.min_structured_share
                ),
            });
        }
        found.extend(checks::constraints(
            ds,
            kind,
            &params,
            &cand.plant,
            &base.plant,
        ));
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

fn failed(base: &Solved, kind: EffectKind, e: &FitError) -> Candidate {
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

/// One rung of the error ladder.
#[derive(Debug, Clone, PartialEq)]
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
        let d = diagnose_dataset(&ds, &plant, opts)?;
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
    use crate::fit::tests::{open_loop_log, truth};
    use crate::params::PlantParams;

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
        let lacking = Plant::from_params(PlantParams {
            j_eq: Some(7.0e-7),
            b_eq: Some(1.0e-6),
            ..PlantParams::TABLE2
        })
        .unwrap();
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
        let lacking = Plant::from_params(PlantParams {
            j_eq: Some(7.0e-7),
            b_eq: Some(1.0e-6),
            ..PlantParams::TABLE2
        })
        .unwrap();
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
