//! Allocation-free parser of the reference text syntax (`step:1.5`, `sine:amp=0.5,freq=1@2`, ...);
//! the syntax is documented in [`super::reference`].

use super::reference::{ChirpMode, RefParseError, Reference, Shape, Snippet};
use crate::math;

/// Physical quantity of a value: decides the accepted unit suffixes.
#[derive(Clone, Copy, PartialEq)]
enum Quantity {
    Angle,
    Speed,
    Accel,
    Time,
    Freq,
    Ratio,
    Integer,
    Mode,
}

impl Quantity {
    /// (suffix, factor to SI), longest suffixes first so `ms` wins over `s`.
    fn units(self) -> &'static [(&'static str, f64)] {
        const DEG: f64 = math::PI / 180.0;
        match self {
            Quantity::Angle => &[("rad", 1.0), ("deg", DEG), ("rev", math::TAU)],
            Quantity::Speed => &[
                ("rad/s", 1.0),
                ("deg/s", DEG),
                ("rev/s", math::TAU),
                ("rpm", math::TAU / 60.0),
            ],
            Quantity::Accel => &[
                ("rad/s^2", 1.0),
                ("deg/s^2", DEG),
                ("rad/s2", 1.0),
                ("deg/s2", DEG),
            ],
            Quantity::Time => &[("ms", 1e-3), ("s", 1.0)],
            Quantity::Freq => &[("hz", 1.0)],
            Quantity::Ratio | Quantity::Integer | Quantity::Mode => &[],
        }
    }

    /// (suffix, factor to SI) of a position, speed or acceleration on a linear axis [m, m/s,
    /// m/s^2], longest suffixes first so `mm` wins over `m`; `None` for other quantities.
    fn linear_units(self) -> Option<&'static [(&'static str, f64)]> {
        match self {
            Quantity::Angle => Some(&[("um", 1e-6), ("mm", 1e-3), ("m", 1.0)]),
            Quantity::Speed => Some(&[("um/s", 1e-6), ("mm/s", 1e-3), ("m/s", 1.0)]),
            Quantity::Accel => Some(&[
                ("mm/s^2", 1e-3),
                ("mm/s2", 1e-3),
                ("m/s^2", 1.0),
                ("m/s2", 1.0),
            ]),
            _ => None,
        }
    }

    fn expected_linear(self) -> &'static str {
        match self {
            Quantity::Angle => "a length in m on this linear axis (suffix m, mm or um allowed)",
            Quantity::Speed => {
                "a speed in m/s on this linear axis (suffix m/s, mm/s or um/s allowed)"
            }
            Quantity::Accel => {
                "an acceleration in m/s^2 on this linear axis (suffix m/s2, mm/s2 allowed)"
            }
            q => q.expected(),
        }
    }

    fn expected(self) -> &'static str {
        match self {
            Quantity::Angle => "a number in rad (suffix rad, deg or rev allowed)",
            Quantity::Speed => "a number in rad/s (suffix rad/s, deg/s, rev/s or rpm allowed)",
            Quantity::Accel => "a number in rad/s^2 (suffix rad/s2, deg/s2 allowed)",
            Quantity::Time => "a number in s (suffix s or ms allowed)",
            Quantity::Freq => "a number in Hz",
            Quantity::Ratio => "a number between 0 and 1",
            Quantity::Integer => "a non-negative integer",
            Quantity::Mode => "`linear` or `log`",
        }
    }
}

/// Keys of one kind: (name, quantity); the first is the primary key.
struct KindSpec {
    kind: &'static str,
    keys: &'static [(&'static str, Quantity)],
    listing: &'static str,
}

