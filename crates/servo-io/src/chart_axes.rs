//! What a chart needs besides drawing: "nice" tick values and their labels on linear and log
//! axes, and a trace reduced to a chart's width (its envelope kept). Pure functions, so that the
//! CLI's SVG charts (plotters), the Python package and a GUI label and thin traces alike.

/// About `n` "nice" tick values (1, 2 or 5 times a power of ten apart) covering [lo, hi], and
/// their spacing.
pub fn nice_ticks(lo: f64, hi: f64, n: usize) -> (Vec<f64>, f64) {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return (vec![lo], 1.0);
    }
    let raw = (hi - lo) / n.max(1) as f64;
    let p = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * p);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    let ticks = (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            if v.abs() < 1e-9 * step {
                0.0
            } else {
                v
            }
        })
        .collect();
    (ticks, step)
}

/// The label of tick `v` on an axis of tick spacing `step` reaching `max_abs`: plain decimals
/// with as many places as the spacing needs when the axis reaches 0.01 to 10^4, else
/// engineering notation (a mantissa and an exponent that is a multiple of 3: `12.5e-6`), so
/// ticks at a 1e-5 scale never all read `0.0`.
pub fn tick_label(v: f64, step: f64, max_abs: f64) -> String {
    let places = |step: f64| -> usize {
        let mut d = 0usize;
        while d < 9 {
            let x = step * 10f64.powi(d as i32);
            if (x - x.round()).abs() < 1e-6 * x.abs().max(1.0) {
                break;
            }
            d += 1;
        }
        d
    };
    // zero, also when plotters computes it as -1e-20 (no "-0e-6")
    if v == 0.0 || v.abs() <= 1e-6 * step.abs() {
        return "0".into();
    }
    // the decimals the value needs (ticks are multiples of plotters' own 1-2-5 step), at most
    // those of a tenth of the step estimated here
    let need = |x: f64, most: usize| -> usize {
        (0..=most)
            .find(|&d| {
                let y = x * 10f64.powi(d as i32);
                (y - y.round()).abs() < 1e-6 * y.abs().max(1.0)
            })
            .unwrap_or(most)
    };
    if (1e-2..1e4).contains(&max_abs) {
        return format!("{:.*}", need(v, places(step) + 1), v);
    }
    let e = 3 * (max_abs.log10() / 3.0).floor() as i32;
    let scale = 10f64.powi(e);
    format!(
        "{:.*}e{e}",
        need(v / scale, places(step / scale) + 1),
        v / scale
    )
}

/// A label for a log-axis tick: 3 significant figures without trailing zeros, engineering
/// notation outside 0.01..1e4.
pub fn log_tick_label(v: f64) -> String {
    let trim = |s: String| -> String {
        if s.contains('.') && !s.contains('e') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    };
    if (1e-2..1e4).contains(&v.abs()) {
        trim(servo_core::math::sig(v, 3))
    } else {
        let e = 3 * (v.abs().log10() / 3.0).floor() as i32;
        format!("{}e{e}", trim(servo_core::math::sig(v / 10f64.powi(e), 3)))
    }
}

/// The points of a run reduced for a chart `columns` pixels wide: when the run has more than
/// two points per column, each column keeps its first, lowest, highest and last point in time
/// order (the trace's envelope is kept, a spike stays visible), so the SVG's size is bounded by
/// the chart's width, not by the log's length. `log_x`: columns spaced on a log scale.
pub fn decimate(
    run: Vec<(f64, f64)>,
    x0: f64,
    x1: f64,
    columns: usize,
    log_x: bool,
) -> Vec<(f64, f64)> {
    if run.len() <= 4 * columns.max(1) || x1 <= x0 {
        return run;
    }
    let map = |x: f64| {
        if log_x {
            x.max(f64::MIN_POSITIVE).ln()
        } else {
            x
        }
    };
    let (a, b) = (map(x0), map(x1));
    let col = |x: f64| {
        (((map(x) - a) / (b - a) * columns as f64).floor().max(0.0) as usize).min(columns - 1)
    };
    let mut out = Vec::with_capacity(4 * columns);
    let mut i = 0;
    while i < run.len() {
        let c = col(run[i].0);
        let mut j = i;
        let (mut lo, mut hi) = (i, i);
        while j < run.len() && col(run[j].0) == c {
            if run[j].1 < run[lo].1 {
                lo = j;
            }
            if run[j].1 > run[hi].1 {
                hi = j;
            }
            j += 1;
        }
        let mut keep = [i, lo, hi, j - 1];
        keep.sort_unstable();
        let mut last = usize::MAX;
        for k in keep {
            if k != last {
                out.push(run[k]);
                last = k;
            }
        }
        i = j;
    }
    out
}
