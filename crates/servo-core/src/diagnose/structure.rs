//! What is left in a balance, in physical terms: its noise floor, how far above it the residual
//! sits, and which interpretable shape carries the structured part (speed, load or motor angle,
//! time, current, voltage, an oscillation in time).
//!
//! A residual that sits well above the noise floor of its balance and that no catalogue effect
//! explains is reported as *unexplained*, with these signatures: the user's first step towards
//! the missing term. The shapes are fitted on the fit blocks and judged on the held-out blocks,
//! so a shape is only named when it predicts the residual on data it was not fitted to.

use crate::fit::dataset::{Dataset, RecData, Rows};
use crate::fit::model::{EqSolution, Equation};
use crate::math;
use crate::plant::Plant;
use crate::signal::derivative;
pub use crate::verdict::BalanceKind;
use alloc::string::String;
use alloc::vec::Vec;
use core::fmt::Write;

use super::thresholds::frac;
pub use super::thresholds::Thresholds;

/// One interpretable shape of a residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Signature {
    /// Family: `speed`, `load_angle`, `motor_angle`, `time_drift`, `oscillation`, `resonance`,
    /// `current`, `voltage`, `offset`, `partial_effect` (a catalogue effect that predicts part
    /// of it, named in the conclusion).
    pub kind: &'static str,
    /// Plain-language description with the measured figure (shape, cycles per revolution, ...).
    pub description: String,
    /// Share of the held-out residual variance it explains (0..1); of the held-out simulation
    /// error's mean square when `on_simulation`.
    pub share: f64,
    /// RMS of what it explains on held-out rows [unit of the balance]; of the held-out
    /// simulated load angle [rad] when `on_simulation`.
    pub explained_rms: f64,
    /// Measured on the simulation of the motion (a mechanism outside the catalogue fitted as a
    /// model, [`super::checks::Neighbour`]), not on the balance's residual.
    pub on_simulation: bool,
    /// On which rows and in which frequency band it was measured, in words (e.g. "4000 held-out
    /// rows of 2 logs at 100 rows/s, 0-25 Hz (the filter's band)").
    pub measured_on: String,
    /// The order and modulation of a shape periodic in angle (kinds `motor_angle` and
    /// `load_angle`); `None` for every other kind.
    pub periodic: Option<Periodic>,
}

/// Where a residual periodic in angle sits: its order on either shaft and whether its amplitude
/// stays the same at every speed (a torque locked to the angle) or not (an angle sensor's error
/// grows with speed, a position-dependent friction reverses with the direction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Periodic {
    /// Cycles per load revolution.
    pub cycles_per_load_rev: f64,
    /// Cycles per motor revolution (cycles per load revolution / N).
    pub cycles_per_motor_rev: f64,
    /// The amplitude is independent of speed.
    pub speed_independent: bool,
}

impl Signature {
    /// What [`Signature::share`] is a share of, for a sentence: "residual" or "simulation
    /// error's mean square".
    pub fn share_of(&self) -> &'static str {
        if self.on_simulation {
            "simulation error's mean square"
        } else {
            "residual"
        }
    }
}

/// The residual of one balance after the model's base parameters are refitted.
#[derive(Debug, Clone, PartialEq)]
pub struct BalanceReport {
    pub equation: Equation,
    /// Where the structure points (torque, electrical, sensor).
    pub balance: BalanceKind,
    /// RMS of the residual [unit].
    pub rms: f64,
    /// Noise floor of the balance [unit]: sensor noise and encoder quantisation through the
    /// filter and derivatives of the equation.
    pub floor: f64,
    /// rms / floor.
    pub ratio_to_noise: f64,
    /// Shapes that predict the held-out residual, strongest first.
    pub signatures: Vec<Signature>,
    /// Above the noise floor by [`Thresholds::unexplained_ratio`] (and structured).
    pub above_noise: bool,
    /// The experiment that would tell the candidates apart.
    pub experiment: String,
    /// A resonance that rings in the residual (named among the signatures as `resonance`).
    pub resonance: Option<super::resonance::Resonance>,
    /// The band a resonance was looked for in [Hz] (`None`: too few contiguous rows): a mode
    /// above it (a stiff coupling) cannot show in this balance.
    pub resonance_band_hz: Option<(f64, f64)>,
}

/// Variance gains of the record's filter applied to white noise: (value, first derivative,
/// second derivative) [1, 1/s^2, 1/s^4].
fn filter_gains(r: &RecData) -> (f64, f64, f64) {
    let m = 2001.min(r.u_v.len().max(3) | 1);
    let mut imp = alloc::vec![0.0; m];
    imp[m / 2] = 1.0;
    let h = r.filt(&imp);
    let h1 = derivative(&h, r.dt_s);
    let h2 = derivative(&h1, r.dt_s);
    let ss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
    (ss(&h), ss(&h1), ss(&h2))
}

