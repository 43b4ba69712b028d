//! Output-error cost: the model simulated (with [`PlantSim`]) from measured states over short
//! horizons, driven by the logged input, compared with the measured motor angle.
//!
//! Re-initialising every segment from the measurement keeps an integrating plant from drifting
//! and works the same on open-loop and closed-loop logs (the logged u drives the model).

use super::dataset::Dataset;
use crate::effects::EffectKind;
use crate::math;
use crate::plant::Plant;
use crate::sim::{PlantSim, PlantState};
use alloc::vec::Vec;

/// Which part of the data a cost is computed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// Blocks used for fitting.
    Fit,
    /// Held-out blocks.
    Holdout,
    /// Everything.
    All,
}

/// Segment starts (record, row) of `part`, at most `opts.oe_max_segments`, spread evenly.
pub fn segments(ds: &Dataset, part: Part) -> Vec<(usize, usize)> {
    let o = &ds.opts;
    let mut all = Vec::new();
    for (ri, r) in ds.recs.iter().enumerate() {
        let fs = 1.0 / r.dt_s;
        let h = ((o.oe_horizon_s * fs) as usize).max(2);
        let edge = libm::ceil((2.0 / o.filter_hz) * fs) as usize + 2;
        let block = ((o.holdout_block_s * fs) as usize).max(1);
        let n = r.u_v.len();
        let mut k = edge.max(1);
        while k + h + edge < n {
            let b = k / block;
            let fit = o.holdout_every == 0 || b % o.holdout_every != o.holdout_every - 1;
            let keep = match part {
                Part::All => true,
                Part::Fit => fit,
                Part::Holdout => !fit,
            };
            // Skip segments at rest: they carry no dynamics.
            let moving = r.omega_f[k..k + h]
                .iter()
                .any(|w| w.abs() > o.min_speed_rad_s);
            if keep && moving {
                all.push((ri, k));
            }
            k += h;
        }
    }
    let m = o.oe_max_segments.max(1);
    if all.len() <= m {
        return all;
    }
    (0..m).map(|i| all[i * all.len() / m]).collect()
}

/// RMS error of the predicted motor angle [rad] over the segments of `part`; `None` when there
/// is no segment or the model cannot be simulated.
pub fn prediction_cost(ds: &Dataset, plant: &Plant, part: Part) -> Option<f64> {
    let segs = segments(ds, part);
    prediction_cost_on(ds, plant, &segs)
}

/// As [`prediction_cost`] on given segment starts.
pub fn prediction_cost_on(ds: &Dataset, plant: &Plant, segs: &[(usize, usize)]) -> Option<f64> {
    if segs.is_empty() {
        return None;
    }
    let p = &plant.params;
    let (mut sum, mut count) = (0.0, 0usize);
    for &(ri, k0) in segs {
        let r = &ds.recs[ri];
        let h = ((ds.opts.oe_horizon_s / r.dt_s) as usize).max(2);
        let mut sim = PlantSim::new(plant, r.dt_s).ok()?;
        let w = r.omega_f[k0];
        let u_prev = r.u_v[k0.saturating_sub(1)];
        let i = match &r.i_f {
            Some(i) => i[k0],
            None => (p.k_drv * u_prev - p.k_e * w) / p.r_eq(),
        };
        let th = r.theta_m_rad[k0];
        // With backlash and the load angle measured, start in contact on the driving flank.
        let half_gap = plant
            .effects
            .value(EffectKind::Backlash, "gap")
            .unwrap_or(0.0)
            * 0.5;
        let dir = if w.abs() > ds.opts.min_speed_rad_s {
            math::sign(w)
        } else {
            math::sign(u_prev)
        };
        let (th_m, th_l) = if r.angle_is_load {
            (th + p.n * half_gap * dir, th / p.n)
        } else {
            (th, th / p.n - half_gap * dir)
        };
        sim.reset(PlantState {
            time_s: r.time_s[k0],
            u_in_v: u_prev,
            u_drv_v: p.k_drv * u_prev,
            i_a_a: i,
            omega_m_rad_s: w,
            theta_m_rad: th_m,
            omega_l_rad_s: w / p.n,
            theta_l_rad: th_l,
            ..PlantState::default()
        });
        for j in 0..h {
            let s = sim.step(r.u_v[k0 + j]);
            let out = if r.angle_is_load {
                s.theta_l_rad * p.n
            } else {
                s.theta_m_rad
            };
            let e = out - r.theta_m_rad[k0 + j + 1];
            if !e.is_finite() {
                return None;
            }
            sum += e * e;
            count += 1;
        }
    }
    Some(math::sqrt(sum / count.max(1) as f64))
}
