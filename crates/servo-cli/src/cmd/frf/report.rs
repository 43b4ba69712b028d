//! `servo frf`: pieces of the JSON report (schema `servo.frf/1`, docs/schemas/frf.json) and of
//! the text report.

use super::*;
use servo_core::frf::analysis::FrfAnalysis;
use servo_core::math::sig;

pub(super) fn interval(i: &Option<Interval>) -> Value {
    match i {
        Some(i) => json!({"value": i.value, "lo": i.lo, "hi": i.hi}),
        None => Value::Null,
    }
}

pub(super) fn fmt_i(i: &Option<Interval>, unit: &str, what: &str) -> String {
    match i {
        Some(i) => format!(
            "{what} {} {unit} [{}, {}]",
            servo_core::math::sig(i.value, 4),
            servo_core::math::sig(i.lo, 4),
            servo_core::math::sig(i.hi, 4)
        ),
        None => format!("{what} not measured"),
    }
}

/// The text report of an analysis of `n_logs` logs.
pub(super) fn print_text(a: &FrfAnalysis, n_logs: usize) {
    let sp = &a.spectra;
    let df = a.resolution_hz;
    outln!(
        "servo frf: {} log(s), {} at {:.0} Hz",
        n_logs,
        if a.closed { "closed loop" } else { "open loop" },
        1.0 / a.ts_s
    );
    outln!("estimate: Welch/H1, Hann window of {} samples ({:.3} Hz resolution), {:.0} % overlap, {} segments (~{:.1} independent averages), {:.0} % bounds", sp.segment_len, df, 100.0 * sp.overlap, sp.segments, sp.averages, 100.0 * a.welch.confidence);
    outln!("plant: {}", a.method);
    match a.band_hz_above_0_9 {
        Some((lo, hi)) => outln!("coherence: >= 0.9 in {} % of the {} excited bins (input power >= 1 % of its peak), between {} and {} Hz ({}-{} rad/s)", servo_core::math::sig(100.0 * a.fraction_above_0_9, 3), a.excited_bins, servo_core::math::sig(lo, 3), servo_core::math::sig(hi, 3), servo_core::math::sig(lo * std::f64::consts::TAU, 3), servo_core::math::sig(hi * std::f64::consts::TAU, 3)),
        None => outln!("coherence: never reaches 0.9: the data carry little information on the frequency response (steps and holds excite few frequencies; use a chirp or multisine)"),
    }
    let no_info = &a.no_information_rad_s;
    let shown: Vec<String> = no_info
        .iter()
        .filter(|r| r.1 > r.0)
        .take(6)
        .map(|r| format!("{}-{}", sig(r.0, 3), sig(r.1, 3)))
        .collect();
    if !shown.is_empty() {
        outln!(
            "no information (coherence < 0.5 where the input was excited) at {} rad/s{}",
            shown.join(", "),
            if no_info.len() > 6 { ", ..." } else { "" }
        );
    }
    if let Some(m) = &a.achieved {
        outln!("achieved ({}):", a.loop_from);
        outln!(
            "  {}; {}; {}",
            fmt_i(&m.crossover_rad_s, "rad/s", "crossover"),
            fmt_i(&m.phase_margin_deg, "deg", "phase margin"),
            fmt_i(&m.gain_margin_db, "dB", "gain margin")
        );
        for n in &m.notes {
            outln!("  {n}");
        }
    }
    if let Some(d) = &a.design {
        outln!(
            "design ({}): crossover {} rad/s, phase margin {} deg, gain margin {}",
            d.loop_words,
            sig(d.crossover_rad_s, 4),
            sig(d.phase_margin_deg, 4),
            if d.gain_margin_db.is_finite() {
                format!("{} dB", sig(d.gain_margin_db, 4))
            } else {
                "infinite".into()
            }
        );
    }
    if let Some(c) = &a.against_model {
        outln!("against the model:");
        for s in &c.sentences {
            outln!("  - {s}");
        }
    }
    if let Some(x) = &a.amplitude {
        outln!("amplitude: {}", x.sentence);
    }
    for n in &a.notes {
        outln!("note: {n}");
    }
}
