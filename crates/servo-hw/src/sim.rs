//! The simulator backend: a [`PlantSim`] behind sensors, driven by a simulated clock.

use crate::backend::{Backend, BoardInfo, HwError, Sample};
use servo_core::sim::{PlantSim, SensorConfig, Sensors};
use servo_core::Plant;

/// A simulated board. Time advances by one control period per [`Backend::apply`]; with
/// `realtime` it also sleeps so that simulated time tracks wall time.
#[derive(Debug, Clone)]
pub struct SimBackend {
    sim: PlantSim,
    sensors: Sensors,
    voltage_limit_v: f64,
    last_u_v: f64,
    realtime: Option<std::time::Instant>,
}

impl SimBackend {
    /// A simulated board for `plant` with control period `dt_s` [s].
    pub fn new(plant: &Plant, sensors: SensorConfig, dt_s: f64) -> Result<SimBackend, HwError> {
        Ok(SimBackend {
            sim: PlantSim::new(plant, dt_s)?,
            sensors: Sensors::new(sensors),
            voltage_limit_v: 10.0,
            last_u_v: 0.0,
            realtime: None,
        })
    }
    /// Paces the simulation to wall-clock time.
    pub fn realtime(mut self, on: bool) -> Self {
        self.realtime = on.then(std::time::Instant::now);
        self
    }
    /// The underlying plant simulator (true state).
    pub fn plant_sim(&self) -> &PlantSim {
        &self.sim
    }
}

impl Backend for SimBackend {
    fn info(&self) -> BoardInfo {
        BoardInfo {
            firmware: concat!("servo-sim ", env!("CARGO_PKG_VERSION")),
            counts_per_rev: self.sensors.config().counts_per_rev,
            voltage_limit_v: self.voltage_limit_v,
            sample_period_s: self.sim.dt_s(),
        }
    }
    fn sample(&mut self) -> Result<Sample, HwError> {
        let s = *self.sim.state();
        if let Some(start) = self.realtime {
            let due = std::time::Duration::from_secs_f64(s.time_s);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let m = self.sensors.measure(&s);
        Ok(Sample {
            time_s: s.time_s,
            theta_l_rad: m.theta_l_rad,
            encoder_count: m.encoder_count,
            i_a_a: m.i_a_a,
            u_applied_v: self.last_u_v,
        })
    }
    fn apply(&mut self, u_v: f64) -> Result<(), HwError> {
        let u = u_v.clamp(-self.voltage_limit_v, self.voltage_limit_v);
        self.last_u_v = u;
        self.sim.step(u);
        Ok(())
    }
    fn stop(&mut self) -> Result<(), HwError> {
        self.last_u_v = 0.0;
        Ok(())
    }
}
