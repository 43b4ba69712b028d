//! Small SVG charts (plotters, SVG backend, no system fonts needed).

use anyhow::anyhow;
use plotters::prelude::*;
pub use servo_io::chart_axes::{decimate, log_tick_label, nice_ticks, tick_label};
use servo_io::markup::svg_text;

/// One line of a chart.
pub struct Series<'a> {
    pub label: &'a str,
    pub x: &'a [f64],
    pub y: &'a [f64],
}

/// Options of a line chart.
pub struct Chart<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    /// Logarithmic x axis (Bode plots).
    pub log_x: bool,
    /// Ticks on whole numbers of x only (counts: "effects added").
    pub integer_x: bool,
    /// Points instead of lines (a residual against a state: samples, not a path in time).
    pub scatter: bool,
    /// One line through the valid points however far apart in x (a frequency response measured
    /// on a multisine's sparse lines). Otherwise a jump of more than 5 median steps in x starts
    /// a new line (a log with a hole). Non-finite values break a line either way.
    pub join_gaps: bool,
    pub width: u32,
    pub height: u32,
}

impl Default for Chart<'_> {
    fn default() -> Self {
        Chart {
            title: "",
            x_label: "",
            y_label: "",
            log_x: false,
            integer_x: false,
            scatter: false,
            join_gaps: false,
            width: 900,
            height: 400,
        }
    }
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(127, 127, 127),
];

