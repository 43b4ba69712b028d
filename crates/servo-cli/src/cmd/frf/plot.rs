//! `servo frf --plot`: Bode plot of the estimate with its bounds, the model and the coherence.

use super::*;

/// Bode plot of the plant estimate (bins with coherence >= 0.5) with its bounds and the model,
/// and the coherence.
pub(super) fn plot(p: &Estimate, model: Option<&[Complex<f64>]>) -> anyhow::Result<String> {
    let keep: Vec<usize> = p.coherent(0.5).collect();
    let w: Vec<f64> = keep.iter().map(|&i| p.omega(i)).collect();
    let db = |x: f64| 20.0 * x.log10();
    let ph = p.phase_deg(-90.0);
    let mag: Vec<f64> = keep.iter().map(|&i| db(p.mag(i))).collect();
    let lo: Vec<f64> = keep.iter().map(|&i| db(p.mag_bounds(i).0)).collect();
    let hi: Vec<f64> = keep.iter().map(|&i| db(p.mag_bounds(i).1)).collect();
    let phm: Vec<f64> = keep.iter().map(|&i| ph[i]).collect();
    let phl: Vec<f64> = keep.iter().map(|&i| ph[i] - p.phase_bound_deg(i)).collect();
    let phh: Vec<f64> = keep.iter().map(|&i| ph[i] + p.phase_bound_deg(i)).collect();
    let (mm, mp): (Vec<f64>, Vec<f64>) = match model {
        Some(m) => keep
            .iter()
            .zip(&phm)
            .map(|(&i, meas)| {
                let v = m[i];
                let a = v.im.atan2(v.re).to_degrees();
                (db(v.norm()), a - 360.0 * ((a - meas) / 360.0).round())
            })
            .unzip(),
        None => (Vec::new(), Vec::new()),
    };
    let mut s1 = vec![
        Series {
            label: "measured",
            x: &w,
            y: &mag,
        },
        Series {
            label: "lower bound",
            x: &w,
            y: &lo,
        },
        Series {
            label: "upper bound",
            x: &w,
            y: &hi,
        },
    ];
    let mut s2 = vec![
        Series {
            label: "measured",
            x: &w,
            y: &phm,
        },
        Series {
            label: "lower bound",
            x: &w,
            y: &phl,
        },
        Series {
            label: "upper bound",
            x: &w,
            y: &phh,
        },
    ];
    if model.is_some() {
        s1.push(Series {
            label: "model",
            x: &w,
            y: &mm,
        });
        s2.push(Series {
            label: "model",
            x: &w,
            y: &mp,
        });
    }
    let wa: Vec<f64> = (0..p.len()).map(|i| p.omega(i)).collect();
    let chart = |title, y_label| Chart {
        title,
        x_label: "omega [rad/s]",
        y_label,
        log_x: true,
        ..Chart::default()
    };
    Ok(stack_svg(&[
        line_chart_svg(
            &chart(
                "plant u -> theta_l: magnitude (coherence >= 0.5)",
                "|P| [dB rad/V]",
            ),
            &s1,
        )?,
        line_chart_svg(&chart("plant u -> theta_l: phase", "phase [deg]"), &s2)?,
        line_chart_svg(
            &chart("coherence", "gamma^2 [-]"),
            &[Series {
                label: "coherence",
                x: &wa,
                y: &p.coherence,
            }],
        )?,
    ]))
}
