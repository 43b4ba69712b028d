//! Open-loop excitation for identification and diagnosis: a pseudo-random voltage step
//! sequence (random level and sign, held for a fixed time, optionally with ramps through zero),
//! and the simulated log it produces on a plant.
//!
//! Random steps of both signs excite inertia (at each step), viscous and dry friction (at the
//! plateaus of several speeds, both directions) and the electrical balance at once; ramps
//! through zero add slow crossings of zero speed, where stiction and play show. This is the
//! experiment `diagnose` and `identify --method combined` expect when no closed-loop log exists,
//! and the one the test suite and the benchmarks simulate.

use super::sensors::SplitMix64;
use super::{PlantSim, SensorConfig, Sensors, SimError};
use crate::plant::Plant;
use crate::record::Record;
use alloc::string::String;
use alloc::vec::Vec;

/// Ramps through zero mixed into a [`RandomSteps`] sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZeroRamps {
    /// Share of the holds that are a ramp rather than a step, in [0, 1].
    pub probability: f64,
    /// Smallest starting magnitude of a ramp [V].
    pub min_v: f64,
    /// Spread of the starting magnitudes above `min_v` [V].
    pub span_v: f64,
}

/// A pseudo-random voltage step sequence: every `hold_samples` samples a new level of random
/// sign and of magnitude uniform in [`min_v`, `min_v + span_v`] (or, with [`ZeroRamps`], a ramp
/// from +-a through zero to -+a over the hold). Deterministic for a given `seed`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RandomSteps {
    /// Samples each level (or ramp) is held.
    pub hold_samples: usize,
    /// Smallest step magnitude [V].
    pub min_v: f64,
    /// Spread of the step magnitudes above `min_v` [V].
    pub span_v: f64,
    /// Ramps through zero, if any.
    pub ramps: Option<ZeroRamps>,
    /// Seed of the sequence.
    pub seed: u64,
}

impl RandomSteps {
    /// Steps of 0.8 to 7.8 V held 0.4 s at 1 kHz, no ramps: a level every 400 samples.
    pub fn new(seed: u64) -> RandomSteps {
        RandomSteps {
            hold_samples: 400,
            min_v: 0.8,
            span_v: 7.0,
            ramps: None,
            seed,
        }
    }

    /// The first `n` inputs [V] at sample period `dt_s` [s].
    pub fn voltages(&self, n: usize, dt_s: f64) -> Vec<f64> {
        let hold = self.hold_samples.max(1);
        let hold_s = hold as f64 * dt_s;
        let mut rng = SplitMix64(self.seed);
        let mut out = Vec::with_capacity(n);
        let mut u = 0.0;
        let mut ramp: Option<(f64, f64)> = None;
        for k in 0..n {
            if k % hold == 0 {
                match self.ramps {
                    Some(r) if rng.uniform() < r.probability => {
                        let a = r.min_v + r.span_v * rng.uniform();
                        let a = if rng.uniform() < 0.5 { a } else { -a };
                        ramp = Some((a, -2.0 * a / hold_s));
                    }
                    _ => {
                        ramp = None;
                        let mag = self.min_v + self.span_v * rng.uniform();
                        u = if rng.uniform() < 0.5 { -mag } else { mag };
                    }
                }
            }
            if let Some((a, slope)) = ramp {
                u = a + slope * ((k % hold) as f64 * dt_s);
            }
            out.push(u);
        }
        out
    }
}

/// The log of `plant` driven open loop by the inputs `u_v` [V] (one per period `dt_s` [s], held
/// over it), measured through `sensors`: time, u, the measured load angle and armature current.
pub fn simulate_open_loop(
    plant: &Plant,
    sensors: SensorConfig,
    dt_s: f64,
    u_v: &[f64],
    source: &str,
) -> Result<Record, SimError> {
    let mut sim = PlantSim::new(plant, dt_s)?;
    let mut sensors = Sensors::new(sensors);
    let n = u_v.len();
    let (mut t, mut th, mut ia) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for (k, &u) in u_v.iter().enumerate() {
        let m = sensors.measure(sim.state());
        t.push(k as f64 * dt_s);
        th.push(m.theta_l_rad);
        ia.push(m.i_a_a);
        sim.step(u);
    }
    Ok(Record {
        source: String::from(source),
        time_s: t,
        theta_l_rad: Some(th),
        i_a_a: Some(ia),
        u_v: Some(u_v.to_vec()),
        ..Record::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_hold_their_level_and_ramps_cross_zero() {
        let steps = RandomSteps::new(3).voltages(4000, 1e-3);
        assert_eq!(steps.len(), 4000);
        for hold in steps.chunks(400) {
            assert!(hold.iter().all(|&u| u == hold[0]), "a step is held");
            assert!((0.8..=7.8).contains(&hold[0].abs()), "{}", hold[0]);
        }
        assert!(steps.iter().any(|&u| u > 0.0) && steps.iter().any(|&u| u < 0.0));
        let mixed = RandomSteps {
            ramps: Some(ZeroRamps {
                probability: 1.0,
                min_v: 3.0,
                span_v: 3.0,
            }),
            ..RandomSteps::new(3)
        }
        .voltages(800, 1e-3);
        for hold in mixed.chunks(400) {
            let (a, b) = (hold[0], hold[399]);
            assert!(a * b < 0.0, "a ramp goes through zero: {a} -> {b}");
            assert!((3.0..=6.0).contains(&a.abs()));
        }
        // Deterministic.
        assert_eq!(RandomSteps::new(3).voltages(1000, 1e-3), steps[..1000]);
    }

    #[test]
    fn the_open_loop_log_holds_every_signal() {
        let plant = Plant::lab();
        let u = RandomSteps::new(1).voltages(500, 1e-3);
        let rec = simulate_open_loop(&plant, SensorConfig::default(), 1e-3, &u, "t").unwrap();
        assert_eq!(rec.time_s.len(), 500);
        assert_eq!(rec.u_v.as_deref(), Some(&u[..]));
        let th = rec.theta_l_rad.as_ref().unwrap();
        assert!(th[499].abs() > 0.01, "the motor moved: {}", th[499]);
    }
}
