//! `servo design --json`: the report as one object of schema `servo.design/1`
//! (docs/schemas/design.json).

use super::*;

impl super::Design {
    pub(super) fn json_report(&self, out: &Outcome, tr: &Translation, src: &PlantSource) -> Value {
        let r = &out.report;
        let g = &r.gains;
        let st = &out.structure;
        let ls = r.request.spec;
        let model = self.design_model(r);
        let p_gc = model.response(ls.omega_gc);
        let (dk, dphi) = required_compensation(&ls, p_gc);
        let plant = match r.request.reduced {
            PlantModel::Reduced { k_m, t_m, n } => json!({"k_m": k_m, "t_m_s": t_m, "n": n}),
            PlantModel::Full { .. } => Value::Null,
        };
        json!({
            "schema": "servo.design/1",
            "controller": r.request.kind.name(),
            "kp": g.kp, "ki": g.ki, "kd": g.kd,
            "ti_s": num(g.ti_s()), "td_s": num(g.td_s()), "tl_s": g.tl_s,
            "wgc_rad_s": ls.omega_gc, "pm_deg": deg(ls.phase_margin), "pm_rad": ls.phase_margin,
            "delta": tr.delta, "alpha": r.request.alpha, "ts_s": r.request.ts_s,
            "translated": {"wgc_rad_s": tr.spec.omega_gc, "pm_deg": deg(tr.spec.phase_margin)},
            "discretization": r.request.discretization.name(),
            "derivative_on": derivative_name(st.derivative_on),
            "kw": st.kw_per_s,
            "u_limit_v": st.u_limit_v,
            "exact": self.exact,
            "meet_specs": out.meet.as_ref().map(|(m, ms)| meet_json(m, *ms)),
            "design_model": model.name(),
            "plant_source": src.label,
            "reduced_model": plant,
            "p_jwgc": {"re": p_gc.re, "im": p_gc.im},
            "delta_k": dk, "delta_phi_rad": dphi,
            "handout_gains": {"kp": r.handout_gains.kp, "ki": r.handout_gains.ki, "kd": r.handout_gains.kd},
            "achieved": {
                "reduced": achieved_json(&r.reduced),
                "full": r.full.as_ref().map(achieved_json).unwrap_or(Value::Null),
                "discrete": achieved_json(&r.discrete),
            },
            "time_specs": out.check.as_ref().map(check_json),
            "run_check": out.run_check.as_ref().map(run_json),
            "compensation_check": Value::Null,
            "transfer_functions": tf_json(r, st),
        })
    }
}

pub(super) fn check_json(c: &RangeCheck) -> Value {
    let sp = &c.specs;
    json!({
        "overshoot_max_pct": sp.overshoot_max.map(|m| 100.0 * m),
        "speed": match sp.speed {
            Some(SpeedTarget::Settling { band, time_s }) => json!({"kind": "settling", "band": band, "time_s": time_s}),
            Some(SpeedTarget::Rise { time_s }) => json!({"kind": "rise_10_90", "time_s": time_s}),
            None => Value::Null,
        },
        "step_min_rad": sp.step_min_rad,
        "step_max_rad": sp.step_max_rad,
        "loop": {
            "derivative_on": derivative_name(c.structure.derivative_on),
            "kw": c.structure.kw_per_s,
            "u_limit_v": c.structure.u_limit_v,
            "discretization": c.structure.discretization.name(),
        },
        "met": c.met(),
        "worst_overshoot_pct": c.worst_overshoot_pct,
        "worst_speed_s": c.worst_speed_s,
        "worst_ratio": c.worst_ratio,
        "overshoot_excess_pct": c.overshoot_excess_pct(),
        "speed_excess_s": c.speed_excess_s().map(num),
        "steps": c.outcomes.iter().map(|o| json!({
            "step_rad": o.step_rad,
            "overshoot_pct": o.overshoot_pct,
            "settling_time_s": o.settling_time_s,
            "rise_time_s": o.rise_time_s,
            "peak_u_v": o.peak_u_v,
            "saturated_fraction": o.saturated_fraction,
        })).collect::<Vec<_>>(),
    })
}

