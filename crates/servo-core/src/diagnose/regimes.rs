//! Operating regimes of each equation row: standstill, velocity reversal, constant speed,
//! acceleration, voltage near its limit. Used to say where a model fails and where a candidate
//! effect helps.

use crate::fit::dataset::{Dataset, Rows};
use crate::math;
use alloc::vec::Vec;

/// An operating regime.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regime {
    Standstill,
    Reversal,
    ConstantSpeed,
    Acceleration,
    VoltageNearLimit,
}

impl Regime {
    pub const ALL: [Regime; 5] = [
        Regime::Standstill,
        Regime::Reversal,
        Regime::ConstantSpeed,
        Regime::Acceleration,
        Regime::VoltageNearLimit,
    ];
    pub const fn name(self) -> &'static str {
        match self {
            Regime::Standstill => "standstill",
            Regime::Reversal => "velocity reversal",
            Regime::ConstantSpeed => "constant speed",
            Regime::Acceleration => "acceleration",
            Regime::VoltageNearLimit => "voltage near its limit",
        }
    }
    /// The phrase used in evidence ("near velocity reversals").
    pub const fn phrase(self) -> &'static str {
        match self {
            Regime::Standstill => "at standstill",
            Regime::Reversal => "within 50 ms of velocity reversals",
            Regime::ConstantSpeed => "at constant speed",
            Regime::Acceleration => "during strong accelerations",
            Regime::VoltageNearLimit => "while the voltage is near its limit",
        }
    }
}

/// Regime membership of each row (a row may be in several).
#[derive(Debug, Clone)]
pub struct RowRegimes {
    pub flags: Vec<[bool; 5]>,
}

/// The regime labels of both equations' rows ([`label`] of the torque balance's and of the
/// electrical balance's rows), made once per diagnosis: every candidate's evidence and the base
/// summary read them.
#[derive(Debug, Clone)]
pub struct Labels {
    pub mech: RowRegimes,
    pub elec: RowRegimes,
}

impl Labels {
    /// Labels the rows of both equations of `ds` (the two on two threads when a core is idle).
    pub fn new(ds: &Dataset) -> Labels {
        let (mech, elec) = super::join(|| label(ds, &ds.mech_rows), || label(ds, &ds.elec_rows));
        Labels { mech, elec }
    }

    /// The labels of the rows of `eq` (the electrical balance's, or the torque balance's).
    pub fn of(&self, eq: crate::fit::model::Equation) -> &RowRegimes {
        if eq == crate::fit::model::Equation::Electrical {
            &self.elec
        } else {
            &self.mech
        }
    }
}

/// Labels the rows of one equation.
pub fn label(ds: &Dataset, rows: &Rows) -> RowRegimes {
    let o = &ds.opts;
    let mut flags = Vec::with_capacity(rows.len());
    // Per record: distance to the nearest reversal (sign change of the filtered speed, with the
    // speed exceeding the stuck threshold on both sides within 0.2 s).
    let mut near_rev: Vec<Vec<bool>> = Vec::new();
    let mut a_ref: Vec<f64> = Vec::new();
    for r in &ds.recs {
        let n = r.omega_f.len();
        let win = (0.05 / r.dt_s) as usize;
        let mut flag = alloc::vec![false; n];
        let mut last_sign = 0.0;
        for k in 0..n {
            let w = r.omega_f[k];
            if w.abs() > o.min_speed_rad_s {
                let s = math::sign(w);
                if last_sign != 0.0 && s != last_sign {
                    // Mark the window around the crossing.
                    let mut c = k;
                    while c > 0 && math::sign(r.omega_f[c - 1]) == s {
                        c -= 1;
                    }
                    for f in flag
                        .iter_mut()
                        .take((c + win).min(n))
                        .skip(c.saturating_sub(win))
                    {
                        *f = true;
                    }
                }
                last_sign = s;
            }
        }
        near_rev.push(flag);
        // The 95th percentile of |acceleration|: the element a full sort would put there
        // (selected in linear time; the rows of a 10-minute log made the sort a tenth of a
        // diagnosis's judging pass).
        let mut acc: Vec<f64> = r.accel_f.iter().map(|a| a.abs()).collect();
        let at = (acc.len() * 95) / 100;
        let a95 = math::order_statistic(&mut acc, at).unwrap_or(0.0);
        a_ref.push(a95.max(1e-9));
    }
    for (&ri, &k) in rows.rec.iter().zip(&rows.k) {
        let r = &ds.recs[ri];
        let w = r.omega_f[k];
        let a = r.accel_f[k].abs();
        let u = r.u_v[k].abs();
        let still = w.abs() < o.min_speed_rad_s;
        let rev = near_rev[ri][k];
        let acc = a > 0.3 * a_ref[ri];
        let cst = !still && !rev && a < 0.05 * a_ref[ri];
        let sat = ds.u_max_v > 0.0 && u > 0.9 * ds.u_max_v;
        flags.push([still, rev, cst, acc, sat]);
    }
    RowRegimes { flags }
}

/// Share (0..1) of `weight` summed over each regime's rows, relative to the total.
pub fn shares(reg: &RowRegimes, weight: &[f64]) -> [f64; 5] {
    let total: f64 = weight.iter().sum();
    let mut out = [0.0; 5];
    if total.abs() < f64::MIN_POSITIVE {
        return out;
    }
    for (f, w) in reg.flags.iter().zip(weight) {
        for i in 0..5 {
            if f[i] {
                out[i] += w;
            }
        }
    }
    out.map(|v| v / total)
}

/// Fraction (0..1) of rows in each regime.
pub fn occupancy(reg: &RowRegimes) -> [f64; 5] {
    let n = reg.flags.len().max(1) as f64;
    let mut out = [0.0; 5];
    for f in &reg.flags {
        for i in 0..5 {
            if f[i] {
                out[i] += 1.0 / n;
            }
        }
    }
    out
}
