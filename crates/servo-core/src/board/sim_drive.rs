//! The simulated gearmotor behind a board: what the encoder, the current-sense ADC and the
//! voltage output of a [`BoardHal`](super::BoardHal) see when the motor is servo's simulator.
//! Used by the virtual board on the host and by the QEMU image, so both boards drive the very
//! same physics.

use crate::math;
use crate::plant::Plant;
use crate::sim::{PlantSim, SensorConfig, Sensors, SimError};

/// A simulated plant with its sensors, advanced in physics sub-steps of
/// `sample_period / substeps` with the voltage held over each sub-step.
#[derive(Debug, Clone)]
pub struct SimDrive {
    sim: PlantSim,
    sensors: Sensors,
    u_v: f32,
    current_scale_a_per_lsb: f32,
}

impl SimDrive {
    /// A plant at rest; `substep_s` is the physics step [s] (the time resolution of command
    /// arrival), `current_scale_a_per_lsb` the ADC scale the board reports.
    pub fn new(
        plant: &Plant,
        sensors: SensorConfig,
        substep_s: f64,
        current_scale_a_per_lsb: f32,
    ) -> Result<SimDrive, SimError> {
        Ok(SimDrive {
            sim: PlantSim::new(plant, substep_s)?,
            sensors: Sensors::new(sensors),
            u_v: 0.0,
            current_scale_a_per_lsb,
        })
    }

    /// Advances the plant one sub-step with the voltage held.
    pub fn step(&mut self) {
        self.sim.step(self.u_v as f64);
    }

    /// The true simulator (states, parameters).
    pub fn plant_sim(&self) -> &PlantSim {
        &self.sim
    }

    /// The voltage applied now [V].
    pub fn voltage_v(&self) -> f32 {
        self.u_v
    }

    /// Sets the voltage held from the next sub-step [V].
    pub fn set_voltage(&mut self, u_v: f32) {
        self.u_v = u_v;
    }

    /// The encoder count of the load angle (quantised by the sensor configuration's counts per
    /// revolution), wrapping at the i32 range like a hardware counter.
    pub fn encoder_count(&self) -> i32 {
        let cpr = self.sensors.config().counts_per_rev.max(1) as f64;
        let c = math::floor(self.sim.state().theta_l_rad / math::TAU * cpr);
        (c as i64) as i32
    }

    /// The current-sense reading with the sensor's noise and offset [LSB], saturated at the
    /// i16 range.
    pub fn current_raw(&mut self) -> i16 {
        let m = self.sensors.measure(self.sim.state());
        math::round(m.i_a_a / self.current_scale_a_per_lsb as f64).clamp(-32768.0, 32767.0) as i16
    }
}
