//! The report of `servo trend`: the text (a table per actuator, what changes in words), the
//! `servo.trend/1` JSON object and the HTML report with a chart per parameter.

use super::when::{date_text, datetime_text};
use super::{Actuator, ParamTrend, TrendReport};
use crate::plot::{line_chart_svg, Chart, Series};
use serde_json::{json, Value};
use servo_core::effects::EffectKind;
use servo_core::trend::{Crossing, Verdict};
use servo_io::markup;
use servo_io::markup::{Markup, CSP_META};

/// z of a two-sided 95 % normal interval (the per-log intervals).
const Z95: f64 = 1.96;

/// A number with 3 significant digits, plain when it reads well, else in e-notation.
pub fn num(x: f64) -> String {
    if !x.is_finite() {
        return "n/a".into();
    }
    let a = x.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e5).contains(&a) {
        let digits = (2 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.digits$}")
    } else {
        format!("{x:.2e}")
    }
}

/// A parameter in words: `the inertia J_eq`, `the total play seen at the load (<effect>.gap)`.
pub fn describe(parameter: &str) -> String {
    match parameter {
        "j_eq" => "the inertia J_eq".into(),
        "b_eq" => "the viscous friction B_eq".into(),
        "tau_sf" => "the Coulomb friction tau_sf".into(),
        "k_drv" => "the driver gain k_drv".into(),
        "r_eq" => "the resistance R_eq".into(),
        p => {
            let doc = p.split_once('.').and_then(|(e, k)| {
                EffectKind::from_name(e)?
                    .params()
                    .iter()
                    .find(|s| s.key == k)
                    .map(|s| s.doc)
            });
            match doc {
                Some(d) => format!("the {d} ({p})"),
                None => p.to_string(),
            }
        }
    }
}

/// Weeks when the span is at least two weeks, else days: (unit name, days per unit).
fn time_unit(span_days: f64) -> (&'static str, f64) {
    if span_days >= 14.0 {
        ("week", 7.0)
    } else {
        ("day", 1.0)
    }
}

fn plural(n: f64, unit: &str) -> String {
    let r = (n * 10.0).round() / 10.0;
    if (r - 1.0).abs() < 1e-9 {
        format!("1 {unit}")
    } else {
        format!("{} {unit}s", num(r))
    }
}

/// First log of an actuator [Unix s].
fn t0(a: &Actuator) -> f64 {
    a.logs.first().map_or(0.0, |l| l.time_unix_s)
}

/// The crossing of a limit as (date [Unix s], earliest, latest), when ahead.
fn crossing_dates(a: &Actuator, p: &ParamTrend) -> Option<(f64, f64, f64)> {
    match p.crossing? {
        Crossing::Ahead {
            t_day,
            earliest_day,
            latest_day,
        } => {
            let at = |d: f64| t0(a) + d * 86_400.0;
            Some((at(t_day), at(earliest_day), at(latest_day)))
        }
        _ => None,
    }
}

/// The sentence of a significant change.
pub fn change_words(a: &Actuator, p: &ParamTrend) -> String {
    let what = describe(&p.parameter);
    let u = &p.unit;
    let Some(lin) = p.trend.linear else {
        return format!("{what} of {}: {}", a.name, p.trend.verdict.word());
    };
    if let (Verdict::Step, Some(s)) = (p.trend.verdict, p.trend.step) {
        return format!(
            "{what} of {} stepped from {} to {} {u} at the log of {} (a step explains the logs better than a steady drift)",
            a.name,
            num(s.before),
            num(s.after),
            date_text(t0(a) + s.t_day * 86_400.0)
        );
    }
    let span = lin.span_days();
    let (unit, per) = time_unit(span);
    let verb = if lin.slope_per_day > 0.0 {
        "grew"
    } else {
        "fell"
    };
    let mut s = format!(
        "{what} of {} {verb} from {} to {} {u} over {}, {}{} {u} per {unit} (95 %: {} to {})",
        a.name,
        num(lin.at(lin.t_first_day)),
        num(lin.at(lin.t_last_day)),
        plural(span / per, unit),
        if lin.slope_per_day > 0.0 { "+" } else { "" },
        num(lin.slope_per_day * per),
        num(lin.slope_ci95.0 * per),
        num(lin.slope_ci95.1 * per),
    );
    match (p.crossing, p.limit) {
        (Some(Crossing::Ahead { t_day, .. }), Some((limit, from))) => {
            let (at, lo, hi) = crossing_dates(a, p).unwrap_or((f64::NAN, f64::NAN, f64::NAN));
            let ahead = (t_day - lin.t_last_day) / per;
            let hi_text = if hi.is_finite() {
                plural((hi - t0(a)) / 86_400.0 / per - lin.t_last_day / per, unit)
            } else {
                "never (the slope's interval includes 0)".into()
            };
            s.push_str(&format!(
                "; at this rate it reaches the {} {u} limit ({from}) in about {} after the last log, on {} (95 %: {} to {})",
                num(limit),
                plural(ahead, unit),
                date_text(at),
                plural((lo - t0(a)) / 86_400.0 / per - lin.t_last_day / per, unit),
                hi_text
            ));
        }
        (Some(Crossing::Passed), Some((limit, from))) => s.push_str(&format!(
            "; it is already past the {} {u} limit ({from})",
            num(limit)
        )),
        (Some(Crossing::AtLimit { lo, hi }), Some((limit, from))) => s.push_str(&format!(
            "; at the last log it is at the {} {u} limit ({from}) within its 95 % interval ({} to {}): these logs cannot tell whether it is past",
            num(limit),
            num(lo),
            num(hi)
        )),
        (Some(Crossing::Never), Some((limit, from))) => s.push_str(&format!(
            "; it moves away from the {} {u} limit ({from})",
            num(limit)
        )),
        _ => {}
    }
    s
}

