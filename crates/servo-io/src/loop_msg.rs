//! The `/servo/loop` message: one per control sample, JSON with a JSON schema (units in the field
//! names and in the schema descriptions) so Foxglove and PlotJuggler plot it directly.

use serde::{Deserialize, Serialize};

/// Topic of the per-sample loop message.
pub const LOOP_TOPIC: &str = "/servo/loop";
/// Schema name of [`LoopMsg`].
pub const LOOP_SCHEMA_NAME: &str = "servo.Loop";

/// One control sample. Row convention: measurements taken at `time_s`, the drive's command
/// (`u_v` on a voltage drive, `i_ref_a` on a current drive, `duty` on a PWM bridge) applied from
/// then until the next sample. Fields that do not apply (no reference in an open-loop run, the
/// other drives' commands) or were not measured are null (NaN in memory); a foreign writer may
/// also leave them out (read as null).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LoopMsg {
    /// Run time of the sample [s].
    pub time_s: f64,
    /// Position reference at the load [rad] (null in open loop).
    #[serde(with = "nullable", default = "nullable::absent")]
    pub ref_rad: f64,
    /// Measured load angle theta_l [rad].
    #[serde(with = "nullable", default = "nullable::absent")]
    pub theta_l_rad: f64,
    /// Load speed estimate omega_l [rad/s].
    #[serde(with = "nullable", default = "nullable::absent")]
    pub omega_l_rad_s: f64,
    /// Tracking error ref - theta_l [rad] (null in open loop).
    #[serde(with = "nullable", default = "nullable::absent")]
    pub err_rad: f64,
    /// Driver input u applied until the next sample [V], after the output limit (null on a
    /// current or duty drive: see `i_ref_a`, `duty`).
    #[serde(with = "nullable", default = "nullable::absent")]
    pub u_v: f64,
    /// Feedforward part of the controller's output [V] (in the drive's equivalent chain: A on
    /// a current drive, the bridge's effective volts on a duty drive; so are `p_v`, `i_v`, `d_v`).
    #[serde(with = "nullable", default = "nullable::absent")]
    pub ff_v: f64,
    /// Proportional term [V].
    #[serde(with = "nullable", default = "nullable::absent")]
    pub p_v: f64,
    /// Integral term [V].
    #[serde(with = "nullable", default = "nullable::absent")]
    pub i_v: f64,
    /// Derivative term [V].
    #[serde(with = "nullable", default = "nullable::absent")]
    pub d_v: f64,
    /// Measured armature current i_a [A].
    #[serde(with = "nullable", default = "nullable::absent")]
    pub i_a_a: f64,
    /// True when the controller output was clipped at the voltage limit (false when absent).
    #[serde(default)]
    pub saturated: bool,
    /// Speed reference at the load [rad/s] of a speed-controlled run (the identification
    /// staircase and ramps); null otherwise.
    #[serde(with = "nullable", default = "nullable::absent")]
    pub ref_omega_l_rad_s: f64,
    /// Current reference i_ref sent to a current (torque) drive until the next sample [A];
    /// null on other drives, and then left out of the message.
    #[serde(
        with = "nullable",
        default = "nullable::absent",
        skip_serializing_if = "nullable::is_null"
    )]
    pub i_ref_a: f64,
    /// Duty cycle in [-1, 1] sent to a PWM bridge or smart servo until the next sample; null on
    /// other drives, and then left out of the message.
    #[serde(
        with = "nullable",
        default = "nullable::absent",
        skip_serializing_if = "nullable::is_null"
    )]
    pub duty: f64,
}

