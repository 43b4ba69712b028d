//! The bars of a diagnosis: every threshold that can refuse an effect or a verdict, named, with
//! its unit and why it is there ([`bars`]), and the figures a candidate was measured against the
//! statistical ones ([`statistical_gates`]), so that a user seeing "BIC gain 9.9" sees the bar
//! of 10 beside it.

use super::{on_simulation, Candidate, DiagnoseOptions};
use crate::compare::gate::{Bar, MAX_WORSENING};
use alloc::vec::Vec;

/// The bars of `opts`: every threshold of the diagnosis ([`super::Thresholds::table`]), then the
/// save gate's. Fractions are given in %.
pub fn bars(opts: &DiagnoseOptions) -> Vec<Bar> {
    let mut out = opts.thresholds.table();
    out.push(MAX_WORSENING);
    out
}

/// The bar named `name` of `opts`.
pub fn bar(opts: &DiagnoseOptions, name: &str) -> Option<Bar> {
    bars(opts).into_iter().find(|b| b.name == name)
}

/// A candidate's figure against one bar.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateOutcome {
    pub bar: Bar,
    /// The measured figure, in the bar's unit (`None`: not measurable, e.g. no logged input).
    pub measured: Option<f64>,
    pub passed: bool,
}

/// The statistical guards of candidate `c` (judged with `opts`): the information criterion, the
/// held-out residual drop (the simulation drop for an effect judged on the simulation) and the
/// held-out simulation drop, each with the measured figure and whether it passed.
pub fn statistical_gates(c: &Candidate, opts: &DiagnoseOptions) -> Vec<GateOutcome> {
    let sim_only = on_simulation(c.effect);
    let mut out = Vec::new();
    if let Some(b) = bar(opts, "min_bic_gain") {
        out.push(GateOutcome {
            bar: b,
            measured: Some(c.bic_gain),
            passed: c.bic_gain > b.value,
        });
    }
    // The drop of the squared residual, from the RMS reduction the candidate carries.
    let eq_drop_pct = if sim_only {
        c.oe_reduction_pct
    } else {
        Some(super::phrase::squared_from_rms(c.error_reduction_pct))
    };
    let drop_bar = if sim_only {
        "min_simulation_oe_drop_pct"
    } else {
        "min_eq_drop_pct"
    };
    if let Some(b) = bar(opts, drop_bar) {
        let passed = eq_drop_pct.is_some_and(|d| d >= b.value - 1e-9);
        out.push(GateOutcome {
            bar: b,
            measured: eq_drop_pct,
            passed,
        });
    }
    if let Some(b) = bar(opts, "min_oe_drop_pct") {
        let passed = c.oe_reduction_pct.is_none_or(|d| d >= b.value - 1e-9);
        out.push(GateOutcome {
            bar: b,
            measured: c.oe_reduction_pct,
            passed,
        });
    }
    out
}

/// The first statistical guard `c` failed, in words with the bar: `BIC gain -10.3 (bar
/// min_bic_gain > 10)`.
pub fn refused_by(c: &Candidate, opts: &DiagnoseOptions) -> Option<alloc::string::String> {
    let g = statistical_gates(c, opts).into_iter().find(|g| !g.passed)?;
    let m = g.measured.map_or(alloc::string::String::from("n/a"), |v| {
        alloc::format!("{v:.1}")
    });
    let unit = if g.bar.unit == "-" { "" } else { g.bar.unit };
    Some(alloc::format!(
        "{} {m}{unit} (bar {} {} {}{unit})",
        label(g.bar.name),
        g.bar.name,
        g.bar.rule,
        g.bar.value
    ))
}

fn label(name: &str) -> &'static str {
    match name {
        "min_bic_gain" => "BIC gain",
        "min_eq_drop_pct" => super::phrase::SQUARED_DROP,
        "min_simulation_oe_drop_pct" | "min_oe_drop_pct" => super::phrase::SIM_DROP,
        _ => "figure",
    }
}