/// The noise floor of balance `eq` in `floors` (per balance, [`noise_floor`]); 0 when it has
/// none.
pub fn floor_in(floors: &[(Equation, f64)], eq: Equation) -> f64 {
    floors
        .iter()
        .find(|(e, _)| *e == eq)
        .map_or(0.0, |(_, f)| *f)
}

/// Noise floor (RMS) of an equation's residual [unit]: white current noise `sigma_i_a` and the
/// encoder quantisation of the angle (uniform, q / sqrt(12)), through the filter and the
/// derivatives each term takes.
pub fn noise_floor(ds: &Dataset, eq: Equation, plant: &Plant, sigma_i_a: Option<f64>) -> f64 {
    let Some(r) = ds.recs.first() else {
        return 0.0;
    };
    let (g0, g1, g2) = filter_gains(r);
    let q = ds
        .recs
        .iter()
        .filter_map(|r| crate::compare::quantum::encoder_quantum(&r.theta_m_rad))
        .fold(0.0f64, f64::max);
    let sq = q / math::sqrt(12.0);
    let si = sigma_i_a.unwrap_or(0.0);
    let p = &plant.params;
    let (j, b) = (plant.params.j_eq(), plant.b_eq());
    let v = match eq {
        Equation::Torque => {
            (p.k_t * si) * (p.k_t * si) * g0 + (j * sq) * (j * sq) * g2 + (b * sq) * (b * sq) * g1
        }
        Equation::Electrical => {
            let k = p.k_drv.max(1e-12);
            let a = p.r_eq() / k * si;
            let e = p.k_e / k * sq;
            let l = p.l_a / k * si;
            a * a * g0 + e * e * g1 + l * l * g1
        }
        Equation::Combined => {
            let bb = b + p.k_t * p.k_e / p.r_eq();
            (j * sq) * (j * sq) * g2 + (bb * sq) * (bb * sq) * g1
        }
    };
    math::sqrt(v)
}

/// Solves the small normal equations (A^T A) x = A^T r by Gaussian elimination with a ridge of
/// 1e-12 relative; `None` when singular.
fn small_lsq(cols: &[Vec<f64>], r: &[f64], sel: &[usize]) -> Option<Vec<f64>> {
    let p = cols.len();
    let mut a = alloc::vec![0.0; p * p];
    let mut b = alloc::vec![0.0; p];
    for &i in sel {
        for u in 0..p {
            let cu = cols[u][i];
            b[u] += cu * r[i];
            for v in u..p {
                a[u * p + v] += cu * cols[v][i];
            }
        }
    }
    for u in 0..p {
        for v in 0..u {
            a[u * p + v] = a[v * p + u];
        }
    }
    let mut x = alloc::vec![0.0; p];
    math::solve_normal(&mut a, &mut b, &mut x, p, 1e-12).then_some(x)
}

/// Rows (subsampled) and the signals at them.
struct View {
    /// Index of each view row in the equation's rows.
    row_idx: Vec<usize>,
    r: Vec<f64>,
    fit: Vec<usize>,
    hold: Vec<usize>,
    omega_m: Vec<f64>,
    theta_m: Vec<f64>,
    t_norm: Vec<f64>,
    time_s: Vec<f64>,
    i_a: Option<Vec<f64>>,
    u: Vec<f64>,
}

const MAX_ROWS: usize = 12_000;

fn view(ds: &Dataset, rows: &Rows, sol: &EqSolution) -> View {
    let n = rows.len().min(sol.resid.len());
    let stride = n.div_ceil(MAX_ROWS).max(1);
    // With the load angle measured, the motor speed is unknown near reversals of the motor
    // torque when the gears have play: the electrical balance is judged away from them.
    let idx: Vec<usize> = (0..n)
        .step_by(stride)
        .filter(|&i| !rows.torque_reversal.get(i).copied().unwrap_or(false))
        .collect();
    let mut v = View {
        row_idx: idx.clone(),
        r: Vec::with_capacity(idx.len()),
        fit: Vec::new(),
        hold: Vec::new(),
        omega_m: Vec::new(),
        theta_m: Vec::new(),
        t_norm: Vec::new(),
        time_s: Vec::new(),
        i_a: ds.has_current.then(Vec::new),
        u: Vec::new(),
    };
    for (j, &i) in idx.iter().enumerate() {
        let rec = &ds.recs[rows.rec[i]];
        let k = rows.k[i];
        v.r.push(sol.resid[i]);
        if rows.fit[i] {
            v.fit.push(j);
        } else {
            v.hold.push(j);
        }
        v.omega_m.push(rec.omega_f[k]);
        v.theta_m.push(rec.theta_m_rad[k]);
        let span = rec.time_s.last().copied().unwrap_or(1.0) - rec.time_s[0];
        v.t_norm
            .push(2.0 * (rec.time_s[k] - rec.time_s[0]) / span.max(1e-9) - 1.0);
        v.time_s.push(rec.time_s[k] - rec.time_s[0]);
        if let (Some(out), Some(i_f)) = (v.i_a.as_mut(), rec.i_f.as_ref()) {
            out.push(i_f[k]);
        }
        v.u.push(rec.u_v[k]);
    }
    // Without held-out rows, judge on every other row.
    if v.hold.is_empty() {
        let all: Vec<usize> = (0..v.r.len()).collect();
        v.fit = all.iter().copied().filter(|j| j % 2 == 0).collect();
        v.hold = all.into_iter().filter(|j| j % 2 == 1).collect();
    }
    v
}

