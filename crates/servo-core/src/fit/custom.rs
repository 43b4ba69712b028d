//! Fitting user-defined effects together with the base parameters.
//!
//! A parameter marked unknown (NaN in [`crate::custom::CustomActive::values`]) is estimated:
//! * a torque effect's parameters that enter the expression *linearly* (checked numerically on
//!   the logged signals, jointly: the expression must be affine in all of them together) become
//!   least-squares columns of the torque balance, next to J_eq, B_eq and tau_sf
//!   ([`torque_columns`], used by [`crate::fit::model::solve_mech`]);
//! * every other unknown parameter (a torque effect's nonlinear ones, an input effect's, a sensor
//!   effect's) is found by a bounded search (grid, then golden section; coordinate-wise in two
//!   passes when there are several) between its `min` and `max`, which must then be finite. The
//!   cost is the residual of the equation where the effect lives: the torque balance (or the
//!   u-driven balance without current) for torques, the electrical balance for an input effect
//!   when the current is logged, and, for a sensor effect, every balance solved again on the
//!   measured angle mapped back through the sensor's inverse (jointly with the base parameters;
//!   see [`sensor_cost`]). The fit that follows runs on that corrected angle
//!   ([`sensor_corrected`]).
//!
//! In the fit, an input effect sees u only (the other signals read 0); the simulator gives it
//! every signal.

use crate::custom::{ActsOn, CustomActive};
use crate::fit::dataset::{Dataset, RecData, Rows};
use crate::fit::{search, FitError};
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

pub use super::custom_columns::{record_signals, torque_columns, TorqueColumn};

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
            let mut base = [0.0; crate::custom::MAX_CUSTOM_PARAMS];
            for (b, s) in base.iter_mut().zip(&start) {
                *b = s + shift;
            }
            for (i, v) in c.values().iter().enumerate() {
                if !v.is_nan() {
                    base[i] = *v;
                }
            }
            for s in points {
                let at = |vals: &[f64; crate::custom::MAX_CUSTOM_PARAMS]| c.def.eval(s, vals);
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
        ActsOn::Sensor => sensor_cost(ds.search_set(), plant),
        _ => per_row(crate::fit::model::solve_mech(ds, &cfg)),
    }
}

/// The cost of a sensor effect's trial values: the measured angle is mapped back through the
/// inverse of the sensor ([`sensor_corrected`]), the balances are solved again on the corrected
/// motion together with the base parameters (an equation-error fit on the corrected angle), and
/// their residuals are pooled as a Gaussian likelihood with one unknown variance per balance:
/// sum over the balances of n ln(rss / n), with n the fit rows of the uncorrected data (the
/// rows selected on the corrected motion differ slightly; each balance's residual enters as a
/// mean per row). A sensor error is not a force: on the measured angle it distorts the speed and
/// the acceleration every balance is written in, by a factor (1 + d(error)/d(theta_l)) that the
/// base parameters cannot absorb unless it is constant.
///
/// A constant factor (a pure scale error, theta_l (1 + s)) is absorbed: J_eq, B_eq and k_e scale
/// by 1/(1 + s) and every balance fits as well. With the base refitted a scale error is
/// therefore not identifiable from the logs (only with the base held, `FitOptions::refit_base`
/// false, whose balances then see it).
fn sensor_cost(ds: &Dataset, plant: &Plant) -> f64 {
    let Ok(corr) = sensor_corrected(ds, plant) else {
        return f64::INFINITY;
    };
    let cfg = corr.config(plant, &[], ds.opts.refit_base);
    let mut total = 0.0;
    let mut pooled = |sol: Option<crate::fit::model::EqSolution>, n_ref: usize| -> bool {
        match sol {
            Some(s) if s.n_fit > 0 && s.rss_fit > 0.0 && s.rss_fit.is_finite() => {
                total += n_ref.max(1) as f64 * crate::math::ln(s.rss_fit / s.n_fit as f64);
                true
            }
            _ => false,
        }
    };
    let n_fit = |rows: &Rows| rows.fit.iter().filter(|f| **f).count();
    if !pooled(
        crate::fit::model::solve_mech(&corr, &cfg),
        n_fit(&ds.mech_rows),
    ) {
        return f64::INFINITY;
    }
    if corr.has_current
        && !corr.elec_rows.is_empty()
        && !pooled(
            crate::fit::model::solve_elec(&corr, &cfg),
            n_fit(&ds.elec_rows),
        )
    {
        return f64::INFINITY;
    }
    total
}