/// The text report.
pub fn text(r: &TrendReport) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "servo trend: {} logs, model {}: {} from the cache, {} fitted, {} failed ({} workers, {:.1} s; cache {})\n",
        r.logs_found,
        r.model.display(),
        r.counts.hits,
        r.counts.new,
        r.counts.failed,
        r.workers,
        r.elapsed_s,
        r.cache_dir.display()
    ));
    for f in &r.failed {
        s.push_str(&format!("skipped {}: {}\n", f.path.display(), f.error));
    }
    for n in &r.notes {
        s.push_str(&format!("note: {n}\n"));
    }
    for a in &r.actuators {
        s.push_str(&format!(
            "\n== {} ({} logs, grouped by {}; times from {}) ==\n",
            a.name,
            a.logs.len(),
            a.grouped_by,
            time_sources(a)
        ));
        s.push_str(&table(a));
        for p in &a.params {
            if p.trend.significant() {
                s.push_str(&format!("CHANGE: {}.\n", change_words(a, p)));
            }
        }
        let steady: Vec<&str> = a
            .params
            .iter()
            .filter(|p| p.trend.verdict == Verdict::Steady)
            .map(|p| p.parameter.as_str())
            .collect();
        if !steady.is_empty() {
            let span = a.logs.last().map_or(0.0, |l| l.time_unix_s) - t0(a);
            let (unit, per) = time_unit(span / 86_400.0);
            s.push_str(&format!(
                "steady: {} of {} (no significant change over {})\n",
                steady.join(", "),
                a.name,
                plural(span / 86_400.0 / per, unit)
            ));
        }
        for p in a
            .params
            .iter()
            .filter(|p| p.trend.verdict == Verdict::Unknown)
        {
            s.push_str(&format!(
                "{}: too few logs to judge ({})\n",
                p.parameter,
                p.points.len()
            ));
        }
    }
    let changes: usize = r
        .actuators
        .iter()
        .map(|a| a.params.iter().filter(|p| p.trend.significant()).count())
        .sum();
    s.push_str(&format!(
        "\n{changes} significant change(s) in {} actuator(s)\n",
        r.actuators.len()
    ));
    s
}

fn time_sources(a: &Actuator) -> String {
    let mut v: Vec<String> = a.logs.iter().map(|l| l.time_from.clone()).collect();
    v.sort();
    v.dedup();
    v.join(", ")
}

/// The actuator's table: a row per log, a column per parameter (value +/- 95 %).
fn table(a: &Actuator) -> String {
    let mut s = format!("{:<10} {:<28}", "date", "log");
    for p in &a.params {
        s.push_str(&format!(" {:>22}", format!("{} [{}]", p.parameter, p.unit)));
    }
    s.push('\n');
    for (i, l) in a.logs.iter().enumerate() {
        let name = l
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        s.push_str(&format!("{:<10} {:<28}", date_text(l.time_unix_s), name));
        for p in &a.params {
            let cell = match p.points.iter().find(|(k, _)| *k == i) {
                Some((_, e)) => match e.std_err {
                    Some(se) => format!("{} +/- {}", num(e.value), num(Z95 * se)),
                    None => num(e.value),
                },
                None => "-".into(),
            };
            s.push_str(&format!(" {cell:>22}"));
        }
        s.push('\n');
    }
    s
}

fn ci(v: f64, se: Option<f64>) -> Value {
    match se {
        Some(se) => json!([v - Z95 * se, v + Z95 * se]),
        None => Value::Null,
    }
}

