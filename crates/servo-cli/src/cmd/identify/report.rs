//! `servo identify`: the text report, the JSON report (schema `servo.identify/1`,
//! docs/schemas/identify.json) and the provenance written to the model file.

use super::*;

impl super::Identify {
    pub(super) fn text_report(&self, r: &Report, logs: &[PathBuf], model: &ModelFile) -> String {
        let p = &model.params;
        let mut s = String::new();
        s.push_str(&format!(
            "servo identify: {} log(s); k_t = {:e} N m/A, k_e = {:e} V s/rad, N = {}\n",
            logs.len(),
            p.k_t,
            p.k_e,
            p.n
        ));
        let line = |name: &str, unit: &str, e: &Estimate, how: &str| {
            format!(
                "  {name:<7}= {:.4e} {unit:<10} se {:.2e}  95% CI [{:.4e}, {:.4e}]  ({how}; residual rms {:.2e}, cond {:.1}, dof {})\n",
                e.value, e.std_err, e.ci95.0, e.ci95.1, e.residual_rms, e.cond, e.dof
            )
        };
        s.push_str("estimates (B_eq, J_eq motor side; tau_sf load side):\n");
        if let Some((e, how)) = r.b_eq() {
            s.push_str(&line("B_eq", "N m s/rad", &e, how));
        }
        if let Some((e, how)) = r.tau_sf() {
            s.push_str(&line("tau_sf", "N m", &e, how));
        }
        if let Some((e, how)) = r.j_eq() {
            s.push_str(&line("J_eq", "kg m^2", &e, how));
        }
        if let Some(axis) = crate::axis::Axis::of(model) {
            s.push_str(&format!("{}; at the load:\n", axis.describe()));
            let (m, f) = (axis.mass_per_j(), axis.force_per_tau());
            if let Some((e, how)) = r.j_eq() {
                s.push_str(&line("m_eq", "kg", &scaled(&e, m), how));
            }
            if let Some((e, how)) = r.b_eq() {
                s.push_str(&line("b_eq", "N s/m", &scaled(&e, m), how));
            }
            if let Some((e, how)) = r.tau_sf() {
                s.push_str(&line("F_c", "N", &scaled(&e, f), how));
            }
        }
        if let Some(el) = &r.electrical {
            s.push_str(&line("k_drv", "V/V", &el.k_drv, "electrical"));
            s.push_str(&line("R_eq", "ohm", &el.r_eq, "electrical"));
            s.push_str(&format!(
                "    datasheet: k_drv = {:.4}, R_eq = {:.4} ohm\n",
                el.nominal_k_drv, el.nominal_r_eq
            ));
            for w in &el.warnings {
                s.push_str(&format!("  WARNING: {w}\n"));
            }
        }
        s.push_str(&self.evidence_text(r));
        for n in notes(r) {
            s.push_str(&format!("  note: {n}\n"));
        }
        for k in &r.skipped {
            match servo_core::ident::auto::absent_experiment(k) {
                Some(what) => s.push_str(&format!("  not part of this run: {what}\n")),
                None => s.push_str(&format!("  not identified: {k}\n")),
            }
        }
        s
    }

    /// What the estimates rest on: one line by default (segments, pairs, samples); with
    /// `--verbose` every constant-speed segment and acceleration/deceleration pair.
    fn evidence_text(&self, r: &Report) -> String {
        let mut s = String::new();
        if !self.verbose {
            let mut parts = Vec::new();
            if let Some(f) = &r.friction {
                parts.push(format!(
                    "friction (4.1) on {} constant-speed segments",
                    f.points.len()
                ));
            }
            if let Some(i) = &r.inertia {
                parts.push(format!(
                    "inertia (4.2) on {} acceleration/deceleration pairs",
                    i.pairs.len()
                ));
            }
            if let Some(c) = &r.combined {
                parts.push(format!("combined LS (4.3) on {} samples", c.rows));
            }
            if !parts.is_empty() {
                let rows = if r.friction.is_some() || r.inertia.is_some() {
                    " (--verbose: each segment and pair)"
                } else {
                    ""
                };
                s.push_str(&format!("from: {}{rows}\n", parts.join("; ")));
            }
            return s;
        }
        if let Some(f) = &r.friction {
            s.push_str(&format!(
                "friction (4.1): {} constant-speed segments\n",
                f.points.len()
            ));
            for pt in &f.points {
                s.push_str(&format!(
                    "    log {} {:7.3}..{:7.3} s  w_m = {:9.2} rad/s  tau_m = {:+.4e} N m\n",
                    pt.experiment + 1,
                    pt.t_start_s,
                    pt.t_end_s,
                    pt.omega_m_rad_s,
                    pt.tau_m_nm
                ));
            }
        }
        if let Some(i) = &r.inertia {
            s.push_str(&format!(
                "inertia (4.2): {} phases, {} acceleration/deceleration pairs\n",
                i.phases.len(),
                i.pairs.len()
            ));
            for &(a, d, j) in &i.pairs {
                let (pa, pd) = (&i.phases[a], &i.phases[d]);
                s.push_str(&format!(
                    "    a+ = {:7.1} rad/s^2 tau_i+ = {:+.3e}  a- = {:7.1} tau_i- = {:+.3e}  J_eq,n = {:.4e} kg m^2\n",
                    pa.accel_rad_s2, pa.tau_i_nm, pd.accel_rad_s2, pd.tau_i_nm, j
                ));
            }
        }
        if let Some(c) = &r.combined {
            s.push_str(&format!("combined LS (4.3): {} samples\n", c.rows));
        }
        if let Some(c) = &r.combined {
            s.push_str(&format!("combined LS (4.3): {} samples\n", c.rows));
        }
        s
    }