/// Held-out share of variance explained by `cols` (fitted on the fit rows, with an intercept),
/// and the RMS it explains.
fn held_out(v: &View, cols: &[Vec<f64>]) -> (f64, f64) {
    let mut all: Vec<Vec<f64>> = Vec::with_capacity(cols.len() + 1);
    all.push(alloc::vec![1.0; v.r.len()]);
    all.extend(cols.iter().cloned());
    let base = held_out_raw(v, &all[..1]);
    let full = held_out_raw(v, &all);
    // Share beyond the intercept alone (an offset is its own signature).
    let ss: f64 = v.hold.iter().map(|&i| v.r[i] * v.r[i]).sum();
    if ss.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return (0.0, 0.0);
    }
    let gain = (base - full).max(0.0);
    (gain / ss, math::sqrt(gain / v.hold.len().max(1) as f64))
}

/// Held-out residual sum of squares after fitting `cols` on the fit rows.
fn held_out_raw(v: &View, cols: &[Vec<f64>]) -> f64 {
    let ss: f64 = v.hold.iter().map(|&i| v.r[i] * v.r[i]).sum();
    let Some(x) = small_lsq(cols, &v.r, &v.fit) else {
        return ss;
    };
    v.hold
        .iter()
        .map(|&i| {
            let pred: f64 = cols.iter().zip(&x).map(|(c, b)| c[i] * b).sum();
            let e = v.r[i] - pred;
            e * e
        })
        .sum()
}

/// Periodogram peak of `r` (mean removed) against phase `x * c` over the grid of `c`; returns
/// the c with the largest power.
fn peak(r: &[f64], x: &[f64], grid: impl Iterator<Item = f64>) -> Option<f64> {
    peaks(core::slice::from_ref(&r), x, grid)
        .into_iter()
        .next()
        .flatten()
}

/// [`peak`] of several signals sampled at the same `x`, in one scan (the phasors, which cost
/// most, are shared).
fn peaks(rs: &[&[f64]], x: &[f64], grid: impl Iterator<Item = f64>) -> Vec<Option<f64>> {
    let n = x.len();
    let none = || rs.iter().map(|_| None).collect();
    if n < 10 || rs.iter().any(|r| r.len() != n) {
        return none();
    }
    let cs: Vec<f64> = grid.collect();
    if cs.is_empty() {
        return none();
    }
    let centred: Vec<Vec<f64>> = rs
        .iter()
        .map(|r| {
            let m = r.iter().sum::<f64>() / n as f64;
            r.iter().map(|v| v - m).collect()
        })
        .collect();
    let mut best: Vec<Option<(f64, f64)>> = rs.iter().map(|_| None).collect();
    let dc = if cs.len() > 1 { cs[1] - cs[0] } else { 0.0 };
    let start: Vec<[f64; 4]> = x
        .iter()
        .map(|&t| {
            [
                math::cos(cs[0] * t),
                math::sin(cs[0] * t),
                math::cos(dc * t),
                math::sin(dc * t),
            ]
        })
        .collect();
    // Phasors advanced by rotation along the uniform grid of c. The rotation and the sums of up
    // to four signals share one pass over the rows; each sum still runs in row order (the same
    // arithmetic as one pass per signal), but the sums are independent, so the core overlaps
    // them.
    for (group, best) in centred.chunks(4).zip(best.chunks_mut(4)) {
        let d: Vec<[f64; 4]> = (0..n)
            .map(|i| core::array::from_fn(|s| group.get(s).map_or(0.0, |g| g[i])))
            .collect();
        let mut ph = start.clone();
        for (j, &c) in cs.iter().enumerate() {
            let (mut sc, mut ss) = ([0.0f64; 4], [0.0f64; 4]);
            for (p, di) in ph.iter_mut().zip(&d) {
                if j > 0 {
                    let (a, b) = (p[0], p[1]);
                    p[0] = a * p[2] - b * p[3];
                    p[1] = a * p[3] + b * p[2];
                }
                for s in 0..4 {
                    sc[s] += di[s] * p[0];
                    ss[s] += di[s] * p[1];
                }
            }
            for (s, best) in best.iter_mut().enumerate() {
                let pw = sc[s] * sc[s] + ss[s] * ss[s];
                if best.is_none_or(|(_, bp)| pw > bp) {
                    *best = Some((c, pw));
                }
            }
        }
    }
    best.into_iter().map(|b| b.map(|(c, _)| c)).collect()
}