fn finite(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// The `servo.trend/1` object.
pub fn to_json(r: &TrendReport) -> Value {
    let mut changes = Vec::new();
    let actuators: Vec<Value> = r
        .actuators
        .iter()
        .map(|a| {
            let params: Vec<Value> = a
                .params
                .iter()
                .map(|p| {
                    let lin = p.trend.linear;
                    let crossing = crossing_dates(a, p);
                    let v = json!({
                        "parameter": p.parameter,
                        "unit": p.unit,
                        "verdict": p.trend.verdict.word(),
                        "points": p.points.len(),
                        "slope_per_day": lin.map(|l| finite(l.slope_per_day)),
                        "slope_ci": lin.map(|l| json!([l.slope_ci95.0, l.slope_ci95.1])),
                        "from": lin.map(|l| finite(l.at(l.t_first_day))),
                        "to": lin.map(|l| finite(l.at(l.t_last_day))),
                        "relative_change": finite(p.trend.relative_change),
                        "step": p.trend.step.map(|s| json!({
                            "date": date_text(t0(a) + s.t_day * 86_400.0),
                            "before": s.before, "after": s.after, "jump_std_err": s.jump_std_err,
                        })),
                        "limit": p.limit.map(|l| json!({"value": l.0, "from": l.1})),
                        "forecast_limit_date": crossing.map(|c| date_text(c.0)),
                        "forecast_limit_date_ci": crossing.map(|c| json!([date_text(c.1), if c.2.is_finite() { json!(date_text(c.2)) } else { Value::Null }])),
                        "limit_passed": matches!(p.crossing, Some(Crossing::Passed)),
                    });
                    if p.trend.significant() {
                        changes.push(json!({
                            "actuator": a.name,
                            "parameter": p.parameter,
                            "unit": p.unit,
                            "verdict": p.trend.verdict.word(),
                            "slope_per_day": v["slope_per_day"],
                            "slope_ci": v["slope_ci"],
                            "from": v["from"],
                            "to": v["to"],
                            "step": v["step"],
                            "forecast_limit_date": v["forecast_limit_date"],
                            "forecast_limit_date_ci": v["forecast_limit_date_ci"],
                            "words": change_words(a, p),
                        }));
                    }
                    v
                })
                .collect();
            json!({
                "actuator": a.name,
                "grouped_by": a.grouped_by,
                "logs": a.logs.iter().map(|l| json!({
                    "log": l.path.display().to_string(),
                    "time": datetime_text(l.time_unix_s),
                    "time_unix_s": l.time_unix_s,
                    "time_from": l.time_from,
                    "cached": l.cached,
                    "samples": l.fit.samples,
                    "estimates": l.fit.estimates.iter().map(|e| json!({
                        "parameter": e.parameter, "unit": e.unit, "value": e.value,
                        "std_err": e.std_err, "ci95": ci(e.value, e.std_err),
                    })).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
                "parameters": params,
                "steady": a.params.iter().filter(|p| p.trend.verdict == Verdict::Steady).map(|p| p.parameter.clone()).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!({
        "schema": "servo.trend/1",
        "model": r.model.display().to_string(),
        "logs_found": r.logs_found,
        "workers": r.workers,
        "elapsed_s": r.elapsed_s,
        "cache": {
            "dir": r.cache_dir.display().to_string(),
            "hits": r.counts.hits, "new": r.counts.new, "failed": r.counts.failed,
        },
        "failed": r.failed.iter().map(|f| json!({"log": f.path.display().to_string(), "error": f.error})).collect::<Vec<_>>(),
        "actuators": actuators,
        "changes": changes,
        "notes": r.notes,
    })
}

/// The chart of one parameter of an actuator over time: the estimates, their 95 % interval,
/// the trend line and the limit.
pub fn param_svg(a: &Actuator, p: &ParamTrend) -> anyhow::Result<String> {
    let span = a.logs.last().map_or(0.0, |l| l.time_unix_s) - t0(a);
    let (unit, per) = time_unit(span / 86_400.0);
    let x: Vec<f64> = p
        .points
        .iter()
        .map(|(i, _)| (a.logs[*i].time_unix_s - t0(a)) / 86_400.0 / per)
        .collect();
    let y: Vec<f64> = p.points.iter().map(|(_, e)| e.value).collect();
    let lo: Vec<f64> = p
        .points
        .iter()
        .map(|(_, e)| e.std_err.map_or(f64::NAN, |s| e.value - Z95 * s))
        .collect();
    let hi: Vec<f64> = p
        .points
        .iter()
        .map(|(_, e)| e.std_err.map_or(f64::NAN, |s| e.value + Z95 * s))
        .collect();
    let (lx, ly): (Vec<f64>, Vec<f64>) = match p.trend.linear {
        Some(l) => (
            vec![l.t_first_day / per, l.t_last_day / per],
            vec![l.at(l.t_first_day), l.at(l.t_last_day)],
        ),
        None => (vec![], vec![]),
    };
    let limit_y: Vec<f64> = match p.limit {
        Some((v, _)) => vec![v, v],
        None => vec![],
    };
    let limit_x: Vec<f64> = if limit_y.is_empty() {
        vec![]
    } else {
        vec![0.0, span / 86_400.0 / per]
    };
    let title = format!("{} of {}: {}", p.parameter, a.name, p.trend.verdict.word());
    let x_label = format!("time since the first log [{unit}s]");
    let y_label = format!("{} [{}]", p.parameter, p.unit);
    let mut series = vec![
        Series {
            label: "estimate",
            x: &x,
            y: &y,
        },
        Series {
            label: "95 % low",
            x: &x,
            y: &lo,
        },
        Series {
            label: "95 % high",
            x: &x,
            y: &hi,
        },
        Series {
            label: "trend",
            x: &lx,
            y: &ly,
        },
    ];
    if !limit_y.is_empty() {
        series.push(Series {
            label: "limit",
            x: &limit_x,
            y: &limit_y,
        });
    }
    line_chart_svg(
        &Chart {
            title: &title,
            x_label: &x_label,
            y_label: &y_label,
            width: 700,
            height: 300,
            ..Chart::default()
        },
        &series,
    )
}

/// The HTML report: the counts, what changes, and per actuator its table and a chart per
/// parameter.
pub fn html(r: &TrendReport) -> anyhow::Result<String> {
    let mut s = Markup::new();
    s.lit("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\">")
        .lit(CSP_META)
        .lit("<title>servo trend</title>\n<style>body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}.change{color:#b00}</style></head><body>\n<h1>servo trend</h1>\n");
    markup!(
        s,
        "<p>{} logs, model <code>{}</code>: {} from the cache, {} fitted, {} failed.</p>\n",
        r.logs_found,
        r.model.display().to_string(),
        r.counts.hits,
        r.counts.new,
        r.counts.failed
    );
    if !r.failed.is_empty() {
        s.lit("<h2>Skipped logs</h2><ul>\n");
        for f in &r.failed {
            markup!(
                s,
                "<li><code>{}</code>: {}</li>\n",
                f.path.display().to_string(),
                f.error
            );
        }
        s.lit("</ul>\n");
    }
    s.lit("<h2>What changes</h2><ul>\n");
    for a in &r.actuators {
        for p in a.params.iter().filter(|p| p.trend.significant()) {
            markup!(s, "<li class=\"change\">{}.</li>\n", change_words(a, p));
        }
        let steady: Vec<&str> = a
            .params
            .iter()
            .filter(|p| p.trend.verdict == Verdict::Steady)
            .map(|p| p.parameter.as_str())
            .collect();
        if !steady.is_empty() {
            markup!(s, "<li>{}: steady: {}</li>\n", a.name, steady.join(", "));
        }
    }
    s.lit("</ul>\n");
    for a in &r.actuators {
        markup!(
            s,
            "<h2>{}</h2>\n<p>{} logs, grouped by {}; times from {}.</p>\n<table><tr><th>date</th><th>log</th>",
            a.name,
            a.logs.len(),
            a.grouped_by,
            time_sources(a)
        );
        for p in &a.params {
            markup!(s, "<th>{} [{}]</th>", p.parameter, p.unit);
        }
        s.lit("</tr>\n");
        for (i, l) in a.logs.iter().enumerate() {
            markup!(
                s,
                "<tr><td>{}</td><td>{}</td>",
                date_text(l.time_unix_s),
                l.path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            );
            for p in &a.params {
                match p.points.iter().find(|(k, _)| *k == i) {
                    Some((_, e)) => match e.std_err {
                        Some(se) => {
                            markup!(s, "<td>{} &plusmn; {}</td>", num(e.value), num(Z95 * se))
                        }
                        None => markup!(s, "<td>{}</td>", num(e.value)),
                    },
                    None => s.lit("<td>-</td>"),
                };
            }
            s.lit("</tr>\n");
        }
        s.lit("</table>\n");
        for p in &a.params {
            s.push(&Markup::from_rendered_svg(&param_svg(a, p)?));
            s.lit("\n");
        }
    }
    s.lit("</body></html>\n");
    Ok(s.into_string())
}