impl LoopMsg {
    /// Appends the message as JSON to `out`: the same JSON value serde_json writes (shortest
    /// round-trip numbers, non-finite as null), by hand because it is the log's hot path.
    pub fn write_json(&self, out: &mut Vec<u8>) {
        let mut b = ryu::Buffer::new();
        let mut num = |out: &mut Vec<u8>, key: &[u8], v: f64| {
            out.extend_from_slice(key);
            if v.is_finite() {
                out.extend_from_slice(b.format_finite(v).as_bytes());
            } else {
                out.extend_from_slice(b"null");
            }
        };
        num(out, b"{\"time_s\":", self.time_s);
        num(out, b",\"ref_rad\":", self.ref_rad);
        num(out, b",\"theta_l_rad\":", self.theta_l_rad);
        num(out, b",\"omega_l_rad_s\":", self.omega_l_rad_s);
        num(out, b",\"err_rad\":", self.err_rad);
        num(out, b",\"u_v\":", self.u_v);
        num(out, b",\"ff_v\":", self.ff_v);
        num(out, b",\"p_v\":", self.p_v);
        num(out, b",\"i_v\":", self.i_v);
        num(out, b",\"d_v\":", self.d_v);
        num(out, b",\"i_a_a\":", self.i_a_a);
        out.extend_from_slice(if self.saturated {
            b",\"saturated\":true"
        } else {
            b",\"saturated\":false"
        });
        num(out, b",\"ref_omega_l_rad_s\":", self.ref_omega_l_rad_s);
        if self.i_ref_a.is_finite() {
            num(out, b",\"i_ref_a\":", self.i_ref_a);
        }
        if self.duty.is_finite() {
            num(out, b",\"duty\":", self.duty);
        }
        out.push(b'}');
    }
}

/// Fully qualified protobuf name of [`LoopMsg`] (package `servo`, message `Loop`): the MCAP
/// schema name of a protobuf-encoded log.
pub const LOOP_PROTO_NAME: &str = "servo.Loop";

/// The numeric fields of the protobuf message, in field-number order (1..=11); field 12 is
/// `saturated` (bool), field 13 `ref_omega_l_rad_s` (double). Every one of them is written, NaN
/// where a value does not apply. Fields 14 `i_ref_a` and 15 `duty` (double: a current drive's
/// reference, a duty drive's command) are written only when they hold a value, so that a
/// voltage drive's log is byte for byte what it was before they existed.
const PROTO_F64_FIELDS: [&str; 11] = [
    "time_s",
    "ref_rad",
    "theta_l_rad",
    "omega_l_rad_s",
    "err_rad",
    "u_v",
    "ff_v",
    "p_v",
    "i_v",
    "d_v",
    "i_a_a",
];

fn pb_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn pb_bytes(out: &mut Vec<u8>, field: u64, bytes: &[u8]) {
    pb_varint(out, field << 3 | 2);
    pb_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

fn pb_read_varint(b: &[u8], at: &mut usize) -> Result<u64, String> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let Some(&x) = b.get(*at) else {
            return Err("varint cut short".into());
        };
        *at += 1;
        v |= u64::from(x & 0x7f) << shift;
        if x < 0x80 {
            return Ok(v);
        }
    }
    Err("varint longer than 10 bytes".into())
}

/// The protobuf schema of [`LoopMsg`] as a serialized `google.protobuf.FileDescriptorSet`
/// (file `servo/loop.proto`, proto3, message `servo.Loop`), the MCAP schema data Foxglove and
/// PlotJuggler expect for `protobuf` channels.
pub fn loop_descriptor_set() -> Vec<u8> {
    // FieldDescriptorProto: name = 1, number = 3, label = 4 (1: optional), type = 5
    // (1: double, 8: bool), json_name = 10.
    let field = |name: &str, number: u64, ty: u64| {
        let mut f = Vec::new();
        pb_bytes(&mut f, 1, name.as_bytes());
        pb_varint(&mut f, 3 << 3);
        pb_varint(&mut f, number);
        pb_varint(&mut f, 4 << 3);
        pb_varint(&mut f, 1);
        pb_varint(&mut f, 5 << 3);
        pb_varint(&mut f, ty);
        pb_bytes(&mut f, 10, name.as_bytes());
        f
    };
    // DescriptorProto: name = 1, field = 2.
    let mut msg = Vec::new();
    pb_bytes(&mut msg, 1, b"Loop");
    for (i, name) in PROTO_F64_FIELDS.iter().enumerate() {
        pb_bytes(&mut msg, 2, &field(name, i as u64 + 1, 1));
    }
    pb_bytes(&mut msg, 2, &field("saturated", 12, 8));
    pb_bytes(&mut msg, 2, &field("ref_omega_l_rad_s", 13, 1));
    pb_bytes(&mut msg, 2, &field("i_ref_a", 14, 1));
    pb_bytes(&mut msg, 2, &field("duty", 15, 1));
    // FileDescriptorProto: name = 1, package = 2, message_type = 4, syntax = 12.
    let mut file = Vec::new();
    pb_bytes(&mut file, 1, b"servo/loop.proto");
    pb_bytes(&mut file, 2, b"servo");
    pb_bytes(&mut file, 4, &msg);
    pb_bytes(&mut file, 12, b"proto3");
    // FileDescriptorSet: file = 1.
    let mut set = Vec::new();
    pb_bytes(&mut set, 1, &file);
    set
}

