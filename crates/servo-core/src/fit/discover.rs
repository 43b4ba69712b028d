//! Judging user-defined effects as diagnosis candidates, and discovering a term outside the
//! catalogue from the torque-balance residual.
//!
//! # Judging ([`judge`])
//!
//! A user effect is fitted with the base parameters ([`super::fit`]) and passes the guards the
//! catalogue uses ([`crate::diagnose`]): the BIC gain of its equation with the effective number of
//! rows (lag-1 autocorrelation) charged for its linear parameters and three times for each
//! searched one, a minimum relative drop of its equation's residual on the held-out blocks, and a
//! minimum drop of the held-out simulation (output-error) cost.
//!
//! # Discovery ([`discover`])
//!
//! When no catalogue or user effect explains the residual, a sparse regression looks for the
//! smallest set of physically motivated terms that does. The residual of the base model's torque
//! balance (or of the u-driven balance without current) is regressed on the base columns (J_eq,
//! B_eq, tau_sf: never dropped) and a library of load torques ([`LIBRARY`]: the load angle and its
//! cube, a constant, speed * |speed| and speed^3, |speed| and the viscous slope of one direction
//! (beside B_eq the same column: the forward slope stands for them), sin/cos of the load angle at
//! harmonics 1-3 and of the motor angle at 1-2, the same harmonics (load 1-2, motor 1) times the
//! direction of motion (a friction that varies with position), a friction growing with the
//! transmitted torque (|i_a| times the direction, with current logged), time, current squared,
//! u, and the Coulomb direction when the model has no Coulomb friction), every column through the
//! same zero-phase filter as the fit. Sequentially
//! thresholded least squares (STLSQ, columns scaled to unit RMS, threshold 5 % of the residual
//! RMS) prunes the library; then a backward elimination drops, one at a time, the term whose
//! removal costs the least held-out residual while that cost is below the practical threshold
//! (2 %). Each kept term must then pass three gates: statistical (|t| >= 5 with the effective
//! number of rows), practical (removing it raises the held-out residual by >= 2 %), and
//! consistency (fitted on each half of the rows, by time, the coefficient keeps its sign and
//! agrees within 35 %). The terms left form one user-defined load torque, which is fitted as any
//! user effect and judged by [`judge`] (the held-out simulation must improve too).

use super::custom::record_signals;
use crate::custom::{ActsOn, CustomActive, CustomDef, ParamDecl};
use crate::fit::dataset::{Dataset, RecData};
use crate::fit::model::Equation;
use crate::fit::oe::{self, Part};
use crate::fit::{lsq, FitError, Solved};
use crate::math;
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

/// Guards of [`judge`] and [`discover`] (defaults as the catalogue's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gates {
    pub min_bic_gain: f64,
    /// Minimum relative drop of the held-out equation residual (sum of squares).
    pub min_eq_drop: f64,
    /// Minimum relative drop of the held-out simulation cost.
    pub min_oe_drop: f64,
    /// Minimum |t| of a discovered term (effective number of rows).
    pub min_t: f64,
    /// Largest relative disagreement of a discovered term's coefficient between the two halves.
    pub max_half_disagreement: f64,
    /// STLSQ threshold: smallest contribution of a term (RMS) relative to the residual RMS.
    pub stlsq_threshold: f64,
}

impl Default for Gates {
    fn default() -> Self {
        Gates {
            min_bic_gain: 10.0,
            min_eq_drop: 0.02,
            min_oe_drop: 0.01,
            min_t: 5.0,
            max_half_disagreement: 0.35,
            stlsq_threshold: 0.05,
        }
    }
}

