//! `servo frf --plot`: Bode plot of the estimate with its bounds, the model and the coherence,
//! and the loop's Bode plot with the achieved margins marked.

use super::*;
use servo_core::frf::analysis::{excited_bins, FrfAnalysis};

/// The bins a Bode plot shows: coherence >= 0.5 on a bin the excitation reached (input power
/// at least 1 % of its peak). Between a multisine's lines the coherence of the noise alone often
/// passes 0.5, and those bins' bounds, from a circle around nothing, zig-zagged the plot.
pub fn plotted_bins(a: &FrfAnalysis, f: &Estimate) -> Vec<usize> {
    let excited = excited_bins(&a.spectra, f);
    f.coherent(0.5)
        .filter(|&i| excited.get(i).copied().unwrap_or(true))
        .collect()
}

/// The loop L's magnitude and phase (bins with coherence >= 0.5), the 0 dB and -180 deg lines,
/// and the crossover and phase crossover marked where they were measured.
pub(super) fn loop_plot(a: &FrfAnalysis) -> anyhow::Result<Option<Vec<String>>> {
    let Some(l) = &a.loop_frf else {
        return Ok(None);
    };
    let keep = plotted_bins(a, l);
    if keep.len() < 2 {
        return Ok(None);
    }
    let w: Vec<f64> = keep.iter().map(|&i| l.omega(i)).collect();
    let ph_all = l.phase_deg(-180.0);
    let mag: Vec<f64> = keep.iter().map(|&i| 20.0 * l.mag(i).log10()).collect();
    let ph: Vec<f64> = keep.iter().map(|&i| ph_all[i]).collect();
    let ends = vec![w[0], w[w.len() - 1]];
    let zero = vec![0.0, 0.0];
    let m180 = vec![-180.0, -180.0];
    let (mlo, mhi) = mag
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let (plo, phi) = ph
        .iter()
        .fold((-180.0f64, -180.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    let m = a.achieved.as_ref();
    let wc = m.and_then(|m| m.crossover_rad_s).map(|i| i.value);
    let wp = m.and_then(|m| m.phase_crossover_rad_s).map(|i| i.value);
    let pm = m.and_then(|m| m.phase_margin_deg).map(|i| i.value);
    let gm = m.and_then(|m| m.gain_margin_db).map(|i| i.value);
    let sig = |x: f64| servo_core::math::sig(x, 3);
    let wc_label = match (wc, pm) {
        (Some(w), Some(p)) => format!("crossover {} rad/s, PM {} deg", sig(w), sig(p)),
        (Some(w), None) => format!("crossover {} rad/s, PM not measured", sig(w)),
        _ => String::new(),
    };
    let wp_label = match (wp, gm) {
        (Some(w), Some(g)) => format!("phase crossover {} rad/s, GM {} dB", sig(w), sig(g)),
        _ => String::new(),
    };
    let vline = |x: Option<f64>| x.map(|x| vec![x, x]).unwrap_or_default();
    let (wcx, wpx) = (vline(wc), vline(wp));
    let (mag_span, ph_span) = (vec![mlo, mhi], vec![plo, phi]);
    let mut s1 = vec![
        Series {
            label: "|L| measured",
            x: &w,
            y: &mag,
        },
        Series {
            label: "0 dB",
            x: &ends,
            y: &zero,
        },
    ];
    let mut s2 = vec![
        Series {
            label: "angle L measured",
            x: &w,
            y: &ph,
        },
        Series {
            label: "-180 deg",
            x: &ends,
            y: &m180,
        },
    ];
    if !wcx.is_empty() {
        s1.push(Series {
            label: &wc_label,
            x: &wcx,
            y: &mag_span,
        });
        s2.push(Series {
            label: &wc_label,
            x: &wcx,
            y: &ph_span,
        });
    }
    if !wpx.is_empty() {
        s1.push(Series {
            label: &wp_label,
            x: &wpx,
            y: &mag_span,
        });
        s2.push(Series {
            label: &wp_label,
            x: &wpx,
            y: &ph_span,
        });
    }
    let chart = |title, y_label| Chart {
        title,
        x_label: "omega [rad/s]",
        y_label,
        log_x: true,
        join_gaps: true,
        ..Chart::default()
    };
    Ok(Some(vec![
        line_chart_svg(
            &chart("loop L: magnitude (coherence >= 0.5)", "|L| [dB]"),
            &s1,
        )?,
        line_chart_svg(&chart("loop L: phase", "angle L [deg]"), &s2)?,
    ]))
}

/// Bode plot of the plant estimate (bins with coherence >= 0.5) with its bounds and the model,
/// and the coherence.
/// Largest relative radius r/|P| of a bin whose bounds the plot draws (see [`plot`]).
pub const PLOTTED_MAX_REL_RADIUS: f64 = 0.5;

pub(super) fn plot(a: &FrfAnalysis) -> anyhow::Result<String> {
    let (p, model) = (&a.plant, a.model_response.as_deref());
    let keep = plotted_bins(a, p);
    let w: Vec<f64> = keep.iter().map(|&i| p.omega(i)).collect();
    let db = |x: f64| 20.0 * x.log10();
    let ph = p.phase_deg(-90.0);
    let mag: Vec<f64> = keep.iter().map(|&i| db(p.mag(i))).collect();
    // The bounds are drawn through the bins where they say something: a circle of radius at
    // most half |P| (+3.5/-6 dB, +-30 deg). Beside a multisine's lines the Hann window's
    // leakage leaves bins with a circle around (nearly) the origin; joined with the lines'
    // narrow bounds they zig-zagged over 30 dB. Those bins keep their estimate (and the
    // coherence panel shows them); only their bounds are left out.
    let bounded: Vec<usize> = keep
        .iter()
        .copied()
        .filter(|&i| p.rel_radius[i] <= PLOTTED_MAX_REL_RADIUS)
        .collect();
    let wb: Vec<f64> = bounded.iter().map(|&i| p.omega(i)).collect();
    let lo: Vec<f64> = bounded.iter().map(|&i| db(p.mag_bounds(i).0)).collect();
    let hi: Vec<f64> = bounded.iter().map(|&i| db(p.mag_bounds(i).1)).collect();
    let phm: Vec<f64> = keep.iter().map(|&i| ph[i]).collect();
    let phl: Vec<f64> = bounded
        .iter()
        .map(|&i| ph[i] - p.phase_bound_deg(i))
        .collect();
    let phh: Vec<f64> = bounded
        .iter()
        .map(|&i| ph[i] + p.phase_bound_deg(i))
        .collect();
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
            x: &wb,
            y: &lo,
        },
        Series {
            label: "upper bound",
            x: &wb,
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
            x: &wb,
            y: &phl,
        },
        Series {
            label: "upper bound",
            x: &wb,
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
        join_gaps: true,
        ..Chart::default()
    };
    let mut panels = vec![
        line_chart_svg(
            &chart(
                "plant u -> theta_l: magnitude (coherence >= 0.5; 95 % bounds where within +3.5/-6 dB)",
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
    ];
    if let Some(l) = loop_plot(a)? {
        panels.extend(l);
    }
    Ok(stack_svg(&panels))
}
