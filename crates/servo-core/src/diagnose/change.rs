//! A plant that changes during a log (a load clamped on, a tightened coupling): a change-point
//! test on the base parameters of the torque balance (handout eq. 13 referred to the motor,
//! k_t i_a = J_eq dw_m/dt + B_eq w_m + tau_sf / N sign(w_m), or its u-driven form without the
//! current).
//!
//! For each log, the base model's residual is regressed on the base regressors (acceleration,
//! speed, sign of speed over N: the columns of J_eq, B_eq and tau_sf) separately before and
//! after every candidate time (a Chow test, every row a candidate, in one pass with prefix sums
//! of the normal equations). The best split's gain is the squared residual the change explains.
//! A change is reported when, on its log:
//!
//! 1. what it explains is material: at least `change_min_noise_ratio` times the balance's noise
//!    floor (RMS over the log's rows) and `change_min_share_pct` of the log's structured
//!    (above-floor) squared error;
//! 2. the parameter that carries it moved by at least `change_min_relative_pct`;
//! 3. it is a step, not a drift (a warming winding or grease): the best further split inside each
//!    of the two segments gains less than `change_max_further_pct` of the step's gain (a linear
//!    drift leaves a quarter of it there, a step only noise);
//!
//! with both segments at least `change_margin_pct` of the log long. The change is a signature of
//! its own ([`Change::signature`]), and the diagnosis is "unexplained" with it: no model of the
//! catalogue holds on both sides, and the experiment is to repeat the identification after it.

use super::structure::Signature;
use super::thresholds::{frac, Thresholds};
use crate::fit::model::{EqSolution, Equation};
use crate::fit::Dataset;
use crate::math;
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

/// Base regressors of the torque balance the test refits on each side: J_eq, B_eq, tau_sf.
const P: usize = 3;

/// One base parameter before and after a change.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamChange {
    /// `J_eq`, `B_eq` or `tau_sf`.
    pub name: &'static str,
    pub unit: &'static str,
    /// Fitted on the log's rows before / after the change [unit].
    pub before: f64,
    pub after: f64,
    /// Share of the change's gain this parameter alone explains (0..1).
    pub share: f64,
}

impl ParamChange {
    /// Relative change after / before - 1 [1] (against the larger magnitude when the value
    /// before is near zero).
    pub fn relative(&self) -> f64 {
        let den = if self.before.abs() > 1e-3 * self.after.abs() {
            self.before.abs()
        } else {
            self.after.abs().max(f64::MIN_POSITIVE)
        };
        (self.after - self.before) / den
    }
}

/// A change of the plant found in one log.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    /// Index of the log (0-based) and its source.
    pub log: usize,
    pub source: String,
    /// Time of the change from the log's start [s].
    pub time_s: f64,
    /// Length of the log [s].
    pub log_s: f64,
    /// The balance it was found in.
    pub equation: Equation,
    /// The base parameters, strongest change first (the first carries it).
    pub params: Vec<ParamChange>,
    /// RMS over the log's rows of what the change explains [unit of the balance].
    pub explained_rms: f64,
    /// The balance's noise floor [unit of the balance].
    pub floor: f64,
    /// Share of the log's structured (above-floor) squared error it explains (0..1).
    pub structured_share: f64,
    /// Gain of the best further split inside the two segments, as a share of the step's (0..1):
    /// small for a step, about a quarter for a drift.
    pub further_share: f64,
    /// Rows of the log the test ran on.
    pub rows: usize,
    /// Share of the whole balance's squared residual the change explains (0..1).
    pub share_of_balance: f64,
}

impl Change {
    /// "J_eq rose 12 % (7.00e-7 -> 7.84e-7 kg m^2) at t = 6.00 s in log 1 (source)".
    pub fn phrase(&self) -> String {
        let mut s = String::new();
        for (i, p) in self.params.iter().enumerate() {
            if i > 0 {
                s.push_str(", ");
            }
            let rel = p.relative();
            let by = if p.before == 0.0 || rel.abs() >= 100.0 {
                alloc::format!("({})", crate::math::change(p.before, p.after))
            } else {
                alloc::format!("{} %", crate::math::sig(100.0 * rel.abs(), 3))
            };
            s.push_str(&alloc::format!(
                "{} {} {by} ({} -> {} {})",
                p.name,
                if rel >= 0.0 { "rose" } else { "fell" },
                crate::math::sig(p.before, 4),
                crate::math::sig(p.after, 4),
                p.unit
            ));
        }
        s.push_str(&alloc::format!(
            " at t = {:.2} s in log {} ({})",
            self.time_s,
            self.log + 1,
            self.source
        ));
        s
    }

