//! The MCAP log of a run: the metadata that makes it replayable (plant, gains, the controller as
//! it ran, the reference program, the board) and the summary record written when it closes
//! (figures of merit, link statistics, why it stopped).
//!
//! `servo run` writes its logs through these functions; any other front end (a GUI, a script)
//! gets the same, readable by every servo command.

use super::{chain, effective_pid_config, RunError, RunOutput};
use crate::backend::BoardInfo;
use crate::serial::LinkStats;
use servo_core::control::{LoopCompensation, PidConfig};
use servo_core::drive::Drive;
use servo_core::sim::SensorConfig;
use servo_core::Plant;
use servo_io::compensation::CompensationChoice;
use servo_io::controller::LoggedController;
use servo_io::gains_file::GainsFile;
use servo_io::model_file::ModelFile;
use servo_io::{meta_keys, McapLog};
use std::collections::BTreeMap;

/// The metadata of a run, built up before the log is created ([`McapLog::create`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunMetadata(pub BTreeMap<String, String>);

impl RunMetadata {
    /// The plant a simulator runs behind `drive`: its model file (with the drive and the
    /// sensors), its effects and the noise seed, so that `servo compare` and `diagnose` know the
    /// truth of a simulated log.
    pub fn simulated_plant(
        &mut self,
        plant: &Plant,
        drive: &Drive,
        sensors: SensorConfig,
    ) -> servo_io::Result<&mut Self> {
        let mut mf = ModelFile::from_plant(plant);
        mf.drive = *drive;
        mf.sensors = Some(sensors);
        self.put(meta_keys::PLANT_TOML, mf.to_toml()?);
        let effects: Vec<String> = plant.effects.iter().map(|e| e.to_string()).collect();
        self.put(meta_keys::PLANT_EFFECTS, effects.join(" "));
        self.put(meta_keys::SEED, sensors.seed.to_string());
        Ok(self)
    }

    /// The serial link a board runs on.
    pub fn serial_port(&mut self, port: &str, baud: u32) -> &mut Self {
        self.put("serial_port", port.to_string());
        self.put("serial_baud", baud.to_string())
    }

    /// The board and the run: servo's version, the backend's name (`sim`, `serial`), firmware,
    /// period, encoder resolution, planned duration [s], the voltage limit in force [V] (the
    /// tighter of `u_limit_v` and the board's) and the program (`--ref` text, experiment file).
    pub fn run(
        &mut self,
        backend: &str,
        info: &BoardInfo,
        duration_s: f64,
        u_limit_v: f64,
        program: &str,
    ) -> &mut Self {
        self.put(meta_keys::SERVO_VERSION, env!("CARGO_PKG_VERSION").into());
        self.put(meta_keys::BACKEND, backend.to_string());
        self.put(meta_keys::FIRMWARE, info.firmware.into());
        self.put(meta_keys::SAMPLE_PERIOD_S, info.sample_period_s.to_string());
        self.put(meta_keys::COUNTS_PER_REV, info.counts_per_rev.to_string());
        self.put(meta_keys::DURATION_S, duration_s.to_string());
        self.put(
            meta_keys::U_LIMIT_V,
            u_limit_v.min(info.voltage_limit_v).to_string(),
        );
        self.put(meta_keys::REFERENCE, program.to_string())
    }

    /// The controller: the gains file, the PID as it runs on this board (limit `u_limit_v` [V]
    /// narrowed by the board's, the board's period) for an exact replay, the feedforward terms
    /// and, with a feedforward, the model its constants came from.
    pub fn controller(
        &mut self,
        info: &BoardInfo,
        u_limit_v: f64,
        gains: Option<&GainsFile>,
        pid: Option<&PidConfig>,
        feedforward: Option<(&LoopCompensation, &CompensationChoice)>,
        model: Option<&ModelFile>,
    ) -> servo_io::Result<&mut Self> {
        if let Some(g) = gains {
            self.put(meta_keys::GAINS_TOML, g.to_toml_commented());
        }
        let label = feedforward.map_or_else(|| "none".to_string(), |(_, ch)| ch.label());
        if let Some(pid) = pid {
            let limit = u_limit_v.min(info.voltage_limit_v);
            let pid_limit = feedforward.map_or(limit, |(c, _)| c.pid_limit_v(limit));
            let runs = effective_pid_config(pid, pid_limit, info.sample_period_s);
            let mut logged = LoggedController::of(&runs, None);
            logged.feedforward = Some(label.clone());
            self.put(meta_keys::CONTROLLER_TOML, logged.to_toml()?);
        }
        self.put(meta_keys::FEEDFORWARD, label);
        if let Some((_, ch)) = feedforward {
            self.put(meta_keys::COMPENSATED_EFFECTS, ch.effect_names());
            self.put(meta_keys::COMPENSATION, ch.lines().join("; "));
        }
        if feedforward.is_some() {
            self.put(
                meta_keys::MODEL_TOML,
                model.cloned().unwrap_or_default().to_toml()?,
            );
        }
        Ok(self)
    }

    /// Sets `key` to `value`.
    pub fn put(&mut self, key: &str, value: String) -> &mut Self {
        self.0.insert(key.to_string(), value);
        self
    }
}

/// The summary record of a run that ended (`result` Ok) or failed: for a finished run its
/// figures of merit ([`servo_core::metrics::RunSummary::to_map`]), the planned duration and why
/// it stopped; for a failed one the error and the samples logged before it (`logged`); the link
/// statistics of a board in both cases.
pub fn summary_map(
    result: Result<&RunOutput, &RunError>,
    link: Option<&LinkStats>,
    planned_duration_s: f64,
    logged: u64,
) -> BTreeMap<String, String> {
    match result {
        Ok(out) => {
            let mut map = out.summary.to_map();
            if let Some(ls) = link {
                map.extend(ls.to_map());
            }
            // What really ran (the run metadata holds the planned duration).
            map.insert("planned_duration_s".into(), planned_duration_s.to_string());
            map.insert("stop_reason".into(), out.stop.describe().into());
            map
        }
        Err(e) => {
            let mut map = link.map(|ls| ls.to_map()).unwrap_or_default();
            map.insert("stop_reason".into(), format!("error: {}", chain(e)));
            map.insert("samples".into(), logged.to_string());
            map
        }
    }
}

/// Writes the summary record of [`summary_map`] and finishes the log (its footer and index):
/// afterwards every MCAP reader opens it as a finished file.
pub fn close_log(
    log: &mut McapLog,
    result: Result<&RunOutput, &RunError>,
    link: Option<&LinkStats>,
    planned_duration_s: f64,
) -> servo_io::Result<()> {
    let map = summary_map(result, link, planned_duration_s, log.messages());
    log.write_summary(&map)?;
    log.finish()
}
