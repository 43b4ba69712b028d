//! The pre-sliding regime: rows near reversals of the motion, within a few encoder counts of
//! travel since the last one. A dynamic friction (bristles: a Dahl or LuGre friction) acts there
//! as a spring that winds up from one side's friction level to the other's over a travel of
//! about twice its breakaway torque over the bristles' stiffness, and lags the speed: not the
//! steady-state (sliding) curve every friction shape of the catalogue describes. Its rows then
//! carry a residual of their own, far above that of the sliding rows, that no steady-state shape
//! fits, and it hides the shape the sliding rows show (a Stribeck hump, named "unexplained").
//!
//! [`extent`] measures the regime on the base model's torque-balance residual: the RMS in bands
//! of travel since the last reversal ([2, 4, 8, 16) encoder counts) against the sliding rows'
//! (travel of 32 counts or more) at the same speeds (in speed bins). The regime spans the bands up to the first that is not
//! `presliding_min_ratio` times the sliding rows' RMS, 16 counts at most; it is its own regime only when the rows
//! inside it are that far above the sliding rows and above the balance's incompleteness bar
//! (`unexplained_ratio` times its floor). The diagnosis then judges the candidates again on the
//! sliding rows ([`crate::fit::Dataset::without_presliding`]).

use super::thresholds::Thresholds;
use crate::fit::dataset::travel_counts;
use crate::fit::model::EqSolution;
use crate::fit::Dataset;
use crate::math;
use alloc::vec::Vec;

/// Travel since the last reversal beyond which a row slides [encoder counts]: the reference.
const SLIDING_COUNTS: f64 = 32.0;
/// Candidate extents [encoder counts]: the regime ends at the first band [edge, next edge) of
/// travel with rows that is not elevated, at the last edge at most (a few counts: beyond it the rows slide,
/// whatever lag is left, and the steady-state shapes are judged on them).
const EDGES: [f64; 4] = [2.0, 4.0, 8.0, 16.0];
/// Fewest rows a band needs to be judged.
const MIN_ROWS: usize = 20;
/// Speed bins the sliding rows are split into, for the comparison at the same speeds.
const SPEED_BINS: usize = 8;

/// The pre-sliding regime found in a torque balance's residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// Travel since the last reversal below which rows are pre-sliding [encoder counts].
    pub counts: f64,
    /// RMS residual of its rows over that of the sliding rows [x].
    pub ratio: f64,
    /// Its rows among the torque balance's.
    pub rows: usize,
    /// RMS residual of its rows [unit of the balance].
    pub rms: f64,
}

/// The pre-sliding regime of the base model's torque balance `sol` on `ds` (`floor`: the
/// balance's noise floor), when its rows carry a residual of their own (see the module's doc).
pub fn extent(ds: &Dataset, sol: &EqSolution, floor: f64, th: &Thresholds) -> Option<Extent> {
    let rows = &ds.mech_rows;
    let travel: Vec<Vec<f64>> = ds
        .recs
        .iter()
        .map(|r| travel_counts(r, ds.opts.min_speed_rad_s))
        .collect();
    let n = rows.len().min(sol.resid.len());
    let t: Vec<f64> = (0..n).map(|i| travel[rows.rec[i]][rows.k[i]]).collect();
    let speed: Vec<f64> = (0..n)
        .map(|i| ds.recs[rows.rec[i]].omega_f[rows.k[i]].abs())
        .collect();
    // The sliding rows' mean square per speed bin (quantiles of their speeds): a band is
    // compared with sliding rows at the same speeds, so a friction that depends on the speed
    // alone (a Stribeck hump at low speed) does not pass for a regime of the travel.
    let mut sliding_speeds: Vec<f64> = (0..n)
        .filter(|&i| t[i] >= SLIDING_COUNTS)
        .map(|i| speed[i])
        .collect();
    if sliding_speeds.len() < SPEED_BINS * MIN_ROWS {
        return None;
    }
    sliding_speeds.sort_by(|a, b| a.total_cmp(b));
    let m = sliding_speeds.len();
    let edges: Vec<f64> = (1..SPEED_BINS)
        .map(|j| sliding_speeds[j * m / SPEED_BINS])
        .collect();
    let bin = |w: f64| edges.iter().take_while(|e| w >= **e).count();
    let mut bin_ms = [0.0; SPEED_BINS];
    let mut bin_n = [0usize; SPEED_BINS];
    for i in (0..n).filter(|&i| t[i] >= SLIDING_COUNTS) {
        bin_ms[bin(speed[i])] += sol.resid[i] * sol.resid[i];
        bin_n[bin(speed[i])] += 1;
    }
    for (v, c) in bin_ms.iter_mut().zip(&bin_n) {
        *v /= (*c).max(1) as f64;
    }
    // Mean square of the rows with travel in [lo, hi), and that of sliding rows at their speeds.
    let ms = |lo: f64, hi: f64| -> Option<(f64, f64, usize)> {
        let (mut s, mut r, mut c) = (0.0, 0.0, 0usize);
        for i in 0..n {
            if t[i] >= lo && t[i] < hi {
                s += sol.resid[i] * sol.resid[i];
                r += bin_ms[bin(speed[i])];
                c += 1;
            }
        }
        (c >= MIN_ROWS).then(|| (s / c as f64, r / c as f64, c))
    };
    let ratio2 = th.presliding_min_ratio * th.presliding_min_ratio;
    // The first band above the regime: not elevated (or too few rows to say).
    let mut counts = EDGES[EDGES.len() - 1];
    for w in EDGES.windows(2) {
        // (A band without rows, e.g. inside the margin around stuck phases, says nothing.)
        if ms(w[0], w[1]).is_some_and(|(m, r, _)| m < ratio2 * r) {
            counts = w[0];
            break;
        }
    }
    let (inside_ms, inside_ref, inside) = ms(0.0, counts)?;
    let rms = math::sqrt(inside_ms);
    (inside_ms >= ratio2 * inside_ref && rms >= th.unexplained_ratio * floor).then(|| Extent {
        counts,
        ratio: math::sqrt(inside_ms / inside_ref.max(f64::MIN_POSITIVE)),
        rows: inside,
        rms,
    })
}
