//! `servo frf --json`: the `frf` point lists streamed into the document (no JSON value tree:
//! 10 minutes at 1 kHz give 3 x 32769 points, and building them as values took longer than the
//! estimate).

use super::Estimate;
use serde_json::Value;

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