/// A user effect fitted and judged.
#[derive(Debug, Clone, PartialEq)]
pub struct Judged {
    pub name: &'static str,
    pub significant: bool,
    /// BIC gain of its equation.
    pub bic_gain: f64,
    /// Relative drop of its equation's held-out residual sum of squares [-].
    pub eq_drop: f64,
    /// Relative drop of the held-out simulation cost [-], when computable.
    pub oe_drop: Option<f64>,
    pub equation: Equation,
    /// The model with the effect, fitted.
    pub plant: Plant,
    /// Fitted parameters (key, unit, value).
    pub params: Vec<(&'static str, &'static str, f64)>,
    /// The guards in words.
    pub checks: Vec<(&'static str, bool, String)>,
}

/// The simulation reference: the base model's held-out output-error cost.
pub fn reference_oe(ds: &Dataset, base: &Solved) -> Option<f64> {
    let rigid = ds.refine_rigid_on_simulation(&base.plant);
    oe::prediction_cost(ds, &rigid, Part::Holdout)
}

/// Fits `effect` (unknown parameters NaN) on top of `model` and judges it against `base` (the
/// model's own fit) and the simulation reference `base_oe` (see [`reference_oe`]).
pub fn judge(
    ds: &Dataset,
    model: &Plant,
    base: &Solved,
    base_oe: Option<f64>,
    effect: CustomActive,
    gates: &Gates,
) -> Result<Judged, FitError> {
    let mut start = *model;
    start
        .custom
        .insert(effect)
        .map_err(|e| FitError::BadModel(alloc::format!("{e}")))?;
    let cand = ds.fit_config(&start, &[])?;
    let place = effect.def.acts_on();
    let eq = match place {
        ActsOn::Input if ds.has_current => Equation::Electrical,
        _ => base.mech.equation,
    };
    let (b, c) = match (base.equation(eq), cand.equation(eq)) {
        (Some(b), Some(c)) => (b, c),
        _ => return Err(FitError::BadModel(String::from("equation missing"))),
    };
    let rho = math::lag1(&b.resid);
    let n_eff = (b.n_fit as f64 * (1.0 - rho) / (1.0 + rho)).max(1.0);
    let n_unknown = effect.values().iter().filter(|v| v.is_nan()).count();
    let q_lin = c.p.saturating_sub(b.p) as f64;
    let q_nl = n_unknown.saturating_sub(c.p.saturating_sub(b.p)) as f64;
    let bic_gain = n_eff * math::ln(b.rss_fit / c.rss_fit.max(1e-300))
        - (q_lin + 3.0 * q_nl) * math::ln(n_eff);
    let (rss0, rss1) = if b.n_hold > 0 {
        (b.rss_hold, c.rss_hold)
    } else {
        (b.rss_fit, c.rss_fit)
    };
    let eq_drop = 1.0 - rss1 / rss0.max(1e-300);
    let cand_oe = oe::prediction_cost(ds, &cand.plant, Part::Holdout);
    let oe_drop = match (base_oe, cand_oe) {
        (Some(x), Some(y)) if x > 0.0 => Some(1.0 - y / x),
        _ => None,
    };
    let oe_ok = match oe_drop {
        Some(d) => d >= gates.min_oe_drop,
        None => !ds.has_input,
    };
    let checks = alloc::vec![
        (
            "information criterion",
            bic_gain > gates.min_bic_gain,
            alloc::format!("BIC gain {bic_gain:.1} (needs > {})", gates.min_bic_gain),
        ),
        (
            "held-out equation residual",
            eq_drop >= gates.min_eq_drop,
            alloc::format!(
                "{} residual down {:.1} % on held-out blocks (needs >= {:.1} %)",
                eq.name(),
                100.0 * eq_drop,
                100.0 * gates.min_eq_drop
            ),
        ),
        (
            "held-out simulation",
            oe_ok,
            match oe_drop {
                Some(d) => alloc::format!(
                    "simulated angle error down {:.1} % on held-out blocks (needs >= {:.1} %)",
                    100.0 * d,
                    100.0 * gates.min_oe_drop
                ),
                None => String::from("not simulated (no logged input)"),
            },
        ),
    ];
    let significant = checks.iter().all(|c| c.1);
    let fitted = cand
        .plant
        .custom
        .get(effect.name())
        .copied()
        .unwrap_or(effect);
    let params = fitted
        .def
        .params()
        .iter()
        .zip(fitted.values())
        .map(|(p, v)| (p.key, p.unit, *v))
        .collect();
    Ok(Judged {
        name: effect.name(),
        significant,
        bic_gain,
        eq_drop,
        oe_drop,
        equation: eq,
        plant: cand.plant,
        params,
        checks,
    })
}

/// One term of the discovery library: a load torque per unit coefficient.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Term {
    /// The term in the expression language (in the signals).
    pub expr: &'static str,
    /// Parameter key of its coefficient in a proposal.
    pub key: &'static str,
    /// Unit of the coefficient.
    pub unit: &'static str,
    /// "a load torque ..." in words.
    pub words: &'static str,
}

