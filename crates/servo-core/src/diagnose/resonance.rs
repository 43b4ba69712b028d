//! A resonance in a balance's residual: a lightly damped oscillation that rings after each step
//! or reversal (a compliant shaft or coupling, a flexible mount), at a frequency fixed by
//! stiffness and inertia whatever the speed.
//!
//! Ringing restarts with a new phase and amplitude at every excitation, so no single steady
//! sinusoid fits it; its power spectrum does: a narrow peak at the damped natural frequency f_d
//! whose half-power half-width is about zeta f_d. The spectrum is averaged over the contiguous
//! runs of rows (Welch-like, Hann window, each run its own segment), the peak and its width are
//! found on the fit rows and the share of the residual in that band is judged on the held-out
//! rows. A periodic torque in angle moves its frequency with speed: the peak must stay at the
//! same frequency in the slow and the fast half of the runs when their speeds differ.

use crate::fit::dataset::{Dataset, Rows};
use crate::math;
use alloc::vec::Vec;

/// A resonance found in a residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonance {
    /// Peak frequency (damped natural frequency) [Hz].
    pub freq_hz: f64,
    /// Damping ratio from the half-power half-width (window broadening removed) [1]; an upper
    /// bound when `damping_resolved` is false.
    pub damping_ratio: f64,
    /// Whether the peak is wider than the window alone makes it: otherwise the contiguous
    /// stretches of the log are too short to resolve the damping, and `damping_ratio` is the
    /// largest one the measured width allows.
    pub damping_resolved: bool,
    /// Half-width of the band judged around the peak [Hz].
    pub band_hz: f64,
    /// Share of the held-out residual's power in the band (0..1).
    pub share: f64,
    /// Mean square of the held-out residual in the band [unit^2].
    pub band_ms: f64,
    /// Peak power of the held-out spectrum in the band over its local background: the median
    /// power between half and twice the peak frequency, outside the band [1].
    pub prominence: f64,
    /// Prominence a peak of pure noise exceeds with probability [`FALSE_ALARM`] (at least
    /// [`MIN_PROMINENCE`]): see [`prominence_needed`] [1].
    pub prominence_needed: f64,
}

/// Probability that noise alone, with a locally flat spectrum, puts a peak in the judged band
/// at or above [`Resonance::prominence_needed`] (per balance and diagnosis).
pub const FALSE_ALARM: f64 = 1e-3;
/// Smallest prominence called a resonance whatever the statistics: a peak less than three times
/// its background is no structural mode a user can act on.
pub const MIN_PROMINENCE: f64 = 3.0;

/// Prominence a resonance needs to refuse a catalogue candidate that leaves it (the check
/// "explains the resonance"), above the one that names it. A model missing a play, a friction or
/// a direction-dependent friction also leaves humps in its residual near the position loop's
/// bandwidth (3.2 to 8.3 times their local background on the diagnose tests' hidden gear play,
/// asymmetry and two-effect logs, 17.8-26.3 Hz): such a hump may be described, but must not
/// refuse the effect that causes it. A shaft's ringing stands 20 to 150 times above its
/// background (0.6 and 1.2 N m/rad, seeds 49-54).
pub const REFUSE_PROMINENCE: f64 = 12.0;

/// Upper-tail quantile of the standard normal distribution: z with P(Z > z) = `p` (0 < p <= 0.5;
/// Abramowitz & Stegun 26.2.23, error below 4.5e-4).
fn normal_upper_quantile(p: f64) -> f64 {
    let p = p.clamp(1e-300, 0.5);
    let t = math::sqrt(-2.0 * math::ln(p));
    t - (2.515517 + 0.802853 * t + 0.010328 * t * t)
        / (1.0 + 1.432788 * t + 0.189269 * t * t + 0.001308 * t * t * t)
}

/// The prominence (peak over median) that noise exceeds with probability `alpha` in an averaged
/// periodogram of `k_eff` independent segments, the peak being the largest of `bins`
/// independent frequency bins. Each bin of such a spectrum, over its expected value, is a
/// chi-square with 2 K degrees of freedom divided by 2 K; its quantiles and median come from the
/// Wilson-Hilferty approximation (chi2_nu / nu ~ (1 - 2/(9 nu) + z sqrt(2/(9 nu)))^3), and the
/// largest of `bins` exceeds the quantile 1 - alpha / bins with probability about alpha.
pub fn prominence_needed(k_eff: f64, bins: f64, alpha: f64) -> f64 {
    let nu = 2.0 * k_eff.max(1.0);
    let c = 2.0 / (9.0 * nu);
    let z = normal_upper_quantile(alpha / bins.max(1.0));
    let cube = |x: f64| x * x * x;
    let q = cube(1.0 - c + z * math::sqrt(c));
    let med = cube(1.0 - c);
    (q / med).max(MIN_PROMINENCE)
}

