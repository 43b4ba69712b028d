//! Experiment files (TOML, in `experiments/`): a sequence of reference segments for the closed
//! loop and/or open-loop voltage segments, played one after the other.
//!
//! ```toml
//! [experiment]
//! name = "padova-steps"              # optional (default: the file name)
//! description = "..."                # optional
//! repeat = 1                         # optional: play the segment list this many times
//!
//! [[segment]]
//! ref = "step:10deg"                 # closed loop: load-angle reference, `--ref` syntax
//! duration_s = 2                     # [s]; optional for `trap` (defaults to the profile time)
//! label = "10 deg"                   # optional, for logs and plots
//!
//! [[segment]]
//! ref = "ramp:speed=-1"
//! duration_s = 1
//! chain = true                       # add the previous position segment's final value
//!
//! [[segment]]
//! u = "step:2"                       # open loop: driver input u [V]; the generator's values
//! duration_s = 1                     # (rad in the `--ref` syntax) are read as volts
//! ```
//!
//! Within a segment, time restarts at 0 (a generator's `@t0` is relative to the segment's
//! start). Before the first segment its initial value holds; after the last one a position holds
//! its final value and a voltage is 0 V. The segment semantics are those of
//! [`servo_core::control::sequence`], shared with the allocation-free sequences of the core.

use crate::error::{self as anyhow, anyhow, bail, Context};
use servo_core::control::sequence::{duration_s, setpoint_at, PlacedSegment};
use servo_core::control::{Reference, Segment, SegmentMode, Setpoint, Target};
use std::path::Path;

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    #[serde(default)]
    experiment: Option<HeaderToml>,
    #[serde(default, rename = "segment")]
    segments: Vec<SegmentToml>,
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct HeaderToml {
    name: Option<String>,
    description: Option<String>,
    repeat: Option<u32>,
    /// What the closed-loop references are: `"rad"`, load angles on any axis (on a linear axis
    /// the load shaft's angle, which its transmission turns into a travel), or `"m"`, lengths
    /// on a linear axis (the default there).
    units: Option<String>,
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentToml {
    #[serde(rename = "ref")]
    reference: Option<toml::Spanned<String>>,
    u: Option<toml::Spanned<String>>,
    duration_s: Option<f64>,
    #[serde(default)]
    chain: bool,
    label: Option<String>,
}

/// An experiment: what to apply at every instant of a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Experiment {
    /// Name (the `[experiment] name`, else the file stem, else the reference text).
    pub name: String,
    /// Free-form description.
    pub description: Option<String>,
    /// Segments with their start times (repeats expanded).
    pub segments: Vec<PlacedSegment>,
    /// Label of each segment (same length as `segments`).
    pub labels: Vec<Option<String>>,
}

impl Experiment {
    /// A single closed-loop reference lasting `duration_s` [s] (what `--ref` gives).
    pub fn from_reference(reference: Reference, duration_s: f64) -> anyhow::Result<Experiment> {
        let seg = PlacedSegment::after(&[], Segment::position(reference, duration_s))
            .map_err(|e| anyhow!("{e}"))?;
        Ok(Experiment {
            name: reference.to_string(),
            description: None,
            segments: vec![seg],
            labels: vec![None],
        })
    }

    /// Parses a `--ref` text (see [`servo_core::control::reference`]) into a one-segment
    /// experiment of `duration_s` [s].
    pub fn from_ref_text(text: &str, duration_s: f64) -> anyhow::Result<Experiment> {
        let r = Reference::parse(text).map_err(|e| anyhow!("--ref `{text}`: {e}"))?;
        Self::from_reference(r, duration_s)
    }

    /// What a `--ref` argument names: an experiment file when it ends in `.toml` (its own
    /// durations apply), else a reference text lasting `duration_s` [s].
    pub fn from_arg(arg: &str, duration_s: f64) -> anyhow::Result<Experiment> {
        if arg.trim_end().to_ascii_lowercase().ends_with(".toml") {
            load_experiment(Path::new(arg.trim()))
        } else {
            Self::from_ref_text(arg, duration_s)
        }
    }

    /// Total duration [s].
    pub fn duration_s(&self) -> f64 {
        duration_s(&self.segments)
    }

    /// What to apply at time `t_s` [s]: a position reference (closed loop) or a voltage.
    pub fn at(&self, t_s: f64) -> Setpoint {
        setpoint_at(&self.segments, t_s)
    }

    /// Index of the segment active at `t_s` (the last one after the end).
    pub fn segment_index_at(&self, t_s: f64) -> usize {
        self.segments
            .partition_point(|p| p.start_s <= t_s + servo_core::control::reference::TIME_EPS_S)
            .saturating_sub(1)
    }