    pub(super) fn json_report(
        &self,
        r: &Report,
        logs: &[PathBuf],
        model: &ModelFile,
    ) -> serde_json::Value {
        let est = |e: Option<(Estimate, &'static str)>, unit: &str, side: &str| match e {
            None => serde_json::Value::Null,
            Some((e, how)) => serde_json::json!({
                "value": e.value, "std_err": e.std_err, "ci95": [e.ci95.0, e.ci95.1], "unit": unit, "side": side,
                "method": how, "residual_rms": e.residual_rms, "cond": e.cond, "dof": e.dof, "n": e.n,
            }),
        };
        let mut v = serde_json::json!({
            "schema": "servo.identify/1",
            "method": "experiments (friction, inertia, combined least squares)",
            "b_eq_n_m_s_rad": est(r.b_eq(), "N m s/rad", "motor"),
            "tau_sf_n_m": est(r.tau_sf(), "N m", "load"),
            "j_eq_kg_m2": est(r.j_eq(), "kg m^2", "motor"),
            "logs": logs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "notes": notes(r),
            "not_identified": r.skipped,
        });
        if let Some(el) = &r.electrical {
            v["k_drv"] = est(Some((el.k_drv, "electrical")), "V/V", "driver");
            v["r_eq_ohm"] = est(Some((el.r_eq, "electrical")), "ohm", "armature");
            v["electrical_warnings"] = serde_json::json!(el.warnings);
        }
        if let Some(f) = &r.friction {
            v["friction_points"] = f
                .points
                .iter()
                .map(|p| serde_json::json!({"log": p.experiment, "t_start_s": p.t_start_s, "t_end_s": p.t_end_s, "omega_m_rad_s": p.omega_m_rad_s, "tau_m_n_m": p.tau_m_nm}))
                .collect();
        }
        if let Some(i) = &r.inertia {
            v["inertia_pairs"] = i.pairs.iter().map(|p| serde_json::json!(p.2)).collect();
        }
        if let Some(axis) = crate::axis::Axis::of(model) {
            let (m, f) = (axis.mass_per_j(), axis.force_per_tau());
            let sc =
                |e: Option<(Estimate, &'static str)>, k: f64| e.map(|(e, h)| (scaled(&e, k), h));
            v["transmission"] = axis.json();
            v["m_eq_kg"] = est(sc(r.j_eq(), m), "kg", "load");
            v["b_eq_n_s_m"] = est(sc(r.b_eq(), m), "N s/m", "load");
            v["f_c_n"] = est(sc(r.tau_sf(), f), "N", "load");
        }
        v
    }
}

/// What is said of a negative friction estimate written as 0 to `out`: zero within its 95 %
/// interval (the logs do not measure it), or unphysical (its whole interval below zero).
pub(super) fn clamp_note(name: &str, unit: &str, e: &Estimate, out: &std::path::Path) -> String {
    let v = servo_core::math::sig(e.value, 3);
    if e.ci95.1 >= 0.0 {
        format!(
            "{name} = {v} {unit} is zero within its 95 % interval: written as 0 in {} \
             (the logs hold too little of that friction to measure it)",
            out.display()
        )
    } else {
        format!(
            "{name} came out negative ({v} {unit}): unphysical, written as 0 in {}; \
             the logs hold too little of that friction to measure it, or a torque \
             the model lacks",
            out.display()
        )
    }
}

/// An estimate times a positive factor (a unit conversion: value, error and interval scale).
fn scaled(e: &Estimate, k: f64) -> Estimate {
    Estimate {
        value: e.value * k,
        std_err: e.std_err * k,
        ci95: (e.ci95.0 * k, e.ci95.1 * k),
        ..*e
    }
}

pub(super) fn notes(r: &Report) -> Vec<String> {
    let mut n = Vec::new();
    if let Some(f) = &r.friction {
        n.extend(f.notes.iter().cloned());
    }
    if let Some(i) = &r.inertia {
        n.extend(i.notes.iter().cloned());
    }
    if let Some(c) = &r.combined {
        n.extend(c.notes.iter().cloned());
    }
    n
}

pub(super) fn provenance(r: &Report, logs: &[PathBuf]) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert(
        "tool".into(),
        toml::Value::String(format!("servo identify {}", env!("CARGO_PKG_VERSION"))),
    );
    t.insert("date".into(), toml::Value::String(utc_now()));
    t.insert(
        "logs".into(),
        toml::Value::Array(
            logs.iter()
                .map(|p| toml::Value::String(p.display().to_string()))
                .collect(),
        ),
    );
    let mut methods = Vec::new();
    for (key, e) in [
        ("b_eq", r.b_eq()),
        ("tau_sf", r.tau_sf()),
        ("j_eq", r.j_eq()),
    ] {
        if let Some((e, how)) = e {
            methods.push(format!("{key}: {how}"));
            t.insert(
                format!("{key}_ci95"),
                toml::Value::Array(vec![e.ci95.0.into(), e.ci95.1.into()]),
            );
            t.insert(format!("{key}_std_err"), toml::Value::Float(e.std_err));
        }
    }
    t.insert("method".into(), toml::Value::String(methods.join(", ")));
    if let Some(el) = &r.electrical {
        t.insert(
            "k_drv_identified".into(),
            toml::Value::Float(el.k_drv.value),
        );
        t.insert(
            "r_eq_identified_ohm".into(),
            toml::Value::Float(el.r_eq.value),
        );
    }
    t
}

