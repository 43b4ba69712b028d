//! `servo diagnose --report`: the HTML report with its residual charts.

use super::*;
use servo_io::markup;
use servo_io::markup::{Markup, CSP_META};

/// Residual of the torque (or u-driven) balance over time and against speed, before and after
/// the winner: one panel (`<div class="panel">`) per log.
pub(super) fn residual_charts(
    records: &[Record],
    model: &Plant,
    d: &Diagnosis,
    opts: &DiagnoseOptions,
) -> anyhow::Result<Markup> {
    let ds = Dataset::new(records, &model.params, &opts.fit).map_err(|e| anyhow!("{e}"))?;
    let base = ds.fit_config(model, &[]).map_err(|e| anyhow!("{e}"))?;
    let winner = d.winner();
    let eq = winner.map_or(base.mech.equation, |w| w.equation);
    let rows = if eq == Equation::Electrical {
        &ds.elec_rows
    } else {
        &ds.mech_rows
    };
    let sol_b = base
        .equation(eq)
        .ok_or_else(|| anyhow!("no {} equation", eq.name()))?;
    let after = match winner {
        Some(w) => Some(ds.fit_config(&w.plant, &[]).map_err(|e| anyhow!("{e}"))?),
        None => None,
    };
    let sol_a = after.as_ref().and_then(|a| a.equation(eq));
    let label_a = winner.map_or(String::new(), |w| format!("with {}", w.effect));
    let unit_label = format!("{} residual [{}]", eq.name(), eq.unit());
    // One panel per log (small multiples): its residual over time and against speed.
    let mut html = Markup::new();
    for (r, rec) in ds.recs.iter().enumerate() {
        let sel: Vec<usize> = (0..rows.len()).filter(|&i| rows.rec[i] == r).collect();
        if sel.is_empty() {
            continue;
        }
        let t: Vec<f64> = sel.iter().map(|&i| rec.time_s[rows.k[i]]).collect();
        let w: Vec<f64> = sel.iter().map(|&i| rec.omega_f[rows.k[i]]).collect();
        let rb: Vec<f64> = sel.iter().map(|&i| sol_b.resid[i]).collect();
        let ra: Vec<f64> = sol_a
            .map(|s| sel.iter().map(|&i| s.resid[i]).collect())
            .unwrap_or_default();
        let mut series = vec![Series {
            label: "model",
            x: &t,
            y: &rb,
        }];
        if !ra.is_empty() {
            series.push(Series {
                label: &label_a,
                x: &t,
                y: &ra,
            });
        }
        // the file's name: a long path is not a title
        let name = std::path::Path::new(&rec.source)
            .file_name()
            .map_or(rec.source.clone(), |n| n.to_string_lossy().into_owned());
        markup!(
            html,
            "<div class=\"panel\" data-log=\"{}\"><h3>log {} of {}: {}</h3>",
            name,
            r + 1,
            ds.recs.len(),
            name
        );
        let title = format!("{} residual over time ({name})", eq.name());
        html.push(&chart_markup(
            &Chart {
                title: &title,
                x_label: "time [s]",
                y_label: &unit_label,
                width: 480,
                height: 320,
                ..Chart::default()
            },
            &series,
        )?);
        // Residual against speed: points, not a path in time.
        let mut series = vec![Series {
            label: "model",
            x: &w,
            y: &rb,
        }];
        if !ra.is_empty() {
            series.push(Series {
                label: &label_a,
                x: &w,
                y: &ra,
            });
        }
        let title = format!("{} residual against motor speed ({name})", eq.name());
        html.push(&chart_markup(
            &Chart {
                title: &title,
                x_label: "motor speed [rad/s]",
                y_label: &unit_label,
                scatter: true,
                width: 480,
                height: 320,
                ..Chart::default()
            },
            &series,
        )?);
        html.lit("</div>");
    }
    Ok(html)
}

/// The plot of the measured friction curve (the classic friction-speed plot): friction torque against log |speed| at the
/// load, both directions, each bin's mean with its 95 % interval, beside the base model's curve.
pub(super) fn friction_chart(d: &Diagnosis) -> anyhow::Result<Markup> {
    let Some(c) = &d.friction_curve else {
        return Ok(Markup::new());
    };
    let pick = |dir: i8,
                v: &dyn Fn(&servo_core::diagnose::friction_curve::FrictionBin) -> f64|
     -> (Vec<f64>, Vec<f64>) {
        c.bins
            .iter()
            .filter(|b| b.direction == dir)
            .map(|b| (b.speed_rad_s, v(b)))
            .unzip()
    };
    let mut cols: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
    for (dir, name) in [(1i8, "forwards"), (-1, "backwards")] {
        let (x, y) = pick(dir, &|b| b.torque_nm);
        cols.push((format!("{name}, measured"), x, y));
        let (x, y) = pick(dir, &|b| b.torque_nm - b.ci_nm);
        cols.push((format!("{name}, 95 % low"), x, y));
        let (x, y) = pick(dir, &|b| b.torque_nm + b.ci_nm);
        cols.push((format!("{name}, 95 % high"), x, y));
        let (x, y) = pick(dir, &|b| b.model_nm);
        cols.push((format!("{name}, model"), x, y));
    }
    let series: Vec<Series> = cols
        .iter()
        .filter(|(_, x, _)| !x.is_empty())
        .map(|(l, x, y)| Series { label: l, x, y })
        .collect();
    let title = format!(
        "measured friction curve ({} sliding rows, {})",
        c.sliding_rows,
        c.shape
            .as_ref()
            .map_or("no shape beyond the model".to_string(), |s| s
                .shape
                .name()
                .replace('_', " "))
    );
    let mut h = Markup::new();
    h.lit("<h2>Measured friction curve</h2>");
    if let Some(s) = &c.shape {
        markup!(h, "<p>{}</p>", s.description);
    }
    h.push(&chart_markup(
        &Chart {
            title: &title,
            x_label: "|speed| at the load [rad/s] (log)",
            y_label: "friction torque at the load [N m]",
            log_x: true,
            join_gaps: true,
            width: 700,
            height: 400,
            ..Chart::default()
        },
        &series,
    )?);
    Ok(h)
}

