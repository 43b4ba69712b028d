//! `servo compare --plot`: measurement against model, the residual, and the residual against
//! speed and position.

use super::*;

/// One titled chart of a single series: (title, SVG).
pub(super) fn one_series_chart(
    title: String,
    x_label: &str,
    y_label: &str,
    label: &str,
    x: &[f64],
    y: &[f64],
) -> anyhow::Result<(String, String)> {
    let svg = line_chart_svg(
        &Chart {
            title: &title,
            x_label,
            y_label,
            ..Default::default()
        },
        &[Series { label, x, y }],
    )?;
    Ok((title, svg))
}

/// Mean of `y` in `bins` equal bins of `x` over [lo, hi]; bins with fewer than 3 samples are
/// NaN (the chart leaves a gap there). Returns (bin centres, means).
pub(super) fn binned_mean(
    x: &[f64],
    y: &[f64],
    lo: f64,
    hi: f64,
    bins: usize,
) -> (Vec<f64>, Vec<f64>) {
    let mut s = vec![0.0; bins];
    let mut n = vec![0usize; bins];
    let w = (hi - lo) / bins as f64;
    if w.is_nan() || w <= 0.0 {
        return (Vec::new(), Vec::new());
    }
    for (a, b) in x.iter().zip(y) {
        if *a < lo || *a > hi {
            continue;
        }
        let i = (((a - lo) / w) as usize).min(bins - 1);
        s[i] += b;
        n[i] += 1;
    }
    let (mut cx, mut cy) = (Vec::new(), Vec::new());
    for i in 0..bins {
        cx.push(lo + (i as f64 + 0.5) * w);
        cy.push(if n[i] >= 3 {
            s[i] / n[i] as f64
        } else {
            f64::NAN
        });
    }
    (cx, cy)
}

/// The compare figures of one report as inline SVG strings (title, svg): measurement vs model of
/// the headline signal, the residual over time, the residual against the measured speed and
/// against the measured position (binned means). Used by `--plot` and the diagnose HTML report.
pub fn compare_figures_svg(r: &CompareReport, name: &str) -> anyhow::Result<Vec<(String, String)>> {
    compare_figures_svg_on(r, name, None)
}

