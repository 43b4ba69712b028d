//! What a diagnosis says of one candidate effect, as data: the candidate fitted and judged, its
//! checks, what its main parameter is conditional on, and a mechanism outside the catalogue that
//! an effect's machinery can size (a neighbour). Here, below the diagnosis, because the effects'
//! fit hooks ([`crate::effects::FitHooks`]) produce and read them: the effects and the fit never
//! reach into `diagnose`. The judging itself stays in `diagnose`.

use crate::effects::EffectKind;
use crate::fit::model::Equation;
use crate::fit::{Dataset, ParamEstimate};
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

/// One candidate effect, fitted and judged.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub effect: EffectKind,
    /// Passed every guard (information criterion, held-out equation drop, held-out output error).
    pub significant: bool,
    /// Whether its fitted torque (or voltage) is above the sensor-noise floor.
    pub resolvable: bool,
    /// RMS reduction of its own equation's residual on held-out data [%].
    pub error_reduction_pct: f64,
    /// Reduction of the held-out output-error (simulation) cost [%], when computable.
    pub oe_reduction_pct: Option<f64>,
    /// BIC gain of its equation (search-corrected, effective sample size).
    pub bic_gain: f64,
    /// The equation it was judged in.
    pub equation: Equation,
    /// Its fitted parameters (catalogue keys and units).
    pub params: Vec<ParamEstimate>,
    /// The model with the effect added and the base refitted (on the fit blocks).
    pub plant: Plant,
    /// Plain-language evidence.
    pub evidence: String,
    /// For non-significant candidates: the experiment that would resolve it.
    pub experiment: Option<String>,
    /// RMS of what it explains in its equation over the balance's noise floor.
    pub noise_ratio: f64,
    /// Share of the balance's structured error (squared residual above the noise floor) it
    /// explains.
    pub structured_share: f64,
    /// Practical-significance and physical-consistency checks, in the order applied.
    pub checks: Vec<Check>,
    /// What the main parameter is conditional on (significant candidates whose effect reports
    /// one: a gear play against the contact stiffness).
    pub conditional: Option<Conditional>,
    /// The other member when this candidate passed only together with it ([`crate::diagnose::joint`]): judged
    /// against the model holding that one alone, and added with it.
    pub joint_with: Option<EffectKind>,
}

impl Candidate {
    /// The first check that failed.
    pub fn failed_check(&self) -> Option<&Check> {
        self.checks.iter().find(|c| !c.passed)
    }
}

/// Where a residual lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BalanceKind {
    /// The torque balance (or the u-driven torque balance without current): a missing torque.
    Torque,
    /// The electrical balance: the drive, the winding or the current sensor.
    Electrical,
    /// The measured angle itself (the error follows the angle sensor, not a torque or voltage).
    Sensor,
}

impl BalanceKind {
    pub const fn name(self) -> &'static str {
        match self {
            BalanceKind::Torque => "torque",
            BalanceKind::Electrical => "electrical",
            BalanceKind::Sensor => "sensor",
        }
    }
}

/// One check and its outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// Short name, e.g. `"tau_s > tau_sf"`, `"same in both halves"`.
    pub name: &'static str,
    pub passed: bool,
    /// The figures behind the outcome.
    pub detail: String,
}

/// A parameter that the data size only together with another one they do not pin down (a
/// gear play against the contact stiffness): the parameter refitted at each value of the other
/// over a plausible range, judged on the held-out simulation error.
#[derive(Debug, Clone, PartialEq)]
pub struct Conditional {
    /// The parameter reported (e.g. `"gap"`) and its unit.
    pub key: &'static str,
    pub unit: &'static str,
    /// The parameter it is conditional on (e.g. `"stiffness"`) and its unit.
    pub on: &'static str,
    pub on_unit: &'static str,
    /// The value of `on` the candidate was sized with (a default unless estimated).
    pub assumed: f64,
    /// `Some((value of on, value of key))` when one value of `on` predicts the held-out motion
    /// clearly best: then `on` is estimated with `key`; `None`: `key` is conditional on the
    /// assumed value.
    pub estimated: Option<(f64, f64)>,
    /// Per value of `on`, ascending: (value of on, refitted value of key, held-out simulation
    /// error [rad]).
    pub rows: Vec<(f64, f64, f64)>,
}

/// A mechanism outside the catalogue that an effect's own simulation machinery can size (a gear
/// play's contact without its gap: a linear shaft or coupling), fitted from the simulation
/// reference ([`crate::effects::FitHooks::neighbour`]). The diagnosis reports it among the
/// signatures of its balance when no catalogue effect passes and it predicts the held-out motion
/// materially better than the reference: a lead on the missing term, not a named effect.
#[derive(Debug, Clone, PartialEq)]
pub struct Neighbour {
    /// Family, used as the signature's kind (e.g. `"compliance"`).
    pub kind: &'static str,
    /// The balance whose error it would explain.
    pub balance: BalanceKind,
    /// What it is, with its fitted parameters and their units.
    pub description: String,
    /// Its fitted parameters: (key, unit, value), e.g. `("stiffness", "N m/rad", 2.9)`.
    pub params: Vec<(&'static str, &'static str, f64)>,
    /// Held-out simulation error (RMS load angle) with it [rad]; the diagnosis's reference has
    /// `oe_cost_rad` of the diagnosis's base summary.
    pub heldout_oe_rad: f64,
    /// Simulation error on the fit blocks with it [rad]: chooses among fits from different
    /// starting models.
    pub fit_oe_rad: f64,
    /// The experiment that would confirm it.
    pub experiment: String,
}

impl Conditional {
    /// Smallest and largest value of `key` over the rows.
    pub fn range(&self) -> (f64, f64) {
        self.rows
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
                (a.min(r.1), b.max(r.1))
            })
    }
}

/// The value of `key` among `params`.
pub fn get(params: &[ParamEstimate], key: &str) -> Option<f64> {
    params.iter().find(|p| p.key == key).map(|p| p.value)
}

/// Fewest levels a log's commanded u must span on its grid for the grid's spacing to be the
/// command's resolution [1]: a PRBS between +-5 V (two levels) or a few voltage steps sit on a
/// "grid" as wide as their steps, which says nothing of the DAC or PWM count behind them (a
/// 0.30 V dead band was refused as narrower than a 10 V "resolution"); a real quantiser spans
/// hundreds (an 8-bit PWM: 511 levels over +-full scale).
pub const MIN_U_LEVELS: f64 = 16.0;

/// The resolution of the commanded u [V]: its grid spacing when u is quantised (a DAC, a PWM
/// count) in a log whose u spans at least [`MIN_U_LEVELS`] levels of it, the coarsest such; 0
/// when none is.
pub fn u_resolution(ds: &Dataset) -> f64 {
    let mut q = 0.0f64;
    for r in ds.recs.iter().filter(|r| r.has_u) {
        if let Some(g) = crate::signal::quantum::encoder_quantum(&r.u_v) {
            let (lo, hi) = r
                .u_v
                .iter()
                .filter(|u| u.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), u| {
                    (a.min(*u), b.max(*u))
                });
            if (hi - lo) / g + 1.0 >= MIN_U_LEVELS {
                q = q.max(g);
            }
        }
    }
    q
}
