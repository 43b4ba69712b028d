//! The torque-balance columns of the user torque effects: what the least-squares fit of the
//! balances ([`super::model::solve_mech`]) takes from a user effect, apart from its fit
//! ([`super::custom`], which solves those balances again).

use crate::custom::ActsOn;
use crate::fit::dataset::{Dataset, RecData, Rows};
use crate::plant::Plant;
use alloc::vec::Vec;

/// A torque-balance column of a user effect: its part with every unknown parameter at 0
/// (`param` = None, coefficient 1), or its derivative with respect to unknown parameter `param`
/// of effect `slot` (coefficient = the parameter).
#[derive(Debug, Clone)]
pub struct TorqueColumn {
    pub col: Vec<f64>,
    pub slot: usize,
    pub param: Option<usize>,
    /// The parameter's lower bound is >= 0.
    pub non_negative: bool,
}

/// The signals of a record at sample `k` ([`crate::custom::SIGNALS`] order): the angle and speed as
/// logged (motor side; load = motor / N), the current (0 when not logged), u and t.
#[inline]
pub fn record_signals(r: &RecData, n: f64, k: usize) -> [f64; 7] {
    let th = r.theta_m_rad.get(k).copied().unwrap_or(0.0);
    let w = r.omega_raw.get(k).copied().unwrap_or(0.0);
    let i = r
        .i_raw
        .as_ref()
        .and_then(|i| i.get(k).copied())
        .unwrap_or(0.0);
    let u = r.u_v.get(k).copied().unwrap_or(0.0);
    let t = r.time_s.get(k).copied().unwrap_or(0.0);
    [th / n, th, w / n, w, i, u, t]
}

/// Columns of the user torque effects of `plant` at `rows` (filtered like every regressor),
/// expressed as torques at the motor (load torques through 1/N).
pub fn torque_columns(ds: &Dataset, plant: &Plant, rows: &Rows) -> Vec<TorqueColumn> {
    let n = plant.params.n;
    let mut out = Vec::new();
    for (si, c) in plant.custom.iter().enumerate() {
        let scale = match c.def.acts_on() {
            ActsOn::LoadTorque => 1.0 / n,
            ActsOn::MotorTorque => 1.0,
            _ => continue,
        };
        let mut v0 = c.values;
        for v in v0.iter_mut() {
            if v.is_nan() {
                *v = 0.0;
            }
        }
        let col_at = |vals: [f64; crate::custom::MAX_CUSTOM_PARAMS], minus: bool| {
            ds.column(rows, |r: &RecData| {
                (0..r.theta_m_rad.len())
                    .map(|k| {
                        let s = record_signals(r, n, k);
                        let mut y = c.def.eval(&s, &vals);
                        if minus {
                            y -= c.def.eval(&s, &v0);
                        }
                        let y = y * scale;
                        if y.is_finite() {
                            y
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
        };
        out.push(TorqueColumn {
            col: col_at(v0, false),
            slot: si,
            param: None,
            non_negative: false,
        });
        for (j, v) in c.values().iter().enumerate() {
            if v.is_nan() {
                let mut vj = v0;
                vj[j] = 1.0;
                out.push(TorqueColumn {
                    col: col_at(vj, true),
                    slot: si,
                    param: Some(j),
                    non_negative: c.def.params()[j].min >= 0.0,
                });
            }
        }
    }
    out
}
