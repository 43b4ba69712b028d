//! The achieved step responses of the loop that runs (normalised by the step size) against the
//! spec box: the shaded regions are forbidden (above 1 + M_p at any time; outside 1 +- band after
//! the settling time; below 0.9 after the rise time with a rise-time spec).

use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::prelude::*;
use servo_core::design::step_range::{SpeedTarget, StepTrace, TimeSpecs};

const COLORS: [RGBColor; 3] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
];

/// What the panel shows.
pub struct SpecPanel {
    pub specs: TimeSpecs,
    /// Responses at a few step sizes (y / A).
    pub traces: Vec<StepTrace>,
    /// Time axis end [s].
    pub t_end_s: f64,
    /// Structure of the loop, for the caption.
    pub caption: String,
}

/// Draws the panel on `area`.
pub fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &SpecPanel,
) -> anyhow::Result<()> {
    let e = |x: &dyn std::fmt::Display| anyhow!("plot: {x}");
    let t1 = p.t_end_s;
    let y_max = p
        .traces
        .iter()
        .flat_map(|t| t.y_norm.iter())
        .copied()
        .filter(|v| v.is_finite())
        .fold(1.2f64, f64::max)
        .min(3.0)
        + 0.05;
    let y_min = p
        .traces
        .iter()
        .flat_map(|t| t.y_norm.iter())
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::min)
        .max(-1.0)
        - 0.05;
    let mut ch = ChartBuilder::on(area)
        .caption(&p.caption, ("sans-serif", 14))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t1, y_min..y_max)
        .map_err(|x| e(&x))?;
    ch.configure_mesh()
        .x_desc("time since the step [s]")
        .y_desc("theta_l / step [-]")
        .draw()
        .map_err(|x| e(&x))?;
    let forbid = RGBColor(214, 39, 40).mix(0.15).filled();
    if let Some(m) = p.specs.overshoot_max {
        ch.draw_series([Rectangle::new([(0.0, 1.0 + m), (t1, y_max)], forbid)])
            .map_err(|x| e(&x))?
            .label(format!("forbidden: overshoot > {:.1} %", 100.0 * m))
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 15, y + 4)], forbid));
    }
    match p.specs.speed {
        Some(SpeedTarget::Settling { band, time_s }) if time_s < t1 => {
            let top = p.specs.overshoot_max.map_or(y_max, |m| 1.0 + m);
            ch.draw_series([
                Rectangle::new([(time_s, 1.0 + band), (t1, top.max(1.0 + band))], forbid),
                Rectangle::new([(time_s, y_min), (t1, 1.0 - band)], forbid),
            ])
            .map_err(|x| e(&x))?
            .label(format!(
                "forbidden: outside +-{:.0} % after t_s = {time_s} s",
                100.0 * band
            ))
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 15, y + 4)], forbid));
        }
        Some(SpeedTarget::Rise { time_s }) if time_s < t1 => {
            ch.draw_series([Rectangle::new([(time_s, y_min), (t1, 0.9)], forbid)])
                .map_err(|x| e(&x))?
                .label(format!("forbidden: below 90 % after t_r = {time_s} s"))
                .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 15, y + 4)], forbid));
        }
        _ => {}
    }
    ch.draw_series(LineSeries::new([(0.0, 1.0), (t1, 1.0)], BLACK.mix(0.5)))
        .map_err(|x| e(&x))?;
    for (i, t) in p.traces.iter().enumerate() {
        let col = COLORS[i % COLORS.len()];
        let pts: Vec<(f64, f64)> = t
            .time_s
            .iter()
            .zip(&t.y_norm)
            .take_while(|(x, _)| **x <= t1)
            .map(|(x, y)| (*x, *y))
            .collect();
        ch.draw_series(LineSeries::new(pts, col.stroke_width(2)))
            .map_err(|x| e(&x))?
            .label(format!("step {:.3} rad", t.step_rad))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], col));
    }
    ch.configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|x| e(&x))?;
    Ok(())
}
