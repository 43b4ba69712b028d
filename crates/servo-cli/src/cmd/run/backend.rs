//! `servo run`: the backend of `--backend` (the simulator or a board on a serial port) and the
//! metadata it gives the log.

use super::BackendKind;
use anyhow::{bail, Context};
use servo_hw::run::logged::RunMetadata;
use servo_hw::{Backend, SimBackend};

impl super::Run {
    /// The backend of `--backend` at period `ts_s` [s] (the board must run at it), and the
    /// metadata it contributes to the log (the simulated plant, or the serial link).
    pub(super) fn open_backend(
        &self,
        ts_s: f64,
        u_limit_v: f64,
    ) -> anyhow::Result<(Box<dyn Backend>, RunMetadata)> {
        let mut meta = RunMetadata::default();
        match self.backend {
            BackendKind::Sim => {
                let (plant, sensors) = self.plant.load()?;
                let sim = SimBackend::new(&plant, sensors, ts_s)
                    .context("simulator")?
                    .realtime(self.realtime);
                let sim = sim.behind(&self.drive()?).context("--plant [drive]")?;
                let sim = match self.soft_limit_rev {
                    Some(rev) => sim
                        .with_position_limit(rev * std::f64::consts::TAU)
                        .context("--soft-limit-rev")?,
                    None => sim,
                };
                meta.simulated_plant(&plant, &self.plant.drive()?, sensors)?;
                Ok((Box::new(sim), meta))
            }
            BackendKind::Serial => {
                let cfg = servo_hw::SerialConfig {
                    port: self.port.clone(),
                    baud: self.baud,
                    timeout_s: self.board_timeout_ms * 1e-3,
                    limits: servo_core::safety::SafetyLimits {
                        voltage_limit_v: u_limit_v,
                        ..Default::default()
                    },
                    ..Default::default()
                };
                let be = servo_hw::SerialBackend::open(cfg)
                    .with_context(|| format!("--backend serial --port {}", self.port))?;
                let board_ts = be.info().sample_period_s;
                if (board_ts - ts_s).abs() > 1e-9 {
                    bail!(
                        "the board on {} samples every {board_ts} s but the controller is for T_s = {ts_s} s \
                         (--ts or the gains file); start the board with that period or redesign",
                        self.port
                    );
                }
                meta.serial_port(&self.port, self.baud);
                Ok((Box::new(be), meta))
            }
        }
    }
}