const fn term(
    expr: &'static str,
    key: &'static str,
    unit: &'static str,
    words: &'static str,
) -> Term {
    Term {
        expr,
        key,
        unit,
        words,
    }
}

/// The library of physically motivated load torques.
pub const LIBRARY: [Term; 30] = [
    term(
        "theta_l",
        "k_theta",
        "N m/rad",
        "proportional to the load angle (a spring)",
    ),
    term(
        "theta_l^3",
        "k_theta3",
        "N m/rad^3",
        "cubic in the load angle (a stiffening spring)",
    ),
    term(
        "1",
        "tau0",
        "N m",
        "constant (a steady load, e.g. a counterweight)",
    ),
    term(
        "omega_l * abs(omega_l)",
        "c_drag",
        "N m s^2/rad^2",
        "proportional to speed times |speed| (aerodynamic or fluid drag)",
    ),
    term(
        "omega_l^3",
        "c_w3",
        "N m s^3/rad^3",
        "cubic in the load speed",
    ),
    term(
        "sign(omega_l)",
        "tau_c",
        "N m",
        "of constant magnitude opposing the motion (dry friction)",
    ),
    term(
        "sin(theta_l)",
        "a_s1",
        "N m",
        "periodic in the load angle, once per revolution (sin)",
    ),
    term(
        "cos(theta_l)",
        "a_c1",
        "N m",
        "periodic in the load angle, once per revolution (cos)",
    ),
    term(
        "sin(2 * theta_l)",
        "a_s2",
        "N m",
        "periodic in the load angle, twice per revolution (sin)",
    ),
    term(
        "cos(2 * theta_l)",
        "a_c2",
        "N m",
        "periodic in the load angle, twice per revolution (cos)",
    ),
    term(
        "sin(3 * theta_l)",
        "a_s3",
        "N m",
        "periodic in the load angle, three times per revolution (sin)",
    ),
    term(
        "cos(3 * theta_l)",
        "a_c3",
        "N m",
        "periodic in the load angle, three times per revolution (cos)",
    ),
    term(
        "sin(theta_m)",
        "m_s1",
        "N m",
        "periodic in the motor angle, once per motor revolution (sin)",
    ),
    term(
        "cos(theta_m)",
        "m_c1",
        "N m",
        "periodic in the motor angle, once per motor revolution (cos)",
    ),
    term(
        "sin(2 * theta_m)",
        "m_s2",
        "N m",
        "periodic in the motor angle, twice per motor revolution (sin)",
    ),
    term(
        "cos(2 * theta_m)",
        "m_c2",
        "N m",
        "periodic in the motor angle, twice per motor revolution (cos)",
    ),
    term("t", "k_t_drift", "N m/s", "growing with time (a drift)"),
    term(
        "i_a^2",
        "k_i2",
        "N m/A^2",
        "proportional to the current squared",
    ),
    term("u", "k_u", "N m/V", "proportional to the driver input u"),
    term(
        "omega_l",
        "b_l_extra",
        "N m s/rad",
        "proportional to the load speed (viscous)",
    ),
    term(
        "abs(omega_l)",
        "c_abs",
        "N m s/rad",
        "proportional to |speed|",
    ),
    term(
        "max(omega_l, 0)",
        "b_fwd",
        "N m s/rad",
        "proportional to the load speed when it turns forwards only (beside B_eq: a viscous friction whose slope differs between the two directions)",
    ),
    term(
        "min(omega_l, 0)",
        "b_bwd",
        "N m s/rad",
        "proportional to the load speed when it turns backwards only (beside B_eq: a viscous friction whose slope differs between the two directions)",
    ),
    term(
        "abs(i_a) * sign(omega_l)",
        "mu_i",
        "N m/A",
        "opposing the motion in proportion to |i_a| (a friction growing with the transmitted torque, k_t |i_a|: a load-dependent gear loss)",
    ),
    term(
        "sin(theta_l) * sign(omega_l)",
        "f_s1",
        "N m",
        "opposing the motion with a size that varies once per load revolution (sin; a friction that varies with position)",
    ),
    term(
        "cos(theta_l) * sign(omega_l)",
        "f_c1",
        "N m",
        "opposing the motion with a size that varies once per load revolution (cos; a friction that varies with position)",
    ),
    term(
        "sin(2 * theta_l) * sign(omega_l)",
        "f_s2",
        "N m",
        "opposing the motion with a size that varies twice per load revolution (sin; a friction that varies with position)",
    ),
    term(
        "cos(2 * theta_l) * sign(omega_l)",
        "f_c2",
        "N m",
        "opposing the motion with a size that varies twice per load revolution (cos; a friction that varies with position)",
    ),
    term(
        "sin(theta_m) * sign(omega_l)",
        "fm_s1",
        "N m",
        "opposing the motion with a size that varies once per motor revolution (sin; a friction that varies with the motor's position)",
    ),
    term(
        "cos(theta_m) * sign(omega_l)",
        "fm_c1",
        "N m",
        "opposing the motion with a size that varies once per motor revolution (cos; a friction that varies with the motor's position)",
    ),
];

