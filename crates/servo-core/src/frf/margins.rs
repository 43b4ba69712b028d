//! The margins a measured loop achieved: gain crossover, phase margin and gain margin of an
//! estimated L(jw), each with an interval from the estimate's confidence bounds.
//!
//! Only bins with coherence >= `min_coherence` are used. Between two bins the magnitude is
//! interpolated linearly in log-log and the phase linearly in log frequency. As for the design
//! (MATLAB's `margin`), the phase margin is the smallest over all gain crossovers and the gain
//! margin that of the phase crossover with the smallest |GM|.
//!
//! Intervals: the crossover interval spans the frequencies where 1 lies inside the magnitude
//! bounds |L| (1 +- r) around the crossover; the phase-margin interval is the range of
//! 180 + angle L +- asin r over that interval; likewise for the gain margin around the phase
//! crossover.

use super::Frf;
use crate::math;
use alloc::string::String;
use alloc::vec::Vec;

/// A value with its interval [lo, hi].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    pub value: f64,
    pub lo: f64,
    pub hi: f64,
}

impl Interval {
    /// True when `x` lies in [lo, hi].
    pub fn contains(&self, x: f64) -> bool {
        x >= self.lo && x <= self.hi
    }
}

/// What the measured loop achieved.
#[derive(Debug, Clone, PartialEq)]
pub struct AchievedMargins {
    /// Gain crossover w_gc [rad/s]; None when |L| does not cross 1 within the coherent band.
    pub crossover_rad_s: Option<Interval>,
    /// Phase margin [deg].
    pub phase_margin_deg: Option<Interval>,
    /// Phase crossover w_pc [rad/s].
    pub phase_crossover_rad_s: Option<Interval>,
    /// Gain margin [dB].
    pub gain_margin_db: Option<Interval>,
    /// The coherent band used [rad/s] (lowest, highest bin).
    pub band_rad_s: (f64, f64),
    /// Why a figure is missing, for the user.
    pub notes: Vec<String>,
}