fn grid(lo: f64, hi: f64, step: f64) -> impl Iterator<Item = f64> {
    let n = ((hi - lo) / step).max(0.0) as usize;
    (0..=n).map(move |j| lo + step * j as f64)
}

fn pair(x: &[f64], c: f64, scale: Option<&[f64]>) -> Vec<Vec<f64>> {
    let s: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, &t)| math::sin(c * t) * scale.map_or(1.0, |w| w[i]))
        .collect();
    let co: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, &t)| math::cos(c * t) * scale.map_or(1.0, |w| w[i]))
        .collect();
    alloc::vec![s, co]
}

/// sin and cos of `c_m` times the motor angle, modulated by each `m(omega_m)` of `ms`, through
/// each record's filter, at the rows of the view: one pair of columns per modulation, in the
/// order of `ms`. The sin and cos of each record are computed once and shared by the
/// modulations.
fn filtered_pairs(
    ds: &Dataset,
    rows: &Rows,
    v: &View,
    c_m: f64,
    ms: &[fn(f64) -> f64],
) -> Vec<Vec<Vec<f64>>> {
    let n = v.row_idx.len();
    let mut out: Vec<Vec<Vec<f64>>> = ms
        .iter()
        .map(|_| alloc::vec![Vec::with_capacity(n), Vec::with_capacity(n)])
        .collect();
    // The view's rows, in runs of one record each: a record is filtered whole, once per run, and
    // only the view's rows of it are kept (one record-length column alive at a time).
    let mut start = 0;
    while start < n {
        let ri = rows.rec[v.row_idx[start]];
        let end = (start..n)
            .find(|&j| rows.rec[v.row_idx[j]] != ri)
            .unwrap_or(n);
        let r = &ds.recs[ri];
        let sin: Vec<f64> = r.theta_m_rad.iter().map(|t| math::sin(c_m * t)).collect();
        let cos: Vec<f64> = r.theta_m_rad.iter().map(|t| math::cos(c_m * t)).collect();
        for (m, pair) in ms.iter().zip(out.iter_mut()) {
            let modulated = |f: &[f64]| -> Vec<f64> {
                f.iter().zip(&r.omega_raw).map(|(x, w)| x * m(*w)).collect()
            };
            let (fs, fc) = r.filt_pair(&modulated(&sin), &modulated(&cos));
            for (filtered, col) in [&fs, &fc].into_iter().zip(pair.iter_mut()) {
                col.extend(v.row_idx[start..end].iter().map(|&i| filtered[rows.k[i]]));
            }
        }
        start = end;
    }
    out
}

fn pow_odd(x: &[f64], p: f64) -> Vec<f64> {
    x.iter()
        .map(|&w| math::sign(w) * math::pow(w.abs(), p))
        .collect()
}

/// The rows a balance's shapes are judged on, in words: the held-out rows of the view, how many
/// logs they come from, their rate, and the band the filter leaves them.
fn rows_phrase(ds: &Dataset, rows: &Rows, v: &View) -> String {
    let mut recs: Vec<usize> = v.hold.iter().map(|&j| rows.rec[v.row_idx[j]]).collect();
    recs.sort_unstable();
    recs.dedup();
    let mut steps: Vec<f64> = v
        .hold
        .windows(2)
        .filter(|w| w[1] == w[0] + 1 && rows.rec[v.row_idx[w[0]]] == rows.rec[v.row_idx[w[1]]])
        .map(|w| v.time_s[w[1]] - v.time_s[w[0]])
        .filter(|d| *d > 0.0)
        .collect();
    steps.sort_by(|a, b| a.total_cmp(b));
    let rate = steps.get(steps.len() / 2).map_or(0.0, |d| 1.0 / d);
    let logs = if recs.len() == 1 { "log" } else { "logs" };
    alloc::format!(
        "{} held-out rows of {} {logs} at {rate:.0} rows/s, 0-{:.0} Hz (the filter's band)",
        v.hold.len(),
        recs.len(),
        ds.opts.filter_hz
    )
}

