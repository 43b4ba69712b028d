#![no_main]
//! The report and chart writers on arbitrary names (`servo_cli::fuzz::check_report_writers`):
//! the input's UTF-8 text, split at `\u{1f}` (unit separator) into a chart's title, axis labels
//! and series labels and into values placed in text, attribute and URL contexts of a report's
//! markup. Every output must pass `servo_io::markup::problems` (no event handler, no script, no
//! broken markup) and every SVG must parse as XML; a panic anywhere is a crash.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let [svg, stacked, _page] = servo_cli::fuzz::check_report_writers(data);
    roxmltree::Document::parse(&svg).expect("the chart is XML");
    roxmltree::Document::parse(&stacked).expect("the stacked charts are XML");
});