/// Bytes of a message as [`LoopMsg::write_protobuf`] writes it (a voltage drive's: fields 1-13;
/// 9 more for each of fields 14 and 15 that holds a value).
pub const PROTOBUF_LEN: usize = 110;

/// Reads one field of a message.
type Field = fn(&LoopMsg) -> f64;

/// The optional doubles after field 13: (field number, getter).
const PROTO_OPTIONAL: [(u8, Field); 2] = [(14, |m| m.i_ref_a), (15, |m| m.duty)];

impl LoopMsg {
    fn f64_fields(&self) -> [f64; 11] {
        [
            self.time_s,
            self.ref_rad,
            self.theta_l_rad,
            self.omega_l_rad_s,
            self.err_rad,
            self.u_v,
            self.ff_v,
            self.p_v,
            self.i_v,
            self.d_v,
            self.i_a_a,
        ]
    }

    /// The message of fields 1-11 in the order of [`LoopMsg::f64_fields`], field 12 and 13.
    fn from_f64_fields(v: [f64; 11], saturated: bool, ref_omega_l_rad_s: f64) -> LoopMsg {
        LoopMsg {
            time_s: v[0],
            ref_rad: v[1],
            theta_l_rad: v[2],
            omega_l_rad_s: v[3],
            err_rad: v[4],
            u_v: v[5],
            ff_v: v[6],
            p_v: v[7],
            i_v: v[8],
            d_v: v[9],
            i_a_a: v[10],
            saturated,
            ref_omega_l_rad_s,
            i_ref_a: f64::NAN,
            duty: f64::NAN,
        }
    }

    /// Sets optional field `field` (14 or 15) to `v`; other fields are ignored.
    fn set_optional(&mut self, field: u64, v: f64) {
        match field {
            14 => self.i_ref_a = v,
            15 => self.duty = v,
            _ => {}
        }
    }

