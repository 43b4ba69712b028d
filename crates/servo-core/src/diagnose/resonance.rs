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
//!
//! Every regressor of a balance goes through the record's zero-phase filter before it is
//! differentiated, so the residual's spectrum is what went in times the filter's power gain.
//! Sensor noise differentiated once or twice, or a missing term that carries the acceleration,
//! rises with frequency until the filter cuts it: the product is a hump at the filter's corner
//! (25 Hz by default), a peak of servo's own making. The peak is therefore found and judged on
//! the spectrum with the filter's response divided out ([`crate::signal::ZeroPhase::power_gain`])
//! and against its local background (the most prominent point, not the highest): a monotonic
//! background, whatever its slope, has no peak, and a mode keeps its narrow peak wherever it
//! falls. Only the share and mean square in the band are of the residual as it is.

use crate::fit::dataset::{Dataset, Rows};
use crate::math;
use crate::signal::ZeroPhase;
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
    /// Peak power of the held-out spectrum in the band over its local background, both with the
    /// filter's response divided out: the median level of the power law through the spectrum
    /// between half and twice the peak frequency, outside the band [1].
    pub prominence: f64,
    /// Prominence a peak of pure noise exceeds with probability [`FALSE_ALARM`] (at least
    /// [`MIN_PROMINENCE`]): see [`prominence_needed`] [1].
    pub prominence_needed: f64,
    /// The band the spectrum was scanned in [Hz] ([`scanned_band`]).
    pub scanned_hz: (f64, f64),
    /// Held-out contiguous runs the band's share and prominence were measured on.
    pub held_out_runs: usize,
    /// Rows in those runs.
    pub held_out_rows: usize,
    /// Rate of the rows [Hz] (the balance's rows are decimated after the filter).
    pub row_rate_hz: f64,
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
/// asymmetry and two-effect logs, 17.8-26.3 Hz, measured against a flat median before the
/// filter's response was divided out): such a hump may be described, but must not refuse the
/// effect that causes it. A shaft's ringing stands 13 to 24 times above the power law of its
/// background in the torque balance with the filter divided out (0.6 and 1.2 N m/rad, seeds
/// 49-54; 20 to 150 times a flat median before).
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
/// Lowest power gain of the record's filter at which the residual's spectrum is still read [1]:
/// the scan stops where the filter has removed more (-30 dB: 2.3 times a Butterworth pair's
/// cut-off). Beyond it, dividing the filter's response out would amplify rounding and the
/// aliases of the decimated rows rather than show what went in.
pub const MIN_FILTER_GAIN: f64 = 1e-3;
/// Step of the frequency grid the spectra are evaluated on [Hz].
const DF_HZ: f64 = 0.25;
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

/// Half-power half-width [Hz] of the peak of `s` at index `p`, on a uniform grid of step `df`;
/// `None` when the peak is not positive or does not fall to half on both sides inside the grid.
fn width_at(s: &[f64], p: usize, df: f64) -> Option<f64> {
    let top = *s.get(p)?;
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
    match (side(-1), side(1)) {
        (Some(a), Some(b)) => Some(0.5 * (a + b)),
        _ => None,
    }
}

/// Background of `sw` at `grid[g]`: the power law through the spectrum between half and twice
/// that frequency, outside `excl_hz` of it, evaluated there. Its slope is the least-squares
/// slope of log power against log frequency, its level the median of the log powers about that
/// slope (so that the background is the median level a peak is compared with, as
/// [`prominence_needed`] assumes). A residual's spectrum is seldom flat: a flat median of an
/// octave on a rising spectrum sits below the level at its top end, and a peak would stand out
/// of a background that merely rises (differentiated noise at the top of the scan). The global
/// median where that octave holds fewer than 8 bins.
fn local_background(sw: &[f64], grid: &[f64], g: usize, excl_hz: f64) -> f64 {
    let f0 = grid[g];
    let pts: Vec<(f64, f64)> = grid
        .iter()
        .zip(sw)
        .filter(|(f, s)| {
            **f > 0.5 * f0 && **f < 2.0 * f0 && (**f - f0).abs() > excl_hz && **s > 0.0
        })
        .map(|(f, s)| (math::ln(*f), math::ln(*s)))
        .collect();
    if pts.len() < 8 {
        return median(sw);
    }
    let n = pts.len() as f64;
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (sxx, sxy) = pts.iter().fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mx) * (x - mx), b + (x - mx) * (y - my))
    });
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let about: Vec<f64> = pts.iter().map(|(x, y)| y - slope * x).collect();
    math::exp(median(&about) + slope * math::ln(f0))
}