const KINDS: &[KindSpec] = &[
    KindSpec {
        kind: "step",
        keys: &[("amp", Quantity::Angle)],
        listing: "amp, t0, offset",
    },
    KindSpec {
        kind: "ramp",
        keys: &[("speed", Quantity::Speed)],
        listing: "speed, t0, offset",
    },
    KindSpec {
        kind: "trap",
        keys: &[
            ("distance", Quantity::Angle),
            ("vmax", Quantity::Speed),
            ("amax", Quantity::Accel),
        ],
        listing: "distance, vmax, amax, t0, offset",
    },
    KindSpec {
        kind: "sine",
        keys: &[
            ("amp", Quantity::Angle),
            ("freq", Quantity::Freq),
            ("phase", Quantity::Angle),
        ],
        listing: "amp, freq, phase, t0, offset",
    },
    KindSpec {
        kind: "chirp",
        keys: &[
            ("amp", Quantity::Angle),
            ("f0", Quantity::Freq),
            ("f1", Quantity::Freq),
            ("duration", Quantity::Time),
            ("mode", Quantity::Mode),
        ],
        listing: "amp, f0, f1, duration, mode, t0, offset",
    },
    KindSpec {
        kind: "square",
        keys: &[
            ("amp", Quantity::Angle),
            ("period", Quantity::Time),
            ("duty", Quantity::Ratio),
        ],
        listing: "amp, period, duty, t0, offset",
    },
    KindSpec {
        kind: "prbs",
        keys: &[
            ("amp", Quantity::Angle),
            ("bit", Quantity::Time),
            ("seed", Quantity::Integer),
            ("order", Quantity::Integer),
        ],
        listing: "amp, bit, seed, order, t0, offset",
    },
    KindSpec {
        kind: "multisine",
        keys: &[
            ("amp", Quantity::Angle),
            ("f0", Quantity::Freq),
            ("f1", Quantity::Freq),
            ("period", Quantity::Time),
            ("lines", Quantity::Integer),
        ],
        listing: "amp, f0, f1, period, lines, t0, offset",
    },
];

/// Index of the common keys after a kind's own keys.
const COMMON: [(&str, Quantity); 2] = [("t0", Quantity::Time), ("offset", Quantity::Angle)];
const MAX_KEYS: usize = 7;

/// Case-insensitive `ends_with` without allocation.
fn strip_suffix_ci<'a>(s: &'a str, suffix: &str) -> Option<&'a str> {
    if s.len() < suffix.len() || !s.is_char_boundary(s.len() - suffix.len()) {
        return None;
    }
    let (head, tail) = s.split_at(s.len() - suffix.len());
    tail.eq_ignore_ascii_case(suffix).then_some(head)
}

/// Parses a number with an optional unit suffix into SI. On a linear axis (`metres_per_rad`
/// Some(s), s the travel per radian of the load shaft) positions, speeds and accelerations are
/// lengths [m, m/s, m/s^2] converted to the load shaft's equivalent rotation (divided by s); a
/// phase stays an angle.
fn parse_value(
    key: &'static str,
    q: Quantity,
    text: &str,
    metres_per_rad: Option<f64>,
) -> Result<f64, RefParseError> {
    let linear = metres_per_rad
        .filter(|_| key != "phase")
        .and_then(|s| q.linear_units().map(|u| (s, u)));
    let bad = || RefParseError::BadValue {
        key,
        value: Snippet::new(text),
        expected: if linear.is_some() {
            q.expected_linear()
        } else {
            q.expected()
        },
    };
    let t = text.trim();
    match q {
        Quantity::Mode => {
            return match t {
                "linear" | "lin" => Ok(0.0),
                "log" | "logarithmic" | "exp" => Ok(1.0),
                _ => Err(bad()),
            }
        }
        Quantity::Integer => {
            return t.parse::<u32>().map(|v| v as f64).map_err(|_| bad());
        }
        _ => {}
    }
    let (units, per) = match linear {
        Some((s, units)) => (units, 1.0 / s),
        None => (q.units(), 1.0),
    };
    let (number, factor) = units
        .iter()
        .find_map(|(suffix, factor)| {
            strip_suffix_ci(t, suffix).map(|head| (head.trim_end(), *factor))
        })
        .unwrap_or((t, 1.0));
    let v: f64 = number.parse().map_err(|_| bad())?;
    if !v.is_finite() {
        return Err(bad());
    }
    Ok(v * factor * per)
}