/// Analyses the residual of one balance of the base model.
pub fn analyse(
    ds: &Dataset,
    sol: &EqSolution,
    floor: f64,
    th: &Thresholds,
    gear_ratio: f64,
) -> BalanceReport {
    let rows = if sol.equation == Equation::Electrical {
        &ds.elec_rows
    } else {
        &ds.mech_rows
    };
    let v = view(ds, rows, sol);
    let rms = math::sqrt(v.r.iter().map(|x| x * x).sum::<f64>() / v.r.len().max(1) as f64);
    let ratio = if floor > 0.0 {
        rms / floor
    } else {
        f64::INFINITY
    };
    let unit = sol.equation.unit();
    let measured_on = rows_phrase(ds, rows, &v);
    let mut sigs: Vec<Signature> = Vec::new();
    // The order of the periodic shape, set on its signature once the shapes are all in.
    let mut periodic: Option<Periodic> = None;
    let mut push = |kind: &'static str, description: String, (share, rms_x): (f64, f64)| {
        sigs.push(Signature {
            kind,
            description,
            share,
            explained_rms: rms_x,
            on_simulation: false,
            periodic: None,
            measured_on: measured_on.clone(),
        });
    };
    // Constant offset.
    {
        let ss: f64 = v.hold.iter().map(|&i| v.r[i] * v.r[i]).sum();
        let m = v.fit.iter().map(|&i| v.r[i]).sum::<f64>() / v.fit.len().max(1) as f64;
        let after: f64 = v.hold.iter().map(|&i| (v.r[i] - m) * (v.r[i] - m)).sum();
        let gain = (ss - after).max(0.0);
        let what = match sol.equation {
            Equation::Electrical => "an offset of the current sensor or of the driver's voltage",
            _ => "a constant torque (a steady load, or an offset of the current sensor)",
        };
        push(
            "offset",
            alloc::format!("a constant offset of {m:.3e} {unit}: {what}"),
            (
                if ss > 0.0 { gain / ss } else { 0.0 },
                math::sqrt(gain / v.hold.len().max(1) as f64),
            ),
        );
    }
    // Speed: odd and even powers (linear and sign are in the base model).
    {
        let mut best: Option<(f64, String, (f64, f64))> = None;
        for (p, odd) in [
            (0.5, true),
            (2.0, true),
            (3.0, true),
            (1.0, false),
            (2.0, false),
        ] {
            let col: Vec<f64> = if odd {
                pow_odd(&v.omega_m, p)
            } else {
                v.omega_m.iter().map(|w| math::pow(w.abs(), p)).collect()
            };
            let res = held_out(&v, &[col]);
            let shape = match (p, odd) {
                (0.5, true) => {
                    "like sign(omega) sqrt|omega| (rises steeply at low speed, then flattens)"
                }
                (2.0, true) => "quadratically with speed, opposing the motion (omega |omega|)",
                (3.0, true) => "with the cube of speed, opposing the motion (omega^3)",
                (1.0, false) => "with |omega|, the same in both directions",
                _ => "with omega^2, the same in both directions",
            };
            if best.as_ref().is_none_or(|b| res.0 > b.2 .0) {
                best = Some((p, String::from(shape), res));
            }
        }
        // The share is that of the odd and even powers together (a friction curve is rarely
        // one power); the shape named is the single power that carries most of it.
        let joint = held_out(
            &v,
            &[
                pow_odd(&v.omega_m, 0.5),
                pow_odd(&v.omega_m, 2.0),
                pow_odd(&v.omega_m, 3.0),
                v.omega_m.iter().map(|w| w.abs()).collect(),
            ],
        );
        if let Some((_, shape, res)) = best {
            let res = if joint.0 > res.0 { joint } else { res };
            push(
                "speed",
                alloc::format!("grows {shape} beyond the linear viscous and Coulomb terms"),
                res,
            );
        }
    }
    // Periodic in angle (load-angle cycles per load revolution; motor harmonics = c / N), with
    // an amplitude that is constant (a torque ripple), grows with speed (the derivative of an
    // angle error), with speed squared (its second derivative), or reverses with the direction
    // of motion (a friction that varies with position). Each modulation gets its own scan; the
    // regressors at the peak go through the record's filter, as the residual did.
    {
        let n = gear_ratio.max(1.0);
        type Modulation = (&'static str, fn(f64) -> f64);
        let mods: [Modulation; 4] = [
            ("with an amplitude independent of speed", |_| 1.0),
            ("with an amplitude growing in proportion to speed", |w| w),
            ("with an amplitude growing like speed^2", |w| w * w),
            (
                "reversing with the direction of motion (a friction that varies with position)",
                math::sign,
            ),
        ];
        let scan_idx: Vec<usize> = v
            .fit
            .iter()
            .copied()
            .step_by(v.fit.len().div_ceil(4000).max(1))
            .collect();
        let fit_x: Vec<f64> = scan_idx.iter().map(|&i| v.theta_m[i] / n).collect();
        let w_max = v
            .omega_m
            .iter()
            .fold(0.0f64, |a, w| a.max(w.abs()))
            .max(1e-9);
        let fit_rs: Vec<Vec<f64>> = mods
            .iter()
            .map(|(_, m)| {
                scan_idx
                    .iter()
                    .map(|&i| v.r[i] * m(v.omega_m[i] / w_max))
                    .collect()
            })
            .collect();
        let refs: Vec<&[f64]> = fit_rs.iter().map(|r| r.as_slice()).collect();
        let found = peaks(&refs, &fit_x, grid(0.5, n * 45.0, 0.1));
        // The regressors of the modulations whose peaks fall at the same c are built together.
        let mut cols_of: Vec<Option<Vec<Vec<f64>>>> = mods.iter().map(|_| None).collect();
        for (mi, c) in found.iter().enumerate() {
            let Some(c) = *c else {
                continue;
            };
            if cols_of[mi].is_some() {
                continue;
            }
            let same: Vec<usize> = (mi..mods.len())
                .filter(|&mj| found[mj] == Some(c))
                .collect();
            let ms: Vec<fn(f64) -> f64> = same.iter().map(|&mj| mods[mj].1).collect();
            for (mj, cols) in same
                .into_iter()
                .zip(filtered_pairs(ds, rows, &v, c / n, &ms))
            {
                cols_of[mj] = Some(cols);
            }
        }
        let mut best: Option<(f64, usize, (f64, f64))> = None;
        for (mi, (c, cols)) in found.iter().zip(&cols_of).enumerate() {
            let (Some(c), Some(cols)) = (*c, cols) else {
                continue;
            };
            let res = held_out(&v, cols);
            if best.as_ref().is_none_or(|b| res.0 > b.2 .0) {
                best = Some((c, mi, res));
            }
        }
        if let Some((c, mi, res)) = best {
            let cm = c / n;
            let near_int = |x: f64| (x - math::round(x)).abs() < 0.06 && math::round(x) >= 1.0;
            let which = if near_int(cm) {
                alloc::format!(
                    "{c:.1} cycles per load revolution = {cm:.2} per motor revolution (a motor-angle harmonic)"
                )
            } else if near_int(c) {
                alloc::format!(
                    "{c:.1} cycles per load revolution (a load-angle harmonic; {cm:.2} per motor revolution)"
                )
            } else {
                alloc::format!(
                    "{c:.2} cycles per load revolution = {cm:.3} per motor revolution (no harmonic of either shaft)"
                )
            };
            let kind = if near_int(cm) {
                "motor_angle"
            } else {
                "load_angle"
            };
            push(
                kind,
                alloc::format!("periodic in angle at {which}, {}", mods[mi].0),
                res,
            );
            periodic = Some(Periodic {
                cycles_per_load_rev: c,
                cycles_per_motor_rev: cm,
                speed_independent: mi == 0,
            });
        }
    }
    // Oscillation in time (a resonance or a ripple at a fixed frequency).
    {
        let fit_r: Vec<f64> = v.fit.iter().map(|&i| v.r[i]).collect();
        let fit_t: Vec<f64> = v.fit.iter().map(|&i| v.time_s[i]).collect();
        let tau = core::f64::consts::TAU;
        let f_max = (0.9 * ds.opts.filter_hz).max(1.0);
        if let Some(w) = peak(&fit_r, &fit_t, grid(tau * 0.5, tau * f_max, tau * 0.02)) {
            let res = held_out(&v, &pair(&v.time_s, w, None));
            push(
                "oscillation",
                alloc::format!("an oscillation at {:.2} Hz in time", w / tau),
                res,
            );
        }
    }
    // Drift with time over each log.
    {
        let p2: Vec<f64> = v.t_norm.iter().map(|t| 1.5 * t * t - 0.5).collect();
        let res = held_out(&v, &[v.t_norm.clone(), p2]);
        push(
            "time_drift",
            String::from("drifts with time over the log (a temperature-dependent resistance or friction, a drifting sensor)"),
            res,
        );
    }
    // Current and voltage.
    if let Some(i) = &v.i_a {
        let sq: Vec<f64> = pow_odd(i, 2.0);
        let sg: Vec<f64> = i.iter().map(|x| math::sign(*x)).collect();
        let (res, what) = if sol.equation == Equation::Electrical {
            let a = held_out(&v, core::slice::from_ref(&sq));
            let b = held_out(&v, &[sg]);
            if b.0 > a.0 {
                (
                    b,
                    "a step with the sign of the current (a brush or switch voltage drop)",
                )
            } else {
                (a, "grows faster than linearly with the current (a current-dependent resistance or sensor gain)")
            }
        } else {
            (
                held_out(&v, &[sq]),
                "grows faster than linearly with the current (a torque constant that falls with current, or a current-sensor nonlinearity)",
            )
        };
        push("current", String::from(what), res);
    }
    if ds.has_input {
        let u3 = pow_odd(&v.u, 3.0);
        let su: Vec<f64> = v.u.iter().map(|x| math::sign(*x)).collect();
        let a = held_out(&v, &[u3]);
        let b = held_out(&v, &[su]);
        let (res, what) = if b.0 > a.0 {
            (
                b,
                "a step with the sign of the command u (a driver offset or dead band)",
            )
        } else {
            (
                a,
                "grows with the cube of the command u (a nonlinear driver gain)",
            )
        };
        push("voltage", String::from(what), res);
    }
    // A resonance: ringing after each step at a fixed frequency, which no steady sinusoid fits
    // (its phase restarts at every excitation) but whose spectrum has a narrow peak.
    let mut resonance = None;
    {
        let steady = sigs
            .iter()
            .find(|s| s.kind == "oscillation")
            .map_or(0.0, |s| s.share);
        // A complete balance holds nothing material: a peak there is the sensors' (a
        // quantisation ripple at the speed a log dwells at moves with that speed) or a
        // friction's pre-sliding ringing, no structural mode.
        let material = ratio >= th.resonance_min_ratio;
        let found = if material {
            super::resonance::find(ds, rows, &v.row_idx, &v.r, &v.omega_m)
        } else {
            None
        };
        if let Some(res) =
            found.filter(|res| res.prominence >= res.prominence_needed && res.share >= 2.0 * steady)
        {
            sigs.push(Signature {
                kind: "resonance",
                description: alloc::format!(
                    "rings as a resonance near {:.1} Hz ({}; spectral peak {:.1} times its local background, where noise alone exceeds {:.1} with probability {}) after steps and reversals, at the same frequency at slow and fast speeds (no harmonic of load or motor angle): a structural mode, e.g. a compliant shaft or coupling",
                    res.freq_hz,
                    super::resonance::damping_phrase(&res),
                    res.prominence,
                    res.prominence_needed,
                    super::resonance::FALSE_ALARM
                ),
                share: res.share,
                explained_rms: math::sqrt(res.band_ms),
                on_simulation: false,
                periodic: None,
                measured_on: alloc::format!(
                    "{} held-out rows in {} contiguous runs at {:.0} rows/s; spectrum {:.1}-{:.1} Hz with the {:.0} Hz filter's response divided out",
                    res.held_out_rows,
                    res.held_out_runs,
                    res.row_rate_hz,
                    res.scanned_hz.0,
                    res.scanned_hz.1,
                    ds.opts.filter_hz
                ),
            });
            resonance = Some(res);
        }
    }
    for s in sigs
        .iter_mut()
        .filter(|s| s.kind == "motor_angle" || s.kind == "load_angle")
    {
        s.periodic = periodic;
    }
    sigs.retain(|s| s.share >= frac(th.min_signature_share_pct) && s.explained_rms > 0.0);
    sigs.sort_by(|a, b| b.share.total_cmp(&a.share));
    let structured =
        !sigs.is_empty() || ratio >= th.structured_without_shape * th.unexplained_ratio;
    let above_noise = ratio >= th.unexplained_ratio && structured;
    // Where it lives: an error whose angle-periodic part grows with speed in the electrical
    // balance (k_e times an angle error's derivative), or with speed^2 in the torque balance
    // (J times its second derivative), follows the angle sensor.
    let sensor = sigs.first().is_some_and(|s| {
        (s.kind == "motor_angle" || s.kind == "load_angle")
            && ((sol.equation == Equation::Electrical
                && s.description.contains("proportion to speed"))
                || (sol.equation != Equation::Electrical && s.description.contains("speed^2")))
    });
    let balance = if sensor {
        BalanceKind::Sensor
    } else if sol.equation == Equation::Electrical {
        BalanceKind::Electrical
    } else {
        BalanceKind::Torque
    };
    let resonance = resonance.filter(|_| sigs.iter().any(|s| s.kind == "resonance"));
    let experiment = match (sigs.first(), resonance) {
        (Some(s), Some(res)) if s.kind == "resonance" => alloc::format!(
            "excite around {:.0} Hz with a small chirp (experiments/chirp.toml, e.g. {:.0} to {:.0} Hz) and run `servo frf` on the log, logging motor and load angles if you can: a compliant shaft or coupling shows a resonance peak and an antiresonance at fixed frequencies, whatever the amplitude and speed, and the motor and load angles differ there; a play would instead change with the amplitude",
            res.freq_hz,
            (0.5 * res.freq_hz).max(1.0),
            2.0 * res.freq_hz
        ),
        _ => experiment_for(balance, sigs.first()),
    };
    BalanceReport {
        equation: sol.equation,
        balance,
        rms,
        floor,
        ratio_to_noise: ratio,
        signatures: sigs,
        above_noise,
        experiment,
        resonance,
        resonance_band_hz: super::resonance::scanned_band(ds, rows, &v.row_idx),
    }
}

