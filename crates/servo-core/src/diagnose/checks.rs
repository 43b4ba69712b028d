//! Physical checks of a candidate: its parameters respect the catalogue's constraints and mean
//! something in these data, and they agree across independent parts of the data.
//!
//! A best fit at or beyond a constraint (a breakaway torque below the Coulomb level, a limit
//! inside the controller's own clip, a gap of zero) and parameters that differ between the first
//! and second half, or between slow and fast motion, are the marks of a mimic: a catalogue effect
//! bent to soak up a mechanism outside the catalogue.

use super::structure::Thresholds;
use super::Candidate;
use crate::effects::EffectKind;
use crate::fit::{Dataset, EffectToFit, ParamEstimate};
use crate::math;
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

/// One check and its outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// Short name, e.g. `"tau_s > tau_sf"`, `"same in both halves"`.
    pub name: &'static str,
    pub passed: bool,
    /// The figures behind the outcome.
    pub detail: String,
}

fn get(params: &[ParamEstimate], key: &str) -> Option<f64> {
    params.iter().find(|p| p.key == key).map(|p| p.value)
}

/// The resolution of the commanded u [V]: its grid spacing when u is quantised (a DAC, a PWM
/// count), else the smallest step between distinct values near zero.
fn u_resolution(ds: &Dataset) -> f64 {
    let mut q = 0.0f64;
    for r in ds.recs.iter().filter(|r| r.has_u) {
        if let Some(g) = crate::compare::quantum::encoder_quantum(&r.u_v) {
            q = q.max(g);
        }
    }
    q
}

/// The catalogue's constraints and the physical meaning of the fitted parameters in these data.
pub fn constraints(
    ds: &Dataset,
    kind: EffectKind,
    params: &[ParamEstimate],
    cand: &Plant,
    base: &Plant,
) -> Vec<Check> {
    let mut out = Vec::new();
    match kind {
        EffectKind::Stribeck => {
            let (ts, tf) = (get(params, "tau_s").unwrap_or(f64::NAN), cand.tau_sf());
            out.push(Check {
                name: "tau_s > tau_sf",
                passed: ts > 1.05 * tf,
                detail: alloc::format!(
                    "breakaway torque tau_s = {ts:.4} N m against the Coulomb level tau_sf = {tf:.4} N m: Stribeck friction decays from a breakaway above the Coulomb level (needs tau_s > 1.05 tau_sf); a best fit below it is a friction rising with speed, not Stribeck"
                ),
            });
            out.push(Check {
                name: "tau_sf off its bound",
                passed: tf > 0.1 * base.tau_sf().max(1e-12),
                detail: alloc::format!(
                    "with it the Coulomb level falls to {tf:.4} N m from {:.4} N m without it (needs more than 10 % of it: a friction level pinned at zero is a curve of another shape, not Stribeck on top of Coulomb)",
                    base.tau_sf()
                ),
            });
            let ws = get(params, "omega_s").unwrap_or(f64::NAN);
            let wl = ds
                .recs
                .iter()
                .flat_map(|r| r.omega_f.iter())
                .fold(0.0f64, |m, w| m.max(w.abs()))
                / ds.gear_ratio;
            out.push(Check {
                name: "omega_s inside the speeds reached",
                passed: ws < 0.45 * wl,
                detail: alloc::format!(
                    "Stribeck speed omega_s = {ws:.3} rad/s against the largest load speed {wl:.2} rad/s (needs omega_s < 45 % of it: a decay over the whole speed range is a friction curve of another shape)"
                ),
            });
        }
        EffectKind::Saturation => {
            let l = get(params, "limit").unwrap_or(f64::NAN);
            let umax = ds.u_max_v;
            let beyond = ds
                .recs
                .iter()
                .filter(|r| r.has_u)
                .flat_map(|r| r.u_v.iter())
                .filter(|u| u.abs() > l)
                .count();
            let total: usize = ds
                .recs
                .iter()
                .filter(|r| r.has_u)
                .map(|r| r.u_v.len())
                .sum();
            out.push(Check {
                name: "limit inside the |u| reached",
                passed: l < 0.97 * umax && beyond as f64 >= 0.002 * total as f64,
                detail: alloc::format!(
                    "limit {l:.3} V against the largest commanded |u| {umax:.3} V with {:.2} % of the samples beyond it (needs the limit at least 3 % below the largest |u|, beyond the controller's own clip, and 0.2 % of the samples beyond it)",
                    100.0 * beyond as f64 / total.max(1) as f64
                ),
            });
        }
        EffectKind::Deadzone => {
            let w = get(params, "width").unwrap_or(f64::NAN);
            let res = u_resolution(ds);
            let floor = (2.0 * res).max(0.005 * ds.u_max_v);
            out.push(Check {
                name: "width above the u resolution",
                passed: w > floor,
                detail: alloc::format!(
                    "half width {w:.4} V against the commanded-u resolution {res:.2e} V (needs more than {floor:.2e} V: twice the resolution and 0.5 % of the largest |u|)"
                ),
            });
        }
        EffectKind::Backlash => {
            let g = get(params, "gap").unwrap_or(f64::NAN);
            let q = ds
                .recs
                .iter()
                .filter_map(|r| crate::compare::quantum::encoder_quantum(&r.theta_m_rad))
                .fold(0.0f64, f64::max)
                / ds.gear_ratio;
            out.push(Check {
                name: "gap > 0",
                passed: g > (2.0 * q).max(1e-4),
                detail: alloc::format!(
                    "gap {g:.4} rad against the load-angle resolution {q:.2e} rad (needs more than twice it: a gap at zero is a compliance without play)"
                ),
            });
        }
        EffectKind::Delay => {
            let d = get(params, "delay").unwrap_or(f64::NAN);
            let max = ds.opts.max_delay_s;
            out.push(Check {
                name: "delay inside the search range",
                passed: d > 0.0 && d < 0.95 * max,
                detail: alloc::format!(
                    "delay {:.2} ms against the searched 0-{:.1} ms (a best fit at the bound is no delay)",
                    1e3 * d,
                    1e3 * max
                ),
            });
        }
        EffectKind::Cogging => {
            let h = get(params, "harmonic").unwrap_or(f64::NAN);
            let max = f64::from(ds.opts.max_cogging_harmonic);
            out.push(Check {
                name: "harmonic inside the search range",
                passed: h < max,
                detail: alloc::format!(
                    "harmonic {h:.0} against the searched 1-{max:.0} cycles per motor revolution"
                ),
            });
        }
        EffectKind::Asymmetry => {
            let (p, n) = (
                get(params, "tau_sf_pos").unwrap_or(f64::NAN),
                get(params, "tau_sf_neg").unwrap_or(f64::NAN),
            );
            out.push(Check {
                name: "both Coulomb levels > 0",
                passed: p > 0.0 && n > 0.0,
                detail: alloc::format!("tau_sf_pos = {p:.4} N m, tau_sf_neg = {n:.4} N m"),
            });
        }
        _ => {}
    }
    out
}

