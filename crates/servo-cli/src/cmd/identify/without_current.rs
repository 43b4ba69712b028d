//! `servo identify` on logs without the armature current: the u-driven balance.

use super::*;

impl super::Identify {
    /// Logs of u and angle only: J_eq, B_eq and tau_sf from the u-driven balance with the drive
    /// constants of the params file (see `servo_core::fit::identify_without_current`).
    pub(super) fn run_without_current(
        &self,
        records: &[servo_core::record::Record],
        logs: &[PathBuf],
        parts: &[servo_core::record::part::UsedPart],
        mut params: ModelFile,
    ) -> anyhow::Result<()> {
        use servo_core::fit::{identify_without_current, FitOptions, DRIVE_CONSTANT_TOLERANCE};
        let est = identify_without_current(records, &params.params, &FitOptions::default())
            .map_err(|e| anyhow!("identification from u and angle failed: {e}"))?;
        let tol_pct = 100.0 * DRIVE_CONSTANT_TOLERANCE;
        let note = format!(
            "no log records the armature current: J_eq, B_eq and tau_sf were estimated from u and the angle alone, with the u-driven balance k_drv k_t u / R_eq = J_eq dw/dt + (B_eq + k_t k_e / R_eq) w + tau_sf/N sign(w), taking k_drv = {}, R_eq = {} ohm, k_e = {}, k_t = {} from the params file; their {tol_pct:.0} % tolerance each is added to the intervals",
            params.params.k_drv,
            params.params.r_eq(),
            params.params.k_e,
            params.params.k_t
        );
        if self.json {
            let mut v = serde_json::json!({
                "schema": "servo.identify/1",
                "method": "u-driven balance (no current logged)",
                "b_eq_n_m_s_rad": null, "tau_sf_n_m": null, "j_eq_kg_m2": null,
                "notes": [note],
                "drive_constant_tolerance": DRIVE_CONSTANT_TOLERANCE,
                "logs": logs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "not_identified": [],
                "log_parts": crate::log_part::json(parts),
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
            outln!("{}", serde_json::to_string_pretty(&v)?);
        } else {
            out!("{}", crate::log_part::text(parts));
            outln!("{note}.");
            for e in &est {
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
        }
        if let Some(out) = &self.output {
            for e in &est {
                match e.key {
                    "j_eq" => params.params.j_eq = Some(e.value),
                    "b_eq" => params.params.b_eq = Some(e.value.max(0.0)),
                    "tau_sf" => params.params.tau_sf = Some(e.value.max(0.0)),
                    _ => {}
                }
            }
            params
                .params
                .validate()
                .map_err(|e| anyhow!("identified parameters are not physical: {e}"))?;
            params.save(out)?;
            if !self.json {
                outln!("wrote {}", out.display());
            }
        }
        Ok(())
    }
}
