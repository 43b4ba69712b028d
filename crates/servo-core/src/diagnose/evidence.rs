//! Plain-language evidence for candidates, the verdict, and the experiments that resolve
//! undecided effects.

use super::regimes::{self, Regime};
use super::structure::{self, BalanceReport, Thresholds};
use super::{Candidate, Status, Unresolvable};
use crate::effects::{EffectKind, Sample};
use crate::fit::dataset::{Dataset, RecData};
use crate::fit::model::{EqSolution, Equation};
use crate::fit::ParamEstimate;
use crate::math;
use alloc::string::String;
use alloc::vec::Vec;
use core::fmt::Write;

/// The experiment that best exposes `kind` ([`crate::effects::EffectModel::experiment`]).
pub fn experiment(kind: EffectKind) -> &'static str {
    kind.model().experiment()
}

/// The signal whose correlation with the residual an effect removes: (name, values at rows)
/// ([`crate::effects::EffectModel::signature`]); `None` for an effect without one (a gear play,
/// judged on the simulation).
fn signature(
    ds: &Dataset,
    kind: EffectKind,
    eq: Equation,
    params: &[ParamEstimate],
) -> Option<(String, Vec<Vec<f64>>)> {
    let m = kind.model();
    let len = m.signature_len();
    if len == 0 {
        return None;
    }
    let rows = if eq == Equation::Electrical {
        &ds.elec_rows
    } else {
        &ds.mech_rows
    };
    let v: Vec<f64> = kind
        .params()
        .iter()
        .map(|p| {
            params
                .iter()
                .find(|e| e.key == p.key)
                .map(|e| e.value)
                .unwrap_or(f64::NAN)
        })
        .collect();
    let n = ds.gear_ratio;
    let filter_hz = ds.opts.filter_hz;
    let cols = (0..len)
        .map(|j| {
            ds.column(rows, |r: &RecData| {
                (0..r.u_v.len())
                    .map(|k| {
                        let x = Sample {
                            omega_m_rad_s: r.omega_raw[k],
                            theta_m_rad: r.theta_m_rad[k],
                            motor_phasor: r.motor_phasor[k],
                            u_v: r.u_v[k],
                            u_prev_v: r.u_v[k.saturating_sub(1)],
                            n,
                            filter_hz,
                        };
                        m.signature(&v, j, &x)
                    })
                    .collect()
            })
        })
        .collect();
    Some((m.signature_name(&v), cols))
}

fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()).max(1) as f64;
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / math::sqrt(saa * sbb)
    } else {
        0.0
    }
}

/// Magnitude of the correlation of `r` with a signature (root-sum-square over its components).
fn corr_mag(r: &[f64], sig: &[Vec<f64>]) -> f64 {
    math::sqrt(
        sig.iter()
            .map(|s| {
                let c = corr(r, s);
                c * c
            })
            .sum::<f64>(),
    )
}

fn fmt_params(params: &[ParamEstimate]) -> String {
    let mut s = String::new();
    for (i, p) in params.iter().filter(|p| p.fitted).enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        let _ = write!(s, "{} = {:.4} {}", p.key, p.value, p.unit);
        // The 95 % interval (robust standard error, see crate::fit::lsq); a parameter found
        // by a search has none and shows its value alone.
        if let Some(e) = p.std_err {
            let _ = write!(s, " (95 %: +/- {:.2e})", 1.96 * e);
        }
    }
    s
}