    /// The change as a signature of its balance (kind `change`).
    pub fn signature(&self) -> Signature {
        Signature {
            kind: "change",
            description: alloc::format!(
                "the plant changes during the log: {}; the base model refitted on each side explains {:.2e} {} RMS of the log, {:.1} times the noise floor and {:.0} % of its structured error, and no further split inside either side gains more than {:.0} % of that (a step, not a drift)",
                self.phrase(),
                self.explained_rms,
                self.equation.unit(),
                self.explained_rms / self.floor.max(f64::MIN_POSITIVE),
                100.0 * self.structured_share,
                100.0 * self.further_share
            ),
            share: self.share_of_balance,
            explained_rms: self.explained_rms,
            on_simulation: false,
            periodic: None,
            measured_on: alloc::format!(
                "all {} rows of log {} (fit and held out), the base parameters refitted before and after every candidate time",
                self.rows,
                self.log + 1
            ),
        }
    }

    /// The experiment that confirms it.
    pub fn experiment(&self) -> String {
        alloc::format!(
            "repeat the identification after the change (on a log recorded entirely after t = {:.1} s of log {}, or after the load was changed) and compare the parameters; if the plant should not change, check what happened at that time (a load clamped on, a loosened coupling)",
            self.time_s,
            self.log + 1
        )
    }
}

/// Normal equations of one segment: A = X^T X (row-major), b = X^T r, rr = r^T r.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    a: [[f64; P]; P],
    b: [f64; P],
    rr: f64,
    n: usize,
}