/// Largest damping ratio still called a resonance (a broader hump is no resonance).
const MAX_DAMPING: f64 = 0.25;
/// Shortest run of contiguous rows used as a segment.
const MIN_RUN: usize = 12;

/// Contiguous runs of rows: (first, end) into `idx`, same record, uniform spacing, one side of
/// the fit / held-out split. Returns the runs and the row period [s].
fn runs(ds: &Dataset, rows: &Rows, idx: &[usize]) -> (Vec<(usize, usize)>, f64) {
    let mut diffs: Vec<usize> = idx
        .windows(2)
        .filter(|w| rows.rec[w[0]] == rows.rec[w[1]] && rows.k[w[1]] > rows.k[w[0]])
        .map(|w| rows.k[w[1]] - rows.k[w[0]])
        .collect();
    if diffs.is_empty() {
        return (Vec::new(), 0.0);
    }
    diffs.sort_unstable();
    let step = diffs[diffs.len() / 2];
    let mut out = Vec::new();
    let mut start = 0;
    for j in 1..=idx.len() {
        let brk = j == idx.len() || {
            let (a, b) = (idx[j - 1], idx[j]);
            rows.rec[a] != rows.rec[b]
                || rows.k[b] != rows.k[a] + step
                || rows.fit[a] != rows.fit[b]
        };
        if brk {
            if j - start >= MIN_RUN {
                out.push((start, j));
            }
            start = j;
        }
    }
    let dt = out
        .first()
        .map_or(0.0, |&(a, _)| ds.recs[rows.rec[idx[a]]].dt_s * step as f64);
    (out, dt)
}

/// Averaged spectrum of `r` over `segs` on the grid `grid` [Hz]: (sum of |X(f)|^2, sum over
/// segments of the windowed energy).
fn spectrum(r: &[f64], segs: &[(usize, usize)], dt: f64, grid: &[f64]) -> (Vec<f64>, f64) {
    let mut s = alloc::vec![0.0; grid.len()];
    let mut energy = 0.0;
    let tau = core::f64::consts::TAU;
    for &(a, b) in segs {
        let n = b - a;
        let m = r[a..b].iter().sum::<f64>() / n as f64;
        let x: Vec<f64> = (0..n)
            .map(|i| {
                let w = 0.5 - 0.5 * math::cos(tau * (i as f64 + 0.5) / n as f64);
                (r[a + i] - m) * w
            })
            .collect();
        energy += x.iter().map(|v| v * v).sum::<f64>();
        for (g, &f) in grid.iter().enumerate() {
            let (c1, s1) = (math::cos(tau * f * dt), math::sin(tau * f * dt));
            let (mut c, mut sn) = (1.0, 0.0);
            let (mut re, mut im) = (0.0, 0.0);
            for &v in &x {
                re += v * c;
                im += v * sn;
                let nc = c * c1 - sn * s1;
                sn = sn * c1 + c * s1;
                c = nc;
            }
            s[g] += re * re + im * im;
        }
    }
    (s, energy)
}

fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    s.get(s.len() / 2).copied().unwrap_or(0.0)
}

/// Peak of `s` (index) and its half-power half-width [Hz] on a uniform grid of step `df`.
fn peak_width(s: &[f64], df: f64) -> Option<(usize, f64)> {
    let (p, &top) = s.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    if top.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return None;
    }
    let half = 0.5 * top;
    let side = |dir: isize| -> Option<f64> {
        let mut j = p as isize;
        loop {
            let nx = j + dir;
            if nx < 0 || nx as usize >= s.len() {
                return None;
            }
            if s[nx as usize] < half {
                let (a, b) = (s[j as usize], s[nx as usize]);
                let frac = (a - half) / (a - b).max(1e-300);
                return Some(((j - p as isize).abs() as f64 + frac) * df);
            }
            j = nx;
        }
    };
    let w = match (side(-1), side(1)) {
        (Some(a), Some(b)) => 0.5 * (a + b),
        _ => return None,
    };
    Some((p, w))
}

/// Frequency band [Hz] in which [`find`] looks for a resonance at the view's rows `idx`: from
/// three Hann main-lobe half-widths of the median contiguous run (at least 2 Hz) to 0.45 times
/// the rows' sampling rate. `None` when the rows hold too few contiguous runs for a spectrum.
/// A structural mode above the band (a stiff coupling) cannot show in this balance.
pub fn scanned_band(ds: &Dataset, rows: &Rows, idx: &[usize]) -> Option<(f64, f64)> {
    let (_, dt, t_seg) = spectral_runs(ds, rows, idx)?;
    Some(((3.0 * 0.72 / t_seg).max(2.0), 0.45 / dt))
}

