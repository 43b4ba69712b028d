//! Does an added effect keep its promise? The gate before `servo compare --add --save` (and
//! `servo diagnose --auto --save`) writes a model: the model with the effects must predict the
//! logs at least as well as the model it started from, on the replay over the logs and, where
//! the logs have held-out motion, on blocks the refit did not see.
//!
//! The held-out check refits the added effects on the fit blocks only (every third block of
//! [`HOLDOUT_BLOCK_S`] held out, as `servo diagnose` does) and compares the output-error cost
//! of short simulations ([`crate::fit::oe`]) on the held-out blocks, started model against
//! refitted model. A refit that only memorises noise (a gear play sized on a log of a rigid
//! drive) predicts those blocks worse.

use super::logs::AddEffect;
use crate::fit::oe::{prediction_cost, Part};
use crate::fit::{Dataset, EffectToFit, FitError, FitOptions};
use crate::plant::Plant;
use crate::record::Record;
use alloc::string::String;
use alloc::vec::Vec;

/// Length of the blocks of the held-out split of the gate [s].
pub const HOLDOUT_BLOCK_S: f64 = 1.0;
/// Every `HOLDOUT_EVERY`-th block is held out.
pub const HOLDOUT_EVERY: usize = 3;

/// One bar an effect (or a model with added effects) has to clear: a named threshold with its
/// unit and why it is there. Every bar that can refuse an effect is stated with the verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bar {
    /// Stable name (the `--json` key), e.g. `min_bic_gain`.
    pub name: &'static str,
    pub value: f64,
    /// Unit of `value` (`-` when dimensionless, `%`, `x noise floor`, ...).
    pub unit: &'static str,
    /// How the measured figure is compared with the bar (`>`, `>=`, `<=`).
    pub rule: &'static str,
    /// One line: why the bar is there.
    pub why: &'static str,
}

/// The bar of the save gate: the worsening of the prediction error a saved model may show [%].
pub const MAX_WORSENING: Bar = Bar {
    name: "max_worsening_pct",
    value: 0.0,
    unit: "%",
    rule: "<=",
    why: "a saved model must not predict the logs worse than the model it replaces",
};

/// One measure the gate compares, started model against model with the effects.
#[derive(Debug, Clone, PartialEq)]
pub struct GateMeasure {
    /// `replay` (load position RMSE of the replay over the logs) or `held_out` (output-error
    /// cost of short simulations on the held-out blocks, effects refitted without them).
    pub name: &'static str,
    /// Plain words for the measure.
    pub words: &'static str,
    pub before: f64,
    pub after: f64,
    pub unit: &'static str,
    /// 100 (after - before) / before [%].
    pub change_pct: f64,
}

impl GateMeasure {
    fn new(
        name: &'static str,
        words: &'static str,
        before: f64,
        after: f64,
        unit: &'static str,
    ) -> Self {
        let change_pct = if before > 0.0 {
            100.0 * (after - before) / before
        } else if after > before {
            f64::INFINITY
        } else {
            0.0
        };
        GateMeasure {
            name,
            words,
            before,
            after,
            unit,
            change_pct,
        }
    }

    /// Worse than the bar allows.
    pub fn worse(&self) -> bool {
        !(self.change_pct <= MAX_WORSENING.value)
    }
}

/// The gate's verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct Gate {
    /// What changed the model, as the subject of the verdict (`adding coulomb`, `adding
    /// coulomb + delay`, `refitting the base parameters`).
    pub change: String,
    pub measures: Vec<GateMeasure>,
    /// Why no held-out measure was made (the logs hold no motion in their held-out blocks, the
    /// refit on the fit blocks failed), when none was.
    pub held_out_missing: Option<String>,
}

impl Gate {
    /// The first measure that is worse than the bar allows.
    pub fn worse(&self) -> Option<&GateMeasure> {
        self.measures.iter().find(|m| m.worse())
    }

    /// One line: `adding a gear play made the held-out error 8.7 % worse` or `adding coulomb
    /// lowered ...`.
    pub fn sentence(&self) -> String {
        match self.worse() {
            Some(m) => alloc::format!(
                "{} made the {} {:.1} % worse ({:.4e} -> {:.4e} {}; bar: {} {} {} %)",
                self.change,
                m.words,
                m.change_pct,
                m.before,
                m.after,
                m.unit,
                MAX_WORSENING.name,
                MAX_WORSENING.rule,
                MAX_WORSENING.value
            ),
            None if self.measures.is_empty() => {
                alloc::format!("{}: no prediction error could be measured", self.change)
            }
            None => {
                let parts: Vec<String> = self
                    .measures
                    .iter()
                    .map(|m| alloc::format!("the {} {:+.1} %", m.words, m.change_pct))
                    .collect();
                alloc::format!(
                    "{} did not make the prediction worse: {}",
                    self.change,
                    parts.join(", ")
                )
            }
        }
    }
}

