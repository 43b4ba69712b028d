//! Simulation of a [`Plant`]: the full dynamics of eqs. 19-21 plus the active effects.
//!
//! The input u is held constant over each control period (zero-order hold); the integrator takes
//! internal sub-steps because the electrical time constants (~60 us and ~130 us) are far shorter
//! than the 1 ms control period.
//!
//! PLACEHOLDER (workspace skeleton): fixed-step RK4 on the linear dynamics with viscous and a
//! regularised Coulomb friction. The full effect physics replaces it; the API stays.

pub mod sensors;

use crate::math;
use crate::plant::Plant;

pub use sensors::{Measurement, SensorConfig, Sensors};

/// Why a simulator could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("sample period must be > 0 and finite, got {0} s")]
    BadPeriod(f64),
    #[error(transparent)]
    Params(#[from] crate::params::ParamError),
    #[error(transparent)]
    Effect(#[from] crate::effects::EffectError),
}

/// The physical state of the simulated gearmotor (true values, before the sensors).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    /// Simulated time [s].
    pub time_s: f64,
    /// Driver input actually seen by the driver after saturation/dead zone/delay [V].
    pub u_in_v: f64,
    /// Driver output voltage u_drv [V].
    pub u_drv_v: f64,
    /// Armature current i_a [A].
    pub i_a_a: f64,
    /// Motor speed omega_m [rad/s].
    pub omega_m_rad_s: f64,
    /// Motor angle theta_m [rad].
    pub theta_m_rad: f64,
    /// Load speed omega_l [rad/s] (omega_m / N without backlash).
    pub omega_l_rad_s: f64,
    /// Load angle theta_l [rad] (theta_m / N without backlash).
    pub theta_l_rad: f64,
}

/// A simulated gearmotor advanced one control period at a time.
#[derive(Debug, Clone)]
pub struct PlantSim {
    plant: Plant,
    dt_s: f64,
    substeps: u32,
    state: PlantState,
}

impl PlantSim {
    /// A simulator at rest at the origin, with control period `dt_s` [s].
    pub fn new(plant: &Plant, dt_s: f64) -> Result<PlantSim, SimError> {
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(SimError::BadPeriod(dt_s));
        }
        plant.params.validate()?;
        for e in plant.effects.iter() {
            e.check_complete()?;
        }
        let substeps = math::floor(dt_s / 10e-6).max(1.0) as u32;
        Ok(PlantSim {
            plant: *plant,
            dt_s,
            substeps,
            state: PlantState::default(),
        })
    }

    /// The plant being simulated.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }
    /// Control period [s].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }
    /// Current state.
    pub fn state(&self) -> &PlantState {
        &self.state
    }
    /// Replaces the state (e.g. to start from a logged position).
    pub fn reset(&mut self, state: PlantState) {
        self.state = state;
    }

    /// Applies driver input `u_v` [V] for one control period (zero-order hold) and returns the
    /// state at the end of it.
    pub fn step(&mut self, u_v: f64) -> &PlantState {
        let p = &self.plant.params;
        let n = p.n;
        let h = self.dt_s / self.substeps as f64;
        let (b_eq, tau_sf) = (self.plant.b_eq(), self.plant.tau_sf());
        let (t_drv, l_a, r_eq, j_eq) = (p.t_drv(), p.l_a, p.r_eq(), p.j_eq());
        let (k_e, k_t, k_drv) = (p.k_e, p.k_t, p.k_drv);
        let deriv = |x: [f64; 4]| -> [f64; 4] {
            let [u_drv, i_a, w_m, _th_m] = x;
            // Regularised Coulomb friction (placeholder).
            let tau_c = tau_sf / n * math::tanh(w_m / 1.0);
            [
                (k_drv * u_v - u_drv) / t_drv,
                (u_drv - r_eq * i_a - k_e * w_m) / l_a,
                (k_t * i_a - b_eq * w_m - tau_c) / j_eq,
                w_m,
            ]
        };
        let s = &mut self.state;
        let mut x = [s.u_drv_v, s.i_a_a, s.omega_m_rad_s, s.theta_m_rad];
        for _ in 0..self.substeps {
            let k1 = deriv(x);
            let k2 = deriv(add(x, k1, h / 2.0));
            let k3 = deriv(add(x, k2, h / 2.0));
            let k4 = deriv(add(x, k3, h));
            for i in 0..4 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        s.u_in_v = u_v;
        s.u_drv_v = x[0];
        s.i_a_a = x[1];
        s.omega_m_rad_s = x[2];
        s.theta_m_rad = x[3];
        s.omega_l_rad_s = x[2] / n;
        s.theta_l_rad = x[3] / n;
        s.time_s += self.dt_s;
        &self.state
    }
}

fn add(x: [f64; 4], k: [f64; 4], h: f64) -> [f64; 4] {
    [
        x[0] + h * k[0],
        x[1] + h * k[1],
        x[2] + h * k[2],
        x[3] + h * k[3],
    ]
}
