//! The simulator backend: a [`PlantSim`] behind sensors, driven by a simulated clock.
//!
//! Each control period: [`Backend::sample`] measures the true state at the start of the period
//! through the sensor model (encoder quantisation, current noise and offset, seeded), then
//! [`Backend::apply`] holds the voltage for the period and advances the plant by one period
//! (log convention: row k = measurements at time_s[k] and the voltage applied from then until
//! row k+1). The simulated clock advances by one period per `apply`; with `realtime(true)` the
//! backend also sleeps so that simulated time tracks wall time. Deterministic: the same plant,
//! sensor seed and inputs give the same samples.

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
    position_limit_rad: Option<f64>,
}

/// Largest |theta_l| [rad] a simulation may reach before it is declared diverged (about 1.6e8
/// load revolutions: days of continuous rotation at full speed; a diverging model gets there,
/// or to a non-finite state, within a few samples).
pub const DIVERGED_THETA_RAD: f64 = 1e9;
/// Largest motor speed |omega_m| [rad/s] before the simulation is declared diverged (about
/// 10 million rpm: no motor spins that fast).
pub const DIVERGED_OMEGA_RAD_S: f64 = 1e6;

impl SimBackend {
    /// A simulated board for `plant` with control period `dt_s` [s].
    pub fn new(plant: &Plant, sensors: SensorConfig, dt_s: f64) -> Result<SimBackend, HwError> {
        Ok(SimBackend {
            sim: PlantSim::new(plant, dt_s)?,
            sensors: Sensors::new(sensors),
            voltage_limit_v: 10.0,
            last_u_v: 0.0,
            realtime: None,
            position_limit_rad: None,
        })
    }
    /// Paces the simulation to wall-clock time.
    pub fn realtime(mut self, on: bool) -> Self {
        self.realtime = on.then(std::time::Instant::now);
        self
    }
    /// Sets the board's symmetric voltage limit [V] (default 10 V, the SRV-02 amplifier input
    /// range); the plant's own `saturation` effect, if any, acts after it.
    pub fn with_voltage_limit(mut self, limit_v: f64) -> Result<Self, HwError> {
        if !(limit_v > 0.0 && limit_v.is_finite()) {
            return Err(HwError::Safety(format!(
                "voltage limit must be > 0 V and finite, got {limit_v}"
            )));
        }
        self.voltage_limit_v = limit_v;
        Ok(self)
    }
    /// Bounds the input at `drive`'s range ([`servo_core::drive::Drive::input_range`]: a duty
    /// drive's whole bridge, a current drive's limit) when the plant is that drive's equivalent
    /// chain, instead of an amplifier's 10 V; a voltage amplifier keeps the board's limit.
    pub fn behind(self, drive: &servo_core::drive::Drive) -> Result<Self, HwError> {
        match drive.input_range() {
            Some(range) => self.with_voltage_limit(range),
            None => Ok(self),
        }
    }
    /// The underlying plant simulator (true state, per-effect torques).
    /// Soft position limit: [`Backend::sample`] fails (and the run stops) when |theta_l| exceeds
    /// `limit_rad`, as a board trips its +-2 rev limit
    /// ([`servo_core::safety::SafetyLimits`]).
    pub fn with_position_limit(mut self, limit_rad: f64) -> Result<Self, HwError> {
        if !(limit_rad > 0.0 && limit_rad.is_finite()) {
            return Err(HwError::Safety(format!(
                "position limit must be > 0 rad and finite, got {limit_rad}"
            )));
        }
        self.position_limit_rad = Some(limit_rad);
        Ok(self)
    }
    /// Fails when the simulated state is non-finite or beyond [`DIVERGED_THETA_RAD`] /
    /// [`DIVERGED_OMEGA_RAD_S`] (a diverging model or effect), or beyond the soft position limit.
    fn check_state(&self, s: &servo_core::sim::PlantState) -> Result<(), HwError> {
        let finite = [
            s.theta_l_rad,
            s.omega_l_rad_s,
            s.theta_m_rad,
            s.omega_m_rad_s,
            s.i_a_a,
            s.u_drv_v,
        ]
        .iter()
        .all(|v| v.is_finite());
        if !finite
            || s.theta_l_rad.abs() > DIVERGED_THETA_RAD
            || s.omega_m_rad_s.abs() > DIVERGED_OMEGA_RAD_S
        {
            return Err(HwError::Safety(
                servo_core::sim::SimError::Diverged {
                    time_s: s.time_s,
                    theta_l_rad: s.theta_l_rad,
                    omega_m_rad_s: s.omega_m_rad_s,
                }
                .to_string(),
            ));
        }
        if let Some(lim) = self.position_limit_rad {
            if s.theta_l_rad.abs() > lim {
                return Err(HwError::Safety(format!(
                    "soft position limit: theta_l = {:.4} rad ({:.3} rev) beyond +-{lim} rad ({:.3} rev) at t = {:.4} s",
                    s.theta_l_rad,
                    s.theta_l_rad / std::f64::consts::TAU,
                    lim / std::f64::consts::TAU,
                    s.time_s
                )));
            }
        }
        Ok(())
    }
    pub fn plant_sim(&self) -> &PlantSim {
        &self.sim
    }
    /// The true (noise-free, unquantised) state of the plant.
    pub fn true_state(&self) -> &servo_core::sim::PlantState {
        self.sim.state()
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
        self.check_state(&s)?;
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
        if !u_v.is_finite() {
            // Hold 0 V for the period so the plant stays consistent, and report the fault.
            self.last_u_v = 0.0;
            self.sim.step(0.0);
            return Err(HwError::Safety(format!(
                "non-finite voltage command {u_v} V (0 V applied)"
            )));
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use servo_core::effects::Effect;

    fn backend(seed: u64) -> SimBackend {
        let mut plant = Plant::nominal();
        plant
            .effects
            .insert(Effect::parse("coulomb:tau_sf=0.004").unwrap());
        let cfg = SensorConfig {
            seed,
            ..SensorConfig::default()
        };
        SimBackend::new(&plant, cfg, 1e-3).unwrap()
    }

    fn run(b: &mut SimBackend, n: usize) -> Vec<Sample> {
        (0..n)
            .map(|k| {
                let s = b.sample().unwrap();
                b.apply(if k < 300 { 4.0 } else { 20.0 }).unwrap();
                s
            })
            .collect()
    }

    #[test]
    fn samples_follow_the_clock_the_grid_and_the_limit() {
        let mut b = backend(1);
        let samples = run(&mut b, 600);
        let q = std::f64::consts::TAU / 4096.0;
        for (k, s) in samples.iter().enumerate() {
            assert!((s.time_s - k as f64 * 1e-3).abs() < 1e-12);
            assert!((s.theta_l_rad / q - (s.theta_l_rad / q).round()).abs() < 1e-9);
            assert_eq!(s.encoder_count as f64, (s.theta_l_rad / q).round());
        }
        assert_eq!(samples[0].u_applied_v, 0.0);
        assert_eq!(samples[1].u_applied_v, 4.0);
        // Commands above the board limit are clipped to 10 V.
        assert_eq!(samples[599].u_applied_v, 10.0);
        assert!(samples[599].theta_l_rad > 0.5);
        assert!(b.apply(f64::NAN).is_err());
        assert_eq!(b.sample().unwrap().u_applied_v, 0.0);
    }

    #[test]
    fn deterministic_per_seed() {
        let a = run(&mut backend(7), 200);
        let b = run(&mut backend(7), 200);
        let c = run(&mut backend(8), 200);
        assert_eq!(a, b);
        assert_ne!(
            a.iter().map(|s| s.i_a_a).collect::<Vec<_>>(),
            c.iter().map(|s| s.i_a_a).collect::<Vec<_>>()
        );
    }
}
