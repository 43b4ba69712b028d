//! What a diagnosis returns: its status, the base model's residual summary and the ranking.

use super::checks;
use super::structure::BalanceReport;
use crate::effects::EffectKind;
use crate::fit::model::Equation;
use crate::plant::Plant;
use crate::verdict::Candidate;
use alloc::string::String;
use alloc::vec::Vec;

/// What the diagnosis concludes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Nothing material is left in any balance.
    Complete,
    /// A catalogue effect passes every check: it is `ranking[0]`; or, with none, a user-defined
    /// effect or a discovered term passes every guard ([`super::user_effects::conclude`]).
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

/// An effect the logs show but cannot resolve: it passes the statistical guards (information
/// criterion, held-out residual and simulation drops), yet what it explains in its balance is
/// below that balance's noise floor, so its size cannot be told from the sensor noise.
#[derive(Debug, Clone, PartialEq)]
pub struct Unresolvable {
    pub effect: EffectKind,
    /// The balance it was judged in.
    pub equation: Equation,
    /// Its main fitted parameter (key, unit, value), when it has one.
    pub size: Option<(&'static str, &'static str, f64)>,
    /// RMS of what it explains in its balance [unit of the balance].
    pub explained_rms: f64,
    /// The balance's noise floor (RMS) [unit of the balance].
    pub floor: f64,
    /// The experiment that would resolve it.
    pub experiment: &'static str,
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
    /// Effects below their balance's noise floor: "not resolvable with these logs", whatever
    /// the status ([`Unresolvable`]).
    pub unresolvable: Vec<Unresolvable>,
    /// The friction curve measured on the sliding rows of the torque (or u-driven) balance, with
    /// the shape it shows beyond the base model ([`super::friction_curve`]).
    pub friction_curve: Option<super::friction_curve::FrictionCurve>,
    /// Changes of the plant during a log ([`super::change`]): each is also the first signature
    /// of its balance, and makes the status "unexplained" when no candidate passes.
    pub changes: Vec<super::change::Change>,
    /// The pre-sliding regime left out of the torque balance, when the candidates were judged
    /// on the sliding rows ([`super::presliding`]).
    pub presliding: Option<super::presliding::Extent>,
    /// A friction the sliding rows show that only the held-out simulation refuses (status
    /// `Unexplained`: a dynamic friction, [`super::sliding_lead`]).
    pub sliding_fit: Option<super::sliding_lead::SlidingFit>,
}

impl Diagnosis {
    /// The best significant candidate.
    pub fn winner(&self) -> Option<&Candidate> {
        self.ranking.first().filter(|c| c.significant)
    }
}