/// The parameters compared across parts of the data.
fn compared(kind: EffectKind) -> &'static [&'static str] {
    match kind {
        EffectKind::Coulomb => &["tau_sf"],
        EffectKind::Stribeck => &["tau_s"],
        EffectKind::Asymmetry => &["tau_sf_pos", "tau_sf_neg"],
        EffectKind::Cogging | EffectKind::Imbalance => &["amplitude"],
        EffectKind::Saturation => &["limit"],
        EffectKind::Deadzone => &["width"],
        EffectKind::Delay => &["delay"],
        _ => &[],
    }
}

/// Refits the candidate on the rows of `ds` where `keep(record, sample)` holds (fit and
/// held-out rows alike) and returns its parameters.
fn refit_on(
    ds: &Dataset,
    model: &Plant,
    kind: EffectKind,
    keep: &dyn Fn(usize, usize) -> bool,
) -> Option<Vec<ParamEstimate>> {
    let mut sub = ds.clone();
    for rows in [&mut sub.mech_rows, &mut sub.elec_rows] {
        for i in 0..rows.len() {
            rows.fit[i] = keep(rows.rec[i], rows.k[i]);
        }
    }
    let solved = sub.fit_config(model, &[EffectToFit::all(kind)]).ok()?;
    Some(
        sub.estimates(&solved)
            .into_iter()
            .filter(|p| {
                p.effect == Some(kind) || (kind == EffectKind::Coulomb && p.key == "tau_sf")
            })
            .collect(),
    )
}

fn agree(
    name: &'static str,
    what: &str,
    kind: EffectKind,
    a: &[ParamEstimate],
    b: &[ParamEstimate],
    tol: f64,
) -> Check {
    let mut passed = true;
    let mut detail = String::new();
    for key in compared(kind) {
        let (Some(pa), Some(pb)) = (
            a.iter().find(|p| p.key == *key),
            b.iter().find(|p| p.key == *key),
        ) else {
            continue;
        };
        let diff = (pa.value - pb.value).abs();
        let scale = pa.value.abs().max(pb.value.abs());
        let (sa, sb) = (pa.std_err.unwrap_or(0.0), pb.std_err.unwrap_or(0.0));
        let se = math::sqrt(sa * sa + sb * sb);
        let ok = diff <= (tol * scale).max(3.0 * se);
        passed &= ok;
        if !detail.is_empty() {
            detail.push_str("; ");
        }
        detail.push_str(&alloc::format!(
            "{key} = {:.4e} vs {:.4e} {} on {what} ({:.0} % apart; allowed {:.0} % or 3 standard errors)",
            pa.value,
            pb.value,
            pa.unit,
            100.0 * diff / scale.max(1e-300),
            100.0 * tol
        ));
    }
    Check {
        name,
        passed,
        detail,
    }
}