    /// Whether any segment is closed loop (needs gains).
    pub fn has_closed_loop(&self) -> bool {
        self.segments
            .iter()
            .any(|s| s.segment.target == Target::Position)
    }

    /// Whether any segment is open loop.
    pub fn has_open_loop(&self) -> bool {
        self.segments
            .iter()
            .any(|s| s.segment.target == Target::Voltage)
    }

    /// Parses experiment TOML; `origin` names the source in errors (e.g. the path).
    /// The standard tracking reference of compensation (issue #29, `experiments/tracking.toml`):
    /// moves of 1.5 rad both ways (trapezoids) and a slow sine, 18 s.
    pub fn standard_tracking() -> anyhow::Result<Experiment> {
        Experiment::parse(STANDARD_TRACKING_TOML, "experiments/tracking.toml")
    }

    pub fn parse(text: &str, origin: &str) -> anyhow::Result<Experiment> {
        Experiment::parse_on(text, origin, None)
    }

    /// [`Experiment::parse`] on a linear axis whose load shaft travels `metres_per_rad` [m/rad]
    /// (`None`: a rotary gear): the closed-loop segments' references are lengths (m, mm, um;
    /// [`Reference::parse_on`]), the open-loop segments stay in volts.
    pub fn parse_on(
        text: &str,
        origin: &str,
        metres_per_rad: Option<f64>,
    ) -> anyhow::Result<Experiment> {
        let file: FileToml = toml::from_str(text)
            .map_err(|e| anyhow!("{origin}: {}", crate::text_file::toml_error(&e)))?;
        let line_of = |span: core::ops::Range<usize>| {
            text[..span.start.min(text.len())].lines().count().max(1)
        };
        let header = file.experiment;
        let repeat = header.as_ref().and_then(|h| h.repeat).unwrap_or(1);
        if repeat == 0 {
            bail!("{origin}: [experiment] `repeat` must be >= 1");
        }
        if file.segments.is_empty() {
            bail!("{origin}: no [[segment]]; expected at least one with `ref = \"...\"` or `u = \"...\"` and `duration_s`");
        }
        let angles = match header.as_ref().and_then(|h| h.units.as_deref()) {
            None => false,
            Some("rad") => true,
            Some("m") if metres_per_rad.is_none() => bail!(
                "{origin}: [experiment] units = \"m\": its references are lengths, and this plant is rotary (no linear [transmission]); use a recipe in rad"
            ),
            Some("m") => false,
            Some(other) => bail!(
                "{origin}: [experiment] units = \"{other}\": expected \"rad\" (load angles, on any axis; on a linear axis the load shaft's angle) or \"m\" (lengths on a linear axis)"
            ),
        };
        let mut one_pass = Vec::with_capacity(file.segments.len());
        for (i, s) in file.segments.iter().enumerate() {
            let n = i + 1;
            let (text_sp, target, key) = match (&s.reference, &s.u) {
                (Some(r), None) => (r, Target::Position, "ref"),
                (None, Some(u)) => (u, Target::Voltage, "u"),
                (Some(r), Some(_)) => bail!(
                    "{origin}:{}: segment {n} has both `ref` and `u`; a segment is either closed loop (`ref`, rad) or open loop (`u`, V)",
                    line_of(r.span())
                ),
                (None, None) => bail!("{origin}: segment {n} needs `ref = \"...\"` (closed loop, rad) or `u = \"...\"` (open loop, V)"),
            };
            let line = line_of(text_sp.span());
            let on = metres_per_rad.filter(|_| target == Target::Position && !angles);
            let reference = Reference::parse_on(text_sp.get_ref(), on).map_err(|e| {
                anyhow!(
                    "{origin}:{line}: segment {n}, `{key} = \"{}\"`: {e}",
                    text_sp.get_ref()
                )
            })?;
            let duration_s = match (s.duration_s, reference.shape.trapezoid_duration_s()) {
                (Some(d), _) => d,
                (None, Some(d)) => reference.t0_s + d,
                (None, None) => bail!("{origin}:{line}: segment {n} needs `duration_s` [s]"),
            };
            let mode = if s.chain {
                SegmentMode::Chained
            } else {
                SegmentMode::Absolute
            };
            one_pass.push((
                Segment {
                    reference,
                    duration_s,
                    mode,
                    target,
                },
                s.label.clone(),
                line,
                n,
            ));
        }
        let mut segments = Vec::with_capacity(one_pass.len() * repeat as usize);
        let mut labels = Vec::with_capacity(segments.capacity());
        for _ in 0..repeat {
            for (seg, label, line, n) in &one_pass {
                let placed = PlacedSegment::after(&segments, *seg).map_err(|e| {
                    // The core's error counts from 0 over the expanded list; name the file's segment.
                    let msg = e.to_string();
                    let msg = msg
                        .split_once(": ")
                        .map_or(msg.as_str(), |(_, m)| m)
                        .to_string();
                    anyhow!("{origin}:{line}: segment {n}: {msg}")
                })?;
                segments.push(placed);
                labels.push(label.clone());
            }
        }
        let name = header
            .as_ref()
            .and_then(|h| h.name.clone())
            .unwrap_or_else(|| {
                Path::new(origin)
                    .file_stem()
                    .map_or_else(|| origin.to_string(), |s| s.to_string_lossy().into_owned())
            });
        Ok(Experiment {
            name,
            description: header.and_then(|h| h.description),
            segments,
            labels,
        })
    }
}