/// `ds` with every record's angle mapped back through the inverse of the sensor effects of
/// `plant` (the true load angle whose reading was logged; [`super::CustomSlots::sensor_inverse`]),
/// prepared again (speeds, accelerations, rows). `ds` itself, cloned, when `plant` has no sensor
/// effect.
pub fn sensor_corrected(ds: &Dataset, plant: &Plant) -> Result<Dataset, FitError> {
    if !plant.custom.has(ActsOn::Sensor) {
        return Ok(ds.clone());
    }
    let n = plant.params.n;
    ds.with_motor_angles(&plant.params, |r: &RecData| {
        (0..r.theta_m_rad.len())
            .map(|k| {
                let s = record_signals(r, n, k);
                n * plant.custom.sensor_inverse(s[0], &s)
            })
            .collect()
    })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compare::Controller;
    use crate::control::{Pid, PidConfig, PidGains};
    use crate::custom::{CustomDef, ParamDecl};
    use crate::fit::{fit_model, FitOptions};
    use crate::record::Record;
    use crate::signal::quantum::quantize;
    use crate::sim::PlantSim;
    use crate::PlantParams;

    fn base() -> Plant {
        Plant::from_params(PlantParams {
            j_eq: Some(7.4e-7),
            b_eq: Some(7.0e-7),
            tau_sf: Some(0.004),
            ..PlantParams::TABLE2
        })
        .unwrap()
    }

    /// A closed-loop PID run of `truth` over steps of several sizes and both signs (4096-count
    /// encoder on the load, +-10 V, current logged), as the fit reads it.
    fn closed_loop(truth: &Plant) -> Record {
        let steps_deg = [
            0.0, 40.0, -30.0, 90.0, -60.0, 10.0, 150.0, 60.0, -120.0, -20.0, 80.0, 0.0,
        ];
        let dt = 1e-3;
        let q = core::f64::consts::TAU / 4096.0;
        let mut sim = PlantSim::new(truth, dt).unwrap();
        let gains = PidGains {
            kp: 7.5244,
            ki: 94.0379,
            kd: 0.1505,
            tl_s: 0.004,
        };
        let mut pid = Pid::new(PidConfig::new(gains, dt).with_symmetric_limit(10.0)).unwrap();
        let mut rec = Record {
            source: "closed loop".into(),
            ..Record::default()
        };
        let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..steps_deg.len() * 1000 {
            let r = f64::to_radians(steps_deg[k / 1000]);
            let y = quantize(sim.state().theta_l_rad, q);
            let u = Controller::update(&mut pid, r, y);
            rec.time_s.push(k as f64 * dt);
            th.push(y);
            ia.push(sim.state().i_a_a);
            uv.push(u);
            sim.step(u);
        }
        (rec.theta_l_rad, rec.i_a_a, rec.u_v) = (Some(th), Some(ia), Some(uv));
        rec
    }

    /// Hides the sensor effect `expr` with `key` = `value` in a closed-loop log, fits it with
    /// `key` unknown and returns the estimate.
    fn recovered(name: &str, expr: &str, key: &str, value: f64, refit_base: bool) -> f64 {
        let decl = |v: f64| ParamDecl {
            key,
            unit: "rad",
            value: v,
            min: Some(-0.1),
            max: Some(0.1),
        };
        let def = CustomDef::new(name, ActsOn::Sensor, expr, &[decl(0.0)]).unwrap();
        let mut truth = base();
        let mut hidden = def.active();
        hidden.set(key, value).unwrap();
        truth.custom.insert(hidden).unwrap();
        let log = closed_loop(&truth);
        let mut start = base();
        let mut unknown = def.active();
        unknown.set(key, f64::NAN).unwrap();
        start.custom.insert(unknown).unwrap();
        let opts = FitOptions {
            refit_base,
            ..FitOptions::default()
        };
        let fit = fit_model(&[log], &start, &[], &opts).unwrap();
        let est = fit.custom.iter().find(|c| c.key == key).unwrap().value;
        std::println!(
            "{expr}: {key} = {est:.5} (true {value}); J_eq {:.4e} B_eq {:.4e}",
            fit.plant.params.j_eq(),
            fit.plant.b_eq()
        );
        est
    }

    #[test]
    fn sensor_effects_of_several_shapes_are_recovered() {
        let cases = [
            ("ecc1", "theta_l + e * sin(theta_l)", 0.02, true),
            ("ecc2", "theta_l + e * cos(2 * theta_l)", -0.015, true),
            ("scale", "theta_l * (1 + s)", 0.03, false),
        ];
        for (name, expr, value, refit) in cases {
            let key = if name == "scale" { "s" } else { "e" };
            let est = recovered(name, expr, key, value, refit);
            assert!(
                (est / value - 1.0).abs() < 0.15,
                "{expr}: {est} for {value}"
            );
        }
    }
}