/// Fits the candidate again on independent parts of the data: the first and second half of
/// every log, and (for effects that should not depend on speed: periodic torques, Coulomb
/// friction) slow and fast motion. A mechanism is the same everywhere; a mimic is not.
pub fn consistency(ds: &Dataset, model: &Plant, c: &Candidate, th: &Thresholds) -> Vec<Check> {
    let kind = c.effect;
    let mut out = Vec::new();
    if compared(kind).is_empty() {
        return out;
    }
    let lens: Vec<usize> = ds.recs.iter().map(|r| r.u_v.len()).collect();
    let first = |ri: usize, k: usize| k < lens[ri] / 2;
    let second = |ri: usize, k: usize| k >= lens[ri] / 2;
    if let (Some(a), Some(b)) = (
        refit_on(ds, model, kind, &first),
        refit_on(ds, model, kind, &second),
    ) {
        out.push(agree(
            "same in both halves",
            "the first vs the second half of the logs",
            kind,
            &a,
            &b,
            th.consistency_tol,
        ));
    }
    // Cogging is left out: at speed its frequency passes the filter's cut-off and the fast
    // rows carry no information on it.
    if matches!(kind, EffectKind::Imbalance | EffectKind::Coulomb) {
        let mut speeds: Vec<f64> = (0..ds.mech_rows.len())
            .map(|i| ds.recs[ds.mech_rows.rec[i]].omega_f[ds.mech_rows.k[i]].abs())
            .collect();
        speeds.sort_by(|a, b| a.total_cmp(b));
        let med = speeds.get(speeds.len() / 2).copied().unwrap_or(0.0);
        let slow = |ri: usize, k: usize| ds.recs[ri].omega_f[k].abs() < med;
        let fast = |ri: usize, k: usize| ds.recs[ri].omega_f[k].abs() >= med;
        if let (Some(a), Some(b)) = (
            refit_on(ds, model, kind, &slow),
            refit_on(ds, model, kind, &fast),
        ) {
            out.push(agree(
                "same at slow and fast speed",
                "motion below vs above the median speed",
                kind,
                &a,
                &b,
                th.consistency_tol,
            ));
        }
    }
    out
}

/// The backlash gap against the contact stiffness it was sized with: the gap is refitted with
/// the stiffness halved and doubled (the default is a guess unless both angles are logged). When
/// one stiffness predicts the held-out motion clearly best (5 % lower simulation error than
/// both others) it is reported as estimated; otherwise the gap is reported as conditional on
/// the assumed stiffness, with the range of gaps over the plausible range.
pub fn backlash_stiffness(ds: &Dataset, model: &Plant, c: &Candidate) -> Option<String> {
    use crate::fit::oe::{prediction_cost, Part};
    let k0 = c.plant.effects.value(EffectKind::Backlash, "stiffness")?;
    let g0 = c.plant.effects.value(EffectKind::Backlash, "gap")?;
    let mut rows: Vec<(f64, f64, f64)> = Vec::new();
    let c0 = prediction_cost(ds, &c.plant, Part::Holdout)?;
    rows.push((k0, g0, c0));
    for f in [0.5, 2.0] {
        let spec = alloc::format!("backlash:stiffness={}", k0 * f);
        let t = EffectToFit::parse(&spec).ok()?;
        let solved = ds.fit_config(model, &[t]).ok()?;
        let g = solved.plant.effects.value(EffectKind::Backlash, "gap")?;
        let cost = prediction_cost(ds, &solved.plant, Part::Holdout)?;
        rows.push((k0 * f, g, cost));
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let best = rows.iter().min_by(|a, b| a.2.total_cmp(&b.2))?;
    let clear = rows
        .iter()
        .filter(|r| r.0 != best.0)
        .all(|r| best.2 < 0.95 * r.2);
    let (gmin, gmax) = rows
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
            (a.min(r.1), b.max(r.1))
        });
    let table: Vec<String> = rows
        .iter()
        .map(|r| {
            alloc::format!(
                "{:.0} N m/rad: gap {:.4} rad, held-out simulation error {:.3e} rad",
                r.0,
                r.1,
                r.2
            )
        })
        .collect();
    Some(if clear {
        alloc::format!(
            " Contact stiffness estimated with the gap: {:.0} N m/rad predicts the held-out motion best (gap {:.4} rad; {}).",
            best.0,
            best.1,
            table.join("; ")
        )
    } else {
        alloc::format!(
            " The gap is conditional on the assumed contact stiffness {k0:.0} N m/rad, which these data do not pin down: over {:.0}-{:.0} N m/rad the gap ranges {gmin:.4}-{gmax:.4} rad ({}). Log both motor and load angles to measure it.",
            rows[0].0,
            rows[rows.len() - 1].0,
            table.join("; ")
        )
    })
}
