//! `servo identify --plot`: the friction and inertia fits.

use super::*;

/// The plot: torque vs speed (plateau means and the fitted friction line) and, when there are
/// phases, the inertial torque against the acceleration with the fitted J_eq line.
pub(super) fn plot_svg(r: &Report, exps: &[Experiment]) -> anyhow::Result<String> {
    use crate::plot::{line_chart_svg, Chart, Series};
    let mut charts = Vec::new();
    if let Some(f) = &r.friction {
        let mut pts: Vec<(f64, f64)> = f
            .points
            .iter()
            .map(|p| (p.omega_m_rad_s, p.tau_m_nm))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (px, py): (Vec<f64>, Vec<f64>) = pts.into_iter().unzip();
        let wmax = px.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
        let lx = [-wmax, -1e-9 * wmax, 1e-9 * wmax, wmax];
        let ly: Vec<f64> = lx.iter().map(|&w| f.torque_nm(w)).collect();
        let chart = Chart {
            title: "Friction: motor torque k_t i_a vs motor speed at constant speeds",
            x_label: "omega_m [rad/s]",
            y_label: "tau_m [N m]",
            ..Chart::default()
        };
        charts.push(line_chart_svg(
            &chart,
            &[
                Series {
                    label: "plateau means (measured)",
                    x: &px,
                    y: &py,
                },
                Series {
                    label: "fit B_eq w + tau_sf/N sign(w)",
                    x: &lx,
                    y: &ly,
                },
            ],
        )?);
    }
    if let Some(i) = &r.inertia {
        if !i.phases.is_empty() {
            let mut pts: Vec<(f64, f64)> = i
                .phases
                .iter()
                .map(|p| (p.accel_rad_s2, p.tau_i_nm))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (px, py): (Vec<f64>, Vec<f64>) = pts.into_iter().unzip();
            let amax = px.iter().fold(0.0_f64, |m, a| m.max(a.abs()));
            let lx = [-amax, amax];
            let ly = [-amax * i.j_eq.value, amax * i.j_eq.value];
            let chart = Chart {
                title: "Inertia: mean inertial torque per phase vs acceleration",
                x_label: "a_m [rad/s^2]",
                y_label: "tau_i [N m]",
                ..Chart::default()
            };
            charts.push(line_chart_svg(
                &chart,
                &[
                    Series {
                        label: "phase means (measured)",
                        x: &px,
                        y: &py,
                    },
                    Series {
                        label: "fit J_eq a_m",
                        x: &lx,
                        y: &ly,
                    },
                ],
            )?);
            // Speed record with the phases marked.
            if let Some(e) = exps.get(i.phases[0].experiment) {
                let step = (e.time_s.len() / 4000).max(1);
                let tx: Vec<f64> = e.time_s.iter().step_by(step).copied().collect();
                let wy: Vec<f64> = e.omega_m_rad_s.iter().step_by(step).copied().collect();
                let mut mx = Vec::new();
                let mut my = Vec::new();
                for p in i
                    .phases
                    .iter()
                    .filter(|p| p.experiment == i.phases[0].experiment)
                {
                    let w0 = e.omega_m_rad_s[p.start];
                    mx.extend([e.time_s[p.start], e.time_s[p.end - 1]]);
                    my.extend([
                        w0,
                        w0 + p.accel_rad_s2 * (e.time_s[p.end - 1] - e.time_s[p.start]),
                    ]);
                }
                let chart = Chart {
                    title:
                        "Inertia test: motor speed and the detected constant-acceleration phases",
                    x_label: "t [s]",
                    y_label: "omega_m [rad/s]",
                    ..Chart::default()
                };
                charts.push(line_chart_svg(
                    &chart,
                    &[
                        Series {
                            label: "omega_m",
                            x: &tx,
                            y: &wy,
                        },
                        Series {
                            label: "phases (fitted slopes)",
                            x: &mx,
                            y: &my,
                        },
                    ],
                )?);
            }
        }
    }
    if charts.is_empty() {
        bail!("--plot: nothing to draw (no friction segments or inertia phases were identified)");
    }
    Ok(stack_svgs(&charts))
}

/// Stacks SVG documents vertically into one SVG (nested <svg> elements).
pub(super) fn stack_svgs(parts: &[String]) -> String {
    let (w, h) = (900, 400);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{}\" viewBox=\"0 0 {w} {}\">\n",
        h * parts.len(),
        h * parts.len()
    );
    for (k, p) in parts.iter().enumerate() {
        let body = p.trim_start_matches(|c| c != '<');
        let body = if body.starts_with("<?xml") {
            body.split_once("?>").map(|x| x.1).unwrap_or(body)
        } else {
            body
        };
        let body = body
            .trim_start()
            .replacen("<svg ", &format!("<svg y=\"{}\" ", k * h), 1);
        s.push_str(&body);
        s.push('\n');
    }
    s.push_str("</svg>\n");
    s
}
