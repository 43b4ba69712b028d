//! `servo frf --json`: the `frf` point lists streamed into the document (no JSON value tree:
//! 10 minutes at 1 kHz give 3 x 32769 points, and building them as values took longer than the
//! estimate).

use super::report::interval;
use super::Estimate;
use serde_json::{json, Value};
use servo_core::frf::analysis::FrfAnalysis;

/// The `servo.frf/1` document of an analysis of the logs `names`.
pub(super) fn json_document(
    a: &FrfAnalysis,
    names: &[String],
    log_parts: Value,
) -> anyhow::Result<String> {
    let mut frf = vec![("plant", points(&a.plant, -90.0))];
    if let Some(l) = &a.loop_frf {
        frf.push(("loop", points(l, -180.0)));
    }
    if let Some(t) = &a.t {
        frf.push(("complementary_sensitivity", points(t, 0.0)));
    }
    let sp = &a.spectra;
    let out = json!({
        "schema": "servo.frf/1",
        "mode": if a.closed { "closed-loop" } else { "open-loop" },
        "logs": names,
        "method": a.method,
        "loop_from": a.loop_from,
        "welch": {"window": sp.window, "segment_len": sp.segment_len, "segment_s": sp.segment_len as f64 * a.ts_s,
                  "overlap": sp.overlap, "segments": sp.segments, "averages": sp.averages,
                  "resolution_hz": a.resolution_hz, "confidence": a.welch.confidence},
        "achieved": a.achieved.as_ref().map(|a| json!({
            "crossover_rad_s": interval(&a.crossover_rad_s),
            "phase_margin_deg": interval(&a.phase_margin_deg),
            "gain_margin_db": interval(&a.gain_margin_db),
            "phase_crossover_rad_s": interval(&a.phase_crossover_rad_s),
            "band_rad_s": [a.band_rad_s.0, a.band_rad_s.1],
            "notes": a.notes,
        })),
        "design": a.design.map(|m| json!({"crossover_rad_s": m.crossover_rad_s, "phase_margin_deg": m.phase_margin_deg,
                "gain_margin_db": if m.gain_margin_db.is_finite() { json!(m.gain_margin_db) } else { Value::Null },
                "loop": m.loop_words})),
        "coherence": {"fraction_above_0_9": a.fraction_above_0_9, "excited_bins": a.excited_bins, "band_hz_above_0_9": a.band_hz_above_0_9.map(|b| vec![b.0, b.1]),
                      "no_information_rad_s": a.no_information_rad_s.iter().map(|r| vec![r.0, r.1]).collect::<Vec<_>>()},
        "against_model": a.against_model.as_ref().map(|c| json!({
            "sentences": c.sentences,
            "bands": c.bands.iter().map(|b| json!({"quantity": b.quantity, "lo_rad_s": b.lo_rad_s, "hi_rad_s": b.hi_rad_s, "worst": b.worst})).collect::<Vec<_>>(),
            "delay_s": c.delay.map(|d| json!({"value": d.delay_s, "ci": d.delay_ci_s, "rms_deg": d.delay_rms_deg, "pole_rad_s": d.pole_rad_s, "pole_rms_deg": d.pole_rms_deg})),
            "resonance_rad_s": c.resonance.map(|r| json!({"value": r.omega_rad_s, "peak_db": r.peak_db})),
        })),
        "amplitude": a.amplitude.as_ref().map(|x| json!({"gain_change_db": x.gain_change_db, "bound_db": x.bound_db, "significant": x.significant, "sentence": x.sentence, "u_rms_v": a.u_rms_v})),
        "notes": a.notes,
        "log_parts": log_parts,
    });
    let Value::Object(rest) = &out else {
        anyhow::bail!("internal error: the JSON document is not an object");
    };
    Ok(serde_json::to_string_pretty(&Doc { rest, frf })?)
}

/// One estimate's `frf` list, serialized point by point (no JSON value tree: a 10-minute log
/// at 1 kHz gives 3 x 32769 points).
pub(super) struct Points<'a> {
    e: &'a Estimate,
    phase_deg: Vec<f64>,
}

pub(super) fn points(e: &Estimate, start_deg: f64) -> Points<'_> {
    Points {
        e,
        phase_deg: e.phase_deg(start_deg),
    }
}

impl serde::Serialize for Points<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{SerializeSeq, SerializeStruct};
        /// One point; fields in the order a JSON object prints them (sorted).
        struct P {
            coherence: f64,
            freq_hz: f64,
            mag: f64,
            mag_hi: f64,
            mag_lo: f64,
            phase_bound_deg: f64,
            phase_deg: f64,
        }
        impl serde::Serialize for P {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut st = s.serialize_struct("point", 7)?;
                st.serialize_field("coherence", &self.coherence)?;
                st.serialize_field("freq_hz", &self.freq_hz)?;
                st.serialize_field("mag", &self.mag)?;
                st.serialize_field("mag_hi", &self.mag_hi)?;
                st.serialize_field("mag_lo", &self.mag_lo)?;
                st.serialize_field("phase_bound_deg", &self.phase_bound_deg)?;
                st.serialize_field("phase_deg", &self.phase_deg)?;
                st.end()
            }
        }
        let e = self.e;
        let mut seq = s.serialize_seq(Some(e.len()))?;
        for i in 0..e.len() {
            let (lo, hi) = e.mag_bounds(i);
            seq.serialize_element(&P {
                coherence: e.coherence[i],
                freq_hz: e.freq_hz[i],
                mag: e.mag(i),
                mag_hi: hi,
                mag_lo: lo,
                phase_bound_deg: e.phase_bound_deg(i),
                phase_deg: self.phase_deg[i],
            })?;
        }
        seq.end()
    }
}

/// The `--json` document: `rest` (a JSON object) with the `frf` lists added in key order,
/// serialized without building a value for the lists.
pub(super) struct Doc<'a> {
    pub rest: &'a serde_json::Map<String, Value>,
    pub frf: Vec<(&'static str, Points<'a>)>,
}

impl serde::Serialize for Doc<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        struct Frf<'b>(&'b [(&'static str, Points<'b>)]);
        impl serde::Serialize for Frf<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut m = s.serialize_map(Some(self.0.len()))?;
                let mut sorted: Vec<&(&str, Points)> = self.0.iter().collect();
                sorted.sort_by_key(|(k, _)| *k);
                for (k, v) in sorted {
                    m.serialize_entry(k, v)?;
                }
                m.end()
            }
        }
        let mut m = s.serialize_map(Some(self.rest.len() + 1))?;
        let mut done = false;
        for (k, v) in self.rest {
            if !done && k.as_str() > "frf" {
                m.serialize_entry("frf", &Frf(&self.frf))?;
                done = true;
            }
            m.serialize_entry(k, v)?;
        }
        if !done {
            m.serialize_entry("frf", &Frf(&self.frf))?;
        }
        m.end()
    }
}