pub(crate) fn parse(text: &str, metres_per_rad: Option<f64>) -> Result<Reference, RefParseError> {
    let text = text.trim();
    if text.is_empty() {
        return Err(RefParseError::Empty);
    }
    let (body, at_t0) = match text.rfind('@') {
        Some(i) => (&text[..i], Some(&text[i + 1..])),
        None => (text, None),
    };
    let (kind, args) = match body.find(':') {
        Some(i) => (body[..i].trim(), body[i + 1..].trim()),
        None => (body.trim(), ""),
    };
    let spec = KINDS
        .iter()
        .find(|s| {
            s.kind.eq_ignore_ascii_case(kind)
                || (s.kind == "trap" && kind.eq_ignore_ascii_case("trapezoid"))
        })
        .ok_or(RefParseError::UnknownKind(Snippet::new(kind)))?;
    let n_own = spec.keys.len();
    let key_at = |i: usize| {
        if i < n_own {
            spec.keys[i]
        } else {
            COMMON[i - n_own]
        }
    };
    let mut values: [Option<f64>; MAX_KEYS] = [None; MAX_KEYS];
    let mut set = |i: usize, text: &str| -> Result<(), RefParseError> {
        let (name, q) = key_at(i);
        if values[i].is_some() {
            return Err(RefParseError::Duplicate(name));
        }
        values[i] = Some(parse_value(name, q, text, metres_per_rad)?);
        Ok(())
    };
    if !args.is_empty() {
        for (n, item) in args.split(',').enumerate() {
            let item = item.trim();
            let (key, value) = match item.find('=') {
                Some(eq) => (item[..eq].trim(), &item[eq + 1..]),
                None if n == 0 => (spec.keys[0].0, item),
                None => {
                    return Err(RefParseError::UnknownKey {
                        kind: spec.kind,
                        key: Snippet::new(item),
                        expected: "key=value after the first value",
                    })
                }
            };
            let key = if key.eq_ignore_ascii_case("amplitude") {
                "amp"
            } else {
                key
            };
            let i = (0..n_own + COMMON.len())
                .find(|&i| key_at(i).0.eq_ignore_ascii_case(key))
                .ok_or(RefParseError::UnknownKey {
                    kind: spec.kind,
                    key: Snippet::new(key),
                    expected: spec.listing,
                })?;
            set(i, value)?;
        }
    }
    if let Some(t0) = at_t0 {
        set(n_own, t0)?;
    }
    let need = |i: usize, unit: &'static str| -> Result<f64, RefParseError> {
        let unit = match (metres_per_rad, unit) {
            (Some(_), "rad") => "m",
            (Some(_), "rad/s") => "m/s",
            (Some(_), "rad/s^2") => "m/s^2",
            (_, u) => u,
        };
        values[i].ok_or(RefParseError::Missing {
            kind: spec.kind,
            key: spec.keys[i].0,
            unit,
        })
    };
    let shape = match spec.kind {
        "step" => Shape::Step {
            amplitude_rad: need(0, "rad")?,
        },
        "ramp" => Shape::Ramp {
            speed_rad_s: need(0, "rad/s")?,
        },
        "trap" => Shape::Trapezoid {
            distance_rad: need(0, "rad")?,
            vmax_rad_s: need(1, "rad/s")?,
            amax_rad_s2: need(2, "rad/s^2")?,
        },
        "sine" => Shape::Sine {
            amplitude_rad: need(0, "rad")?,
            freq_hz: need(1, "Hz")?,
            phase_rad: values[2].unwrap_or(0.0),
        },
        "chirp" => Shape::Chirp {
            amplitude_rad: need(0, "rad")?,
            f0_hz: need(1, "Hz")?,
            f1_hz: need(2, "Hz")?,
            duration_s: need(3, "s")?,
            mode: if values[4] == Some(1.0) {
                ChirpMode::Log
            } else {
                ChirpMode::Linear
            },
        },
        "square" => Shape::Square {
            amplitude_rad: need(0, "rad")?,
            period_s: need(1, "s")?,
            duty: values[2].unwrap_or(0.5),
        },
        "multisine" => {
            let lines = values[4].unwrap_or(40.0);
            if lines > f64::from(super::reference::MULTISINE_MAX_LINES) {
                return Err(RefParseError::Invalid {
                    key: "lines",
                    reason: "must be an integer in 1..=200",
                });
            }
            Shape::Multisine {
                amplitude_rad: need(0, "rad")?,
                f0_hz: need(1, "Hz")?,
                f1_hz: need(2, "Hz")?,
                period_s: need(3, "s")?,
                lines: lines as u16,
            }
        }
        _ => {
            let order = values[3].unwrap_or(10.0);
            if order > 16.0 {
                return Err(RefParseError::Invalid {
                    key: "order",
                    reason: "must be an integer in 2..=16",
                });
            }
            Shape::Prbs {
                amplitude_rad: need(0, "rad")?,
                bit_s: need(1, "s")?,
                seed: values[2].unwrap_or(1.0) as u32,
                order: order as u8,
            }
        }
    };
    let r = Reference {
        shape,
        t0_s: values[n_own].unwrap_or(0.0),
        offset_rad: values[n_own + 1].unwrap_or(0.0),
    };
    r.validate()?;
    Ok(r)
}