/// Evidence text of one candidate.
#[allow(clippy::too_many_arguments)]
pub fn describe(
    ds: &Dataset,
    labels: &regimes::Labels,
    kind: EffectKind,
    eq: Equation,
    b: &EqSolution,
    c: &EqSolution,
    params: &[ParamEstimate],
    explained: f64,
    floor: Option<f64>,
    eq_drop: f64,
    oe_drop: Option<f64>,
    bic_gain: f64,
    significant: bool,
) -> String {
    let mut s = String::new();
    let _ = write!(s, "{}: fitted {}. ", kind.description(), fmt_params(params));
    let rms_pct = 100.0 * (1.0 - math::sqrt((1.0 - eq_drop).max(0.0)));
    if super::on_simulation(kind) {
        let _ = write!(
            s,
            "It {}",
            super::phrase::change(
                "the held-out simulation error",
                100.0 * oe_drop.unwrap_or(0.0)
            )
        );
    } else {
        let _ = write!(s, "It {}", super::phrase::rms_drop(eq.name(), rms_pct));
        if let Some(d) = oe_drop {
            let _ = write!(
                s,
                " and {}",
                super::phrase::change("the held-out simulation error", 100.0 * d)
            );
        }
    }
    // Where it helps.
    let reg = labels.of(eq);
    let gain: Vec<f64> = b
        .resid
        .iter()
        .zip(&c.resid)
        .map(|(x, y)| x * x - y * y)
        .collect();
    let sh = regimes::shares(reg, &gain);
    let occ = regimes::occupancy(reg);
    let best = (0..5)
        .filter(|&i| occ[i] > 0.0)
        .max_by(|&i, &j| (sh[i] / occ[i]).total_cmp(&(sh[j] / occ[j])))
        .map(|i| Regime::ALL[i]);
    if let Some(r) = best {
        let i = Regime::ALL.iter().position(|&q| q == r).unwrap_or(0);
        if sh[i] > 0.05 {
            let _ = write!(
                s,
                "; {:.0} % of that gain sits {} ({:.0} % of the samples)",
                100.0 * sh[i].min(1.0),
                r.phrase(),
                100.0 * occ[i]
            );
        }
    }
    s.push('.');
    if let Some((name, sig)) = signature(ds, kind, eq, params) {
        let (c0, c1) = (corr_mag(&b.resid, &sig), corr_mag(&c.resid, &sig));
        let _ = write!(
            s,
            " The residual's correlation with {name} goes from {c0:.2} to {c1:.2}."
        );
    }
    if !significant {
        if let Some(f) = floor.filter(|f| explained < *f) {
            let unit = eq.unit();
            let _ = write!(
                s,
                " Not resolvable with this data: what it explains ({explained:.2e} {unit} RMS) is below the sensor-noise level ({f:.2e} {unit}); to resolve it, {}.",
                experiment(kind)
            );
        } else {
            let _ = write!(
                s,
                " Not significant (BIC gain {bic_gain:.1}, {} {} % (residual RMS drop {} %)",
                super::phrase::SQUARED_DROP,
                super::phrase::pct(100.0 * eq_drop),
                super::phrase::pct(rms_pct)
            );
            if let Some(d) = oe_drop {
                let _ = write!(
                    s,
                    ", {} {} %",
                    super::phrase::SIM_DROP,
                    super::phrase::pct(100.0 * d)
                );
            }
            s.push_str(").");
        }
    }
    s
}

/// Appends to a candidate's evidence the first check it failed.
pub fn append_failed(c: &mut Candidate) {
    if let Some(k) = c.failed_check() {
        let add = alloc::format!(" Not accepted: check \"{}\" failed: {}.", k.name, k.detail);
        c.evidence.push_str(&add);
    }
}

/// The parameters of `c`'s own effect, "key = value unit" joined by commas (the base's left out).
pub(super) fn own_params(c: &Candidate) -> String {
    let params: Vec<String> = c
        .params
        .iter()
        .filter(|p| p.effect == Some(c.effect))
        .map(|p| alloc::format!("{} = {:.4} {}", p.key, p.value, p.unit))
        .collect();
    params.join(", ")
}

/// Why candidate `c` was not named, in words: the first guard it failed in the order the
/// diagnosis applies them (the information criterion, the held-out residual drop of its balance
/// (an effect judged on the simulation: its held-out simulation drop), the held-out simulation
/// drop, then its checks); `None` when it passed every one.
pub fn refusal(c: &Candidate, th: &Thresholds) -> Option<String> {
    if c.significant {
        return None;
    }
    let sim = super::on_simulation(c.effect);
    let sim_drop = |d: f64, need: f64| {
        alloc::format!(
            "simulating it {} (needs a {} % drop)",
            super::phrase::change("the held-out prediction error", d),
            super::phrase::pct(need)
        )
    };
    if c.bic_gain <= th.min_bic_gain {
        return Some(alloc::format!(
            "the information criterion gains {:.1} (needs more than {:.1})",
            c.bic_gain,
            th.min_bic_gain
        ));
    }
    if sim {
        let d = c.oe_reduction_pct.unwrap_or(0.0);
        if d < th.min_simulation_oe_drop_pct {
            return Some(sim_drop(d, th.min_simulation_oe_drop_pct));
        }
    } else if c.error_reduction_pct < th.min_eq_rms_drop_pct() {
        return Some(alloc::format!(
            "it {} (needs {} %)",
            super::phrase::rms_drop(c.equation.name(), c.error_reduction_pct),
            super::phrase::pct(th.min_eq_rms_drop_pct())
        ));
    }
    if let Some(d) = c.oe_reduction_pct.filter(|d| *d < th.min_oe_drop_pct) {
        return Some(sim_drop(d, th.min_oe_drop_pct));
    }
    c.failed_check()
        .map(|k| alloc::format!("{}: {}", k.name, k.detail))
}

/// The thresholds in one sentence (stated in every verdict).
pub fn thresholds_text(th: &Thresholds) -> String {
    alloc::format!(
        "Thresholds: an effect must pass the information criterion, the held-out residual and simulation drops, explain at least {:.1} times its balance's noise floor (RMS) and {:.0} % of its structured error, have physically meaningful parameters and agree within {:.0} % across halves of the data; no torque is named while the electrical balance is {:.0} times its noise floor; a balance is incomplete when its residual exceeds {:.1} times its noise floor; a shape is named when it explains {:.0} % of the held-out residual.",
        th.min_noise_ratio,
        th.min_structured_share_pct,
        th.consistency_tol_pct,
        th.electrical_block_ratio,
        th.unexplained_ratio,
        th.min_signature_share_pct
    )
}