    /// Appends the message in protobuf wire format (`servo.Loop`, [`loop_descriptor_set`]):
    /// fields 1-11 and 13 as 64-bit doubles, 12 as a bool (110 bytes), then 14 and 15 when they
    /// hold a value; no number formatting.
    pub fn write_protobuf(&self, out: &mut Vec<u8>) {
        // Laid out on the stack and appended at once: the log's hot path.
        let mut b = [0u8; PROTOBUF_LEN];
        for (i, v) in self.f64_fields().into_iter().enumerate() {
            b[9 * i] = ((i as u8 + 1) << 3) | 1;
            b[9 * i + 1..9 * i + 9].copy_from_slice(&v.to_le_bytes());
        }
        b[99] = 12 << 3;
        b[100] = self.saturated as u8;
        b[101] = (13 << 3) | 1;
        b[102..110].copy_from_slice(&self.ref_omega_l_rad_s.to_le_bytes());
        out.extend_from_slice(&b);
        for (field, get) in PROTO_OPTIONAL {
            let v = get(self);
            if v.is_finite() {
                out.push((field << 3) | 1);
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }

    /// The message exactly as [`LoopMsg::write_protobuf`] lays it out (the fast path of the
    /// reader); `None` for any other layout, which the general parser reads.
    fn from_protobuf_as_written(b: &[u8]) -> Option<LoopMsg> {
        // 101 bytes: fields 1-12 (logs written before field 13 existed); 110: with field 13;
        // 119 or 128: with one or both of the optional fields 14 and 15.
        if !matches!(b.len(), 101 | 110 | 119 | 128) || b[99] != 12 << 3 || b[100] > 1 {
            return None;
        }
        let ref_omega_l_rad_s = if b.len() >= 110 {
            if b[101] != (13 << 3) | 1 {
                return None;
            }
            let mut a = [0u8; 8];
            a.copy_from_slice(&b[102..110]);
            f64::from_le_bytes(a)
        } else {
            f64::NAN
        };
        let mut v = [0.0f64; 11];
        for (i, x) in v.iter_mut().enumerate() {
            let at = 9 * i;
            if b[at] != ((i as u8 + 1) << 3) | 1 {
                return None;
            }
            let mut a = [0u8; 8];
            a.copy_from_slice(&b[at + 1..at + 9]);
            *x = f64::from_le_bytes(a);
        }
        let mut m = Self::from_f64_fields(v, b[100] == 1, ref_omega_l_rad_s);
        for extra in b.get(110..).unwrap_or_default().chunks(9) {
            let (key, x) = extra.split_first()?;
            let field = u64::from(key >> 3);
            if key & 7 != 1 || !(14..=15).contains(&field) {
                return None;
            }
            let mut a = [0u8; 8];
            a.copy_from_slice(x);
            m.set_optional(field, f64::from_le_bytes(a));
        }
        Some(m)
    }

    /// Parses a protobuf `servo.Loop` message (fields absent from the bytes take proto3's
    /// default, 0, except `ref_omega_l_rad_s`, which logs written before it existed lack: null;
    /// unknown fields are skipped).
    pub fn from_protobuf(b: &[u8]) -> Result<LoopMsg, String> {
        if let Some(m) = Self::from_protobuf_as_written(b) {
            return Ok(m);
        }
        let mut v = [0.0f64; 11];
        let mut ref_omega = f64::NAN;
        let mut optional: [(u64, f64); 2] = [(14, f64::NAN), (15, f64::NAN)];
        let mut saturated = false;
        let mut at = 0usize;
        while at < b.len() {
            let key = pb_read_varint(b, &mut at)?;
            let (field, wire) = (key >> 3, key & 7);
            match wire {
                1 => {
                    let Some(x) = b.get(at..at + 8) else {
                        return Err(format!("field {field}: 64-bit value cut short"));
                    };
                    at += 8;
                    let mut a = [0u8; 8];
                    a.copy_from_slice(x);
                    if (1..=11).contains(&field) {
                        v[field as usize - 1] = f64::from_le_bytes(a);
                    } else if field == 13 {
                        ref_omega = f64::from_le_bytes(a);
                    } else if let Some(o) = optional.iter_mut().find(|o| o.0 == field) {
                        o.1 = f64::from_le_bytes(a);
                    }
                }
                0 => {
                    let x = pb_read_varint(b, &mut at)?;
                    if field == 12 {
                        saturated = x != 0;
                    }
                }
                2 => {
                    let n = pb_read_varint(b, &mut at)?;
                    let n = usize::try_from(n).unwrap_or(usize::MAX);
                    if n > b.len() - at {
                        return Err(format!("field {field}: length {n} beyond the message"));
                    }
                    at += n;
                }
                5 => {
                    if b.len() - at < 4 {
                        return Err(format!("field {field}: 32-bit value cut short"));
                    }
                    at += 4;
                }
                w => return Err(format!("field {field}: unsupported wire type {w}")),
            }
        }
        let mut m = Self::from_f64_fields(v, saturated, ref_omega);
        for (field, x) in optional {
            m.set_optional(field, x);
        }
        Ok(m)
    }
}

/// JSON schema of [`LoopMsg`] (draft 2020-12, as Foxglove reads it).
pub fn loop_schema() -> String {
    let num = |d: &str| serde_json::json!({ "type": ["number", "null"], "description": d });

    serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": LOOP_SCHEMA_NAME,
        "description": "servo position loop, one message per control sample: measurements taken at time_s, u_v applied from then until the next sample",
        "type": "object",
        "properties": {
            "time_s": { "type": "number", "description": "run time of the sample [s]" },
            "ref_rad": num("position reference at the load [rad] (null in open loop)"),
            "theta_l_rad": num("measured load angle theta_l [rad]"),
            "omega_l_rad_s": num("load speed estimate omega_l [rad/s]"),
            "err_rad": num("tracking error ref - theta_l [rad] (null in open loop)"),
            "u_v": num("driver input voltage u applied until the next sample [V] (after the limit; null on a current or duty drive)"),
            "ff_v": num("feedforward part of the controller's output [V] (A on a current drive; the bridge's effective volts on a duty drive; so are the PID terms)"),
            "p_v": num("PID proportional term [V]"),
            "i_v": num("PID integral term [V]"),
            "d_v": num("PID derivative term [V]"),
            "i_a_a": num("measured armature current i_a [A]"),
            "saturated": { "type": "boolean", "description": "controller output clipped at the voltage limit" },
            "ref_omega_l_rad_s": num("speed reference at the load [rad/s] of a speed-controlled run (identification staircase and ramps; null otherwise)"),
            "i_ref_a": num("current reference i_ref sent to a current (torque) drive until the next sample [A] (left out on other drives)"),
            "duty": num("duty cycle in [-1, 1] sent to a PWM bridge or smart servo until the next sample (left out on other drives)")
        },
        // Only the time is required: every other field may be null or left out (a foreign log
        // without a current sensor, an open-loop run), and the reader takes it as missing.
        "required": ["time_s"]
    })
    .to_string()
}