/// The experiment that would separate the candidate mechanisms behind a signature.
fn experiment_for(balance: BalanceKind, top: Option<&Signature>) -> String {
    let base = match top.map(|s| s.kind) {
        Some("speed") => "run a friction staircase (constant speeds in both directions, slow to fast) and log the current: the torque at each speed gives the friction curve's shape directly",
        Some("motor_angle") | Some("load_angle") => "turn the shaft at two different constant speeds over several revolutions: a torque ripple keeps its amplitude in N m, an angle-sensor error grows with speed in the torque and electrical balances, and a periodic error in both the load and motor encoders points at the sensor",
        Some("oscillation") => "apply a chirp or PRBS of small amplitude and log motor and load angles: a compliant shaft shows a resonance at a fixed frequency between the two angles; a ripple at a fixed frequency stays when the speed changes",
        Some("time_drift") => "repeat the same experiment cold and after 10 minutes of running, and log the winding temperature or resistance",
        Some("current") => "apply slow current (torque) ramps at standstill and at constant speed and compare the current sensor with an external meter",
        Some("voltage") => "apply slow voltage ramps through zero with the motor free and clamped, and measure the driver output with a meter",
        Some("offset") => "log the current and the voltage with the motor at rest and powered off: a nonzero reading is a sensor offset; a constant torque that reverses with the mounting is a load",
        _ => "log motor and load angles and the current over slow constant-speed and fast chirp segments to expose the structure",
    };
    match balance {
        BalanceKind::Sensor => alloc::format!(
            "{base}; to confirm a sensor error, compare the encoder with a second angle sensor or turn the shaft by hand through known angles"
        ),
        _ => String::from(base),
    }
}

