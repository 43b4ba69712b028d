//! `servo compare --json`: the report as one object of schema `servo.compare/1`
//! (docs/schemas/compare.json).

use super::*;

/// One signal's figures; on a linear axis (`lin`: the travel per radian [m/rad]) the load
/// position and speed are `x` [m] and `v_x` [m/s].
pub(super) fn figures_json(kind: SignalKind, f: &Figures, lin: Option<f64>) -> Value {
    let k = kind.scale_on(lin);
    json!({
        "signal": kind.name_on(lin), "unit": kind.unit_on(lin),
        "fit_pct": finite(f.fit_percent), "rmse": finite(f.rmse * k), "max_error": finite(f.max_abs_error * k),
        "mean_error": finite(f.mean_error * k), "samples": f.samples,
    })
}

pub(super) fn finite(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// Regime statistics pooled over the logs whose headline is `kind` (rms and mean in the unit of
/// [`SignalKind::unit_on`]).
pub(super) fn pooled_regimes(
    c: &ModelComparison,
    kind: SignalKind,
    opts: &CompareOptions,
) -> Vec<Value> {
    let lin = opts.metres_per_rad;
    let k = kind.scale_on(lin);
    let mut per: Vec<(Regime, usize, f64, f64)> =
        Regime::ALL.iter().map(|r| (*r, 0, 0.0, 0.0)).collect();
    let (mut total_n, mut total_se) = (0usize, 0.0);
    for r in c
        .reports
        .iter()
        .filter(|r| r.headline_signal().kind == kind)
    {
        for (e, g) in r.residual.iter().zip(&r.classification.regime) {
            let i = Regime::ALL.iter().position(|x| x == g).unwrap_or(0);
            per[i].1 += 1;
            per[i].2 += e * e;
            per[i].3 += e;
            total_n += 1;
            total_se += e * e;
        }
    }
    let first = c.reports.iter().find(|r| r.headline_signal().kind == kind);
    per.iter()
        .map(|(g, n, se, s)| {
            let time = 100.0 * *n as f64 / total_n.max(1) as f64;
            let err = if total_se > 0.0 {
                100.0 * se / total_se
            } else {
                0.0
            };
            json!({
                "regime": g.name(),
                "where": first.map(|r| regime_phrase_on(*g, &r.classification, &opts.regimes, lin)),
                "samples": n,
                "time_share_pct": time,
                "error_share_pct": err,
                "rms": if *n > 0 { k * (se / *n as f64).sqrt() } else { 0.0 },
                "mean": if *n > 0 { k * s / *n as f64 } else { 0.0 },
                "concentration": if time > 0.0 { err / time } else { 0.0 },
                "suspects": g.suspects(),
            })
        })
        .collect()
}

pub(super) fn to_json(
    logs: &[LogData],
    modes: &[ModeChoice],
    c: &ModelComparison,
    ladder: &[LadderStep],
    opts: &CompareOptions,
) -> Value {
    let pooled_figs = pooled(c);
    let (hk, hf) = pooled_figs[0];
    let lin = opts.metres_per_rad;
    let hs = hk.scale_on(lin);
    let effects: Vec<Value> = c
        .plant
        .effects
        .iter()
        .map(|e| {
            let params: serde_json::Map<String, Value> = e
                .iter()
                .map(|(p, v)| (p.key.to_string(), json!(v)))
                .collect();
            let units: serde_json::Map<String, Value> = e
                .iter()
                .map(|(p, _)| (p.key.to_string(), json!(p.unit)))
                .collect();
            json!({ "effect": e.kind.name(), "params": params, "units": units })
        })
        .collect();
    let p = c.plant.params;
    let base = json!({
        "j_eq_kg_m2": p.j_eq(), "b_eq_n_m_s_rad": c.plant.b_eq(), "tau_sf_n_m": c.plant.tau_sf(),
        "r_eq_ohm": p.r_eq(), "k_e_v_s_rad": p.k_e, "k_t_n_m_a": p.k_t, "k_drv": p.k_drv, "n": p.n,
    });
    let ladder_json: Vec<Value> = ladder
        .iter()
        .map(|s| {
            let (k, f) = s.cmp_fit[0];
            let ks = k.scale_on(lin);
            json!({
                "step": s.label, "effect": s.effect, "signal": k.name_on(lin), "unit": k.unit_on(lin),
                "fit_pct": finite(f.fit_percent), "rmse": finite(f.rmse * ks), "max_error": finite(f.max_abs_error * ks),
                "signals": s.cmp_fit.iter().map(|(k, f)| figures_json(*k, f, lin)).collect::<Vec<_>>(),
                "fitted_params": fitted_json(s),
                "base_refitted": s.base_refitted,
            })
        })
        .collect();
    let mut windows: Vec<(f64, Value)> = Vec::new();
    let total_se: f64 = c
        .reports
        .iter()
        .filter(|r| r.headline_signal().kind == hk)
        .map(|r| r.residual.iter().map(|e| e * e).sum::<f64>())
        .sum();
    for (log, r) in logs
        .iter()
        .zip(&c.reports)
        .filter(|(_, r)| r.headline_signal().kind == hk)
    {
        let se_log: f64 = r.residual.iter().map(|e| e * e).sum();
        for w in &r.worst_windows {
            let share = if total_se > 0.0 {
                w.error_share_pct * se_log / total_se
            } else {
                0.0
            };
            let mut j = json!({
                "log": log.path.display().to_string(),
                "t_start_s": w.t_start_s, "t_end_s": w.t_end_s,
                "error_share_pct": share, "rms": w.rms * hs, "mean": w.mean * hs,
                "regime": w.regime.name(),
                "omega_min_rad_s": w.omega_min_rad_s, "omega_max_rad_s": w.omega_max_rad_s,
                "u_abs_max_v": w.u_abs_max_v,
                "description": describe_window(w, r, opts),
            });
            if let Some(m) = lin {
                j["v_x_min_m_s"] = json!(w.omega_min_rad_s * m);
                j["v_x_max_m_s"] = json!(w.omega_max_rad_s * m);
            }
            windows.push((share, j));
        }
    }
    windows.sort_by(|a, b| b.0.total_cmp(&a.0));
    let r0 = &c.reports[0];
    let x = &r0.input_xcorr;
    let per_log: Vec<Value> = logs
        .iter()
        .zip(c.reports.iter().zip(modes))
        .map(|(l, (r, mc))| {
            json!({
                "log": l.path.display().to_string(),
                "mode": r.mode.name(), "mode_reason": mc.reason,
                "samples": r.time_s.len(), "dt_s": r.dt_s,
                "speed_derived_from_position": l.measured.speed_derived,
                "logged_speed_lag_samples": l.measured.logged_speed_lag_samples,
                "controller": controller_json(l),
                "signal": r.headline_signal().kind.name(),
                "signals": r.signals.iter().map(|s| figures_json(s.kind, &s.figures, lin)).collect::<Vec<_>>(),
                "whiteness": whiteness_json(r),
                "periodic": r.periodic.iter().map(|p| json!({
                    "angle": p.source.name(), "harmonic": p.harmonic, "share_pct": p.share_pct,
                    "amplitude": p.amplitude * r.headline_signal().kind.scale_on(lin), "phase_rad": p.phase_rad, "p_value": p.p_value, "significant": p.significant,
                })).collect::<Vec<_>>(),
                "findings": r.findings,
            })
        })
        .collect();
    json!({
        "schema": "servo.compare/1",
        "mode": r0.mode.name(),
        "mode_reason": modes[0].reason,
        "controller": controller_json(&logs[0]),
        "signal": hk.name_on(lin),
        "unit": hk.unit_on(lin),
        "fit_pct": finite(hf.fit_percent),
        "rmse": finite(hf.rmse * hs),
        "max_error": finite(hf.max_abs_error * hs),
        "signals": pooled_figs.iter().map(|(k, f)| figures_json(*k, f, lin)).collect::<Vec<_>>(),
        "effects": effects,
        "custom": c.plant.custom.iter().map(|e| {
            let params: serde_json::Map<String, Value> = e
                .def
                .params()
                .iter()
                .zip(e.values())
                .map(|(p, v)| (p.key.to_string(), json!(v)))
                .collect();
            let units: serde_json::Map<String, Value> = e
                .def
                .params()
                .iter()
                .map(|p| (p.key.to_string(), json!(p.unit)))
                .collect();
            json!({"effect": e.name(), "acts_on": e.def.acts_on().name(), "expr": e.def.expr(), "params": params, "units": units})
        }).collect::<Vec<_>>(),
        "base": base,
        "ladder": ladder_json,
        "regimes": pooled_regimes(c, hk, opts),
        "worst_windows": windows.into_iter().take(opts.worst_count).map(|(_, v)| v).collect::<Vec<_>>(),
        "whiteness": whiteness_json(r0),
        "input_xcorr": json!({
            "input": r0.input_name, "max_lag": x.max_lag, "bound99": x.bound99, "lags_outside": x.lags_outside,
            "peak_lag": x.peak_lag, "peak": x.peak, "xcorr": x.xcorr,
        }),
        "findings": r0.findings,
        "logs": per_log,
    })
}

pub(super) fn controller_json(log: &LogData) -> Value {
    let Some(r) = &log.controller else {
        return Value::Null;
    };
    let g = &r.config;
    let c = log.check.as_ref();
    let value = |part: &str| r.part(part).map(|p| p.value.clone());
    let parts: serde_json::Map<String, Value> = r
        .parts
        .iter()
        .map(|p| {
            (
                p.part.to_string(),
                json!({ "value": p.value, "text": p.words, "source": p.source }),
            )
        })
        .collect();
    json!({
        "source": r.part("gains").map(|p| p.source.clone()),
        "kp": g.kp, "ki": g.ki, "kd": g.kd, "tl_s": g.tl_s, "ts_s": g.ts_s,
        "discretization": value("discretization"),
        "derivative_on": value("derivative_on"),
        "anti_windup": value("anti_windup"),
        "kw": match g.anti_windup { AntiWindup::BackCalculation { kw } => json!(kw), _ => Value::Null },
        "u_limit_v": log.u_limit.as_ref().map(|l| l.0),
        "feedforward": value("feedforward"),
        "parts": parts,
        "description": r.describe(),
        "notes": log.notes,
        "check_fit_pct": c.map(|c| finite(c.fit_percent)),
        "check_rms_v": c.map(|c| finite(c.rms_v)),
        "check_samples": c.map(|c| c.samples),
        "ls_gains": c.and_then(|c| c.ls_gains).map(|[kp, ki, kd]| json!({"kp": kp, "ki": ki, "kd": kd})),
        "ls_fit_pct": c.map(|c| finite(c.ls_fit_percent)),
    })
}

pub(super) fn whiteness_json(r: &CompareReport) -> Value {
    let w = &r.whiteness;
    json!({
        "signal": r.headline_signal().kind.name(),
        "ljung_box_q": finite(w.ljung_box_q), "dof": w.ljung_box_dof, "p_value": finite(w.ljung_box_p), "white": w.white,
        "bound99": w.bound99, "lags_outside": w.lags_outside, "correlation_lags": w.correlation_lags,
        "autocorr": w.autocorr,
    })
}

/// The parameters fitted at one rung of the ladder, as JSON rows.
fn fitted_json(s: &LadderStep) -> Vec<Value> {
    s.params
        .iter()
        .map(|p| {
            json!({
                "effect": p.effect.map(|k| k.name()),
                "key": p.key, "unit": p.unit, "value": p.value,
                "std_err": p.std_err, "fitted": p.fitted,
            })
        })
        .chain(s.custom.iter().map(|p| {
            json!({
                "effect": p.effect,
                "key": p.key, "unit": p.unit, "value": p.value,
                "std_err": p.std_err, "fitted": p.fitted,
            })
        }))
        .collect()
}

/// The linear axis' additions to the report: the `transmission`, the base in kg, N s/m and N
/// (`base.m_eq_kg`, `base.b_eq_n_s_m`, `base.f_c_n`) and each effect's load-side parameters in
/// linear units (`effects[].linear`, keys with unit suffixes: `tau_sf_pos_n`).
pub(super) fn linear_json(v: &mut Value, axis: &crate::axis::Axis, c: &ModelComparison) {
    v["transmission"] = axis.json();
    let p = &c.plant;
    if let (Some(Value::Object(base)), Value::Object(l)) = (
        v.get_mut("base"),
        axis.base_json(p.params.j_eq(), p.b_eq(), p.tau_sf()),
    ) {
        base.extend(l);
    }
    if let Some(Value::Array(effects)) = v.get_mut("effects") {
        for (j, e) in effects.iter_mut().zip(p.effects.iter()) {
            j["linear"] = axis.effect_json(e);
        }
    }
}

/// The `"compensation_checks"` array: each compensated effect replayed without it per log.
pub(super) fn compensation_checks(
    logs: &[LogData],
    checks: &[servo_core::compare::suspects::CompensationCheck],
) -> Value {
    Value::Array(
        checks
            .iter()
            .map(|c| {
                json!({
                    "log": logs.get(c.log).map(|l| l.name.clone()).unwrap_or_default(),
                    "effect": c.effect.name(),
                    "rmse_with": finite(c.rmse_with),
                    "rmse_without": finite(c.rmse_without),
                    "unit": c.unit,
                    "change_pct": finite(100.0 * c.change()),
                    "suspect": c.suspect,
                    "min_drop_pct": 100.0 * servo_core::compare::suspects::SUSPECT_MIN_DROP,
                })
            })
            .collect(),
    )
}