/// Contiguous runs (start, end) of a view's rows, their sample period [s] and their median
/// length [s].
type SpectralRuns = (Vec<(usize, usize)>, f64, f64);

/// The contiguous runs of the view's rows `idx` ([`runs`]), their sample period [s] and their
/// median length [s] (the window of the averaged spectrum); `None` with fewer than 4 runs.
fn spectral_runs(ds: &Dataset, rows: &Rows, idx: &[usize]) -> Option<SpectralRuns> {
    let (segs, dt) = runs(ds, rows, idx);
    if segs.len() < 4 || dt <= 0.0 {
        return None;
    }
    let mut lens: Vec<f64> = segs.iter().map(|(a, b)| (b - a) as f64 * dt).collect();
    lens.sort_by(|a, b| a.total_cmp(b));
    let t_seg = lens[lens.len() / 2];
    Some((segs, dt, t_seg))
}

/// Finds a resonance in a balance's residual over `rows`, at the view's rows `idx`
/// (indices into `rows`, in time order) with residual values `r`. `omega_m` holds the motor speed
/// at the same rows.
pub fn find(
    ds: &Dataset,
    rows: &Rows,
    idx: &[usize],
    r: &[f64],
    omega_m: &[f64],
) -> Option<Resonance> {
    let (segs, dt, t_seg) = spectral_runs(ds, rows, idx)?;
    // Hann main lobe: half-power half-width about 0.72 / T.
    let win_hw = 0.72 / t_seg;
    let df = 0.25;
    let f_lo = (3.0 * win_hw).max(2.0);
    let f_hi = 0.45 / dt;
    if f_hi <= f_lo + 4.0 * df {
        return None;
    }
    let n_grid = ((f_hi - f_lo) / df) as usize;
    let grid: Vec<f64> = (0..=n_grid).map(|j| f_lo + df * j as f64).collect();
    // Contiguous runs (first, past-the-end row) on fit rows and on held-out rows.
    type Runs = Vec<(usize, usize)>;
    let (fit, hold): (Runs, Runs) = segs.iter().partition(|&&(a, _)| rows.fit[idx[a]]);
    let (fit, hold) = if hold.is_empty() || fit.is_empty() {
        // Without held-out rows, judge on every other run.
        segs.iter()
            .enumerate()
            .fold((Vec::new(), Vec::new()), |(mut f, mut h), (i, s)| {
                if i % 2 == 0 {
                    f.push(*s);
                } else {
                    h.push(*s);
                }
                (f, h)
            })
    } else {
        (fit, hold)
    };
    let (s_fit, _) = spectrum(r, &fit, dt, &grid);
    let (p, hw) = peak_width(&s_fit, df)?;
    let f0 = grid[p];
    // Not at the edges of the band scanned.
    if p < 2 || p + 2 >= grid.len() {
        return None;
    }
    // The window alone makes a peak about `win_hw` wide: a narrower true peak is not resolved,
    // and the measured width then only bounds the damping.
    let hw_true = math::sqrt((hw * hw - win_hw * win_hw).max(0.0));
    let damping_resolved = hw_true >= 0.5 * win_hw;
    let zeta = if damping_resolved {
        hw_true
    } else {
        hw.max(0.5 * win_hw)
    } / f0;
    if zeta > MAX_DAMPING {
        return None;
    }
    let band = 2.0 * hw.max(win_hw);
    let (s_hold, e_hold) = spectrum(r, &hold, dt, &grid);
    let in_band: f64 = grid
        .iter()
        .zip(&s_hold)
        .filter(|(f, _)| (**f - f0).abs() <= band)
        .map(|(_, s)| s)
        .sum::<f64>()
        * df;
    // One-sided integral of |X(f)|^2 over 0..fs/2 equals fs/2 times the windowed energy.
    let total = 0.5 / dt * e_hold;
    if total <= 0.0 {
        return None;
    }
    let share = (in_band / total).min(1.0);
    let top_hold = grid
        .iter()
        .zip(&s_hold)
        .filter(|(f, _)| (**f - f0).abs() <= band)
        .map(|(_, s)| *s)
        .fold(0.0, f64::max);
    // The background: the median of the held-out spectrum from half to twice the peak frequency,
    // outside the band (a residual's spectrum is seldom flat over the whole scan, and a global
    // median under- or over-states the level around the peak); the global median where that
    // octave holds too few bins.
    let local: Vec<f64> = grid
        .iter()
        .zip(&s_hold)
        .filter(|(f, _)| **f > 0.5 * f0 && **f < 2.0 * f0 && (**f - f0).abs() > band)
        .map(|(_, s)| *s)
        .collect();
    let background = if local.len() >= 8 {
        median(&local)
    } else {
        median(&s_hold)
    };
    let prominence = top_hold / background.max(1e-300);
    // Its false-alarm threshold: the held-out runs are the averaged segments (weighted by their
    // length: K = (sum n)^2 / sum n^2), the band holds about 2 band T independent bins (the
    // spectral resolution of a run of T seconds is 1/T), and the peak frequency was chosen on
    // the fit rows, so only the band's bins are searched on the held-out ones.
    let (sum_n, sum_n2) = hold.iter().fold((0.0, 0.0), |(a, b), &(i, j)| {
        let n = (j - i) as f64;
        (a + n, b + n * n)
    });
    let k_eff = if sum_n2 > 0.0 {
        sum_n * sum_n / sum_n2
    } else {
        1.0
    };
    let needed = prominence_needed(k_eff, 2.0 * band * t_seg, FALSE_ALARM);
    // The same frequency at two speeds: split the runs by their mean |speed|.
    let mean_speed = |&(a, b): &(usize, usize)| {
        omega_m[a..b].iter().map(|w| w.abs()).sum::<f64>() / (b - a) as f64
    };
    let mut by_speed: Vec<(f64, (usize, usize))> =
        segs.iter().map(|s| (mean_speed(s), *s)).collect();
    by_speed.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mid = by_speed.len() / 2;
    let (slow, fast) = by_speed.split_at(mid);
    let speed =
        |h: &[(f64, (usize, usize))]| h.iter().map(|x| x.0).sum::<f64>() / h.len().max(1) as f64;
    if slow.len() >= 2 && fast.len() >= 2 && speed(fast) > 1.3 * speed(slow) {
        let seg = |h: &[(f64, (usize, usize))]| h.iter().map(|x| x.1).collect::<Vec<_>>();
        let (a, _) = spectrum(r, &seg(slow), dt, &grid);
        let (b, _) = spectrum(r, &seg(fast), dt, &grid);
        let fa = peak_width(&a, df).map(|(i, _)| grid[i]);
        let fb = peak_width(&b, df).map(|(i, _)| grid[i]);
        if let (Some(fa), Some(fb)) = (fa, fb) {
            if (fa - fb).abs() > band {
                return None;
            }
        }
    }
    let ms = in_band
        / (0.5 / dt)
        / hold
            .iter()
            .map(|(a, b)| 0.375 * (b - a) as f64)
            .sum::<f64>()
            .max(1.0);
    Some(Resonance {
        freq_hz: f0,
        damping_ratio: zeta,
        damping_resolved,
        band_hz: band,
        share,
        band_ms: ms,
        prominence,
        prominence_needed: needed,
    })
}

