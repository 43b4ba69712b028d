//! `servo design --plot`: the step responses of the verified loops and the specs panel.

use super::*;

/// The step-response panel of --plot: the smallest, middle and largest steps.
pub(super) fn spec_panel(out: &Outcome, c: &RangeCheck) -> anyhow::Result<spec_plot::SpecPanel> {
    let r = &out.report;
    let plant = FastPlant::new(&r.discrete_plant).map_err(|e| anyhow!("{e}"))?;
    let sp = &c.specs;
    let steps: Vec<f64> = {
        let mut v = vec![sp.step_min_rad];
        for x in [0.5 * (sp.step_min_rad + sp.step_max_rad), sp.step_max_rad] {
            if x > v[v.len() - 1] {
                v.push(x);
            }
        }
        v
    };
    let worst = c.worst_speed_s.unwrap_or(0.0);
    let t_end = (2.0 * speed_spec_s(sp).unwrap_or(0.0))
        .max(1.3 * worst)
        .max(10.0 / r.request.spec.omega_gc);
    let tr = traces(&plant, &r.gains, &out.structure, sp.band(), &steps, t_end)
        .map_err(|e| anyhow!("{e}"))?;
    Ok(spec_plot::SpecPanel {
        specs: *sp,
        traces: tr,
        t_end_s: t_end,
        caption: format!(
            "achieved steps on the loop that runs ({} model, ZOH, {})",
            r.discrete.plant,
            structure_words(&out.structure)
        ),
    })
}

pub(super) fn write_step_plot(path: &std::path::Path, r: &DesignReport) -> anyhow::Result<()> {
    use crate::plot::{line_chart, Chart, Series};
    let loops: Vec<&Achieved> = [Some(&r.reduced), r.full.as_ref(), Some(&r.discrete)]
        .into_iter()
        .flatten()
        .filter(|a| !a.response.time_s.is_empty())
        .collect();
    if loops.is_empty() {
        bail!("no loop is stable, there is no step response to plot");
    }
    // show up to the longest 1 % settling time x 1.5 (or the whole horizon)
    let t_end = loops
        .iter()
        .filter_map(|a| a.step.and_then(|m| m.settling_time_1pct_s))
        .fold(0.0, f64::max)
        .max(5.0 / r.request.spec.omega_gc)
        * 1.5;
    let cut: Vec<(String, Vec<f64>, Vec<f64>)> = loops
        .iter()
        .map(|a| {
            let n = a
                .response
                .time_s
                .iter()
                .take_while(|&&t| t <= t_end)
                .count()
                .max(2);
            (
                format!("{} loop", a.name),
                a.response.time_s[..n].to_vec(),
                a.response.y_rad[..n].to_vec(),
            )
        })
        .collect();
    let t_ref = vec![0.0, t_end];
    let y_ref = vec![1.0, 1.0];
    let mut series = vec![Series {
        label: "reference 1 rad",
        x: &t_ref,
        y: &y_ref,
    }];
    for (label, t, y) in &cut {
        series.push(Series { label, x: t, y });
    }
    line_chart(
        path,
        &Chart {
            title: "closed-loop step response (r = 1 rad)",
            x_label: "time [s]",
            y_label: "theta_l [rad]",
            ..Chart::default()
        },
        &series,
    )
}
