//! `servo identify` on logs without the armature current: the u-driven balance.

use super::*;

impl super::Identify {
    /// Logs of u and angle only: J_eq, B_eq and tau_sf from the u-driven balance with the drive
    /// constants of the params file, the file's effects fitted with them, and a dominant
    /// position-dependent load torque found and fitted (see
    /// `servo_core::fit::udriven::identify_without_current_model`).
    pub(super) fn run_without_current(
        &self,
        records: &[servo_core::record::Record],
        logs: &[PathBuf],
        parts: &[servo_core::record::part::UsedPart],
        mut params: ModelFile,
    ) -> anyhow::Result<()> {
        use servo_core::fit::udriven::{
            describe_effects, identify_with_model, identify_without_current_model,
        };
        use servo_core::fit::{FitOptions, DRIVE_CONSTANT_TOLERANCE};
        let base = params.plant().context("--params")?;
        let with_current = !needs_u_driven_balance(records);
        let id = if with_current {
            identify_with_model(records, &base, &FitOptions::default())
                .map_err(|e| anyhow!("identification with the declared effects failed: {e}"))?
        } else {
            identify_without_current_model(records, &base, &FitOptions::default())
                .map_err(|e| anyhow!("identification from u and angle failed: {e}"))?
        };
        let est: Vec<_> = id.estimates.iter().filter(|e| e.effect.is_none()).collect();
        let tol_pct = 100.0 * DRIVE_CONSTANT_TOLERANCE;
        let mut notes = vec![if with_current {
            format!("the params file declares effects: J_eq, B_eq and tau_sf were fitted with them on the torque balance k_t i_a = J_eq dw/dt + B_eq w + tau_sf/N sign(w) + tau_effects/N (and the electrical balance), one least squares over every log (handout 4.3), instead of the dedicated friction and inertia tests; a {tol_pct:.0} % tolerance on each drive constant is added to the intervals")
        } else if params.drive.kind == servo_core::drive::DriveKind::Current {
            format!(
                "current drive: J_eq, B_eq and tau_sf were estimated from the current reference and the angle, with the torque balance k_t i_ref = J_eq dw/dt + B_eq w + tau_sf/N sign(w), the reference through the current loop's lag ({} s) and clipped at its limit, k_t = {} from the params file (nothing electrical is fitted; a measured current is not used); its {tol_pct:.0} % tolerance is added to the intervals",
                crate::cmd::design::sig6(params.drive.loop_lag_s()),
                crate::cmd::design::sig6(params.params.k_t)
            )
        } else if params.drive.kind == servo_core::drive::DriveKind::Duty {
            format!(
                "duty drive: J_eq, B_eq and tau_sf were estimated from the duty and the angle, with the input balance k_t u / R_eq = J_eq dw/dt + (B_eq + k_t k_e / R_eq) w + tau_sf/N sign(w) on the bridge's voltage u = duty x V_supply - dead-time loss, R_eq = {} ohm (R_a + R_s + the supply's {} ohm), k_e = {}, k_t = {} from the params file; their {tol_pct:.0} % tolerance each is added to the intervals",
                crate::cmd::design::sig6(params.params.r_eq()),
                crate::cmd::design::sig6(params.drive.r_supply()),
                crate::cmd::design::sig6(params.params.k_e),
                crate::cmd::design::sig6(params.params.k_t)
            )
        } else {
            format!(
            "no log records the armature current: J_eq, B_eq and tau_sf were estimated from u and the angle alone, with the u-driven balance k_drv k_t u / R_eq = J_eq dw/dt + (B_eq + k_t k_e / R_eq) w + tau_sf/N sign(w), taking k_drv = {}, R_eq = {} ohm, k_e = {}, k_t = {} from the params file; their {tol_pct:.0} % tolerance each is added to the intervals",
            crate::cmd::design::sig6(params.params.k_drv),
            crate::cmd::design::sig6(params.params.r_eq()),
            crate::cmd::design::sig6(params.params.k_e),
            crate::cmd::design::sig6(params.params.k_t)
        )
        }];
        if !id.declared.is_empty() {
            let names: Vec<&str> = id.declared.iter().map(|k| k.name()).collect();
            notes.push(format!(
                "the effects declared in the params file were fitted with the base: {}",
                names.join(", ")
            ));
        }
        if let Some(d) = &id.dominant {
            notes.push(format!(
                "a position-dependent load torque dominates the balance: {} explains {:.1} % of the base fit's residual (without it J_eq = {:.4e} kg m^2, B_eq = {:.4e} N m s/rad, absorbing it); it was fitted with the base; declare it in the params file ([effects.{}]) to fit it from the start",
                d.effect.name(),
                100.0 * d.share,
                d.bare_j_eq_kg_m2,
                d.bare_b_eq_n_m_s_rad,
                d.effect.name()
            ));
        }
        for (key, v) in &id.clamped {
            notes.push(format!(
                "WARNING: {key} came out negative ({v:.4e}): unphysical, written as 0 with -o; the model lacks a torque the logs hold, or the drive constants are off"
            ));
        }
        for e in id.estimates.iter().filter(|e| e.effect.is_none()) {
            if let Some(why) = not_determined(e) {
                notes.push(format!("{} not determined by these logs: {why}", e.key));
            }
        }
        let effect_lines = describe_effects(&id);
        if self.json {
            let mut v = serde_json::json!({
                "schema": "servo.identify/1",
                "method": if with_current { "model fit with the declared effects" } else { "u-driven balance (no current logged)" },
                "b_eq_n_m_s_rad": null, "tau_sf_n_m": null, "j_eq_kg_m2": null,
                "notes": notes,
                "effects_fitted": id.estimates.iter().filter(|e| e.effect.is_some()).map(|e| serde_json::json!({
                    "effect": e.effect.map(|k| k.name()),
                    "key": e.key, "unit": e.unit, "value": e.value,
                    "std_err": e.std_err.is_finite().then_some(e.std_err),
                    "std_err_with_drive_tolerance": e.std_err_total,
                    "how": if id.declared.iter().any(|k| Some(*k) == e.effect) { "declared" } else { "found dominant" },
                })).collect::<Vec<_>>(),
                "dominant_torque": id.dominant.as_ref().map(|d| serde_json::json!({
                    "effect": d.effect.name(), "share_of_residual": d.share,
                    "bare_j_eq_kg_m2": d.bare_j_eq_kg_m2,
                    "bare_b_eq_n_m_s_rad": d.bare_b_eq_n_m_s_rad,
                })),
                "drive_constant_tolerance": DRIVE_CONSTANT_TOLERANCE,
                "logs": logs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "not_identified": [],
                "log_parts": crate::log_part::json(parts),
                "sysid": self.sysid.json(),
            });
            for e in &est {
                // keys of the JSON convention (docs/schemas/README.md): quantity and SI unit
                let key = match e.key {
                    "j_eq" => "j_eq_kg_m2",
                    "b_eq" => "b_eq_n_m_s_rad",
                    "tau_sf" => "tau_sf_n_m",
                    "r_eq" => "r_eq_ohm",
                    other => other,
                };
                v[key] = serde_json::json!({
                    "value": e.value, "unit": e.unit,
                    "side": if e.key == "tau_sf" { "load" } else { "motor" },
                    "method": "u-driven balance", "std_err": e.std_err,
                    "std_err_with_drive_tolerance": e.std_err_total,
                    "widening": (e.std_err > 0.0).then(|| e.std_err_total / e.std_err),
                });
            }
            // A linear axis: the same estimates in the user's units (kg, N s/m, N at the load).
            if let Some(axis) = crate::axis::Axis::of(&params) {
                v["transmission"] = axis.json();
                for e in &est {
                    let (key, unit, k) = match e.key {
                        "j_eq" => ("m_eq_kg", "kg", axis.mass_per_j()),
                        "b_eq" => ("b_eq_n_s_m", "N s/m", axis.mass_per_j()),
                        "tau_sf" => ("f_c_n", "N", axis.force_per_tau()),
                        _ => continue,
                    };
                    v[key] = serde_json::json!({
                        "value": k * e.value, "unit": unit, "side": "load",
                        "method": "u-driven balance", "std_err": k * e.std_err,
                        "std_err_with_drive_tolerance": k * e.std_err_total,
                        "widening": (e.std_err > 0.0).then(|| e.std_err_total / e.std_err),
                    });
                }
            }
            crate::json_out::emit(&v)?;
        } else {
            out!("{}{}", crate::log_part::text(parts), self.sysid.text());
            for note in &notes {
                outln!("{note}.");
            }
            for e in &est {
                if not_determined(e).is_some() {
                    outln!(
                        "  {:<7}   not determined by these logs (pinned at its bound {} {}; see above)",
                        e.key,
                        servo_core::math::sig(e.value.max(0.0), 4),
                        e.unit
                    );
                    continue;
                }
                outln!(
                    "  {:<7} = {:.4e} {:<10} +/- {:.2e} (statistical) -> +/- {:.2e} with the drive-constant tolerance ({:.1}x wider)",
                    e.key,
                    e.value,
                    e.unit,
                    e.std_err,
                    e.std_err_total,
                    if e.std_err > 0.0 { e.std_err_total / e.std_err } else { f64::NAN }
                );
            }
            if let Some(axis) = crate::axis::Axis::of(&params) {
                outln!("{} (load side):", axis.describe());
                for e in &est {
                    let (name, unit, k) = match e.key {
                        "j_eq" => ("m_eq", "kg", axis.mass_per_j()),
                        "b_eq" => ("b_eq", "N s/m", axis.mass_per_j()),
                        "tau_sf" => ("F_c", "N", axis.force_per_tau()),
                        _ => continue,
                    };
                    outln!(
                        "  {name:<7} = {:.4e} {unit:<10} +/- {:.2e} with the drive-constant tolerance",
                        k * e.value,
                        k * e.std_err_total
                    );
                }
            }
            for line in &effect_lines {
                outln!("  {line}");
            }
        }
        if let Some(out) = &self.output {
            for e in &est {
                match e.key {
                    "j_eq" => params.params.j_eq = Some(e.value),
                    "b_eq" => {
                        params.params.b_eq = Some(e.value.max(0.0));
                        params
                            .effects
                            .remove(servo_core::effects::EffectKind::Viscous);
                    }
                    "tau_sf" => {
                        params.params.tau_sf = Some(e.value.max(0.0));
                        params
                            .effects
                            .remove(servo_core::effects::EffectKind::Coulomb);
                    }
                    _ => {}
                }
            }
            for k in id
                .declared
                .iter()
                .chain(id.dominant.as_ref().map(|d| &d.effect))
            {
                if let Some(e) = id.plant.effects.get(*k) {
                    params.effects.insert(*e);
                }
            }
            params
                .params
                .validate()
                .map_err(|e| anyhow!("identified parameters are not physical: {e}"))?;
            params.save_over(out, &crate::model_file::ModelFile::FRICTION_KINDS)?;
            if !self.json {
                outln!("wrote {}", out.display());
            }
        }
        Ok(())
    }
}

/// Why a base estimate is not determined by the logs (None when it is): the fit pinned it at
/// its bound (0: a negative friction or inertia is unphysical), where it has no standard error,
/// and the experiment that would determine it.
fn not_determined(e: &servo_core::fit::UDrivenEstimate) -> Option<String> {
    if e.std_err.is_finite() && e.std_err_total.is_finite() {
        return None;
    }
    let experiment = match e.key {
        "b_eq" => "a torque that grows with speed needs constant-speed segments at several speeds (the friction staircase of `servo identify --ramp`, or a log of it with the current)",
        "tau_sf" => "a Coulomb level needs slow motion in both directions (the friction staircase of `servo identify --ramp`)",
        "j_eq" => "an inertia needs strong accelerations (the inertia ramps of `servo identify --ramp`, or a step or a sine)",
        _ => "a log that excites it",
    };
    Some(format!(
        "the fit pinned it at its bound {} {} (a negative value is unphysical), where it has no interval; the logs hold too little of it next to the other torques. Written as {} with -o. To determine it: {experiment}",
        servo_core::math::sig(e.value.max(0.0), 4),
        e.unit,
        servo_core::math::sig(e.value.max(0.0), 4)
    ))
}