/// The held-out measure: `adds` refitted on the fit blocks of `records` (every
/// [`HOLDOUT_EVERY`]-th block of [`HOLDOUT_BLOCK_S`] held out), starting from `start`, and the
/// output-error cost on the held-out blocks of `start` and of the refitted model [rad].
/// `refit_base[i]`: the base parameters are refitted with `adds[i]` (as the ladder chose; kept
/// as given when false or missing). `Err(reason)` when it cannot be made.
pub fn held_out_measure(
    records: &[Record],
    start: &Plant,
    adds: &[AddEffect],
    refit_base: &[bool],
) -> Result<GateMeasure, String> {
    let mut opts = FitOptions {
        holdout_block_s: HOLDOUT_BLOCK_S,
        holdout_every: HOLDOUT_EVERY,
        ..FitOptions::default()
    };
    let words = |e: FitError| alloc::format!("the refit on the fit blocks failed: {e}");
    let mut ds = Dataset::new(records, &start.params, &opts).map_err(words)?;
    let before = prediction_cost(&ds, start, Part::Holdout).filter(|c| c.is_finite());
    let Some(before) = before else {
        return Err(String::from(
            "the logs hold no motion with a logged input in their held-out blocks",
        ));
    };
    let mut plant = *start;
    for (i, eff) in adds.iter().enumerate() {
        opts.refit_base = refit_base.get(i).copied().unwrap_or(false);
        ds.opts = opts.clone();
        let mut from = plant;
        let catalogue: Vec<EffectToFit> = match eff {
            AddEffect::Catalogue(e) => alloc::vec![*e],
            AddEffect::Custom(c) => {
                from.custom
                    .insert(*c)
                    .map_err(|e| alloc::format!("adding {}: {e}", eff.name()))?;
                Vec::new()
            }
        };
        plant = ds.fit(&from, &catalogue).map_err(words)?.plant;
    }
    let after = prediction_cost(&ds, &plant, Part::Holdout)
        .filter(|c| c.is_finite())
        .ok_or_else(|| {
            String::from("the refitted model cannot be simulated on the held-out blocks")
        })?;
    Ok(GateMeasure::new(
        "held_out",
        "held-out error",
        before,
        after,
        "rad",
    ))
}

/// The gate of an error ladder: the replay error of the model as given (`replay_before`) and
/// after the effects (`replay_after`, load position RMSE [rad] over the logs), and the held-out
/// measure of [`held_out_measure`].
pub fn gate(
    records: &[Record],
    start: &Plant,
    adds: &[AddEffect],
    refit_base: &[bool],
    replay_before: f64,
    replay_after: f64,
    replay_unit: &'static str,
) -> Gate {
    let names: Vec<&str> = adds.iter().map(|a| a.name()).collect();
    let mut measures = alloc::vec![GateMeasure::new(
        "replay",
        "replay error over the logs",
        replay_before,
        replay_after,
        replay_unit,
    )];
    let mut held_out_missing = None;
    match held_out_measure(records, start, adds, refit_base) {
        Ok(m) => measures.insert(0, m),
        Err(why) => held_out_missing = Some(why),
    }
    Gate {
        change: alloc::format!("adding {}", names.join(" + ")),
        measures,
        held_out_missing,
    }
}

/// A base parameter that a refit changed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refitted {
    pub key: &'static str,
    pub unit: &'static str,
    pub before: f64,
    pub after: f64,
}

/// The base parameters (J_eq, B_eq, tau_sf, R_eq, k_drv) that differ between `before` and
/// `after` by more than 1e-9 relative (what a refit changed besides the added effects).
pub fn refitted_base(before: &Plant, after: &Plant) -> Vec<Refitted> {
    let rows = [
        ("j_eq", "kg m^2", before.params.j_eq(), after.params.j_eq()),
        ("b_eq", "N m s/rad", before.b_eq(), after.b_eq()),
        ("tau_sf", "N m", before.tau_sf(), after.tau_sf()),
        ("r_eq", "ohm", before.params.r_eq(), after.params.r_eq()),
        ("k_drv", "V/V", before.params.k_drv, after.params.k_drv),
    ];
    rows.iter()
        .filter(|(_, _, b, a)| (a - b).abs() > 1e-9 * b.abs().max(a.abs()))
        .map(|&(key, unit, before, after)| Refitted {
            key,
            unit,
            before,
            after,
        })
        .collect()
}

/// The gate of a model `end` reached from `start` on `records` by fits that did not see the
/// held-out blocks of `opts` (`servo diagnose --auto`, whose fits use the fit blocks only): the
/// output-error cost on the held-out blocks and over the whole logs, `start` against `end`.
pub fn held_out_gate(
    records: &[Record],
    start: &Plant,
    end: &Plant,
    change: String,
    opts: &FitOptions,
) -> Gate {
    let mut measures = Vec::new();
    let mut held_out_missing = None;
    match Dataset::new(records, &start.params, opts) {
        Ok(ds) => {
            for (part, name, words) in [
                (Part::Holdout, "held_out", "held-out error"),
                (Part::All, "simulation", "simulation error over the logs"),
            ] {
                let cost = |p: &Plant| prediction_cost(&ds, p, part).filter(|c| c.is_finite());
                match (cost(start), cost(end)) {
                    (Some(b), Some(a)) => measures.push(GateMeasure::new(name, words, b, a, "rad")),
                    _ if part == Part::Holdout => {
                        held_out_missing = Some(String::from(
                            "the logs hold no motion with a logged input in their held-out blocks",
                        ))
                    }
                    _ => {}
                }
            }
        }
        Err(e) => held_out_missing = Some(alloc::format!("the logs cannot be prepared: {e}")),
    }
    Gate {
        change,
        measures,
        held_out_missing,
    }
}