/// Mean square of `r` in the band of `res` on the held-out runs (the same runs and grid as
/// [`find`]): how much of the resonance a candidate leaves.
pub fn band_ms(ds: &Dataset, rows: &Rows, idx: &[usize], r: &[f64], res: &Resonance) -> f64 {
    let (segs, dt) = runs(ds, rows, idx);
    if segs.is_empty() || dt <= 0.0 {
        return 0.0;
    }
    let df = 0.25;
    let n = (2.0 * res.band_hz / df) as usize;
    let grid: Vec<f64> = (0..=n)
        .map(|j| res.freq_hz - res.band_hz + df * j as f64)
        .filter(|f| *f > 0.0)
        .collect();
    let hold: Vec<(usize, usize)> = segs
        .iter()
        .copied()
        .filter(|&(a, _)| !rows.fit[idx[a]])
        .collect();
    let hold = if hold.is_empty() { segs } else { hold };
    let (s, _) = spectrum(r, &hold, dt, &grid);
    let in_band = s.iter().sum::<f64>() * df;
    in_band
        / (0.5 / dt)
        / hold
            .iter()
            .map(|(a, b)| 0.375 * (b - a) as f64)
            .sum::<f64>()
            .max(1.0)
}

/// The damping ratio of `res` in words: its value, or the bound when the log's contiguous
/// stretches are too short to resolve it.
pub fn damping_phrase(res: &Resonance) -> alloc::string::String {
    if res.damping_resolved {
        alloc::format!("damping ratio ~{:.2}", res.damping_ratio)
    } else {
        alloc::format!(
            "damping ratio below ~{:.2}: lighter than the log's contiguous stretches resolve",
            res.damping_ratio
        )
    }
}
