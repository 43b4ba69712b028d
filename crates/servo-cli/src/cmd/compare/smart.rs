//! `servo compare` with a smart servo's model (`[drive] kind = "position"`): each log replayed
//! in closed loop from its goal positions through the firmware's loop
//! (`servo_core::smart::replay`; with the torque off, an open bridge), the position error as
//! MAE beside RMSE.

use super::Compare;
use crate::model_file::ModelFile;
use anyhow::{bail, Context};
use serde_json::json;
use servo_core::smart::{self, PositionError, SmartLog};

/// The flags of a smart servo's comparison.
#[derive(Debug, Clone, clap::Args)]
pub struct SmartCompareArgs {
    /// A smart servo's model: the firmware's P gain each log was taken at (vendor units), once
    /// for every log or once per log; default the log's own (a BAM log's `kp`), else the
    /// model's `[smart_servo] kp_fw`.
    #[arg(long = "kp-fw", value_name = "KP", value_delimiter = ',')]
    pub kp_fw: Vec<f64>,
}

/// Whether `model` is a smart servo's (then [`run`] compares).
pub fn applies(model: &ModelFile) -> bool {
    model.smart_servo.is_some()
}

/// Replays each log through the model's firmware loop and prints the position errors.
pub fn run(cmd: &Compare, model: &ModelFile) -> anyhow::Result<()> {
    let Some(sm) = model.smart_servo else {
        bail!("--model {}: not a smart servo's model", cmd.model.display());
    };
    let refused = [
        ("--gains", cmd.gains.is_some()),
        ("--gains-from-log", cmd.gains_from_log),
        ("--add", !cmd.add.is_empty()),
        ("--save", cmd.save.is_some()),
        ("--columns", cmd.columns.is_some()),
        ("--mode", cmd.mode.is_some()),
        ("--plot", cmd.plot.is_some()),
    ];
    if let Some((flag, _)) = refused.iter().find(|(_, given)| *given) {
        bail!(
            "{flag} is not for a smart servo's model (--model {} has [drive] kind = \"position\"): its logs are replayed from the goal positions through the firmware's loop",
            cmd.model.display()
        );
    }
    let kp = &cmd.smart.kp_fw;
    if !(kp.len() <= 1 || kp.len() == cmd.logs.len()) {
        bail!(
            "--kp-fw given {} times for {} logs: give it once (every log) or once per log",
            kp.len(),
            cmd.logs.len()
        );
    }
    if let Some(k) = kp.iter().find(|k| !(**k > 0.0 && k.is_finite())) {
        bail!("--kp-fw must be a positive gain, got {k}");
    }
    let params = sm.params(&model.params, &model.effects);
    let mut rows = Vec::new();
    let mut parts = Vec::new();
    for (i, path) in cmd.logs.iter().enumerate() {
        let log: SmartLog = servo_io::smart_log::read_smart(path)
            .with_context(|| format!("reading log {}", path.display()))?;
        let kp_fw = kp.get(i.min(kp.len().max(1) - 1)).copied().or(log.kp_fw);
        let drive = sm.position_loop(&model.drive, kp_fw);
        let r = smart::replay(&params, &drive, &log)?;
        let e = PositionError::of(&r.theta_rad, &log.theta_rad);
        let off = log
            .torque_enable
            .as_ref()
            .map_or(0, |t| t.iter().filter(|on| !**on).count());
        rows.push((path.display().to_string(), drive.kp_fw, e, off));
        parts.push(e);
    }
    let all = PositionError::pooled(&parts);
    if cmd.json {
        let logs: Vec<_> = rows
            .iter()
            .map(|(name, kp, e, off)| {
                json!({"log": name, "kp_fw": kp, "mae_rad": e.mae_rad, "rmse_rad": e.rmse_rad,
                       "rows": e.rows, "torque_off_rows": off})
            })
            .collect();
        crate::json_out::emit(&json!({
            "schema": "servo.smart_compare/1",
            "model": cmd.model.display().to_string(),
            "replay": "closed loop from the goal positions through the firmware's position loop",
            "logs": logs,
            "pooled": {"mae_rad": all.mae_rad, "rmse_rad": all.rmse_rad, "rows": all.rows},
        }))?;
        return Ok(());
    }
    outln!(
        "smart servo: position MAE {:.1} mrad, RMSE {:.1} mrad over {} logs ({} rows), replayed in closed loop from the goal positions through the firmware's loop",
        all.mae_rad * 1e3,
        all.rmse_rad * 1e3,
        rows.len(),
        all.rows
    );
    for (name, kp, e, off) in &rows {
        let off = if *off > 0 {
            format!("; {off} rows with the torque off, replayed as an open bridge")
        } else {
            String::new()
        };
        outln!(
            "  {name} (kp_fw {kp}): MAE {:.1} mrad, RMSE {:.1} mrad{off}",
            e.mae_rad * 1e3,
            e.rmse_rad * 1e3
        );
    }
    Ok(())
}
