//! A measured or simulated record: sampled signals on a common time base.
//!
//! Log convention (servo's own logs and the simulator): row k holds the measurements taken at
//! `time_s[k]` and the voltage `u_v[k]` applied from then until row k+1. Measurements therefore lag
//! the input by one sample.

pub mod part;

use alloc::string::String;
use alloc::vec::Vec;

/// Sampled signals, SI units. Every present signal has the length of `time_s`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Record {
    /// Where it came from (file path or description), for messages and provenance.
    pub source: String,
    /// Sample times [s], strictly increasing.
    pub time_s: Vec<f64>,
    /// Driver input voltage u [V] (before the driver gain k_drv), applied from this row to the next.
    pub u_v: Option<Vec<f64>>,
    /// Load angle theta_l [rad].
    pub theta_l_rad: Option<Vec<f64>>,
    /// Motor angle theta_m [rad].
    pub theta_m_rad: Option<Vec<f64>>,
    /// Load speed omega_l [rad/s].
    pub omega_l_rad_s: Option<Vec<f64>>,
    /// Motor speed omega_m [rad/s].
    pub omega_m_rad_s: Option<Vec<f64>>,
    /// Armature current i_a [A].
    pub i_a_a: Option<Vec<f64>>,
    /// Current reference i_ref [A] of a current (torque) drive ([`crate::drive`]), applied from
    /// this row to the next.
    pub i_ref_a: Option<Vec<f64>>,
    /// Duty cycle [-1, 1] of a PWM H-bridge or smart servo ([`crate::drive`]).
    pub duty: Option<Vec<f64>>,
    /// Supply voltage [V] of a duty drive, per sample.
    pub v_supply_v: Option<Vec<f64>>,
    /// Position reference [rad] at the load.
    pub ref_rad: Option<Vec<f64>>,
    /// Drive enable / torque-on flag per sample (nonzero = on, 0 = off), when the log has one:
    /// [`part::cut`] ends the usable part of the log at the first off sample.
    pub enable: Option<Vec<f64>>,
}

impl Record {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }
    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }
    /// Median sample period [s] (NaN with fewer than two samples).
    pub fn sample_period_s(&self) -> f64 {
        if self.time_s.len() < 2 {
            return f64::NAN;
        }
        let mut d: Vec<f64> = self.time_s.windows(2).map(|w| w[1] - w[0]).collect();
        let mid = d.len() / 2;
        *d.select_nth_unstable_by(mid, f64::total_cmp).1
    }
    /// Rows `a..b` of every signal (indices clamped to the length), same source.
    pub fn slice(&self, a: usize, b: usize) -> Record {
        let b = b.min(self.len());
        let a = a.min(b);
        let cut = |v: &Option<Vec<f64>>| {
            v.as_ref()
                .map(|v| v[a.min(v.len())..b.min(v.len())].to_vec())
        };
        Record {
            source: self.source.clone(),
            time_s: self.time_s[a..b].to_vec(),
            u_v: cut(&self.u_v),
            theta_l_rad: cut(&self.theta_l_rad),
            theta_m_rad: cut(&self.theta_m_rad),
            omega_l_rad_s: cut(&self.omega_l_rad_s),
            omega_m_rad_s: cut(&self.omega_m_rad_s),
            i_a_a: cut(&self.i_a_a),
            i_ref_a: cut(&self.i_ref_a),
            duty: cut(&self.duty),
            v_supply_v: cut(&self.v_supply_v),
            ref_rad: cut(&self.ref_rad),
            enable: cut(&self.enable),
        }
    }
    /// Names of the signals present, in the names users type (`u`, `theta_l`, ...).
    pub fn signals(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        for (name, present) in [
            ("u", self.u_v.is_some()),
            ("theta_l", self.theta_l_rad.is_some()),
            ("theta_m", self.theta_m_rad.is_some()),
            ("omega_l", self.omega_l_rad_s.is_some()),
            ("omega_m", self.omega_m_rad_s.is_some()),
            ("i_a", self.i_a_a.is_some()),
            ("i_ref", self.i_ref_a.is_some()),
            ("duty", self.duty.is_some()),
            ("v_supply", self.v_supply_v.is_some()),
            ("ref", self.ref_rad.is_some()),
            ("enable", self.enable.is_some()),
        ] {
            if present {
                v.push(name);
            }
        }
        v
    }
}