fn bounds(series: &[Series], log_x: bool) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for s in series {
        for (&x, &y) in s.x.iter().zip(s.y) {
            if !x.is_finite() || !y.is_finite() || (log_x && x <= 0.0) {
                continue;
            }
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if !x0.is_finite() {
        return ((0.0, 1.0), (0.0, 1.0));
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let pad = if y1 > y0 { 0.05 * (y1 - y0) } else { 1.0 };
    ((x0, x1), (y0 - pad, y1 + pad))
}

/// The points of `s` cut into runs that a line may join: a non-finite value (an empty bin, a
/// missing sample) ends a run, and so does a step in x more than 5 times the median step (a
/// time gap between records or segments).
fn runs(s: &Series, join_gaps: bool) -> Vec<Vec<(f64, f64)>> {
    let mut steps: Vec<f64> =
        s.x.windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .filter(|d| d.is_finite() && *d > 0.0)
            .collect();
    let gap = if steps.len() >= 8 && !join_gaps {
        steps.sort_by(f64::total_cmp);
        5.0 * steps[steps.len() / 2]
    } else {
        f64::INFINITY
    };
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    let mut last: Option<f64> = None;
    for (&x, &y) in s.x.iter().zip(s.y) {
        let valid = x.is_finite() && y.is_finite();
        let jump = last.is_some_and(|l| (x - l).abs() > gap);
        if (!valid || jump) && out.last().is_some_and(|r| !r.is_empty()) {
            out.push(Vec::new());
        }
        if valid {
            if let Some(r) = out.last_mut() {
                r.push((x, y));
            }
            last = Some(x);
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

/// Renders a line chart to an SVG string. Every text (title, axis labels, series labels) may
/// come from input (file and column names): plotters escapes XML's five special characters,
/// and [`svg_text`] first replaces the characters XML forbids, so the SVG stays well-formed.
pub fn line_chart_svg(chart: &Chart, series: &[Series]) -> anyhow::Result<String> {
    let (title, x_label, y_label) = (
        svg_text(chart.title),
        svg_text(chart.x_label),
        svg_text(chart.y_label),
    );
    let labels: Vec<_> = series.iter().map(|s| svg_text(s.label)).collect();
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (chart.width, chart.height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
        let ((x0, x1), (y0, y1)) = bounds(series, chart.log_x);
        let (_, y_step) = nice_ticks(y0, y1, 7);
        let y_max_abs = y0.abs().max(y1.abs());
        let (_, x_step) = nice_ticks(x0, x1, 8);
        let x_max_abs = x0.abs().max(x1.abs());
        let columns = chart.width.saturating_sub(80).max(50) as usize;
        let mut builder = ChartBuilder::on(&root);
        builder
            .caption(title.as_ref(), ("sans-serif", 16))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(70);
        macro_rules! draw {
            ($ctx:expr, $x_fmt:expr, $x_labels:expr) => {{
                let mut ctx = $ctx;
                let integer_ticks = |x: &f64| {
                    if (x - x.round()).abs() < 1e-6 {
                        format!("{:.0}", x)
                    } else {
                        String::new()
                    }
                };
                let y_fmt = |v: &f64| tick_label(*v, y_step, y_max_abs);
                let mut mesh = ctx.configure_mesh();
                mesh.x_desc(x_label.as_ref())
                    .y_desc(y_label.as_ref())
                    .y_labels(7)
                    .x_labels($x_labels)
                    .y_label_formatter(&y_fmt)
                    .x_label_formatter(&$x_fmt);
                if chart.integer_x {
                    mesh.x_labels(((x1 - x0).round() as usize + 1).clamp(2, 12))
                        .x_label_formatter(&integer_ticks);
                }
                mesh.draw().map_err(|e| anyhow!("plot: {e}"))?;
                for (i, s) in series.iter().enumerate() {
                    let color = COLORS[i % COLORS.len()];
                    if chart.scatter {
                        let pts: Vec<(f64, f64)> =
                            runs(s, chart.join_gaps).into_iter().flatten().collect();
                        let pts = thin_points(pts, x0, x1, y0, y1, columns);
                        let dots = ctx
                            .draw_series(pts.into_iter().map(|p| Circle::new(p, 1, color.filled())))
                            .map_err(|e| anyhow!("plot: {e}"))?;
                        dots.label(labels[i].as_ref())
                            .legend(move |(x, y)| Circle::new((x + 7, y), 3, color.filled()));
                        continue;
                    }
                    // one line per run of valid points: no line across a gap
                    for (j, run) in runs(s, chart.join_gaps).into_iter().enumerate() {
                        let run = decimate(run, x0, x1, columns, chart.log_x);
                        let line = ctx
                            .draw_series(LineSeries::new(run, color.stroke_width(1)))
                            .map_err(|e| anyhow!("plot: {e}"))?;
                        if j == 0 {
                            line.label(labels[i].as_ref()).legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 15, y)], color)
                            });
                        }
                    }
                }
                if series.len() > 1 {
                    ctx.configure_series_labels()
                        .background_style(WHITE.mix(0.8))
                        .border_style(BLACK)
                        .draw()
                        .map_err(|e| anyhow!("plot: {e}"))?;
                }
            }};
        }
        if chart.log_x {
            // from the decade below the data: labels below the first power of ten inside
            let x0 = 10f64.powf(x0.log10().floor());
            // Labels on the powers of ten alone: plotters' in-between key points repeat the
            // next decade's (two `10` labels on one spot), and 2 and 5 crowd a wide band.
            let decades = (x1 / x0).log10().ceil().max(1.0) as usize;
            // plotters may also give one power of ten twice (two key points a rounding apart):
            // within one ascending pass over the key points, a decade is labelled once (a key
            // point below the previous one starts a new pass).
            let seen = std::cell::Cell::new((f64::NEG_INFINITY, f64::NAN));
            let x_fmt = move |v: &f64| {
                let (prev_v, prev_dec) = seen.get();
                let prev_dec = if *v < prev_v { f64::NAN } else { prev_dec };
                let m = v / 10f64.powf(v.log10().floor());
                if (m - 1.0).abs() < 1e-6 || (m - 10.0).abs() < 1e-5 {
                    let dec = v.log10().round();
                    seen.set((*v, dec));
                    if dec == prev_dec {
                        return String::new();
                    }
                    log_tick_label(*v)
                } else {
                    seen.set((*v, prev_dec));
                    String::new()
                }
            };
            draw!(
                builder
                    .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
                    .map_err(|e| anyhow!("plot: {e}"))?,
                x_fmt,
                5 * decades
            );
        } else {
            let x_fmt = |v: &f64| tick_label(*v, x_step, x_max_abs);
            draw!(
                builder
                    .build_cartesian_2d(x0..x1, y0..y1)
                    .map_err(|e| anyhow!("plot: {e}"))?,
                x_fmt,
                8
            );
        }
        root.present().map_err(|e| anyhow!("plot: {e}"))?;
    }
    Ok(svg)
}

