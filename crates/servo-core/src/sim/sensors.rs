//! Measurement effects of the simulator: encoder quantisation, current-sensor noise and offset.
//! Seeded and deterministic.

use crate::math;
use crate::sim::PlantState;

/// Sensor configuration of the simulated board.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields, default))]
pub struct SensorConfig {
    /// Encoder counts per load revolution (quadrature counts) [counts/rev]; 0 = no quantisation.
    pub counts_per_rev: u32,
    /// Standard deviation of the current-sensor noise [A].
    pub current_noise_a: f64,
    /// Constant current-sensor offset [A].
    pub current_offset_a: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            counts_per_rev: 4096,
            current_noise_a: 2e-3,
            current_offset_a: 0.0,
            seed: 1,
        }
    }
}

/// Why a sensor configuration was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SensorError {
    #[error("current_noise_a must be a finite standard deviation >= 0 A, got {0}")]
    Noise(f64),
    #[error("current_offset_a must be a finite current in A, got {0}")]
    Offset(f64),
}

impl SensorConfig {
    /// Checks that the noise is a finite non-negative standard deviation and the offset finite.
    pub fn validate(&self) -> Result<(), SensorError> {
        if !(self.current_noise_a.is_finite() && self.current_noise_a >= 0.0) {
            return Err(SensorError::Noise(self.current_noise_a));
        }
        if !self.current_offset_a.is_finite() {
            return Err(SensorError::Offset(self.current_offset_a));
        }
        Ok(())
    }
}

/// What the board measures at one sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measurement {
    /// Load angle from the encoder [rad], quantised.
    pub theta_l_rad: f64,
    /// Encoder count (signed, since start).
    pub encoder_count: i64,
    /// Measured armature current [A] with noise and offset.
    pub i_a_a: f64,
}

/// The sensor model: turns true states into measurements.
#[derive(Debug, Clone)]
pub struct Sensors {
    cfg: SensorConfig,
    rng: SplitMix64,
}

impl Sensors {
    pub fn new(cfg: SensorConfig) -> Sensors {
        Sensors {
            cfg,
            rng: SplitMix64(cfg.seed),
        }
    }
    pub fn config(&self) -> &SensorConfig {
        &self.cfg
    }
    /// Measures the state.
    pub fn measure(&mut self, s: &PlantState) -> Measurement {
        let (count, theta) = if self.cfg.counts_per_rev > 0 {
            let cpr = self.cfg.counts_per_rev as f64;
            let c = math::floor(s.theta_l_rad / math::TAU * cpr);
            (c as i64, c * math::TAU / cpr)
        } else {
            (0, s.theta_l_rad)
        };
        let noise = self.cfg.current_noise_a * self.rng.normal();
        Measurement {
            theta_l_rad: theta,
            encoder_count: count,
            i_a_a: s.i_a_a + self.cfg.current_offset_a + noise,
        }
    }
}

/// SplitMix64 generator with a Box-Muller normal deviate: small, seeded, no_std.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        math::sqrt(-2.0 * math::ln(u1)) * math::cos(math::TAU * u2)
    }
}