/// The verdict paragraph.
pub fn verdict(
    status: Status,
    ranking: &[Candidate],
    unexplained: &[BalanceReport],
    balances: &[BalanceReport],
    unresolvable: &[Unresolvable],
    th: &Thresholds,
) -> String {
    let mut s = match status {
        Status::Missing => verdict_missing(ranking),
        Status::Complete => verdict_complete(balances, th),
        Status::Unexplained => {
            let mut s = String::from(
                "The model is incomplete, and no catalogue effect explains what is missing (status: unexplained): ",
            );
            for (i, b) in unexplained.iter().enumerate() {
                if i > 0 {
                    s.push_str(" Also, ");
                }
                s.push_str(&structure::describe(b));
            }
            let rejected: Vec<String> = ranking
                .iter()
                .filter_map(|c| {
                    c.failed_check()
                        .map(|k| alloc::format!("{} ({})", c.effect, k.name))
                })
                .collect();
            if !rejected.is_empty() {
                let _ = write!(
                    s,
                    " Catalogue effects that fit some of it but fail a physical check: {}.",
                    rejected.join(", ")
                );
            }
            s
        }
    };
    s.push_str(&unresolvable_text(unresolvable));
    s.push(' ');
    s.push_str(&thresholds_text(th));
    s
}

/// " Not resolvable with these logs: ..." for each effect below its balance's noise floor, with
/// its fitted size, what it explains against the floor and the experiment that would resolve
/// it; empty when there is none.
pub fn unresolvable_text(unresolvable: &[Unresolvable]) -> String {
    let mut s = String::new();
    for u in unresolvable {
        let unit = u.equation.unit();
        let size = u.size.map_or(String::new(), |(k, unit, v)| {
            alloc::format!("{k} = {v:.3e} {unit}; ")
        });
        let _ = write!(
            s,
            " Not resolvable with these logs: {} ({}; {size}it explains {:.2e} {unit} RMS of the {}, below its noise floor {:.2e} {unit}); to resolve it, {}.",
            u.effect,
            u.effect.description(),
            u.explained_rms,
            u.equation.name(),
            u.floor,
            u.experiment
        );
    }
    s
}

/// The verdict when the winner passed only together with another effect
/// ([`super::joint`]).
fn joint_missing(w: &Candidate, sig: &[&Candidate]) -> String {
    let other = sig.iter().find(|c| Some(c.effect) == w.joint_with);
    let mut s = alloc::format!(
        "The model is missing {} ({}) together with {}: neither passes alone, each hides the other, and each is material once the other is in the model (",
        w.effect,
        w.effect.description(),
        w.joint_with.map_or("", |k| k.name()),
    );
    for (i, c) in core::iter::once(w).chain(other.copied()).enumerate() {
        let _ = write!(
            s,
            "{}{} removes {:.1} % of the held-out {} residual and {:.1} % of the held-out simulation error given the other",
            if i > 0 { "; " } else { "" },
            c.effect,
            c.error_reduction_pct,
            c.equation.name(),
            c.oe_reduction_pct.unwrap_or(0.0)
        );
    }
    s.push_str("): add both, refit and diagnose again.");
    s
}

fn verdict_missing(ranking: &[Candidate]) -> String {
    let sig: Vec<&Candidate> = ranking.iter().filter(|c| c.significant).collect();
    match sig.first() {
        Some(w) if w.joint_with.is_some() => joint_missing(w, &sig),
        Some(w) => {
            let mut s = alloc::format!(
                "The model is missing {} ({}): adding it removes {:.1} % of the held-out {} residual.",
                w.effect,
                w.effect.description(),
                w.error_reduction_pct,
                w.equation.name()
            );
            if sig.len() > 1 {
                let others: Vec<&str> = sig[1..].iter().map(|c| c.effect.name()).collect();
                let _ = write!(
                    s,
                    " Also significant now: {} — add the first one, refit and diagnose again before believing them (one effect can masquerade as another).",
                    others.join(", ")
                );
            }
            s
        }
        None => String::new(),
    }
}

fn verdict_complete(balances: &[BalanceReport], th: &Thresholds) -> String {
    let mut s = String::from(
        "No missing effect is significant and nothing material is left (status: complete): every balance's residual is near its noise floor or holds no structure (",
    );
    for (i, b) in balances.iter().enumerate() {
        let unit = b.equation.unit();
        let _ = write!(
            s,
            "{}{} {:.2e} {unit} RMS, {:.2} times its floor {:.2e} {unit}",
            if i > 0 { "; " } else { "" },
            b.equation.name(),
            b.rms,
            b.ratio_to_noise,
            b.floor
        );
        if b.ratio_to_noise > th.unexplained_ratio {
            let _ = write!(
                s,
                ", above the {:.1} times that makes a balance incomplete but with no shape that predicts its held-out residual (an unshaped residual counts from {:.1} times)",
                th.unexplained_ratio,
                th.structured_without_shape * th.unexplained_ratio
            );
        }
    }
    s.push_str("), and no catalogue effect added to the model explains a material part of it, judged on held-out data.");
    s
}