/// Share of the resonance band's power that a candidate's residual `cand` keeps against the base
/// model's residual `base` (same balance) [1]: both mean squares in the band of `res` on the
/// held-out rows that BOTH weigh. A model with a gear play gives no weight to the rows near a
/// reversal of the motor torque (`contact`: the candidate's model has a contact effect), which
/// is where a resonance rings after each step: those rows leave both sums, so a candidate cannot
/// "explain" the ringing by ignoring the rows it lives in.
pub fn resonance_kept(
    ds: &Dataset,
    base: &EqSolution,
    cand: &EqSolution,
    contact: bool,
    res: &super::resonance::Resonance,
) -> f64 {
    let rows = if cand.equation == Equation::Electrical {
        &ds.elec_rows
    } else {
        &ds.mech_rows
    };
    let band = |sol: &EqSolution| {
        let v = view(ds, rows, sol);
        let keep: Vec<usize> = (0..v.row_idx.len())
            .filter(|&j| {
                !(contact
                    && rows
                        .gap_crossing
                        .get(v.row_idx[j])
                        .copied()
                        .unwrap_or(false))
            })
            .collect();
        let idx: Vec<usize> = keep.iter().map(|&j| v.row_idx[j]).collect();
        let r: Vec<f64> = keep.iter().map(|&j| v.r[j]).collect();
        super::resonance::band_ms(ds, rows, &idx, &r, res)
    };
    let before = band(base);
    if before.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return 0.0;
    }
    band(cand) / before
}

