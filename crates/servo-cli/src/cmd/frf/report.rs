//! `servo frf`: pieces of the JSON report (schema `servo.frf/1`, docs/schemas/frf.json) and of
//! the text report.

use super::*;

pub(super) fn interval(i: &Option<Interval>) -> Value {
    match i {
        Some(i) => json!({"value": i.value, "lo": i.lo, "hi": i.hi}),
        None => Value::Null,
    }
}

pub(super) fn fmt_i(i: &Option<Interval>, unit: &str, what: &str) -> String {
    match i {
        Some(i) => format!("{what} {:.2} {unit} [{:.2}, {:.2}]", i.value, i.lo, i.hi),
        None => format!("{what} not measured"),
    }
}

pub(super) fn std_dev(x: &[f64]) -> f64 {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len().max(1) as f64).sqrt()
}