/// At most one point per pixel of a `columns` x `columns / 2` grid over the plot area: a
/// scatter of a long log stays small, and every occupied pixel keeps a point.
fn thin_points(
    pts: Vec<(f64, f64)>,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    columns: usize,
) -> Vec<(f64, f64)> {
    let rows = (columns / 2).max(1);
    if pts.len() <= columns || x1 <= x0 || y1 <= y0 {
        return pts;
    }
    let mut seen = std::collections::HashSet::new();
    pts.into_iter()
        .filter(|&(x, y)| {
            let c = ((x - x0) / (x1 - x0) * columns as f64) as i64;
            let r = ((y - y0) / (y1 - y0) * rows as f64) as i64;
            seen.insert((c, r))
        })
        .collect()
}

/// Renders a line chart to an SVG file.
pub fn line_chart(path: &std::path::Path, chart: &Chart, series: &[Series]) -> anyhow::Result<()> {
    let svg = line_chart_svg(chart, series)?;
    crate::io::output::write_file(path, "plot", svg)?;
    Ok(())
}

/// Plots reference and angle [deg] over time, and the voltage (second SVG `<stem>_u.svg`).
pub fn plot_run(path: &std::path::Path, out: &servo_hw::run::RunOutput) -> anyhow::Result<()> {
    plot_run_on(path, out, &servo_core::Transmission::GEAR)
}

/// [`plot_run`] on the axis `axis`: on a linear axis the load position and the reference in mm.
pub fn plot_run_on(
    path: &std::path::Path,
    out: &servo_hw::run::RunOutput,
    axis: &servo_core::Transmission,
) -> anyhow::Result<()> {
    let rec = &out.record;
    let (k, labels) = match axis.metres_per_rad() {
        Some(m) => (
            m * 1e3,
            [
                "reference [mm]",
                "x [mm]",
                "servo run: load position",
                "position [mm]",
            ],
        ),
        None => (
            180.0 / std::f64::consts::PI,
            [
                "reference [deg]",
                "theta_l [deg]",
                "servo run: load angle",
                "angle [deg]",
            ],
        ),
    };
    let scaled = |v: &Option<Vec<f64>>| {
        v.as_ref()
            .map(|v| v.iter().map(|x| x * k).collect::<Vec<f64>>())
    };
    let th = scaled(&rec.theta_l_rad).unwrap_or_default();
    let r = scaled(&rec.ref_rad);
    let mut series = Vec::new();
    if let Some(r) = &r {
        series.push(Series {
            label: labels[0],
            x: &rec.time_s,
            y: r,
        });
    }
    series.push(Series {
        label: labels[1],
        x: &rec.time_s,
        y: &th,
    });
    line_chart(
        path,
        &Chart {
            title: labels[2],
            x_label: "time [s]",
            y_label: labels[3],
            ..Chart::default()
        },
        &series,
    )?;
    // The drive's command: u [V], or a current drive's reference, or a duty drive's duty.
    let (u, label) = match (&rec.u_v, &rec.i_ref_a, &rec.duty) {
        (None, Some(i), _) => (i.clone(), "i_ref [A]"),
        (None, None, Some(d)) => (d.clone(), "duty [-]"),
        (u, _, _) => (u.clone().unwrap_or_default(), "u [V]"),
    };
    let upath = path.with_file_name(format!(
        "{}_u.svg",
        path.file_stem().and_then(|s| s.to_str()).unwrap_or("run")
    ));
    line_chart(
        &upath,
        &Chart {
            title: "servo run: the drive's command",
            x_label: "time [s]",
            y_label: label,
            ..Chart::default()
        },
        &[Series {
            label,
            x: &rec.time_s,
            y: &u,
        }],
    )
}