pub(super) fn meet_json(m: &MeetResult, ms: f64) -> Value {
    let p = &m.params;
    let dm = &m.report.discrete.margins;
    json!({
        "feasible": m.feasible,
        "closest_pair": {
            "overshoot_pct": m.check.worst_overshoot_pct,
            "speed_s": m.check.worst_speed_s,
        },
        "wgc_rad_s": p.omega_gc,
        "pm_deg": deg(p.phase_margin),
        "alpha": p.alpha,
        "tl_factor": p.tl_factor,
        "derivative_on": derivative_name(p.derivative_on),
        "kw": p.kw_per_s,
        "margins": {
            "pm_deg": num(dm.phase_margin_deg),
            "wgc_rad_s": num(dm.omega_gc),
            "gm_db": num(dm.gain_margin_db),
            "sensitivity_peak": m.sensitivity_peak,
        },
        "evaluations": m.evaluations,
        "elapsed_ms": ms,
    })
}

/// Coefficient lists in descending powers (MATLAB `tf(num, den)`, python-control
/// `control.tf(num, den[, dt])`).
pub(super) fn tf_entry(t: &TransferFunction) -> Value {
    json!({
        "num": TransferFunction::descending(&t.num),
        "den": TransferFunction::descending(&t.den),
    })
}

pub(super) fn tf_json(r: &DesignReport, st: &LoopStructure) -> Value {
    let g = &r.gains;
    let ts = r.request.ts_s;
    let method = r.request.discretization;
    // the reference path: C(s) with the derivative on the error, K_P + K_I/s on the measurement
    let g_ref = match st.derivative_on {
        DerivativeOn::Error => *g,
        DerivativeOn::Measurement => PidGains { kd: 0.0, ..*g },
    };
    let plant = r.request.full.unwrap_or(r.request.reduced);
    let mut cz = tf_entry(&controller_tf_z(g, ts, method));
    cz["ts_s"] = json!(ts);
    let mut crz = tf_entry(&controller_tf_z(&g_ref, ts, method));
    crz["ts_s"] = json!(ts);
    let mut p = tf_entry(&plant.transfer_function());
    p["model"] = json!(plant.name());
    let mut pr = tf_entry(&r.request.reduced.transfer_function());
    pr["model"] = json!("reduced");
    json!({
        "ordering": "coefficients in descending powers of s or z, as MATLAB tf(num, den) and python-control tf(num, den[, dt])",
        "loop": "u = C_r r - C y: the feedback controller C acts on the measurement y [rad], C_r on the reference r [rad] (C_r = C with the derivative on the error, K_P + K_I/s with it on the measurement)",
        "plant_s": p,
        "plant_reduced_s": pr,
        "controller_s": tf_entry(&controller_tf_s(g)),
        "controller_z": cz,
        "controller_ref_s": tf_entry(&controller_tf_s(&g_ref)),
        "controller_ref_z": crz,
    })
}

pub(super) fn num(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

pub(super) fn achieved_json(a: &Achieved) -> Value {
    let m = &a.margins;
    let st = a.step;
    json!({
        "plant": a.plant,
        "pm_deg": num(m.phase_margin_deg),
        "wgc_rad_s": num(m.omega_gc),
        "gm_db": num(m.gain_margin_db),
        "wpc_rad_s": num(m.omega_pc),
        "gain_crossovers": m.gain_crossovers,
        "overshoot_pct": st.map(|s| s.overshoot_pct),
        "rise_time_s": st.and_then(|s| s.rise_time_s),
        "settling_time_5pct_s": st.and_then(|s| s.settling_time_5pct_s),
        "settling_time_1pct_s": st.and_then(|s| s.settling_time_1pct_s),
        "stable": a.stability == Stability::Stable,
        "stability": stability_name(a.stability).to_lowercase(),
        "poles": a.poles.iter().map(|p| json!([p.re, p.im])).collect::<Vec<_>>(),
    })
}
