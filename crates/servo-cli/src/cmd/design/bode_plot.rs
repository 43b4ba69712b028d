//! Bode plot of the loop L = C P (reduced, full, discrete) with crossover and margins marked,
//! and, for a design from time-domain specs, the achieved step responses against the spec box.

use anyhow::anyhow;
use plotters::prelude::*;
use servo_core::design::verify::DesignReport;
use servo_core::design::{c_abs, c_arg, deg};

const COLORS: [RGBColor; 3] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
];

/// Writes the SVG (with the step-response panel below the Bode plot when given).
pub fn write(
    path: &std::path::Path,
    r: &DesignReport,
    steps: Option<&super::spec_plot::SpecPanel>,
) -> anyhow::Result<()> {
    let svg = render(r, steps)?;
    crate::io::output::write_file(path, "plot", svg)?;
    Ok(())
}

struct Curve {
    name: &'static str,
    w: Vec<f64>,
    mag_db: Vec<f64>,
    phase_deg: Vec<f64>,
    wgc: f64,
    pm: f64,
    wpc: f64,
    gm: f64,
}

fn curves(r: &DesignReport) -> Vec<Curve> {
    let wgc = r.request.spec.omega_gc;
    let nyq = std::f64::consts::PI / r.request.ts_s;
    let (lo, hi) = (wgc * 1e-2, (wgc * 1e3).min(1e5));
    let mut out = Vec::new();
    for a in [Some(&r.reduced), r.full.as_ref(), Some(&r.discrete)]
        .into_iter()
        .flatten()
    {
        let top = if a.name == "discrete" {
            hi.min(0.999 * nyq)
        } else {
            hi
        };
        let n = 600;
        let mut c = Curve {
            name: a.name,
            w: Vec::new(),
            mag_db: Vec::new(),
            phase_deg: Vec::new(),
            wgc: a.margins.omega_gc,
            pm: a.margins.phase_margin_deg,
            wpc: a.margins.omega_pc,
            gm: a.margins.gain_margin_db,
        };
        let mut prev = -90.0 * (1 + i32::from(r.gains.ki != 0.0)) as f64;
        for k in 0..n {
            let w = lo * (top / lo).powf(k as f64 / (n - 1) as f64);
            let Some(l) = r.loop_response(a.name, w) else {
                continue;
            };
            let p = deg(c_arg(l));
            let p = p - 360.0 * ((p - prev) / 360.0).round();
            prev = p;
            c.w.push(w);
            c.mag_db.push(20.0 * c_abs(l).log10());
            c.phase_deg.push(p);
        }
        out.push(c);
    }
    out
}

fn render(r: &DesignReport, steps: Option<&super::spec_plot::SpecPanel>) -> anyhow::Result<String> {
    let cs = curves(r);
    let e = |e: &dyn std::fmt::Display| anyhow!("plot: {e}");
    let (w0, w1) = cs
        .iter()
        .flat_map(|c| c.w.iter())
        .fold((f64::INFINITY, 0.0f64), |(a, b), &w| (a.min(w), b.max(w)));
    let range = |f: &dyn Fn(&Curve) -> &Vec<f64>| {
        let (a, b) = cs
            .iter()
            .flat_map(|c| f(c).iter())
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        (a - 5.0, b + 5.0)
    };
    let (m0, m1) = range(&|c| &c.mag_db);
    let (p0, p1) = range(&|c| &c.phase_deg);
    let (p0, p1) = (p0.min(-185.0), p1.max(-175.0));
    let mut svg = String::new();
    {
        let height = if steps.is_some() { 1050 } else { 700 };
        let root = SVGBackend::with_string(&mut svg, (900, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let (bode, step_area) = root.split_vertically(700);
        if let Some(p) = steps {
            super::spec_plot::draw(&step_area, p)?;
        }
        let (top, bottom) = bode.split_vertically(350);
        let s = &r.request.spec;
        let title = format!(
            "loop L = C P: spec w_gc = {:.3} rad/s, PM = {:.2} deg; K_P = {:.4}, K_I = {:.4}, K_D = {:.5}, T_L = {:.3e} s",
            s.omega_gc,
            deg(s.phase_margin),
            r.gains.kp,
            r.gains.ki,
            r.gains.kd,
            r.gains.tl_s
        );
        let mut mag = ChartBuilder::on(&top)
            .caption(title, ("sans-serif", 14))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d((w0..w1).log_scale(), m0..m1)
            .map_err(|x| e(&x))?;
        mag.configure_mesh()
            .y_desc("|L| [dB]")
            .draw()
            .map_err(|x| e(&x))?;
        mag.draw_series(LineSeries::new([(w0, 0.0), (w1, 0.0)], BLACK.mix(0.5)))
            .map_err(|x| e(&x))?;
        for (i, c) in cs.iter().enumerate() {
            let col = COLORS[i % 3];
            let label = format!(
                "{}: w_gc = {:.3} rad/s, GM = {}",
                c.name,
                c.wgc,
                if c.gm.is_finite() {
                    format!("{:.2} dB at {:.1} rad/s", c.gm, c.wpc)
                } else {
                    "inf".into()
                }
            );
            mag.draw_series(LineSeries::new(
                c.w.iter().copied().zip(c.mag_db.iter().copied()),
                col.stroke_width(1),
            ))
            .map_err(|x| e(&x))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], col));
            if c.wgc.is_finite() {
                mag.draw_series([Circle::new((c.wgc, 0.0), 4, col.filled())])
                    .map_err(|x| e(&x))?;
            }
            if c.gm.is_finite() && c.wpc > w0 && c.wpc < w1 {
                mag.draw_series(LineSeries::new(
                    [(c.wpc, 0.0), (c.wpc, -c.gm)],
                    col.stroke_width(2),
                ))
                .map_err(|x| e(&x))?;
            }
        }
        mag.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| e(&x))?;

        let mut ph = ChartBuilder::on(&bottom)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d((w0..w1).log_scale(), p0..p1)
            .map_err(|x| e(&x))?;
        ph.configure_mesh()
            .x_desc("w [rad/s]")
            .y_desc("angle L [deg]")
            .draw()
            .map_err(|x| e(&x))?;
        ph.draw_series(LineSeries::new(
            [(w0, -180.0), (w1, -180.0)],
            BLACK.mix(0.5),
        ))
        .map_err(|x| e(&x))?;
        for (i, c) in cs.iter().enumerate() {
            let col = COLORS[i % 3];
            ph.draw_series(LineSeries::new(
                c.w.iter().copied().zip(c.phase_deg.iter().copied()),
                col.stroke_width(1),
            ))
            .map_err(|x| e(&x))?
            .label(format!("{}: PM = {:.2} deg", c.name, c.pm))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], col));
            if c.wgc.is_finite() {
                ph.draw_series(LineSeries::new(
                    [(c.wgc, -180.0), (c.wgc, -180.0 + c.pm)],
                    col.stroke_width(2),
                ))
                .map_err(|x| e(&x))?;
            }
        }
        ph.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| e(&x))?;
        root.present().map_err(|x| e(&x))?;
    }
    Ok(svg)
}