/// A discovered term with its coefficient.
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    pub term: Term,
    /// Coefficient from the discovery regression (load torque per unit of the term).
    pub value: f64,
    /// Its |t| with the effective number of rows.
    pub t: f64,
    /// Held-out residual increase when it is removed [-].
    pub practical: f64,
    /// Coefficients on the first and second half of the rows.
    pub halves: (f64, f64),
}

/// The outcome of [`discover`].
#[derive(Debug, Clone, PartialEq)]
pub struct Discovery {
    /// The equation searched.
    pub equation: Equation,
    /// Terms that passed every gate (empty: nothing found).
    pub terms: Vec<Found>,
    /// Terms STLSQ kept that a gate then removed, with the reason.
    pub rejected: Vec<(Term, String)>,
    /// The proposal as a user effect, fitted and judged (None when no term passed).
    pub proposal: Option<(CustomActive, Judged)>,
}

impl Discovery {
    /// "a load torque proportional to the load angle, 0.021 N m/rad, plus ..." (fitted values).
    pub fn words(&self) -> String {
        let Some((_, j)) = &self.proposal else {
            return String::from("no term of the library explains the residual");
        };
        let mut s = String::from("a load torque ");
        for (i, f) in self.terms.iter().enumerate() {
            let v = j
                .params
                .iter()
                .find(|p| p.0 == f.term.key)
                .map_or(f.value, |p| p.2);
            if i > 0 {
                s.push_str(", plus one ");
            }
            s.push_str(&alloc::format!(
                "{}, {:.3e} {}",
                f.term.words,
                v,
                f.term.unit
            ));
        }
        s
    }
}

/// Library columns at the torque-balance rows (load torques through 1/N, filtered).
fn library_columns(ds: &Dataset, n: f64, terms: &[Term]) -> Result<Vec<Vec<f64>>, FitError> {
    let mut cols = Vec::new();
    for t in terms {
        let prog = crate::custom::Program::compile(t.expr, &[])
            .map_err(|e| FitError::BadModel(alloc::format!("library term {}: {e}", t.expr)))?;
        cols.push(ds.column(&ds.mech_rows, |r: &RecData| {
            (0..r.theta_m_rad.len())
                .map(|k| {
                    let v = prog.eval(&record_signals(r, n, k), &[]) / n;
                    if v.is_finite() {
                        v
                    } else {
                        0.0
                    }
                })
                .collect()
        }));
    }
    Ok(cols)
}