#[allow(clippy::too_many_arguments)]
pub(super) fn html_report(
    records: &[Record],
    model: &Plant,
    first: &Diagnosis,
    ladder: &[Rung],
    diags: &[Diagnosis],
    opts: &DiagnoseOptions,
    logs: &[PathBuf],
    drive: &servo_core::drive::Drive,
) -> anyhow::Result<String> {
    let last = diags.last().unwrap_or(first);
    let mut h = Markup::new();
    h.lit("<!DOCTYPE html><html><head><meta charset=\"utf-8\">")
        .lit(CSP_META)
        .lit(
            "<title>servo diagnose report</title><style>\
         body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px;vertical-align:top}\
         .yes{color:#080;font-weight:bold}.no{color:#888}\
         .panel{display:flex;flex-wrap:wrap;border-top:1px solid #ccc;margin:0.5em 0}.panel h3{width:100%;margin:0.3em 0}</style></head><body>",
        );
    markup!(
        h,
        "<h1>servo diagnose</h1><p>Logs: {}</p>",
        logs.iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let effects: Vec<String> = model.effects.iter().map(|e| e.to_string()).collect();
    markup!(
        h,
        "<p>Model effects: <code>{}</code></p>",
        effects.join(" ")
    );
    markup!(
        h,
        "<h2>Verdict</h2><p class=\"status-{}\"><b>{}</b></p><p>{}</p>",
        last.status.name(),
        headline(ladder, last),
        last.verdict
    );
    markup!(
        h,
        "<h2>The fit and where it fails</h2><pre>{}</pre>",
        where_it_fails(first)
    );
    h.push(&residual_charts(records, model, first, opts)?);
    h.push(&friction_chart(first)?);
    for (step, d) in diags.iter().enumerate() {
        markup!(
            h,
            "<h2>Ranking{}</h2><table><tr><th>effect</th><th>significant</th><th>{}</th><th>{}</th><th>BIC gain</th><th>evidence</th></tr>",
            if diags.len() > 1 { format!(", step {}", step + 1) } else { String::new() },
            servo_core::diagnose::phrase::RMS_DROP,
            servo_core::diagnose::phrase::SIM_DROP
        );
        for c in &d.ranking {
            markup!(
                h,
                "<tr><td>{}</td><td class=\"{}\">{}</td><td>{} %</td><td>{}</td><td>{}</td><td>{}",
                c.effect.to_string(),
                if c.significant { "yes" } else { "no" },
                if c.significant {
                    "yes"
                } else if c.resolvable {
                    "no"
                } else {
                    "not resolvable"
                },
                servo_core::diagnose::phrase::pct(c.error_reduction_pct),
                c.oe_reduction_pct.map_or("-".into(), |v| format!(
                    "{} %",
                    servo_core::diagnose::phrase::pct(v)
                )),
                format!("{:.1}", c.bic_gain),
                c.evidence
            );
            if let Some(e) = &c.experiment {
                markup!(h, "<br><i>To resolve: {}</i>", e);
            }
            h.lit("</td></tr>");
        }
        h.lit("</table>");
    }
    let friction = friction_text(first);
    if !friction.is_empty() {
        markup!(
            h,
            "<h2>Measured friction curve</h2><pre>{}</pre>",
            friction.trim()
        );
    }
    markup!(
        h,
        "<h2>Bars (thresholds that can refuse an effect or a verdict)</h2><pre>{}</pre>",
        bars_text(opts)
    );
    markup!(h, "<h2>Error ladder</h2><pre>{}</pre>", ladder_text(ladder));
    if ladder.len() > 1 {
        let x: Vec<f64> = (0..ladder.len()).map(|i| i as f64).collect();
        let y: Vec<f64> = ladder
            .iter()
            .map(|r| r.equations.first().map_or(f64::NAN, |e| e.1))
            .collect();
        let unit = ladder[0].equations.first().map_or("", |e| e.0.unit());
        let y_label = format!("residual RMS [{unit}]");
        h.push(&chart_markup(
            &Chart {
                title: "equation residual RMS as effects are added",
                x_label: "effects added",
                y_label: &y_label,
                integer_x: true,
                ..Chart::default()
            },
            &[Series {
                label: "residual",
                x: &x,
                y: &y,
            }],
        )?);
    }
    // the model with what was found: the ladder's last (--auto), else the winner's fit
    let found = match ladder {
        [_, .., l] => Some(l.plant),
        _ => last.winner().map(|c| c.plant),
    };
    if let Some(found) = found {
        h.push(&super::report_compensation::compensation_html(
            model, &found, drive,
        )?);
    }
    h.lit("</body></html>\n");
    Ok(h.into_string())
}

/// A chart of the report: the SVG renderer's output (its labels escaped), inlined.
fn chart_markup(chart: &Chart, series: &[Series]) -> anyhow::Result<Markup> {
    Ok(Markup::from_rendered_svg(&line_chart_svg(chart, series)?))
}