/// [`compare_figures_svg`] on a linear axis of travel `metres_per_rad` [m/rad] (`None`: a
/// rotary gear): the load position and its residual in mm, speeds in m/s.
pub fn compare_figures_svg_on(
    r: &CompareReport,
    name: &str,
    metres_per_rad: Option<f64>,
) -> anyhow::Result<Vec<(String, String)>> {
    // the file's name, not its whole path, in the titles
    let name = std::path::Path::new(name)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or(name);
    let h0 = r.headline_signal();
    let (scale, k, unit) = match (h0.kind, metres_per_rad) {
        (SignalKind::Position, Some(m)) => (m * 1e3, "x", "mm"),
        (SignalKind::Speed, Some(m)) => (m, "v_x", "m/s"),
        (kind, _) => (1.0, kind.name(), kind.unit()),
    };
    let sc = |v: &[f64]| v.iter().map(|x| x * scale).collect::<Vec<f64>>();
    let h = servo_core::compare::SignalComparison {
        kind: h0.kind,
        measured: sc(&h0.measured),
        model: sc(&h0.model),
        figures: h0.figures,
    };
    let residual = sc(&r.residual);
    let mut out = Vec::new();
    let t1 = format!(
        "{name}: {} measured vs model ({}, fit {:.1} %)",
        h.kind.words(),
        r.mode.name(),
        h.figures.fit_percent
    );
    let yl = format!("{k} [{unit}]");
    let svg = line_chart_svg(
        &Chart {
            title: &t1,
            x_label: "t [s]",
            y_label: &yl,
            ..Default::default()
        },
        &[
            Series {
                label: "measured",
                x: &r.time_s,
                y: &h.measured,
            },
            Series {
                label: "model",
                x: &r.time_s,
                y: &h.model,
            },
        ],
    )?;
    out.push((t1, svg));
    // At a high fit the two traces hide each other: zoom on the worst window where the error is
    // largest against the signal's own swing (a hold, not a fast move), so the two part visibly.
    let swing = |w: &servo_core::compare::windows::Window| {
        let seg = &h.measured[w.start.min(h.measured.len())..w.end.min(h.measured.len())];
        let (lo, hi) = seg
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        w.rms / (hi - lo).max(1e-12)
    };
    let zoom = r
        .worst_windows
        .iter()
        .filter(|_| h.figures.fit_percent > 95.0)
        .max_by(|a, b| swing(a).total_cmp(&swing(b)));
    if let Some(w) = zoom {
        let idx: Vec<usize> = (0..r.time_s.len())
            .filter(|&i| r.time_s[i] >= w.t_start_s && r.time_s[i] <= w.t_end_s)
            .collect();
        if idx.len() >= 2 {
            let pick = |v: &[f64]| idx.iter().map(|&i| v[i]).collect::<Vec<f64>>();
            let (t, m, y) = (pick(&r.time_s), pick(&h.measured), pick(&h.model));
            let tz = format!(
                "{name}: zoom on {:.2}-{:.2} s, where the model departs most ({:.0} % of the squared error)",
                w.t_start_s, w.t_end_s, w.error_share_pct
            );
            let svg = line_chart_svg(
                &Chart {
                    title: &tz,
                    x_label: "t [s]",
                    y_label: &yl,
                    ..Default::default()
                },
                &[
                    Series {
                        label: "measured",
                        x: &t,
                        y: &m,
                    },
                    Series {
                        label: "model",
                        x: &t,
                        y: &y,
                    },
                ],
            )?;
            out.push((tz, svg));
        }
    }
    let t2 = format!(
        "{name}: residual (measured - model), RMSE {:.3e} {unit}",
        h.figures.rmse * scale
    );
    let rl = format!("residual [{unit}]");
    out.push(one_series_chart(
        t2, "t [s]", &rl, "residual", &r.time_s, &residual,
    )?);
    let (w, wl): (Vec<f64>, &str) = match metres_per_rad {
        Some(m) => (r.omega_l_rad_s.iter().map(|v| v * m).collect(), "v_x [m/s]"),
        None => (r.omega_l_rad_s.clone(), "omega_l [rad/s]"),
    };
    let lim = servo_core::compare::regimes::abs_percentile(&w, 0.995).max(1e-12);
    let (bx, by) = binned_mean(&w, &residual, -lim, lim, 60);
    let t3 = format!("{name}: residual vs measured load speed (mean per speed bin)");
    out.push(one_series_chart(t3, wl, &rl, "mean residual", &bx, &by)?);
    if let (Some(th), Some(m)) = (&r.theta_l_rad, metres_per_rad) {
        let xs: Vec<f64> = th.iter().map(|v| v * m * 1e3).collect();
        let (lo, hi) = xs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        let (bx, by) = binned_mean(&xs, &residual, lo, hi, 90);
        let t4 = format!("{name}: residual vs measured load position (mean per position bin)");
        out.push(one_series_chart(
            t4,
            "x [mm]",
            &rl,
            "mean residual",
            &bx,
            &by,
        )?);
    } else if let Some(th) = &r.theta_l_rad {
        let (lo, hi) = th
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        let tau = std::f64::consts::TAU;
        let (xs, lo, hi, xl): (Vec<f64>, f64, f64, &str) = if hi - lo > tau {
            (
                th.iter().map(|v| v.rem_euclid(tau)).collect(),
                0.0,
                tau,
                "theta_l mod 2 pi [rad]",
            )
        } else {
            (th.clone(), lo, hi, "theta_l [rad]")
        };
        let (bx, by) = binned_mean(&xs, &residual, lo, hi, 90);
        let t4 = format!("{name}: residual vs measured load position (mean per position bin)");
        out.push(one_series_chart(t4, xl, &rl, "mean residual", &bx, &by)?);
    }
    Ok(out)
}

/// Stacks SVG documents vertically into one SVG document.
pub fn stack_svg(panels: &[String]) -> String {
    let mut y = 0u32;
    let mut width = 0u32;
    let mut body = String::new();
    for p in panels {
        let (w, h) = svg_size(p).unwrap_or((900, 400));
        let inner = match p.find("<svg") {
            Some(i) => &p[i..],
            None => p.as_str(),
        };
        body.push_str(&inner.replacen("<svg", &format!("<svg x=\"0\" y=\"{y}\""), 1));
        body.push('\n');
        y += h;
        width = width.max(w);
    }
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{y}\" viewBox=\"0 0 {width} {y}\">\n{body}</svg>\n"
    )
}

pub(super) fn svg_size(svg: &str) -> Option<(u32, u32)> {
    let i = svg.find("<svg")?;
    let head = &svg[i..i + svg[i..].find('>')?];
    let attr = |name: &str| -> Option<u32> {
        let j = head.find(&format!("{name}=\""))? + name.len() + 2;
        let rest = &head[j..];
        rest[..rest.find('"')?].trim_end_matches("px").parse().ok()
    };
    Some((attr("width")?, attr("height")?))
}