/// Text of a balance report (for the verdict).
pub fn describe(b: &BalanceReport) -> String {
    // "the torque balance", or "the electrical balance (u-driven balance)" where the balance
    // was judged through another equation.
    let mut s = alloc::format!("the {} balance", b.balance.name());
    if b.equation.name() != alloc::format!("{} balance", b.balance.name()) {
        let _ = write!(s, " ({})", b.equation.name());
    }
    if b.floor > 0.0 && b.floor.is_finite() && b.ratio_to_noise.is_finite() {
        let _ = write!(
            s,
            " leaves {:.2e} {} RMS, {:.1} times its noise floor ({:.2e} {})",
            b.rms,
            b.equation.unit(),
            b.ratio_to_noise,
            b.floor,
            b.equation.unit()
        );
    } else {
        // No sensor noise model for this balance (no current logged, an angle that is not on
        // an encoder's grid): the floor is unknown, not zero.
        let _ = write!(
            s,
            " leaves {:.2e} {} RMS against a noise floor these logs do not give (no current logged, or an angle that is not on an encoder's grid): how much of it is structure rather than noise is not determined",
            b.rms,
            b.equation.unit()
        );
    }
    if b.signatures.is_empty() {
        s.push_str("; no simple shape of speed, angle, time, current or voltage carries it");
    } else {
        // The shapes' descriptions are phrases of either kind ("a constant offset of ...",
        // "drifts with time ..."): listed after a colon, not as the verb of a sentence.
        s.push_str("; shapes that carry it: ");
        let mut last_on: Option<&str> = None;
        for (i, sig) in b.signatures.iter().take(3).enumerate() {
            if i > 0 {
                s.push_str("; ");
            }
            let _ = write!(
                s,
                "{} ({:.0} % of the held-out {}",
                sig.description,
                100.0 * sig.share,
                sig.share_of()
            );
            // Where it was measured, once for the shapes that share their rows and band.
            if !sig.measured_on.is_empty() && last_on != Some(sig.measured_on.as_str()) {
                let _ = write!(s, "; measured on {}", sig.measured_on);
                last_on = Some(sig.measured_on.as_str());
            }
            s.push(')');
        }
    }
    if let (true, None, Some((lo, hi))) = (b.above_noise, &b.resonance, b.resonance_band_hz) {
        // Say what was not seen: a stiff coupling's mode above the rows' band is not ruled out.
        let _ = write!(
            s,
            "; no resonance stands out between {lo:.0} and {hi:.0} Hz, the band these rows resolve (a structural mode above it, e.g. a stiff shaft or coupling, cannot show here: a chirp to a higher frequency analysed with `servo frf` would)"
        );
    }
    let _ = write!(s, ". To tell the candidates apart: {}.", b.experiment);
    s
}