impl Sums {
    fn add(&mut self, x: &[f64; P], r: f64) {
        for u in 0..P {
            for v in 0..P {
                self.a[u][v] += x[u] * x[v];
            }
            self.b[u] += x[u] * r;
        }
        self.rr += r * r;
        self.n += 1;
    }
    fn minus(&self, o: &Sums) -> Sums {
        let mut s = *self;
        for u in 0..P {
            for v in 0..P {
                s.a[u][v] -= o.a[u][v];
            }
            s.b[u] -= o.b[u];
        }
        s.rr -= o.rr;
        s.n -= o.n;
        s
    }
    /// Least-squares coefficients of the regressors in `cols` (the others held at zero).
    fn solve(&self, cols: &[usize]) -> Option<[f64; P]> {
        let m = cols.len().min(P);
        let mut a = [0.0; P * P];
        let mut b = [0.0; P];
        for (i, &u) in cols.iter().take(m).enumerate() {
            for (j, &v) in cols.iter().take(m).enumerate() {
                a[i * m + j] = self.a[u][v];
            }
            b[i] = self.b[u];
        }
        let mut x = [0.0; P];
        if !math::solve_normal(&mut a, &mut b, &mut x, m, 1e-10) {
            return None;
        }
        let mut out = [0.0; P];
        for (i, &u) in cols.iter().take(m).enumerate() {
            out[u] = x[i];
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
    /// Residual sum of squares after the least-squares fit on `cols`.
    fn rss(&self, cols: &[usize]) -> f64 {
        let Some(x) = self.solve(cols) else {
            return self.rr;
        };
        let fitted: f64 = cols.iter().map(|&u| x[u] * self.b[u]).sum();
        (self.rr - fitted).max(0.0)
    }
}

/// The best split of rows `lo..hi` of the prefix sums `pre` (each side at least `margin` rows):
/// (split index, gain of refitting `cols` on each side over one fit).
fn best_split(pre: &[Sums], lo: usize, hi: usize, margin: usize, cols: &[usize]) -> (usize, f64) {
    let whole = pre[hi].minus(&pre[lo]);
    let rss0 = whole.rss(cols);
    let mut best = (lo, 0.0);
    if hi < lo + 2 * margin.max(1) {
        return best;
    }
    for s in lo + margin.max(1)..=hi - margin.max(1) {
        let left = pre[s].minus(&pre[lo]);
        let right = pre[hi].minus(&pre[s]);
        let gain = rss0 - left.rss(cols) - right.rss(cols);
        if gain > best.1 {
            best = (s, gain);
        }
    }
    best
}

/// The changes of the plant in the logs of `ds`, found in the base model's torque balance
/// `sol` (see the module's doc); `floor` is that balance's noise floor.
pub fn find(
    ds: &Dataset,
    plant: &Plant,
    sol: &EqSolution,
    floor: f64,
    th: &Thresholds,
) -> Vec<Change> {
    let rows = &ds.mech_rows;
    let n = rows.len().min(sol.resid.len());
    if n == 0 || floor.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return Vec::new();
    }
    let accel = ds.sample(rows, |r| &r.accel_f);
    let omega = ds.sample(rows, |r| &r.omega_f);
    let coulomb = &ds.coulomb_col;
    let total_ss: f64 = sol.resid[..n].iter().map(|r| r * r).sum();
    let p = &plant.params;
    let base = [p.j_eq(), plant.b_eq(), p.tau_sf()];
    const NAMES: [(&str, &str); P] = [("J_eq", "kg m^2"), ("B_eq", "N m s/rad"), ("tau_sf", "N m")];
    let all = [0, 1, 2];
    let mut out = Vec::new();
    for (ri, rec) in ds.recs.iter().enumerate() {
        let mut idx: Vec<usize> = (0..n).filter(|&i| rows.rec[i] == ri).collect();
        idx.sort_by_key(|&i| rows.k[i]);
        if idx.len() < 50 {
            continue;
        }
        let mut pre = Vec::with_capacity(idx.len() + 1);
        let mut s = Sums::default();
        pre.push(s);
        for &i in &idx {
            let c = coulomb.get(i).copied().unwrap_or(0.0);
            s.add(&[accel[i], omega[i], c], sol.resid[i]);
            pre.push(s);
        }
        let m = idx.len();
        let margin = ((frac(th.change_margin_pct) * m as f64) as usize).max(10);
        let (split, gain) = best_split(&pre, 0, m, margin, &all);
        if gain.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            continue;
        }
        // 1. Material: against the floor and the log's structured error.
        let explained_rms = math::sqrt(gain / m as f64);
        let log_ms = pre[m].rr / m as f64;
        let structured_ms = (log_ms - floor * floor).max(f64::MIN_POSITIVE);
        let structured_share = (gain / m as f64) / structured_ms;
        if explained_rms < th.change_min_noise_ratio * floor
            || structured_share < frac(th.change_min_share_pct)
        {
            continue;
        }
        // 3. A step, not a drift: the best further split inside each side.
        let inner = margin / 2;
        let further =
            best_split(&pre, 0, split, inner, &all).1 + best_split(&pre, split, m, inner, &all).1;
        let further_share = further / gain;
        if further_share >= frac(th.change_max_further_pct) {
            continue;
        }
        // 2. The parameters on each side, strongest single carrier first.
        let (left, right) = (pre[split], pre[m].minus(&pre[split]));
        let (Some(xl), Some(xr)) = (left.solve(&all), right.solve(&all)) else {
            continue;
        };
        let whole = pre[m];
        let mut params: Vec<ParamChange> = (0..P)
            .map(|u| {
                let one = [u];
                let single = whole.rss(&one) - left.rss(&one) - right.rss(&one);
                ParamChange {
                    name: NAMES[u].0,
                    unit: NAMES[u].1,
                    before: base[u] + xl[u],
                    after: base[u] + xr[u],
                    share: (single / gain).clamp(0.0, 1.0),
                }
            })
            .collect();
        params.sort_by(|a, b| b.share.total_cmp(&a.share));
        // The carrier, and any other parameter that alone explains half of the change.
        let lead = params[0].name;
        params.retain(|q| q.name == lead || q.share >= 0.5);
        if params[0].relative().abs() < frac(th.change_min_relative_pct) {
            continue;
        }
        params.retain(|q| q.relative().abs() >= frac(th.change_min_relative_pct));
        let k_split = rows.k[idx[split.min(m - 1)]];
        let t0 = rec.time_s.first().copied().unwrap_or(0.0);
        out.push(Change {
            log: ri,
            source: rec.source.clone(),
            time_s: rec.time_s[k_split] - t0,
            log_s: rec.time_s.last().copied().unwrap_or(t0) - t0,
            equation: sol.equation,
            params,
            explained_rms,
            floor,
            structured_share: structured_share.min(1.0),
            further_share,
            rows: m,
            share_of_balance: if total_ss > 0.0 { gain / total_ss } else { 0.0 },
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step in the coefficient of one regressor is found where it is, with its size; a ramp
    /// of the same size is refused by the further-split test.
    #[test]
    fn a_step_is_located_and_a_drift_is_not_a_step() {
        let m = 2000;
        let xs: Vec<[f64; P]> = (0..m)
            .map(|i| {
                let t = i as f64 * 0.37;
                [
                    math::sin(t),
                    math::cos(1.3 * t),
                    math::sign(math::sin(0.11 * t)),
                ]
            })
            .collect();
        let noise = |i: usize| 1e-3 * math::sin(i as f64 * 12.9898).fract();
        let prefix = |r: &dyn Fn(usize) -> f64| {
            let mut pre = alloc::vec![Sums::default()];
            let mut s = Sums::default();
            for (i, x) in xs.iter().enumerate() {
                s.add(x, r(i));
                pre.push(s);
            }
            pre
        };
        let all = [0, 1, 2];
        // A step of 0.1 in the first coefficient at row 1200.
        let step = |i: usize| if i >= 1200 { 0.1 * xs[i][0] } else { 0.0 } + noise(i);
        let pre = prefix(&step);
        let (s, gain) = best_split(&pre, 0, m, 200, &all);
        assert!((s as i64 - 1200).abs() <= 2, "split {s}");
        let further = best_split(&pre, 0, s, 100, &all).1 + best_split(&pre, s, m, 100, &all).1;
        assert!(further < 0.05 * gain, "{further} of {gain}");
        // The same change as a linear drift over the log.
        let drift = |i: usize| 0.1 * (i as f64 / m as f64) * xs[i][0] + noise(i);
        let pre = prefix(&drift);
        let (s, gain) = best_split(&pre, 0, m, 200, &all);
        let further = best_split(&pre, 0, s, 100, &all).1 + best_split(&pre, s, m, 100, &all).1;
        assert!(further > 0.15 * gain, "{further} of {gain}");
    }
}
