//! `servo diagnose --report`: the HTML report with its residual charts.

use super::*;

pub(super) fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Residual of the torque (or u-driven) balance over time and versus speed, before and after the
/// winner, for the first record.
pub(super) fn residual_charts(
    records: &[Record],
    model: &Plant,
    d: &Diagnosis,
    opts: &DiagnoseOptions,
) -> anyhow::Result<String> {
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
    let sel: Vec<usize> = (0..rows.len()).filter(|&i| rows.rec[i] == 0).collect();
    let t: Vec<f64> = sel.iter().map(|&i| ds.recs[0].time_s[rows.k[i]]).collect();
    let w: Vec<f64> = sel.iter().map(|&i| ds.recs[0].omega_f[rows.k[i]]).collect();
    let rb: Vec<f64> = sel.iter().map(|&i| sol_b.resid[i]).collect();
    let ra: Vec<f64> = sol_a
        .map(|s| sel.iter().map(|&i| s.resid[i]).collect())
        .unwrap_or_default();
    let label_a = winner.map_or(String::new(), |w| format!("with {}", w.effect));
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
    let title = format!(
        "{} residual [{}] over time ({})",
        eq.name(),
        eq.unit(),
        // the file's name: a long path is not a title
        std::path::Path::new(&ds.recs[0].source)
            .file_name()
            .map_or(ds.recs[0].source.clone(), |n| n
                .to_string_lossy()
                .into_owned())
    );
    let mut html = line_chart_svg(
        &Chart {
            title: &title,
            x_label: "time [s]",
            y_label: eq.unit(),
            ..Chart::default()
        },
        &series,
    )?;
    // Residual versus speed: sort by speed so that the line reads as a scatter envelope.
    let mut order: Vec<usize> = (0..w.len()).collect();
    order.sort_by(|&a, &b| w[a].total_cmp(&w[b]));
    let ws: Vec<f64> = order.iter().map(|&i| w[i]).collect();
    let rbs: Vec<f64> = order.iter().map(|&i| rb[i]).collect();
    let ras: Vec<f64> = if ra.is_empty() {
        vec![]
    } else {
        order.iter().map(|&i| ra[i]).collect()
    };
    let mut series = vec![Series {
        label: "model",
        x: &ws,
        y: &rbs,
    }];
    if !ras.is_empty() {
        series.push(Series {
            label: &label_a,
            x: &ws,
            y: &ras,
        });
    }
    let title = format!("{} residual versus motor speed", eq.name());
    html.push_str(&line_chart_svg(
        &Chart {
            title: &title,
            x_label: "motor speed [rad/s]",
            y_label: eq.unit(),
            ..Chart::default()
        },
        &series,
    )?);
    Ok(html)
}

pub(super) fn html_report(
    records: &[Record],
    model: &Plant,
    first: &Diagnosis,
    ladder: &[Rung],
    diags: &[Diagnosis],
    opts: &DiagnoseOptions,
    logs: &[PathBuf],
) -> anyhow::Result<String> {
    let last = diags.last().unwrap_or(first);
    let mut h = String::from(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>servo diagnose report</title><style>\
         body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px;vertical-align:top}\
         .yes{color:#080;font-weight:bold}.no{color:#888}</style></head><body>",
    );
    let _ = write!(
        h,
        "<h1>servo diagnose</h1><p>Logs: {}</p>",
        esc(&logs
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "))
    );
    let effects: Vec<String> = model.effects.iter().map(|e| e.to_string()).collect();
    let _ = write!(
        h,
        "<p>Model effects: <code>{}</code></p>",
        esc(&effects.join(" "))
    );
    let _ = write!(
        h,
        "<h2>Verdict</h2><p class=\"status-{}\"><b>{}</b></p><p>{}</p>",
        last.status.name(),
        esc(&headline(ladder, last)),
        esc(&last.verdict)
    );
    let _ = write!(
        h,
        "<h2>The fit and where it fails</h2><pre>{}</pre>",
        esc(&where_it_fails(first))
    );
    h.push_str(&residual_charts(records, model, first, opts)?);
    for (step, d) in diags.iter().enumerate() {
        let _ = write!(h, "<h2>Ranking{}</h2><table><tr><th>effect</th><th>significant</th><th>equation residual drop (held out)</th><th>simulation error drop (held out)</th><th>BIC gain</th><th>evidence</th></tr>", if diags.len() > 1 { format!(", step {}", step + 1) } else { String::new() });
        for c in &d.ranking {
            let _ = write!(
                h,
                "<tr><td>{}</td><td class=\"{}\">{}</td><td>{:.1} %</td><td>{}</td><td>{:.1}</td><td>{}{}</td></tr>",
                c.effect,
                if c.significant { "yes" } else { "no" },
                if c.significant { "yes" } else if c.resolvable { "no" } else { "not resolvable" },
                c.error_reduction_pct,
                c.oe_reduction_pct.map_or("-".into(), |v| format!("{v:.1} %")),
                c.bic_gain,
                esc(&c.evidence),
                c.experiment.as_ref().map_or(String::new(), |e| format!("<br><i>To resolve: {}</i>", esc(e)))
            );
        }
        h.push_str("</table>");
    }
    let _ = write!(
        h,
        "<h2>Error ladder</h2><pre>{}</pre>",
        esc(&ladder_text(ladder))
    );
    if ladder.len() > 1 {
        let x: Vec<f64> = (0..ladder.len()).map(|i| i as f64).collect();
        let y: Vec<f64> = ladder
            .iter()
            .map(|r| r.equations.first().map_or(f64::NAN, |e| e.1))
            .collect();
        let unit = ladder[0].equations.first().map_or("", |e| e.0.unit());
        let y_label = format!("residual RMS [{unit}]");
        h.push_str(&line_chart_svg(
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
    h.push_str("</body></html>\n");
    Ok(h)
}