struct Pt {
    lw: f64,
    lm: f64,
    ph: f64,
    rel: f64,
    dph: f64,
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// The edge of the interval around a crossing at log w `lw_c` (where the band [lo, hi] of
/// `band(point)` holds `level`, with `at_c` the band there): walks from point `from` in direction
/// `dir` while the bands hold `level`, and interpolates where the violated bound reaches it.
/// Returns the first/last point's log w when the band holds `level` up to the data's end.
fn edge(
    pts: &[Pt],
    band: &dyn Fn(&Pt) -> (f64, f64),
    level: f64,
    lw_c: f64,
    at_c: (f64, f64),
    from: usize,
    dir: i64,
) -> f64 {
    let (mut plw, mut pb) = (lw_c, at_c);
    let mut i = from as i64;
    while i >= 0 && (i as usize) < pts.len() {
        let p = &pts[i as usize];
        let b = band(p);
        if b.0 <= level && level <= b.1 {
            plw = p.lw;
            pb = b;
            i += dir;
            continue;
        }
        let (v0, v1) = if b.0 > level {
            (pb.0, b.0)
        } else {
            (pb.1, b.1)
        };
        let t = if v1 != v0 {
            ((level - v0) / (v1 - v0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        return lerp(plw, p.lw, t);
    }
    plw
}

/// The range of `g` over the points with log w in [lw_lo, lw_hi], together with the points'
/// values at the interval's ends interpolated.
fn range_over(pts: &[Pt], lw_lo: f64, lw_hi: f64, g: &dyn Fn(&Pt, f64) -> f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut take = |v: f64| {
        lo = lo.min(v);
        hi = hi.max(v);
    };
    for w in pts.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        for lw in [lw_lo, lw_hi] {
            if lw >= a.lw && lw <= b.lw {
                let t = (lw - a.lw) / (b.lw - a.lw);
                for s in [-1.0, 1.0] {
                    take(lerp(g(a, s), g(b, s), t));
                }
            }
        }
    }
    for p in pts.iter().filter(|p| p.lw >= lw_lo && p.lw <= lw_hi) {
        for s in [-1.0, 1.0] {
            take(g(p, s));
        }
    }
    (lo, hi)
}

/// Margins of the measured loop `l` (bins with coherence >= `min_coherence`); `start_deg` is the
/// phase branch at low frequency (-90 per integrator in the loop).
pub fn achieved_margins(l: &Frf, min_coherence: f64, start_deg: f64) -> AchievedMargins {
    let phase = l.phase_deg(start_deg);
    let pts: Vec<Pt> = l
        .coherent(min_coherence)
        .filter(|&i| l.rel_radius[i].is_finite())
        .map(|i| Pt {
            lw: math::ln(l.omega(i)),
            lm: math::ln(l.mag(i)),
            ph: phase[i],
            rel: l.rel_radius[i],
            dph: l.phase_bound_deg(i),
        })
        .collect();
    let mut out = AchievedMargins {
        crossover_rad_s: None,
        phase_margin_deg: None,
        phase_crossover_rad_s: None,
        gain_margin_db: None,
        band_rad_s: (f64::NAN, f64::NAN),
        notes: Vec::new(),
    };
    if pts.len() < 2 {
        out.notes.push(alloc::format!(
            "fewer than two frequencies have coherence >= {min_coherence}: the data carry no information on the loop's margins"
        ));
        return out;
    }
    out.band_rad_s = (math::exp(pts[0].lw), math::exp(pts[pts.len() - 1].lw));
    let band = alloc::format!("{:.3}..{:.1} rad/s", out.band_rad_s.0, out.band_rad_s.1);
    let upper = |p: &Pt| p.lm + math::ln(1.0 + p.rel);
    let lower = |p: &Pt| p.lm + math::ln((1.0 - p.rel).max(1e-300));
    // Gain crossovers.
    let mut best: Option<(Interval, Interval)> = None;
    for k in 0..pts.len() - 1 {
        let (a, b) = (&pts[k], &pts[k + 1]);
        if (a.lm > 0.0) == (b.lm > 0.0) {
            continue;
        }
        let t = a.lm / (a.lm - b.lm);
        let lw = lerp(a.lw, b.lw, t);
        let pm = 180.0 + lerp(a.ph, b.ph, t);
        // Crossover interval: where 1 lies inside the magnitude bounds around the crossover.
        let band = |p: &Pt| (lower(p), upper(p));
        let at_c = (lerp(lower(a), lower(b), t), lerp(upper(a), upper(b), t));
        let left = edge(&pts, &band, 0.0, lw, at_c, k, -1);
        let right = edge(&pts, &band, 0.0, lw, at_c, k + 1, 1);
        let (lo, hi) = range_over(&pts, left, right, &|p, s| 180.0 + p.ph + s * p.dph);
        let wc = Interval {
            value: math::exp(lw),
            lo: math::exp(left),
            hi: math::exp(right),
        };
        let pmi = Interval {
            value: pm,
            lo: lo.min(pm),
            hi: hi.max(pm),
        };
        if !matches!(&best, Some((_, p)) if p.value <= pm) {
            best = Some((wc, pmi));
        }
    }
    match best {
        Some((wc, pm)) if pm.hi - pm.lo >= 360.0 => {
            out.crossover_rad_s = Some(wc);
            out.notes.push(alloc::format!(
                "phase margin not measured: its {:.0} % interval [{}, {}] deg is wider than the circle (the bounds around L near the crossover {}..{} rad/s allow any phase); average more periods or excite more strongly",
                100.0 * l.confidence,
                math::sig(pm.lo, 3),
                math::sig(pm.hi, 3),
                math::sig(wc.lo, 3),
                math::sig(wc.hi, 3)
            ));
        }
        Some((wc, pm)) => {
            out.crossover_rad_s = Some(wc);
            out.phase_margin_deg = Some(pm);
        }
        None => out.notes.push(alloc::format!(
            "|L| does not cross 1 within the coherent band {band} (|L| from {:.3} to {:.3}): crossover and phase margin not measured",
            math::exp(pts[0].lm),
            math::exp(pts[pts.len() - 1].lm)
        )),
    }
    // Phase crossovers at -180 + 360 k.
    let mut best_gm: Option<(Interval, Interval, bool)> = None;
    for k in 0..pts.len() - 1 {
        let (a, b) = (&pts[k], &pts[k + 1]);
        let (lo, hi) = (a.ph.min(b.ph), a.ph.max(b.ph));
        let mut m = math::floor((lo + 180.0) / 360.0) + 1.0;
        while -180.0 + 360.0 * m <= hi {
            let target = -180.0 + 360.0 * m;
            m += 1.0;
            if b.ph == a.ph {
                continue;
            }
            let t = (target - a.ph) / (b.ph - a.ph);
            let lw = lerp(a.lw, b.lw, t);
            let gm = -20.0 * lerp(a.lm, b.lm, t) / math::ln(10.0);
            let band = |p: &Pt| (p.ph - p.dph, p.ph + p.dph);
            let at_c = (
                lerp(a.ph - a.dph, b.ph - b.dph, t),
                lerp(a.ph + a.dph, b.ph + b.dph, t),
            );
            let left = edge(&pts, &band, target, lw, at_c, k, -1);
            let right = edge(&pts, &band, target, lw, at_c, k + 1, 1);
            let db = 20.0 / math::ln(10.0);
            let (glo, ghi) = range_over(&pts, left, right, &|p, s| {
                -db * if s < 0.0 { upper(p) } else { lower(p) }
            });
            let wp = Interval {
                value: math::exp(lw),
                lo: math::exp(left),
                hi: math::exp(right),
            };
            let gmi = Interval {
                value: gm,
                lo: glo.min(gm),
                hi: ghi.max(gm),
            };
            // the circle around L contains 0 somewhere in the interval: any gain, any phase
            let origin = pts
                .iter()
                .filter(|p| p.lw >= left && p.lw <= right)
                .any(|p| p.rel >= 1.0);
            if !matches!(&best_gm, Some((_, g, _)) if g.value.abs() <= gm.abs()) {
                best_gm = Some((wp, gmi, origin));
            }
        }
    }
    match best_gm {
        // The bound around |L| reaches 0 somewhere near the phase crossover (the interval's top
        // is then -20 log10 of ~0): the gain margin could be anything.
        Some((wp, gm, origin)) if origin || !(gm.hi - gm.lo).is_finite() => {
            out.notes.push(alloc::format!(
                "gain margin not measured: its {:.0} % interval [{}, {}] dB spans more than the data can tell (the bounds around L near the phase crossover {}..{} rad/s contain L = 0, so any gain and phase); average more periods or excite more strongly",
                100.0 * l.confidence,
                math::sig(gm.lo, 3),
                math::sig(gm.hi, 3),
                math::sig(wp.lo, 3),
                math::sig(wp.hi, 3)
            ));
        }
        Some((wp, gm, _)) => {
            out.phase_crossover_rad_s = Some(wp);
            out.gain_margin_db = Some(gm);
        }
        None => out.notes.push(alloc::format!(
            "the phase of L does not reach -180 deg within the coherent band {band} (lowest {:.1} deg): gain margin not measured (excite higher frequencies to measure it)",
            pts.iter().map(|p| p.ph).fold(f64::INFINITY, f64::min)
        )),
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::Complex;

    fn loop_frf(rel: f64) -> Frf {
        // L = K / (s (s + 1)^2), K = 0.5: see design::margins' test
        let freq_hz: Vec<f64> = (1..4000).map(|k| k as f64 * 1e-3).collect();
        let h = freq_hz
            .iter()
            .map(|f| {
                let s = Complex::new(0.0, math::TAU * f);
                Complex::new(0.5, 0.0) / (s * (s + 1.0) * (s + 1.0))
            })
            .collect();
        Frf {
            coherence: alloc::vec![0.99; freq_hz.len()],
            rel_radius: alloc::vec![rel; freq_hz.len()],
            freq_hz,
            h,
            averages: 20.0,
            confidence: 0.95,
        }
    }

    #[test]
    fn exact_loop_gives_the_design_margins() {
        let m = achieved_margins(&loop_frf(0.0), 0.9, -90.0);
        let wc = m.crossover_rad_s.unwrap().value;
        assert!((wc * (1.0 + wc * wc) - 0.5).abs() < 1e-3, "{m:?}");
        let pm = 90.0 - 2.0 * wc.atan().to_degrees();
        assert!((m.phase_margin_deg.unwrap().value - pm).abs() < 0.05);
        assert!((m.phase_crossover_rad_s.unwrap().value - 1.0).abs() < 1e-3);
        assert!((m.gain_margin_db.unwrap().value - 20.0 * 4f64.log10()).abs() < 0.01);
    }

    #[test]
    fn bounds_widen_the_intervals() {
        let m = achieved_margins(&loop_frf(0.1), 0.9, -90.0);
        let (wc, pm, gm) = (
            m.crossover_rad_s.unwrap(),
            m.phase_margin_deg.unwrap(),
            m.gain_margin_db.unwrap(),
        );
        assert!(wc.lo < wc.value && wc.value < wc.hi);
        assert!(pm.hi - pm.lo > 2.0 * 5.7 - 0.1, "{pm:?}"); // asin 0.1 = 5.74 deg each side
        assert!(gm.lo < gm.value - 0.8 && gm.hi > gm.value + 0.8, "{gm:?}");
    }

    #[test]
    fn intervals_wider_than_the_circle_are_not_measured() {
        // A confidence circle as large as |L| itself: the phase can be anything.
        let m = achieved_margins(&loop_frf(1.2), 0.9, -90.0);
        assert!(m.phase_margin_deg.is_none(), "{m:?}");
        assert!(m.gain_margin_db.is_none(), "{m:?}");
        assert!(
            m.notes
                .iter()
                .any(|n| n.contains("phase margin not measured")),
            "{:?}",
            m.notes
        );
        assert!(
            m.notes
                .iter()
                .any(|n| n.contains("gain margin not measured")),
            "{:?}",
            m.notes
        );
        // still measured with tight bounds
        assert!(achieved_margins(&loop_frf(0.1), 0.9, -90.0)
            .phase_margin_deg
            .is_some());
    }

    #[test]
    fn incoherent_data_measure_nothing() {
        let mut l = loop_frf(0.1);
        l.coherence.iter_mut().for_each(|c| *c = 0.2);
        let m = achieved_margins(&l, 0.9, -90.0);
        assert!(m.crossover_rad_s.is_none() && !m.notes.is_empty());
    }
}
