//! Fitting user-defined effects together with the base parameters.
//!
//! A parameter marked unknown (NaN in [`super::CustomActive::values`]) is estimated:
//! * a torque effect's parameters that enter the expression *linearly* (checked numerically on
//!   the logged signals, jointly: the expression must be affine in all of them together) become
//!   least-squares columns of the torque balance, next to J_eq, B_eq and tau_sf
//!   ([`torque_columns`], used by [`crate::fit::model::solve_mech`]);
//! * every other unknown parameter (a torque effect's nonlinear ones, an input effect's, a sensor
//!   effect's) is found by a bounded search (grid, then golden section; coordinate-wise in two
//!   passes when there are several) between its `min` and `max`, which must then be finite. The
//!   cost is the residual of the equation where the effect lives: the torque balance (or the
//!   u-driven balance without current) for torques, the electrical balance for an input effect
//!   when the current is logged, and the simulated angle over short segments
//!   ([`crate::fit::oe`]) for a sensor effect, which no balance sees apart from J_eq and B_eq.
//!
//! In the fit, an input effect sees u only (the other signals read 0); the simulator gives it
//! every signal.

use super::{ActsOn, CustomActive};
use crate::fit::dataset::{Dataset, RecData, Rows};
use crate::fit::{search, FitError};
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

/// A torque-balance column of a user effect: its part with every unknown parameter at 0
/// (`param` = None, coefficient 1), or its derivative with respect to unknown parameter `param`
/// of effect `slot` (coefficient = the parameter).
#[derive(Debug, Clone)]
pub struct TorqueColumn {
    pub col: Vec<f64>,
    pub slot: usize,
    pub param: Option<usize>,
    /// The parameter's lower bound is >= 0.
    pub non_negative: bool,
}

/// The signals of a record at sample `k` ([`super::SIGNALS`] order): the angle and speed as
/// logged (motor side; load = motor / N), the current (0 when not logged), u and t.
#[inline]
pub fn record_signals(r: &RecData, n: f64, k: usize) -> [f64; 7] {
    let th = r.theta_m_rad.get(k).copied().unwrap_or(0.0);
    let w = r.omega_raw.get(k).copied().unwrap_or(0.0);
    let i = r
        .i_raw
        .as_ref()
        .and_then(|i| i.get(k).copied())
        .unwrap_or(0.0);
    let u = r.u_v.get(k).copied().unwrap_or(0.0);
    let t = r.time_s.get(k).copied().unwrap_or(0.0);
    [th / n, th, w / n, w, i, u, t]
}

