#![no_main]
//! The report and chart writers on arbitrary names: the input's UTF-8 text, split at `\u{1f}`
//! (unit separator) into a chart's title, axis labels and series labels and into values placed
//! in text, attribute and URL contexts of a report's markup. Every output must pass
//! `servo_io::markup::problems` (no event handler, no script, no broken markup) and every SVG
//! must parse as XML; a panic anywhere is a crash.
use libfuzzer_sys::fuzz_target;
use servo_cli::plot::{line_chart_svg, Chart, Series};
use servo_io::markup;
use servo_io::markup::{problems, Attr, Markup, Url};

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let mut f: Vec<&str> = text.split('\u{1f}').collect();
    f.resize(8, "");
    let x = [0.1, 0.2, 0.5, 1.0, 2.0];
    let y = [1.0, -1.0, 0.5, f64::NAN, 2.0];
    let chart = Chart {
        title: f[0],
        x_label: f[1],
        y_label: f[2],
        log_x: data.first().is_some_and(|b| b & 1 == 1),
        scatter: data.first().is_some_and(|b| b & 2 == 2),
        ..Chart::default()
    };
    let series = [
        Series { label: f[3], x: &x, y: &y },
        Series { label: f[4], x: &x, y: &x },
    ];
    let svg = line_chart_svg(&chart, &series).expect("the chart renders");
    let p = problems(&svg);
    assert!(p.is_empty(), "{p:?}");
    roxmltree::Document::parse(&svg).expect("the chart is XML");
    let stacked = servo_cli::cmd::compare::stack_svg(&[svg.clone(), svg.clone()]);
    roxmltree::Document::parse(&stacked).expect("the stacked charts are XML");
    let mut h = Markup::new();
    h.lit("<!DOCTYPE html><html><head>").lit(markup::CSP_META).lit("</head><body>");
    markup!(
        h,
        "<div class=\"panel\" data-log=\"{}\" title='{}'><h3>{}</h3><a href=\"{}\">{}</a>",
        f[5],
        Attr(f[6]),
        f[5],
        Url(f[7]),
        f[6]
    );
    h.push(&Markup::from_rendered_svg(&svg)).lit("</div></body></html>");
    let p = problems(h.as_str());
    assert!(p.is_empty(), "{p:?}");
});