/// NaN <-> JSON null for optional numbers (JSON has no NaN).
mod nullable {
    use serde::{Deserialize, Deserializer, Serializer};
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else {
            s.serialize_none()
        }
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
    /// A field left out: null.
    pub fn absent() -> f64 {
        f64::NAN
    }
    /// True when the value is null (not finite): an optional field is then left out.
    pub fn is_null(v: &f64) -> bool {
        !v.is_finite()
    }
}

/// Sample `k` of a made-up 1 kHz run for the log tests: every field different from message to
/// message, NaN where a value does not apply (no reference for k < 3, no speed reference up
/// to k = 900), `saturated` every 7th.
#[cfg(test)]
pub(crate) fn test_msg(k: usize) -> LoopMsg {
    let t = k as f64 * 1e-3;
    LoopMsg {
        time_s: t,
        ref_rad: if k < 3 { f64::NAN } else { 1.5 },
        theta_l_rad: (t * 7.0).sin() / 3.0,
        omega_l_rad_s: (t * 7.0).cos() * 7.0 / 3.0,
        err_rad: 1.5 - (t * 7.0).sin() / 3.0,
        u_v: (k as f64 * 0.37).sin() * 10.0,
        ff_v: 0.1,
        p_v: 1.0 / (k as f64 + 1.0),
        i_v: -0.25,
        d_v: 1e-9 * k as f64,
        i_a_a: 0.01 * k as f64,
        saturated: k.is_multiple_of(7),
        ref_omega_l_rad_s: if k > 900 { 2.5 } else { f64::NAN },
        i_ref_a: if k.is_multiple_of(3) {
            0.002 * k as f64
        } else {
            f64::NAN
        },
        duty: if k.is_multiple_of(4) { -0.5 } else { f64::NAN },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_round_trip_and_schema() {
        let m = LoopMsg {
            time_s: 0.123,
            ref_rad: f64::NAN,
            theta_l_rad: 1.0 / 3.0,
            omega_l_rad_s: -2.0,
            err_rad: f64::NAN,
            u_v: 9.999999999,
            ff_v: 0.0,
            p_v: 1e-300,
            i_v: -0.5,
            d_v: 0.25,
            i_a_a: 0.1,
            saturated: true,
            ref_omega_l_rad_s: 12.5,
            i_ref_a: f64::NAN,
            duty: -0.75,
        };
        let s = serde_json::to_string(&m).unwrap();
        assert!(
            !s.contains("i_ref_a") && s.contains("\"duty\":-0.75"),
            "{s}"
        );
        assert!(s.contains("\"ref_rad\":null"), "{s}");
        let b: LoopMsg = serde_json::from_str(&s).unwrap();
        assert!(b.ref_rad.is_nan() && b.err_rad.is_nan());
        assert_eq!(
            (b.time_s, b.theta_l_rad, b.u_v, b.p_v),
            (m.time_s, m.theta_l_rad, m.u_v, m.p_v)
        );
        // The hand-written encoder writes exactly serde's text.
        for v in [
            0.0,
            -0.0,
            1.0,
            1e-300,
            -2.5e300,
            0.1 + 0.2,
            f64::NAN,
            f64::INFINITY,
            123456789.0,
        ] {
            let x = LoopMsg {
                time_s: v,
                ref_rad: v,
                u_v: -v,
                ref_omega_l_rad_s: v,
                saturated: v > 0.5,
                i_ref_a: v,
                duty: -v,
                ..m
            };
            let mut out = Vec::new();
            x.write_json(&mut out);
            // The same JSON value as serde's (serde writes `2.5e+300` where ryu writes
            // `2.5e300`; both parse to the same number).
            let ours: serde_json::Value = serde_json::from_slice(&out).unwrap();
            let theirs = serde_json::to_value(x).unwrap();
            assert_eq!(ours, theirs, "{}", String::from_utf8_lossy(&out));
        }
        // Protobuf: exact round trip, NaN included; the optional fields only when set (a
        // voltage drive's message is 110 bytes, as before they existed).
        for (i_ref_a, duty, len) in [
            (f64::NAN, f64::NAN, 110),
            (1.5, f64::NAN, 119),
            (f64::NAN, -0.25, 119),
            (1.5, -0.25, 128),
        ] {
            let x = LoopMsg { i_ref_a, duty, ..m };
            let mut pb = Vec::new();
            x.write_protobuf(&mut pb);
            assert_eq!(pb.len(), len);
            let back = LoopMsg::from_protobuf(&pb).unwrap();
            assert_eq!(
                back.f64_fields().map(f64::to_bits),
                x.f64_fields().map(f64::to_bits)
            );
            assert_eq!(
                [back.i_ref_a, back.duty].map(f64::to_bits),
                [i_ref_a, duty].map(f64::to_bits)
            );
            assert_eq!(back.ref_omega_l_rad_s, 12.5);
            // The general parser reads the same (the optional fields moved to the front).
            let mut moved = pb[110..].to_vec();
            moved.extend_from_slice(&pb[..110]);
            let back = LoopMsg::from_protobuf(&moved).unwrap();
            assert_eq!(
                [back.i_ref_a, back.duty].map(f64::to_bits),
                [i_ref_a, duty].map(f64::to_bits)
            );
        }
        let m = LoopMsg {
            duty: f64::NAN,
            ..m
        };
        let mut pb = Vec::new();
        m.write_protobuf(&mut pb);
        assert_eq!(pb.len(), 110);
        let back = LoopMsg::from_protobuf(&pb).unwrap();
        assert_eq!(
            back.f64_fields().map(f64::to_bits),
            m.f64_fields().map(f64::to_bits)
        );
        assert_eq!(back.saturated, m.saturated);
        assert_eq!(back.ref_omega_l_rad_s, 12.5);
        // A message written before field 13 existed: no speed reference (null).
        assert!(LoopMsg::from_protobuf(&pb[..101])
            .unwrap()
            .ref_omega_l_rad_s
            .is_nan());
        assert!(LoopMsg::from_protobuf(&pb[..50]).is_err());
        // The same message with its fields in another order takes the general path.
        let mut shuffled = pb[9..99].to_vec();
        shuffled.extend_from_slice(&pb[..9]);
        shuffled.extend_from_slice(&pb[99..]);
        let back2 = LoopMsg::from_protobuf(&shuffled).unwrap();
        assert_eq!(
            back2.f64_fields().map(f64::to_bits),
            m.f64_fields().map(f64::to_bits)
        );
        let d = loop_descriptor_set();
        assert!(d.windows(4).any(|w| w == b"Loop"));
        let schema: serde_json::Value = serde_json::from_str(&loop_schema()).unwrap();
        let props = schema["properties"].as_object().unwrap();
        for k in serde_json::from_str::<serde_json::Value>(&s)
            .unwrap()
            .as_object()
            .unwrap()
            .keys()
        {
            assert!(props.contains_key(k), "schema lacks {k}");
        }
    }

    /// The MCAP schema of a protobuf log is what Foxglove and PlotJuggler decode: a serialized
    /// `google.protobuf.FileDescriptorSet` (decoded here by prost-types, an independent
    /// implementation) holding `servo/loop.proto`, package `servo`, message `Loop` with the
    /// JSON log's field names, 1-11 and 13 double, 12 bool; a message written by servo decodes
    /// against it field by field.
    #[test]
    fn protobuf_schema_is_a_file_descriptor_set() {
        use prost::Message;
        use prost_types::field_descriptor_proto::{Label, Type};
        let set = prost_types::FileDescriptorSet::decode(loop_descriptor_set().as_slice())
            .expect("a valid FileDescriptorSet");
        assert_eq!(set.file.len(), 1);
        let file = &set.file[0];
        assert_eq!(file.name(), "servo/loop.proto");
        assert_eq!(file.package(), "servo");
        assert_eq!(file.syntax(), "proto3");
        assert_eq!(file.message_type.len(), 1);
        let msg = &file.message_type[0];
        assert_eq!(
            format!("{}.{}", file.package(), msg.name()),
            LOOP_PROTO_NAME
        );
        let names: Vec<&str> = msg.field.iter().map(|f| f.name()).collect();
        let mut expected: Vec<&str> = PROTO_F64_FIELDS.to_vec();
        expected.extend(["saturated", "ref_omega_l_rad_s", "i_ref_a", "duty"]);
        assert_eq!(names, expected);
        for (i, f) in msg.field.iter().enumerate() {
            assert_eq!(f.number(), i as i32 + 1, "{}", f.name());
            assert_eq!(f.label(), Label::Optional, "{}", f.name());
            assert_eq!(f.json_name(), f.name());
            let ty = if i == 11 { Type::Bool } else { Type::Double };
            assert_eq!(f.r#type(), ty, "{}", f.name());
        }
        // The JSON log names the same fields.
        let schema: serde_json::Value = serde_json::from_str(&loop_schema()).unwrap();
        for n in &names {
            assert!(schema["properties"].get(*n).is_some(), "{n}");
        }
        // A message as servo writes it, decoded by prost as the generic wire format: field k
        // holds the k-th value.
        #[derive(Clone, PartialEq, prost::Message)]
        struct Loop {
            #[prost(double, tag = "1")]
            time_s: f64,
            #[prost(double, tag = "3")]
            theta_l_rad: f64,
            #[prost(double, tag = "6")]
            u_v: f64,
            #[prost(double, tag = "11")]
            i_a_a: f64,
            #[prost(bool, tag = "12")]
            saturated: bool,
            #[prost(double, tag = "13")]
            ref_omega_l_rad_s: f64,
            #[prost(double, tag = "14")]
            i_ref_a: f64,
        }
        let m = LoopMsg {
            time_s: 1.25,
            ref_rad: 0.5,
            theta_l_rad: -0.125,
            omega_l_rad_s: 3.0,
            err_rad: 0.625,
            u_v: 9.5,
            ff_v: 0.0,
            p_v: 1.0,
            i_v: 2.0,
            d_v: 3.0,
            i_a_a: 0.0625,
            saturated: true,
            ref_omega_l_rad_s: 12.5,
            i_ref_a: 0.75,
            duty: f64::NAN,
        };
        let mut pb = Vec::new();
        m.write_protobuf(&mut pb);
        let d = Loop::decode(pb.as_slice()).unwrap();
        assert_eq!(d.i_ref_a, 0.75);
        assert_eq!(
            (
                d.time_s,
                d.theta_l_rad,
                d.u_v,
                d.i_a_a,
                d.saturated,
                d.ref_omega_l_rad_s
            ),
            (1.25, -0.125, 9.5, 0.0625, true, 12.5)
        );
    }

    #[test]
    fn nullable_fields_may_be_absent() {
        // A foreign writer that logs only what it measured.
        let m: LoopMsg =
            serde_json::from_str(r#"{"time_s":0.5,"theta_l_rad":1.25,"u_v":null}"#).unwrap();
        assert_eq!((m.time_s, m.theta_l_rad, m.saturated), (0.5, 1.25, false));
        assert!(
            m.omega_l_rad_s.is_nan() && m.u_v.is_nan() && m.i_a_a.is_nan() && m.ref_rad.is_nan()
        );
        let e = serde_json::from_str::<LoopMsg>(r#"{"theta_l_rad":1.0}"#).unwrap_err();
        assert!(e.to_string().contains("time_s"), "{e}");
    }
}
