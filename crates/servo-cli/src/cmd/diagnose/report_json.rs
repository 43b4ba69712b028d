//! `servo diagnose --json`: the report as one object of schema `servo.diagnose/1`
//! (docs/schemas/diagnose.json).

use super::*;
use servo_core::diagnose::checks::Neighbour;

pub(super) fn f(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

pub(super) fn candidate_json(c: &Candidate, opts: &DiagnoseOptions) -> Value {
    let mut params = serde_json::Map::new();
    for p in &c.params {
        params.insert(
            p.key.to_string(),
            json!({ "value": f(p.value), "unit": p.unit, "std_err": p.std_err.map(f), "fitted": p.fitted }),
        );
    }
    json!({
        "effect": c.effect.name(),
        "significant": c.significant,
        "resolvable": c.resolvable,
        "error_reduction_pct": f(c.error_reduction_pct),
        "oe_reduction_pct": c.oe_reduction_pct.map(f),
        "bic_gain": f(c.bic_gain),
        "equation": c.equation.name(),
        "params": params,
        "evidence": c.evidence,
        "experiment": c.experiment,
        "noise_ratio": f(c.noise_ratio),
        "structured_share": f(c.structured_share),
        "gates": servo_core::diagnose::bars::statistical_gates(c, opts).iter().map(|g| json!({
            "bar": g.bar.name, "value": g.bar.value, "unit": g.bar.unit, "rule": g.bar.rule,
            "measured": g.measured.map(f), "passed": g.passed,
        })).collect::<Vec<_>>(),
        "checks": c.checks.iter().map(|k| json!({ "check": k.name, "passed": k.passed, "detail": k.detail })).collect::<Vec<_>>(),
        "joint_with": c.joint_with.map(|k| k.name()),
        "conditional": c.conditional.as_ref().map(|k| {
            let (lo, hi) = k.range();
            json!({
                "key": k.key, "unit": k.unit, "on": k.on, "on_unit": k.on_unit,
                "assumed": f(k.assumed),
                "estimated": k.estimated.map(|(on, v)| json!({ "on_value": f(on), "value": f(v) })),
                "range": [f(lo), f(hi)],
                "rows": k.rows.iter().map(|r| json!({ "on_value": f(r.0), "value": f(r.1), "heldout_oe_cost_rad": f(r.2) })).collect::<Vec<_>>(),
            })
        }),
    })
}

pub(super) fn balance_json(b: &BalanceReport) -> Value {
    json!({
        "balance": b.balance.name(),
        "equation": b.equation.name(),
        "unit": b.equation.unit(),
        "rms": f(b.rms),
        "noise_floor": f(b.floor),
        "ratio_to_noise": f(b.ratio_to_noise),
        "above_noise": b.above_noise,
        "signatures": b.signatures.iter().map(|s| json!({
            "kind": s.kind,
            "description": s.description,
            "share_of_heldout_residual": f(s.share),
            "explained_rms": f(s.explained_rms),
            "measured_on": if s.on_simulation { "simulation" } else { "balance" },
            "rows_and_band": s.measured_on,
            "periodic": s.periodic.map(|p| json!({
                "cycles_per_load_rev": f(p.cycles_per_load_rev),
                "cycles_per_motor_rev": f(p.cycles_per_motor_rev),
                "speed_independent": p.speed_independent,
            })),
        })).collect::<Vec<_>>(),
        "experiment": b.experiment,
    })
}

/// An effect below its balance's noise floor
/// ([`servo_core::diagnose::Unresolvable`]): "not resolvable with these logs".
pub(super) fn unresolvable_json(u: &servo_core::diagnose::Unresolvable) -> Value {
    json!({
        "effect": u.effect.name(),
        "balance": u.equation.name(),
        "unit": u.equation.unit(),
        "size": u.size.map(|(key, unit, value)| json!({ "key": key, "unit": unit, "value": f(value) })),
        "explained_rms": f(u.explained_rms),
        "noise_floor": f(u.floor),
        "experiment": u.experiment,
    })
}

/// The measured friction curve ([`servo_core::diagnose::friction_curve::FrictionCurve`]): bins
/// of both directions, load side, and the shape it shows beyond the base model.
pub(super) fn friction_curve_json(
    c: &servo_core::diagnose::friction_curve::FrictionCurve,
) -> Value {
    json!({
        "balance": c.equation.name(),
        "side": "load",
        "sliding_rows": c.sliding_rows,
        "bins": c.bins.iter().map(|b| json!({
            "direction": b.direction,
            "speed_lo_rad_s": f(b.speed_lo_rad_s),
            "speed_hi_rad_s": f(b.speed_hi_rad_s),
            "speed_rad_s": f(b.speed_rad_s),
            "torque_nm": f(b.torque_nm),
            "ci95_nm": f(b.ci_nm),
            "model_nm": f(b.model_nm),
            "rows": b.rows,
        })).collect::<Vec<_>>(),
        "shape": c.shape.as_ref().map(|s| json!({
            "shape": s.shape.name(),
            "coefficient": f(s.coef),
            "unit": s.unit,
            "t": f(s.t),
            "share_of_heldout_residual": f(s.share),
            "description": s.description,
        })),
    })
}

/// A change of the plant during a log ([`servo_core::diagnose::change::Change`]).
pub(super) fn change_json(c: &servo_core::diagnose::change::Change) -> Value {
    json!({
        "log": c.log + 1,
        "source": c.source,
        "time_s": f(c.time_s),
        "log_s": f(c.log_s),
        "balance": c.equation.name(),
        "unit": c.equation.unit(),
        "params": c.params.iter().map(|p| json!({
            "name": p.name,
            "unit": p.unit,
            "before": f(p.before),
            "after": f(p.after),
            "relative_pct": f(100.0 * p.relative()),
            "share_of_change": f(p.share),
        })).collect::<Vec<_>>(),
        "explained_rms": f(c.explained_rms),
        "noise_floor": f(c.floor),
        "structured_share": f(c.structured_share),
        "further_split_share": f(c.further_share),
        "rows": c.rows,
        "description": c.phrase(),
        "experiment": c.experiment(),
    })
}

/// A lead beyond the catalogue ([`servo_core::diagnose::checks::Neighbour`]); `reference_rad`:
/// the reference's held-out simulation error.
pub(super) fn neighbour_json(n: &Neighbour, reference_rad: Option<f64>) -> Value {
    json!({
        "kind": n.kind,
        "balance": n.balance.name(),
        "description": n.description,
        "parameters": n.params.iter().map(|(key, unit, value)| json!({ "key": key, "unit": unit, "value": f(*value) })).collect::<Vec<_>>(),
        "heldout_oe_cost_rad": f(n.heldout_oe_rad),
        "oe_reduction_pct": reference_rad.map_or(Value::Null, |c0| f(100.0 * (1.0 - n.heldout_oe_rad / c0))),
        "experiment": n.experiment,
    })
}

pub(super) fn thresholds_json(t: &Thresholds) -> Value {
    json!({
        "min_noise_ratio": f(t.min_noise_ratio),
        "min_structured_share": f(t.min_structured_share_pct / 100.0),
        "unexplained_ratio": f(t.unexplained_ratio),
        "min_signature_share": f(t.min_signature_share_pct / 100.0),
        "consistency_tol": f(t.consistency_tol_pct / 100.0),
        "electrical_block_ratio": f(t.electrical_block_ratio),
    })
}

pub(super) fn base_json(d: &Diagnosis) -> Value {
    json!({
        "equations": d.base.equations.iter().map(|(eq, rms, share, occ)| {
            let regimes: serde_json::Map<String, Value> = Regime::ALL.iter().enumerate().map(|(i, r)| {
                (r.name().to_string(), json!({ "share_of_squared_error": f(share[i]), "share_of_samples": f(occ[i]) }))
            }).collect();
            json!({ "equation": eq.name(), "unit": eq.unit(), "rms": f(*rms), "regimes": regimes })
        }).collect::<Vec<_>>(),
        "oe_cost_rad": d.base.oe_cost_rad.map(f),
        "current_noise_a": d.base.current_noise_a.map(f),
    })
}

pub(super) fn rung_json(r: &Rung) -> Value {
    json!({
        "added": r.added.map(|k| k.name()),
        "added_with": r.added_with.map(|k| k.name()),
        "added_also": r.added_also.iter().map(|k| k.name()).collect::<Vec<_>>(),
        "equations": r.equations.iter().map(|(e, rms)| json!({ "equation": e.name(), "unit": e.unit(), "rms": f(*rms) })).collect::<Vec<_>>(),
        "oe_cost_rad": r.oe_cost_rad.map(f),
        "effects": r.plant.effects.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
    })
}

/// Every bar (named threshold) of `opts`, with unit, rule and why.
pub(super) fn bars_json(opts: &DiagnoseOptions) -> Value {
    Value::Array(
        servo_core::diagnose::bars::bars(opts)
            .iter()
            .map(|b| json!({ "name": b.name, "value": b.value, "unit": b.unit, "rule": b.rule, "why": b.why }))
            .collect(),
    )
}

/// The `"save"` object: the gate's verdict and whether the model was written.
pub(super) fn save_json(
    g: &servo_core::compare::gate::Gate,
    path: &std::path::Path,
    saved: bool,
    forced: bool,
) -> Value {
    json!({
        "path": path.display().to_string(),
        "saved": saved,
        "forced": forced,
        "worse": g.worse().is_some(),
        "reason": g.sentence(),
        "held_out_missing": g.held_out_missing,
        "measures": g.measures.iter().map(|m| json!({
            "measure": m.name, "words": m.words, "before": f(m.before), "after": f(m.after),
            "unit": m.unit, "change_pct": f(m.change_pct),
        })).collect::<Vec<_>>(),
        "bar": {
            "name": servo_core::compare::gate::MAX_WORSENING.name,
            "value": servo_core::compare::gate::MAX_WORSENING.value,
            "unit": servo_core::compare::gate::MAX_WORSENING.unit,
            "rule": servo_core::compare::gate::MAX_WORSENING.rule,
            "why": servo_core::compare::gate::MAX_WORSENING.why,
        },
    })
}

/// The linear axis' figures of a diagnosis, added beside the rotary ones: the `transmission`;
/// each candidate's fitted effect and base in linear units (`linear`: keys with unit suffixes,
/// e.g. `tau_sf_pos_n`, `m_eq_kg`); the prediction errors in metres (`oe_cost_m`).
pub(super) fn linear_json(
    v: &mut Value,
    axis: &crate::axis::Axis,
    first: &Diagnosis,
    last: &Diagnosis,
    ladder: &[Rung],
) {
    let s = axis.transmission.metres_per_rad().unwrap_or(f64::NAN);
    v["transmission"] = axis.json();
    let linear = |c: &Candidate| {
        let p = &c.plant.params;
        let mut l = axis.base_json(p.j_eq(), p.b_eq(), p.tau_sf());
        if let Some(e) = c.plant.effects.get(c.effect) {
            if let (Value::Object(m), Value::Object(e)) = (&mut l, axis.effect_json(e)) {
                m.extend(e);
            }
        }
        l
    };
    if let Some(Value::Array(rank)) = v.get_mut("ranking") {
        for (j, c) in rank.iter_mut().zip(&last.ranking) {
            j["linear"] = linear(c);
        }
    }
    v["base"]["oe_cost_m"] = first.base.oe_cost_rad.map_or(Value::Null, |c| f(c * s));
    if let Some(Value::Array(rungs)) = v.get_mut("ladder") {
        for (j, r) in rungs.iter_mut().zip(ladder) {
            j["oe_cost_m"] = r.oe_cost_rad.map_or(Value::Null, |c| f(c * s));
        }
    }
}

/// A friction the sliding rows show that only the simulation refuses (`sliding_fit`).
pub(super) fn sliding_fit_json(s: &servo_core::diagnose::sliding_lead::SlidingFit) -> Value {
    let c = &s.candidate;
    let mut params = serde_json::Map::new();
    for p in c.params.iter().filter(|p| p.effect == Some(c.effect)) {
        params.insert(
            p.key.to_string(),
            json!({ "value": f(p.value), "unit": p.unit }),
        );
    }
    json!({
        "effect": c.effect.name(),
        "params": params,
        "held_out_residual_drop_pct": f(c.error_reduction_pct),
        "held_out_simulation_drop_pct": c.oe_reduction_pct.map(f),
        "bic_gain": f(c.bic_gain),
        "presliding_counts": f(s.extent.counts),
        "presliding_ratio_to_sliding": f(s.extent.ratio),
        "presliding_rows": s.extent.rows,
        "description": s.sentence().trim(),
    })
}