/// Columns of the user torque effects of `plant` at `rows` (filtered like every regressor),
/// expressed as torques at the motor (load torques through 1/N).
pub fn torque_columns(ds: &Dataset, plant: &Plant, rows: &Rows) -> Vec<TorqueColumn> {
    let n = plant.params.n;
    let mut out = Vec::new();
    for (si, c) in plant.custom.iter().enumerate() {
        let scale = match c.def.acts_on() {
            ActsOn::LoadTorque => 1.0 / n,
            ActsOn::MotorTorque => 1.0,
            _ => continue,
        };
        let mut v0 = c.values;
        for v in v0.iter_mut() {
            if v.is_nan() {
                *v = 0.0;
            }
        }
        let col_at = |vals: [f64; super::MAX_CUSTOM_PARAMS], minus: bool| {
            ds.column(rows, |r: &RecData| {
                (0..r.theta_m_rad.len())
                    .map(|k| {
                        let s = record_signals(r, n, k);
                        let mut y = c.def.eval(&s, &vals);
                        if minus {
                            y -= c.def.eval(&s, &v0);
                        }
                        let y = y * scale;
                        if y.is_finite() {
                            y
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
        };
        out.push(TorqueColumn {
            col: col_at(v0, false),
            slot: si,
            param: None,
            non_negative: false,
        });
        for (j, v) in c.values().iter().enumerate() {
            if v.is_nan() {
                let mut vj = v0;
                vj[j] = 1.0;
                out.push(TorqueColumn {
                    col: col_at(vj, true),
                    slot: si,
                    param: Some(j),
                    non_negative: c.def.params()[j].min >= 0.0,
                });
            }
        }
    }
    out
}

/// Up to 400 sample points spread over the torque-balance rows, as signal vectors.
fn probe_points(ds: &Dataset, n: f64) -> Vec<[f64; 7]> {
    let rows = &ds.mech_rows;
    let m = rows.len();
    let step = (m / 400).max(1);
    (0..m)
        .step_by(step)
        .map(|i| record_signals(&ds.recs[rows.rec[i]], n, rows.k[i]))
        .collect()
}

/// Which unknown parameters of `c` enter its expression jointly linearly (affine), checked on
/// `points` with the other parameters at two different settings; greedy in declaration order.
fn linear_params(c: &CustomActive, points: &[[f64; 7]]) -> Vec<bool> {
    let np = c.def.params().len();
    let start: Vec<f64> = c
        .def
        .params()
        .iter()
        .map(|p| if p.value != 0.0 { p.value } else { 0.37 })
        .collect();
    let mut lin = alloc::vec![false; np];
    let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-7 * (1.0 + scale);
    for j in 0..np {
        if !c.values[j].is_nan() {
            continue;
        }
        let mut ok = true;
        'settings: for shift in [0.0, 0.61] {
            let mut base = [0.0; super::MAX_CUSTOM_PARAMS];
            for (b, s) in base.iter_mut().zip(&start) {
                *b = s + shift;
            }
            for (i, v) in c.values().iter().enumerate() {
                if !v.is_nan() {
                    base[i] = *v;
                }
            }
            for s in points {
                let at = |vals: &[f64; super::MAX_CUSTOM_PARAMS]| c.def.eval(s, vals);
                let mut v = base;
                v[j] = 0.0;
                let e0 = at(&v);
                v[j] = 1.0;
                let e1 = at(&v);
                v[j] = 2.0;
                let e2 = at(&v);
                let scale = e0.abs() + e1.abs() + e2.abs();
                if !(e0.is_finite()
                    && e1.is_finite()
                    && e2.is_finite()
                    && close(e2 - e1, e1 - e0, scale))
                {
                    ok = false;
                    break 'settings;
                }
                for i in (0..j).filter(|&i| lin[i]) {
                    let mut w = base;
                    w[i] = 0.0;
                    w[j] = 0.0;
                    let a = at(&w);
                    w[i] = 1.0;
                    let b = at(&w);
                    w[j] = 1.0;
                    let d = at(&w);
                    w[i] = 0.0;
                    let cc = at(&w);
                    let scale = a.abs() + b.abs() + cc.abs() + d.abs();
                    if !close(d - b - cc + a, 0.0, scale) {
                        ok = false;
                        break 'settings;
                    }
                }
            }
        }
        lin[j] = ok;
    }
    lin
}

/// A parameter to search: effect slot, parameter index, bounds.
#[derive(Debug, Clone, Copy)]
struct Searched {
    slot: usize,
    param: usize,
    lo: f64,
    hi: f64,
    place: ActsOn,
}

/// Sets every unknown parameter of the user effects of `plant` that least squares cannot
/// estimate (see the module documentation) by a bounded search on `ds`; the linear ones of the
/// torque effects stay unknown for the least-squares fit that follows.
pub fn search_nonlinear(ds: &Dataset, plant: &mut Plant) -> Result<(), FitError> {
    if plant.custom.iter().all(|c| c.is_complete()) {
        return Ok(());
    }
    let n = plant.params.n;
    let points = probe_points(ds, n);
    let mut searched = Vec::new();
    for (si, c) in plant.custom.iter().enumerate() {
        let place = c.def.acts_on();
        let lin = if place.is_torque() {
            linear_params(c, &points)
        } else {
            alloc::vec![false; c.def.params().len()]
        };
        for (j, p) in c.def.params().iter().enumerate() {
            if !c.values[j].is_nan() || lin[j] {
                continue;
            }
            if !(p.min.is_finite() && p.max.is_finite()) {
                return Err(FitError::BadModel(alloc::format!(
                    "user effect `{}`: `{}` {}; give it finite min and max to search it, or give its value and do not fit it",
                    c.name(),
                    p.key,
                    if place.is_torque() {
                        "enters the expression nonlinearly"
                    } else {
                        "belongs to an input or sensor effect, which is fitted by search"
                    }
                )));
            }
            if place == ActsOn::Input && !ds.has_input {
                return Err(FitError::NoData(alloc::format!(
                    "user effect `{}` acts on the input, and no log has u",
                    c.name()
                )));
            }
            searched.push(Searched {
                slot: si,
                param: j,
                lo: p.min,
                hi: p.max,
                place,
            });
        }
    }
    // Start every searched parameter at its declared value.
    for s in &searched {
        if let Some(c) = plant.custom.iter_mut().nth(s.slot) {
            c.values[s.param] = c.def.params()[s.param].value;
        }
    }
    let passes = if searched.len() > 1 { 2 } else { 1 };
    for _ in 0..passes {
        for s in &searched {
            let mut trial = *plant;
            let mut f = |x: f64| {
                if let Some(c) = trial.custom.iter_mut().nth(s.slot) {
                    c.values[s.param] = x;
                }
                cost(ds, &trial, s.place)
            };
            let grid = search::linspace(s.lo, s.hi, 21);
            let (x, _) = search::grid_then_golden(&grid, &mut f, 20).ok_or_else(|| {
                FitError::Singular(String::from(
                    "a user effect: no finite cost over its search range",
                ))
            })?;
            if let Some(c) = plant.custom.iter_mut().nth(s.slot) {
                c.values[s.param] = x;
            }
        }
    }
    Ok(())
}

/// The cost a parameter of an effect at `place` is searched on.
fn cost(ds: &Dataset, plant: &Plant, place: ActsOn) -> f64 {
    let cfg = ds.config(plant, &[], ds.opts.refit_base);
    let per_row = |s: Option<crate::fit::model::EqSolution>| {
        s.map_or(f64::INFINITY, |s| s.rss_fit / s.n_fit.max(1) as f64)
    };
    match place {
        ActsOn::Input if ds.has_current => per_row(crate::fit::model::solve_elec(ds, &cfg)),
        ActsOn::Sensor => {
            // The linear unknowns of torque effects are estimated first; the simulation needs
            // every value.
            match ds.solve_config(&cfg) {
                Ok(solved) => {
                    crate::fit::oe::prediction_cost(ds, &solved.plant, crate::fit::oe::Part::Fit)
                        .unwrap_or(f64::INFINITY)
                }
                Err(_) => f64::INFINITY,
            }
        }
        _ => per_row(crate::fit::model::solve_mech(ds, &cfg)),
    }
}

/// The plant with only its complete user effects (the model "as given" before a fit).
pub fn without_unknown(plant: &Plant) -> Plant {
    let mut p = *plant;
    let names: Vec<&'static str> = p
        .custom
        .iter()
        .filter(|c| !c.is_complete())
        .map(|c| c.name())
        .collect();
    for name in names {
        p.custom.remove(name);
    }
    p
}

/// One fitted parameter of a user effect.
#[derive(Debug, Clone, PartialEq)]
pub struct CustomEstimate {
    pub effect: &'static str,
    pub key: &'static str,
    pub unit: &'static str,
    pub value: f64,
    /// Least-squares standard error (linear parameters only).
    pub std_err: Option<f64>,
    /// Estimated (true) or kept as given.
    pub fitted: bool,
}