/// Reads an experiment file.
pub fn load_experiment(path: &Path) -> anyhow::Result<Experiment> {
    load_experiment_on(path, None)
}

/// Reads an experiment file of a linear axis ([`Experiment::parse_on`]).
pub fn load_experiment_on(path: &Path, metres_per_rad: Option<f64>) -> anyhow::Result<Experiment> {
    let text = crate::text_file::read_text(path)
        .with_context(|| format!("reading experiment file {}", path.display()))?;
    Experiment::parse_on(&text, &path.display().to_string(), metres_per_rad)
}

/// The text of `experiments/tracking.toml`, the standard tracking reference of compensation.
pub const STANDARD_TRACKING_TOML: &str = include_str!("../../../experiments/tracking.toml");

#[cfg(test)]
mod tests {
    use super::*;
    use servo_core::control::RefSample;
    use std::f64::consts::PI;

    fn pos(s: Setpoint) -> RefSample {
        match s {
            Setpoint::Position(r) => r,
            Setpoint::Voltage { u_v } => panic!("expected a position, got {u_v} V"),
        }
    }

    fn experiments_dir() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments")
    }

    /// A recipe in load angles (`units = "rad"`) on a linear axis moves the load shaft by those
    /// angles (the transmission sets the travel), never by as many metres; one without `units`
    /// is in metres there; `units = "m"` on a rotary plant and an unknown unit are refused.
    #[test]
    fn recipe_units_scale_to_the_rig_or_refuse() {
        let text = std::fs::read_to_string(experiments_dir().join("tracking.toml")).unwrap();
        let lead_m_per_rad = 0.010 / (2.0 * PI);
        let on_screw = Experiment::parse_on(&text, "tracking.toml", Some(lead_m_per_rad)).unwrap();
        let rotary = Experiment::parse(&text, "tracking.toml").unwrap();
        for t in [0.5, 1.0, 1.9, 3.0, 9.0] {
            assert_eq!(
                pos(on_screw.at(t)).pos_rad,
                pos(rotary.at(t)).pos_rad,
                "t = {t}"
            );
        }
        assert!((pos(rotary.at(1.99)).pos_rad - 1.5).abs() < 1e-9);
        let metres = text.replace("units = \"rad\"", "units = \"m\"");
        let in_m = Experiment::parse_on(&metres, "x.toml", Some(lead_m_per_rad)).unwrap();
        assert!((pos(in_m.at(1.99)).pos_rad - 1.5 / lead_m_per_rad).abs() < 1e-6);
        let e = Experiment::parse(&metres, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("units = \"m\"") && e.contains("rotary"), "{e}");
        let odd = text.replace("units = \"rad\"", "units = \"furlong\"");
        let e = Experiment::parse(&odd, "x.toml").unwrap_err().to_string();
        assert!(e.contains("furlong") && e.contains("expected"), "{e}");
    }

    #[test]
    fn padova_steps_recipe() {
        let e = load_experiment(&experiments_dir().join("steps.toml")).unwrap();
        assert_eq!(e.name, "padova-steps");
        assert!(e.has_closed_loop() && !e.has_open_loop());
        assert_eq!(e.duration_s(), 24.0);
        let deg = |t: f64| pos(e.at(t)).pos_rad * 180.0 / PI;
        let expected = [
            10.0, 0.0, 30.0, 0.0, 50.0, 0.0, 90.0, 0.0, 180.0, 0.0, 360.0, 360.0,
        ];
        for (k, want) in expected.iter().enumerate() {
            let t = 2.0 * k as f64 + 1.0;
            assert!(
                (deg(t) - want).abs() < 1e-9,
                "t = {t}: {} deg, expected {want}",
                deg(t)
            );
        }
        assert_eq!(e.segment_index_at(4.5), 2);
    }

    #[test]
    fn chirp_and_open_loop_recipes() {
        let e = load_experiment(&experiments_dir().join("chirp.toml")).unwrap();
        assert!(e.duration_s() > 10.0);
        // A chirp segment has analytic speed for the feedforward.
        let s = pos(e.at(e.segments[1].start_s + 0.5));
        assert!(s.vel_rad_s != 0.0);
        let e = load_experiment(&experiments_dir().join("openloop_sweep.toml")).unwrap();
        assert!(e.has_open_loop());
        assert!(matches!(e.at(0.5), Setpoint::Voltage { .. }));
        // Every voltage stays within the driver's +-10 V input range.
        let mut t = 0.0;
        while t < e.duration_s() {
            if let Setpoint::Voltage { u_v } = e.at(t) {
                assert!(u_v.abs() <= 10.0, "{u_v} V at {t} s");
            }
            t += 1e-3;
        }
        assert_eq!(e.at(e.duration_s() + 1.0), Setpoint::Voltage { u_v: 0.0 });
    }

    #[test]
    fn chain_repeat_trap_default_duration_and_voltage() {
        let text = r#"
[experiment]
repeat = 2
[[segment]]
ref = "trap:distance=1,vmax=1,amax=1"
[[segment]]
ref = "step:0"
duration_s = 0.5
chain = true
[[segment]]
u = "sine:amp=2,freq=1"
duration_s = 1
"#;
        let e = Experiment::parse(text, "inline.toml").unwrap();
        assert_eq!(e.name, "inline");
        // Trapezoid of 1 rad at 1 rad/s, 1 rad/s^2: 1 s accelerating + 1 s decelerating.
        assert_eq!(e.segments.len(), 6);
        assert!((e.duration_s() - 2.0 * (2.0 + 0.5 + 1.0)).abs() < 1e-12);
        assert!((pos(e.at(2.2)).pos_rad - 1.0).abs() < 1e-12); // chained hold at 1 rad
        match e.at(2.75) {
            Setpoint::Voltage { u_v } => assert!((u_v - 2.0).abs() < 1e-9, "{u_v}"),
            s => panic!("{s:?}"),
        }
        assert!((pos(e.at(4.5)).pos_rad - 0.5).abs() < 1e-12); // second pass, mid-trapezoid
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let err = |t: &str| format!("{:#}", Experiment::parse(t, "x.toml").unwrap_err());
        let m = err("[[segment]]\nduration_s = 1\nref = \"sine:amp=1,frq=2\"\n");
        assert!(
            m.contains("x.toml:3") && m.contains("segment 1") && m.contains("`frq`"),
            "{m}"
        );
        let m = err("[[segment]]\nref = \"step:1\"\n");
        assert!(m.contains("x.toml:2") && m.contains("duration_s"), "{m}");
        let m = err("[[segment]]\nref = \"step:1\"\nu = \"step:1\"\nduration_s = 1\n");
        assert!(m.contains("both `ref` and `u`"), "{m}");
        let m = err("[[segment]]\nduration_s = 1\n");
        assert!(m.contains("needs `ref"), "{m}");
        let m = err("[[segment]]\nref = \"step:1\"\nduration_s = -1\n");
        assert!(m.contains("x.toml:2") && m.contains("duration_s"), "{m}");
        let m = err("[[segment]]\nref = \"step:1\"\nduration_s = 1\nspeed = 3\n");
        assert!(m.contains("speed"), "{m}");
        assert!(err("").contains("no [[segment]]"));
        assert!(
            err("[experiment]\nrepeat = 0\n[[segment]]\nref = \"step:1\"\nduration_s = 1\n")
                .contains("repeat")
        );
    }

    #[test]
    fn from_ref_text() {
        let e = Experiment::from_ref_text("step:1.5@0.1", 5.0).unwrap();
        assert_eq!(e.duration_s(), 5.0);
        assert_eq!(pos(e.at(0.05)).pos_rad, 0.0);
        assert_eq!(pos(e.at(1.0)).pos_rad, 1.5);
        let m = format!(
            "{:#}",
            Experiment::from_ref_text("stepp:1", 5.0).unwrap_err()
        );
        assert!(m.contains("--ref") && m.contains("stepp"), "{m}");
        assert!(Experiment::from_ref_text("step:1", 0.0).is_err());
        let steps = experiments_dir().join("steps.toml");
        let e = Experiment::from_arg(steps.to_str().unwrap(), 5.0).unwrap();
        assert_eq!((e.name.as_str(), e.duration_s()), ("padova-steps", 24.0));
        assert_eq!(
            Experiment::from_arg("ramp:speed=1", 3.0)
                .unwrap()
                .duration_s(),
            3.0
        );
        let m = format!(
            "{:#}",
            Experiment::from_arg("missing.toml", 3.0).unwrap_err()
        );
        assert!(m.contains("missing.toml"), "{m}");
        // Experiments serialise (for the run's metadata).
        let json = serde_json::to_string(&e).unwrap();
        assert!(
            json.contains("padova-steps") && json.contains("duration_s"),
            "{json}"
        );
    }
}