/// The most prominent point of the spectrum `sw` (the filter's response divided out): the index,
/// away from the scan's two ends, with the largest power over its local background
/// ([`local_background`], `excl_hz` around it left out), and its half-power half-width [Hz].
/// A background that only rises or falls, however steeply, has no such point standing out; the
/// highest point of a spectrum would be its end or the filter's corner.
fn most_prominent(sw: &[f64], grid: &[f64], excl_hz: f64, df: f64) -> Option<(usize, f64)> {
    let n = sw.len();
    if n < 5 {
        return None;
    }
    let (p, _) = (2..n - 2)
        .filter(|&g| sw[g] >= sw[g - 1] && sw[g] >= sw[g + 1])
        .map(|g| {
            (
                g,
                sw[g] / local_background(sw, grid, g, excl_hz).max(1e-300),
            )
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    Some((p, width_at(sw, p, df)?))
}

/// Frequency band [Hz] in which [`find`] looks for a resonance at the view's rows `idx`: from
/// three Hann main-lobe half-widths of the median contiguous run (at least 2 Hz) to 0.45 times
/// the rows' sampling rate or where the record's filter keeps [`MIN_FILTER_GAIN`] of the power,
/// whichever is lower. `None` when the rows hold too few contiguous runs for a spectrum. A
/// structural mode above the band (a stiff coupling) cannot show in this balance.
pub fn scanned_band(ds: &Dataset, rows: &Rows, idx: &[usize]) -> Option<(f64, f64)> {
    let sr = spectral_runs(ds, rows, idx)?;
    Some((sr.f_lo_hz, sr.f_hi_hz))
}

/// The contiguous runs of a view's rows and the band their spectrum is read in.
struct SpectralRuns {
    /// (first, past-the-end) into the view's rows.
    segs: Vec<(usize, usize)>,
    /// Period of the rows [s].
    dt_s: f64,
    /// Median run length [s] (the window of the averaged spectrum).
    t_seg_s: f64,
    /// The filter the rows' regressors went through (that of the first run's record).
    filter: ZeroPhase,
    /// The band scanned [Hz] ([`scanned_band`]).
    f_lo_hz: f64,
    f_hi_hz: f64,
}

/// The contiguous runs of the view's rows `idx` ([`runs`]) and the band of their spectrum;
/// `None` with fewer than 4 runs.
fn spectral_runs(ds: &Dataset, rows: &Rows, idx: &[usize]) -> Option<SpectralRuns> {
    let (segs, dt) = runs(ds, rows, idx);
    if segs.len() < 4 || dt <= 0.0 {
        return None;
    }
    let mut lens: Vec<f64> = segs.iter().map(|(a, b)| (b - a) as f64 * dt).collect();
    lens.sort_by(|a, b| a.total_cmp(b));
    let t_seg = lens[lens.len() / 2];
    let filter = ds.recs.get(rows.rec[idx[segs[0].0]])?.filter;
    let f_lo = (3.0 * 0.72 / t_seg).max(2.0);
    let mut f_hi = 0.45 / dt;
    // Where the filter has taken the spectrum below its floor, nothing is read (the gain falls
    // monotonically: the first grid point below the floor ends the scan).
    let mut f = f_lo;
    while f <= f_hi {
        if filter.power_gain(f) < MIN_FILTER_GAIN {
            f_hi = f - DF_HZ;
            break;
        }
        f += DF_HZ;
    }
    Some(SpectralRuns {
        segs,
        dt_s: dt,
        t_seg_s: t_seg,
        filter,
        f_lo_hz: f_lo,
        f_hi_hz: f_hi,
    })
}

/// `s` with the filter's power gain at each frequency of `grid` divided out.
fn unfiltered(s: &[f64], grid: &[f64], filter: &ZeroPhase) -> Vec<f64> {
    s.iter()
        .zip(grid)
        .map(|(v, f)| v / filter.power_gain(*f).max(MIN_FILTER_GAIN))
        .collect()
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
    let SpectralRuns {
        segs,
        dt_s: dt,
        t_seg_s: t_seg,
        filter,
        f_lo_hz: f_lo,
        f_hi_hz: f_hi,
    } = spectral_runs(ds, rows, idx)?;
    // Hann main lobe: half-power half-width about 0.72 / T.
    let win_hw = 0.72 / t_seg;
    let df = DF_HZ;
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
    // The peak and its width, on the fit rows' spectrum with the filter divided out.
    let (s_fit, _) = spectrum(r, &fit, dt, &grid);
    let (p, hw) = most_prominent(&unfiltered(&s_fit, &grid, &filter), &grid, 2.0 * win_hw, df)?;
    let f0 = grid[p];
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
    // The prominence, on the held-out spectrum with the filter divided out: its top in the band
    // over its local background (the power law around it).
    let sw_hold = unfiltered(&s_hold, &grid, &filter);
    let top_hold = grid
        .iter()
        .zip(&sw_hold)
        .filter(|(f, _)| (**f - f0).abs() <= band)
        .map(|(_, s)| *s)
        .fold(0.0, f64::max);
    let background = local_background(&sw_hold, &grid, p, band);
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
        let at = |h: &[(f64, (usize, usize))]| {
            let (s, _) = spectrum(r, &seg(h), dt, &grid);
            most_prominent(&unfiltered(&s, &grid, &filter), &grid, 2.0 * win_hw, df)
                .map(|(i, _)| grid[i])
        };
        if let (Some(fa), Some(fb)) = (at(slow), at(fast)) {
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
    let held_rows = hold.iter().map(|(a, b)| b - a).sum();
    Some(Resonance {
        freq_hz: f0,
        damping_ratio: zeta,
        damping_resolved,
        band_hz: band,
        share,
        band_ms: ms,
        prominence,
        prominence_needed: needed,
        scanned_hz: (f_lo, f_hi),
        held_out_runs: hold.len(),
        held_out_rows: held_rows,
        row_rate_hz: 1.0 / dt,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The spectra of a balance's residual as the filter leaves them, on the scan's grid (rows
    /// at 100 Hz after a 25 Hz filter at 1 kHz: 2-45 Hz): twice-differentiated white noise
    /// (power ~ f^4) times the filter's power gain, a hump whose top sits at the filter's corner,
    /// with a mode added or not.
    fn shaped(mode_hz: Option<f64>) -> (Vec<f64>, Vec<f64>, ZeroPhase) {
        let filter = ZeroPhase::clamped(25.0, 1e-3);
        let grid: Vec<f64> = (0..=172).map(|j| 2.0 + DF_HZ * j as f64).collect();
        let s = grid
            .iter()
            .map(|&f| {
                let x = f / 25.0;
                // A lightly damped mode (damping ratio 0.03), 20 times the background there.
                let mode = mode_hz.map_or(0.0, |f0| {
                    let (r, z) = (f / f0, 0.03);
                    20.0 / ((1.0 - r * r).powi(2) + (2.0 * z * r).powi(2)) * (2.0 * z).powi(2)
                });
                x.powi(4) * (1.0 + mode) * filter.power_gain(f)
            })
            .collect();
        (grid, s, filter)
    }

    /// The filter's hump tops out at its corner: the highest point of the spectrum as filtered
    /// (what the scan used to take as the peak) is within a hertz of 25 Hz. With the filter's
    /// response divided out, no point stands out of its local background.
    #[test]
    fn the_filters_corner_is_no_peak_once_its_response_is_divided_out() {
        let (grid, s, filter) = shaped(None);
        let top = (0..s.len()).max_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap();
        assert!((grid[top] - 25.0).abs() < 1.0, "hump at {} Hz", grid[top]);
        let sw = unfiltered(&s, &grid, &filter);
        if let Some((p, _)) = most_prominent(&sw, &grid, 0.5, DF_HZ) {
            let prom = sw[p] / local_background(&sw, &grid, p, 0.5);
            assert!(
                prom < MIN_PROMINENCE,
                "{} Hz stands {prom:.2} times out",
                grid[p]
            );
        }
    }

    /// A mode keeps its narrow peak wherever it falls, the filter's corner included: found at
    /// its frequency, far above its local background.
    #[test]
    fn a_mode_is_found_at_its_frequency_near_the_corner_too() {
        for f0 in [12.0, 21.0, 25.0, 29.8, 38.0] {
            let (grid, s, filter) = shaped(Some(f0));
            let sw = unfiltered(&s, &grid, &filter);
            let (p, hw) = most_prominent(&sw, &grid, 0.5, DF_HZ).unwrap();
            assert!(
                (grid[p] - f0).abs() <= DF_HZ,
                "{f0} Hz found at {} Hz",
                grid[p]
            );
            // Judged as `find` does: twice the half-width left out of the background.
            let prom = sw[p] / local_background(&sw, &grid, p, 2.0 * hw);
            assert!(prom > 10.0, "{f0} Hz: prominence {prom:.1}");
        }
    }
}