/// Current UTC time as ISO 8601 (no external crate: civil-from-days).
pub(super) fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Writes the electrical constants named in `keys` (`k_drv`, `r_eq`) as fitted by the
/// electrical balance into `params`, each with its provenance (`<key>_kept`: fitted value,
/// `<key>_datasheet`, `<key>_kept_ci95`, `<key>_kept_method`). An error when the electrical balance was not fitted.
pub(super) fn keep_fitted(
    keys: &[String],
    r: &Report,
    params: &mut servo_core::PlantParams,
    prov: &mut toml::Table,
) -> anyhow::Result<()> {
    if keys.is_empty() {
        return Ok(());
    }
    let Some(el) = &r.electrical else {
        anyhow::bail!(
            "--keep-fitted {}: the electrical balance was not fitted (it needs logs of u, i_a and speed at constant speeds)",
            keys.join(",")
        );
    };
    for key in keys {
        let (est, datasheet) = match key.as_str() {
            "k_drv" => (&el.k_drv, params.k_drv),
            "r_eq" => (&el.r_eq, params.r_eq()),
            other => anyhow::bail!("--keep-fitted: unknown key `{other}` (k_drv or r_eq)"),
        };
        match key.as_str() {
            "k_drv" => params.k_drv = est.value,
            _ => {
                if est.value.is_nan() || est.value <= params.r_s {
                    anyhow::bail!(
                        "--keep-fitted r_eq: the fitted R_eq = {:.4} ohm is not above R_s = {:.4} ohm",
                        est.value,
                        params.r_s
                    );
                }
                params.r_a = est.value - params.r_s;
            }
        }
        // Flat keys, as the rest of [provenance].
        prov.insert(format!("{key}_kept"), toml::Value::Float(est.value));
        prov.insert(format!("{key}_datasheet"), toml::Value::Float(datasheet));
        prov.insert(
            format!("{key}_kept_ci95"),
            toml::Value::Array(vec![est.ci95.0.into(), est.ci95.1.into()]),
        );
        prov.insert(
            format!("{key}_kept_method"),
            toml::Value::String("electrical balance (servo identify --keep-fitted)".into()),
        );
    }
    Ok(())
}