/// Searches the library for the smallest set of terms that explains the residual of `base` (the
/// model's own fit on `ds`), and proposes it as a user-defined load torque named `name`, fitted
/// and judged on top of `model`.
pub fn discover(
    ds: &Dataset,
    model: &Plant,
    base: &Solved,
    base_oe: Option<f64>,
    name: &str,
    gates: &Gates,
) -> Result<Discovery, FitError> {
    let n = model.params.n;
    let rows = &ds.mech_rows;
    let resid = &base.mech.resid;
    let has_coulomb = model.effects.contains(crate::effects::EffectKind::Coulomb);
    let terms: Vec<Term> = LIBRARY
        .iter()
        .copied()
        .filter(|t| t.key != "tau_c" || !has_coulomb)
        .filter(|t| (t.key != "k_i2" && t.key != "mu_i") || ds.has_current)
        .filter(|t| t.key != "k_u" || ds.has_input)
        // B_eq is a base column: a viscous load term is the same column.
        .filter(|t| t.key != "b_l_extra")
        // Beside B_eq (omega = max(omega, 0) + min(omega, 0)), |omega| and the two one-direction
        // slopes span one column: the forward slope stands for the three (a viscous friction
        // whose slope differs between the directions, the more telling of their names).
        .filter(|t| t.key != "c_abs" && t.key != "b_bwd")
        .collect();
    let lib = library_columns(ds, n, &terms)?;
    let base_cols: Vec<Vec<f64>> = alloc::vec![
        ds.sample(rows, |r| &r.accel_f),
        ds.sample(rows, |r| &r.omega_f),
        ds.coulomb_col.clone(),
    ]
    .into_iter()
    .filter(|c| c.len() == rows.len())
    .collect();
    let nb = base_cols.len();
    let fit_rows: Vec<usize> = (0..rows.len()).filter(|&i| rows.fit[i]).collect();
    let hold_rows: Vec<usize> = {
        let h: Vec<usize> = (0..rows.len()).filter(|&i| !rows.fit[i]).collect();
        if h.is_empty() {
            fit_rows.clone()
        } else {
            h
        }
    };
    // Unit-RMS scaling of the library columns (fit rows).
    let scale: Vec<f64> = lib
        .iter()
        .map(|c| {
            let s: f64 = fit_rows.iter().map(|&i| c[i] * c[i]).sum::<f64>();
            math::sqrt(s / fit_rows.len().max(1) as f64)
        })
        .collect();
    let resid_rms = math::sqrt(
        fit_rows.iter().map(|&i| resid[i] * resid[i]).sum::<f64>() / fit_rows.len().max(1) as f64,
    );
    let mut active: Vec<usize> = (0..terms.len()).filter(|&j| scale[j] > 0.0).collect();
    let solve = |act: &[usize], on: &[usize]| -> Option<lsq::LsSolution> {
        let cols: Vec<&Vec<f64>> = base_cols
            .iter()
            .chain(act.iter().map(|&j| &lib[j]))
            .collect();
        lsq::solve_on(&cols, resid, on)
    };
    let hold_rss = |act: &[usize]| -> f64 {
        match solve(act, &fit_rows) {
            Some(s) => {
                let cols: Vec<&Vec<f64>> = base_cols
                    .iter()
                    .chain(act.iter().map(|&j| &lib[j]))
                    .collect();
                lsq::rss_on(&cols, &s.theta, resid, &hold_rows)
            }
            None => f64::INFINITY,
        }
    };
    // STLSQ.
    for _ in 0..20 {
        let Some(s) = solve(&active, &fit_rows) else {
            break;
        };
        let keep: Vec<usize> = active
            .iter()
            .enumerate()
            .filter(|(i, &j)| {
                (s.theta[nb + i] * scale[j]).abs() >= gates.stlsq_threshold * resid_rms
            })
            .map(|(_, &j)| j)
            .collect();
        if keep.len() == active.len() {
            break;
        }
        active = keep;
    }
    // Backward elimination: drop the cheapest term while it costs less than the practical gate.
    loop {
        if active.is_empty() {
            break;
        }
        let full = hold_rss(&active);
        let mut best: Option<(usize, f64)> = None;
        for i in 0..active.len() {
            let mut a = active.clone();
            a.remove(i);
            let cost = hold_rss(&a) / full.max(1e-300) - 1.0;
            if best.is_none_or(|(_, c)| cost < c) {
                best = Some((i, cost));
            }
        }
        match best {
            Some((i, c)) if c < gates.min_eq_drop => {
                active.remove(i);
            }
            _ => break,
        }
    }
    // Gates on each kept term.
    let mut rejected = Vec::new();
    let mut found = Vec::new();
    while let Some(s) = solve(&active, &fit_rows) {
        let rho = math::lag1(resid);
        let infl = math::sqrt((1.0 + rho) / (1.0 - rho));
        let half = fit_rows.len() / 2;
        let (h1, h2) = (
            solve(&active, &fit_rows[..half]),
            solve(&active, &fit_rows[half..]),
        );
        let full = hold_rss(&active);
        let mut worst: Option<(usize, String)> = None;
        found.clear();
        for (i, &j) in active.iter().enumerate() {
            let v = s.theta[nb + i];
            let t = v.abs() / (s.std_err[nb + i] * infl).max(1e-300);
            let mut a = active.clone();
            a.remove(i);
            let practical = hold_rss(&a) / full.max(1e-300) - 1.0;
            let halves = (
                h1.as_ref().map_or(f64::NAN, |h| h.theta[nb + i]),
                h2.as_ref().map_or(f64::NAN, |h| h.theta[nb + i]),
            );
            let mean = 0.5 * (halves.0 + halves.1);
            let consistent = halves.0 * halves.1 > 0.0
                && (halves.0 - halves.1).abs() <= gates.max_half_disagreement * mean.abs();
            let why = if t < gates.min_t {
                Some(alloc::format!(
                    "statistical: |t| = {t:.1} < {}",
                    gates.min_t
                ))
            } else if practical < gates.min_eq_drop {
                Some(alloc::format!(
                    "practical: it lowers the held-out residual by {:.1} % (< {:.1} %)",
                    100.0 * practical,
                    100.0 * gates.min_eq_drop
                ))
            } else if !consistent {
                Some(alloc::format!(
                    "consistency: {:.3e} on the first half of the rows, {:.3e} on the second",
                    halves.0,
                    halves.1
                ))
            } else {
                None
            };
            match why {
                Some(w) => {
                    if worst.is_none() {
                        worst = Some((i, w));
                    }
                }
                None => found.push(Found {
                    term: terms[j],
                    value: v,
                    t,
                    practical,
                    halves,
                }),
            }
        }
        match worst {
            Some((i, w)) => {
                rejected.push((terms[active[i]], w));
                active.remove(i);
            }
            None => break,
        }
    }
    let found: Vec<Found> = found.into_iter().map(steeper_direction).collect();
    let equation = base.mech.equation;
    if found.is_empty() {
        return Ok(Discovery {
            equation,
            terms: found,
            rejected,
            proposal: None,
        });
    }
    // The proposal: sum of coefficient * term.
    let expr = found
        .iter()
        .map(|f| {
            if f.term.expr == "1" {
                String::from(f.term.key)
            } else {
                alloc::format!("{} * {}", f.term.key, paren(f.term.expr))
            }
        })
        .collect::<Vec<_>>()
        .join(" + ");
    let decls: Vec<ParamDecl<'_>> = found
        .iter()
        .map(|f| ParamDecl {
            key: f.term.key,
            unit: f.term.unit,
            value: f.value,
            min: None,
            max: None,
        })
        .collect();
    let def = CustomDef::new(name, ActsOn::LoadTorque, &expr, &decls)
        .map_err(|e| FitError::BadModel(alloc::format!("{e}")))?;
    let mut unknown = def.active();
    for v in unknown.values.iter_mut() {
        *v = f64::NAN;
    }
    let judged = judge(ds, model, base, base_oe, unknown, gates)?;
    let fitted = judged
        .plant
        .custom
        .get(name)
        .copied()
        .unwrap_or_else(|| def.active());
    Ok(Discovery {
        equation,
        terms: found,
        rejected,
        proposal: Some((fitted, judged)),
    })
}

/// `f` told as the slope of the steeper direction: beside B_eq (refitted with the proposal), a
/// negative extra slope forwards is a positive extra slope backwards (omega = max(omega, 0) +
/// min(omega, 0)), the friction a user measures in that direction. Other terms unchanged.
fn steeper_direction(f: Found) -> Found {
    let backwards = LIBRARY.iter().find(|t| t.key == "b_bwd");
    match backwards {
        Some(&term) if f.term.key == "b_fwd" && f.value < 0.0 => Found {
            term,
            value: -f.value,
            halves: (-f.halves.0, -f.halves.1),
            ..f
        },
        _ => f,
    }
}

fn paren(e: &str) -> String {
    if e.contains(' ') && !e.starts_with("sin") && !e.starts_with("cos") && !e.starts_with("abs") {
        alloc::format!("({e})")
    } else {
        String::from(e)
    }
}