impl Reference {
    /// Parses the text syntax of the [module documentation](super::reference). (Here, beside
    /// the parser, so that the reference's types do not import their parser.)
    pub fn parse(text: &str) -> Result<Reference, RefParseError> {
        parse(text, None)
    }

    /// [`Reference::parse`] on a linear axis whose load shaft travels `metres_per_rad` [m/rad]
    /// (a screw's lead / 2 pi, a belt's radius; `None`: a rotary gear): positions in m (suffix
    /// `m`, `mm`, `um`), speeds in m/s (`mm/s`), accelerations in m/s^2 (`mm/s2`), converted to
    /// the load shaft's equivalent rotation [rad]; a sine's phase stays in rad.
    pub fn parse_on(text: &str, metres_per_rad: Option<f64>) -> Result<Reference, RefParseError> {
        parse(text, metres_per_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::ToString;

    #[test]
    fn parses_the_documented_examples() {
        let r = Reference::parse("step:1.5").unwrap();
        assert_eq!(r, Reference::step(1.5, 0.0));
        let r = Reference::parse("step:90deg@0.5").unwrap();
        assert!((r.at(1.0).pos_rad - math::PI / 2.0).abs() < 1e-15);
        assert_eq!(r.t0_s, 0.5);
        assert_eq!(
            Reference::parse("ramp:speed=2").unwrap().shape,
            Shape::Ramp { speed_rad_s: 2.0 }
        );
        assert_eq!(
            Reference::parse("sine:amp=0.5,freq=1").unwrap().shape,
            Shape::Sine {
                amplitude_rad: 0.5,
                freq_hz: 1.0,
                phase_rad: 0.0
            }
        );
        assert_eq!(
            Reference::parse("chirp:amp=0.2,f0=0.1,f1=20,duration=10")
                .unwrap()
                .shape,
            Shape::Chirp {
                amplitude_rad: 0.2,
                f0_hz: 0.1,
                f1_hz: 20.0,
                duration_s: 10.0,
                mode: ChirpMode::Linear
            }
        );
        assert_eq!(
            Reference::parse("trap:distance=3.0,vmax=10,amax=100")
                .unwrap()
                .shape,
            Shape::Trapezoid {
                distance_rad: 3.0,
                vmax_rad_s: 10.0,
                amax_rad_s2: 100.0
            }
        );
        assert_eq!(
            Reference::parse("square:amp=1,period=2").unwrap().shape,
            Shape::Square {
                amplitude_rad: 1.0,
                period_s: 2.0,
                duty: 0.5
            }
        );
        assert_eq!(
            Reference::parse("prbs:amp=0.5,bit=0.05,seed=1")
                .unwrap()
                .shape,
            Shape::Prbs {
                amplitude_rad: 0.5,
                bit_s: 0.05,
                seed: 1,
                order: 10
            }
        );
    }

    #[test]
    fn units_offsets_and_round_trip() {
        let r = Reference::parse(" ramp : speed = 60rpm , offset=0.5rev, t0=200ms ").unwrap();
        assert!(
            (r.shape
                == Shape::Ramp {
                    speed_rad_s: math::TAU
                })
        );
        assert!((r.offset_rad - math::PI).abs() < 1e-15);
        assert!((r.t0_s - 0.2).abs() < 1e-15);
        let r = Reference::parse("trap:180deg,vmax=90deg/s,amax=1e3deg/s^2").unwrap();
        let Shape::Trapezoid {
            distance_rad,
            vmax_rad_s,
            amax_rad_s2,
        } = r.shape
        else {
            panic!()
        };
        assert!((distance_rad - math::PI).abs() < 1e-15);
        assert!((vmax_rad_s - math::PI / 2.0).abs() < 1e-15);
        assert!((amax_rad_s2 - 1000.0 * math::PI / 180.0).abs() < 1e-12);
        let r = Reference::parse("chirp:0.1,f0=1Hz,f1=10hz,duration=5s,mode=log").unwrap();
        assert!(matches!(
            r.shape,
            Shape::Chirp {
                mode: ChirpMode::Log,
                ..
            }
        ));
        for text in [
            "step:amp=-1.25,offset=0.5@2",
            "sine:amp=0.5,freq=1.5,phase=0.3",
            "chirp:amp=0.2,f0=0.1,f1=20,duration=10,mode=log@1",
            "square:amp=1,period=2,duty=0.25",
            "prbs:amp=0.5,bit=0.05,seed=7,order=9",
            "trap:distance=3.0,vmax=10,amax=100",
        ] {
            let r = Reference::parse(text).unwrap();
            assert_eq!(
                Reference::parse(&r.to_string()).unwrap(),
                r,
                "{text} -> {r}"
            );
        }
    }

    #[test]
    fn lengths_on_a_linear_axis_become_the_equivalent_rotation() {
        // A 5 mm lead screw: s = 0.005 / 2 pi m/rad.
        let s = 0.005 / math::TAU;
        let r = Reference::parse_on("step:10mm@0.5", Some(s)).unwrap();
        assert_eq!(r.t0_s, 0.5);
        match r.shape {
            Shape::Step { amplitude_rad } => {
                assert!((amplitude_rad - 0.01 / s).abs() < 1e-9, "{amplitude_rad}")
            }
            _ => panic!("not a step"),
        }
        let r = Reference::parse_on("trap:0.02,vmax=50mm/s,amax=0.5m/s2", Some(s)).unwrap();
        match r.shape {
            Shape::Trapezoid {
                distance_rad,
                vmax_rad_s,
                amax_rad_s2,
            } => {
                assert!((distance_rad * s - 0.02).abs() < 1e-12);
                assert!((vmax_rad_s * s - 0.05).abs() < 1e-12);
                assert!((amax_rad_s2 * s - 0.5).abs() < 1e-12);
            }
            _ => panic!("not a trapezoid"),
        }
        // A phase stays an angle; an angle unit is refused on a linear axis, with the lengths
        // it takes named.
        let r = Reference::parse_on("sine:amp=1mm,freq=2,phase=0.5", Some(s)).unwrap();
        match r.shape {
            Shape::Sine {
                amplitude_rad,
                phase_rad,
                ..
            } => {
                assert!((amplitude_rad * s - 1e-3).abs() < 1e-12);
                assert_eq!(phase_rad, 0.5);
            }
            _ => panic!("not a sine"),
        }
        let e = Reference::parse_on("step:90deg", Some(s))
            .unwrap_err()
            .to_string();
        assert!(e.contains("mm") && e.contains("linear axis"), "{e}");
        let e = Reference::parse_on("trap:vmax=1,amax=2", Some(s))
            .unwrap_err()
            .to_string();
        assert!(e.contains("(m)"), "{e}");
        // Without an axis nothing changes.
        assert_eq!(
            Reference::parse_on("step:1.5", None).unwrap(),
            Reference::parse("step:1.5").unwrap()
        );
    }

    #[test]
    fn errors_name_the_bad_part() {
        let msg = |t: &str| Reference::parse(t).unwrap_err().to_string();
        assert!(msg("").contains("empty"));
        assert!(msg("stp:1").contains("`stp`"), "{}", msg("stp:1"));
        let m = msg("sine:amp=1,frq=2");
        assert!(m.contains("`frq`") && m.contains("freq"), "{m}");
        let m = msg("sine:amp=1");
        assert!(m.contains("`freq`") && m.contains("Hz"), "{m}");
        let m = msg("step:abc");
        assert!(
            m.contains("`abc`") && m.contains("`amp`") && m.contains("rad"),
            "{m}"
        );
        let m = msg("step:1furlong");
        assert!(m.contains("1furlong"), "{m}");
        assert!(msg("step:1,amp=2").contains("`amp` given twice"));
        assert!(msg("step:1,t0=1@2").contains("`t0` given twice"));
        let m = msg("trap:distance=1,vmax=0,amax=1");
        assert!(m.contains("`vmax`") && m.contains("> 0"), "{m}");
        assert!(msg("square:amp=1,period=1,duty=1.5").contains("`duty`"));
        assert!(msg("prbs:amp=1,bit=0.01,order=40").contains("`order`"));
        assert!(msg("prbs:amp=1,bit=0.01,seed=-3").contains("`seed`"));
        assert!(msg("chirp:amp=1,f0=0,f1=10,duration=1,mode=log").contains("`f0`"));
        assert!(msg("chirp:amp=1,f0=0,f1=10,duration=1,mode=cubic").contains("`linear` or `log`"));
        assert!(msg("step:inf").contains("`amp`"));
        assert!(msg("step:1,2").contains("key=value"));
        assert!(msg("step").contains("needs `amp`"));
    }
}
