//! The messages of the board protocol and their fixed little-endian payload layout.
//!
//! A message body is `[type: u8][payload]`; every field is little-endian, floats are IEEE-754
//! `f32`, and each type has exactly one payload length (a frame of another length is rejected).
//! The byte-by-byte layout is in `docs/protocol.md`; this file is its only implementation.

/// Protocol version spoken by this implementation (exchanged in [`Message::Hello`]).
pub const PROTOCOL_VERSION: u16 = 1;
/// Length of the fixed, NUL-padded firmware name in [`HelloAck`] [bytes].
pub const FIRMWARE_LEN: usize = 16;
/// Length of the fixed, NUL-padded text of a [`Fault`] [bytes].
pub const FAULT_TEXT_LEN: usize = 32;
/// Largest payload of any message [bytes].
pub const MAX_PAYLOAD: usize = 36;

/// Message type bytes. Host to board below 0x80, board to host from 0x80.
pub mod kind {
    pub const HELLO: u8 = 0x01;
    pub const START: u8 = 0x02;
    pub const SET_VOLTAGE: u8 = 0x03;
    pub const STOP: u8 = 0x04;
    pub const LOOP_GAINS: u8 = 0x05;
    pub const LOOP_REFERENCE: u8 = 0x06;
    pub const HELLO_ACK: u8 = 0x81;
    pub const SAMPLE: u8 = 0x82;
    pub const FAULT: u8 = 0x83;
    pub const STOPPED: u8 = 0x84;
    pub const GAINS_ACK: u8 = 0x85;
}

/// Bits of [`Sample::flags`].
pub mod flags {
    /// The command answering the previous sample arrived after the next sample was due (or never).
    pub const MISSED_DEADLINE: u8 = 0x01;
    /// The board runs its on-board PID loop (the host streams references, not voltages).
    pub const ONBOARD_LOOP: u8 = 0x02;
    /// The applied voltage was clipped by the board's voltage limit.
    pub const VOLTAGE_CLIPPED: u8 = 0x04;
}

/// Why the board stopped driving the motor (the `code` of a [`Fault`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum FaultCode {
    /// No voltage command (or reference, in on-board mode) within the watchdog time.
    Watchdog = 1,
    /// Measured current above the trip level.
    OverCurrent = 2,
    /// Load angle outside the soft position limits.
    PositionLimit = 3,
    /// A command that is not valid now (e.g. SetVoltage before Start, a non-finite value).
    BadCommand = 4,
    /// Protocol version mismatch.
    Version = 5,
    /// Anything else (driver fault, internal error).
    Other = 0xFFFF,
}

impl FaultCode {
    /// The code on the wire.
    pub fn to_u16(self) -> u16 {
        self as u16
    }
    /// Known code, or `Other` for an unknown one.
    pub fn from_u16(c: u16) -> FaultCode {
        match c {
            1 => FaultCode::Watchdog,
            2 => FaultCode::OverCurrent,
            3 => FaultCode::PositionLimit,
            4 => FaultCode::BadCommand,
            5 => FaultCode::Version,
            _ => FaultCode::Other,
        }
    }
}

/// Board description, the answer to [`Message::Hello`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HelloAck {
    pub protocol_version: u16,
    /// Firmware name and version, NUL-padded UTF-8.
    pub firmware: [u8; FIRMWARE_LEN],
    /// Encoder counts per load revolution [counts/rev].
    pub counts_per_rev: u32,
    /// Current-sense scale [A per LSB] of [`Sample::current_raw`].
    pub current_scale_a_per_lsb: f32,
    /// Largest |voltage| the board applies [V].
    pub voltage_limit_v: f32,
    /// Control (sample) period [us].
    pub sample_period_us: u32,
    /// Board watchdog: no command for this long means 0 V and a fault [ms].
    pub watchdog_ms: u16,
}

impl HelloAck {
    /// The firmware name as text (up to the first NUL or invalid UTF-8 byte).
    pub fn firmware_str(&self) -> &str {
        text_of(&self.firmware)
    }
}

/// One sample of the board's sensors, sent once per control period while running.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// Tick number since Start (wraps at 2^32).
    pub seq: u32,
    /// Board time of the sample since Start [us] (wraps at 2^32 us, ~71.6 min).
    pub time_us: u32,
    /// Encoder count since Start (signed).
    pub encoder_count: i32,
    /// Armature current in LSB of `current_scale_a_per_lsb` (saturates at the i16 range).
    pub current_raw: i16,
    /// Driver input applied over the previous period, after the board's limit [V].
    pub u_applied_v: f32,
    /// Board-measured round trip of the previous period: from sending sample `seq-1` to receiving
    /// its command [us]; 0xFFFF = no command received (or longer than 65.5 ms).
    pub rtt_us: u16,
    /// [`flags`] bits.
    pub flags: u8,
}

/// A fault report: why the board went to 0 V.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    pub code: FaultCode,
    /// Human-readable text, NUL-padded UTF-8.
    pub text: [u8; FAULT_TEXT_LEN],
}

impl Fault {
    /// A fault with `text` truncated to [`FAULT_TEXT_LEN`] bytes (at a char boundary).
    pub fn new(code: FaultCode, text: &str) -> Fault {
        Fault {
            code,
            text: fixed_text(text),
        }
    }
    /// The text up to the first NUL (or invalid UTF-8 byte).
    pub fn text_str(&self) -> &str {
        text_of(&self.text)
    }
}

/// PID gains for the on-board loop: u = kp e + ki ∫e dt + kd de/dt filtered by a first-order
/// low-pass with time constant `tau_f_s`, e = ref - theta_l.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopGains {
    /// Proportional gain [V/rad].
    pub kp: f32,
    /// Integral gain [V/(rad s)].
    pub ki: f32,
    /// Derivative gain [V s/rad].
    pub kd: f32,
    /// Derivative filter time constant [s].
    pub tau_f_s: f32,
}

/// Every message of the protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// Host → board: open a session; the board answers [`Message::HelloAck`].
    Hello { protocol_version: u16 },
    /// Host → board: reset board time and sequence to 0, arm the watchdog, start sampling.
    Start,
    /// Host → board: hold `u_v` [V] from now on; `seq` is the sample this command answers.
    SetVoltage { seq: u32, u_v: f32 },
    /// Host → board: 0 V now, stop sampling; the board answers [`Message::Stopped`].
    Stop,
    /// Host → board: gains of the on-board PID loop; answered by [`Message::GainsAck`].
    LoopGains(LoopGains),
    /// Host → board: run (or keep running) the on-board loop towards `ref_rad` [rad]; feeds the
    /// watchdog like SetVoltage.
    LoopReference { seq: u32, ref_rad: f32 },
    /// Board → host.
    HelloAck(HelloAck),
    /// Board → host.
    Sample(Sample),
    /// Board → host.
    Fault(Fault),
    /// Board → host: the answer to Stop.
    Stopped,
    /// Board → host: the answer to LoopGains.
    GainsAck,
}

/// Why a message body could not be parsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParseError {
    /// Empty body.
    Empty,
    /// Unknown type byte.
    UnknownType(u8),
    /// Payload length differs from the one of this type.
    BadLength {
        kind: u8,
        expected: usize,
        got: usize,
    },
}

impl core::fmt::Display for ParseError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ParseError::Empty => write!(f, "empty message"),
            ParseError::UnknownType(t) => write!(f, "unknown message type 0x{t:02X}"),
            ParseError::BadLength {
                kind,
                expected,
                got,
            } => {
                write!(
                    f,
                    "message 0x{kind:02X}: payload of {got} bytes, expected {expected}"
                )
            }
        }
    }
}

/// Payload length of each type, `None` for unknown types.
pub fn payload_len(kind: u8) -> Option<usize> {
    Some(match kind {
        kind::HELLO => 2,
        kind::START | kind::STOP | kind::STOPPED | kind::GAINS_ACK => 0,
        kind::SET_VOLTAGE => 8,
        kind::LOOP_GAINS => 16,
        kind::LOOP_REFERENCE => 8,
        kind::HELLO_ACK => 2 + FIRMWARE_LEN + 4 + 4 + 4 + 4 + 2,
        kind::SAMPLE => 4 + 4 + 4 + 2 + 4 + 2 + 1,
        kind::FAULT => 2 + FAULT_TEXT_LEN,
        _ => return None,
    })
}

/// Little-endian writer over a fixed buffer (caller guarantees the size via [`payload_len`]).
struct W<'a> {
    buf: &'a mut [u8],
    at: usize,
}

impl W<'_> {
    fn put(&mut self, bytes: &[u8]) -> Option<()> {
        let end = self.at.checked_add(bytes.len())?;
        self.buf.get_mut(self.at..end)?.copy_from_slice(bytes);
        self.at = end;
        Some(())
    }
}

/// Little-endian reader; the length was checked before, so the `?` never fires in practice.
struct R<'a> {
    buf: &'a [u8],
    at: usize,
}

impl R<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let end = self.at.checked_add(N)?;
        let mut out = [0u8; N];
        out.copy_from_slice(self.buf.get(self.at..end)?);
        self.at = end;
        Some(out)
    }
    fn u8(&mut self) -> Option<u8> {
        Some(self.take::<1>()?[0])
    }
    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes(self.take()?))
    }
    fn i16(&mut self) -> Option<i16> {
        Some(i16::from_le_bytes(self.take()?))
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take()?))
    }
    fn i32(&mut self) -> Option<i32> {
        Some(i32::from_le_bytes(self.take()?))
    }
    fn f32(&mut self) -> Option<f32> {
        Some(f32::from_le_bytes(self.take()?))
    }
}

impl Message {
    /// The type byte.
    pub fn kind(&self) -> u8 {
        match self {
            Message::Hello { .. } => kind::HELLO,
            Message::Start => kind::START,
            Message::SetVoltage { .. } => kind::SET_VOLTAGE,
            Message::Stop => kind::STOP,
            Message::LoopGains(_) => kind::LOOP_GAINS,
            Message::LoopReference { .. } => kind::LOOP_REFERENCE,
            Message::HelloAck(_) => kind::HELLO_ACK,
            Message::Sample(_) => kind::SAMPLE,
            Message::Fault(_) => kind::FAULT,
            Message::Stopped => kind::STOPPED,
            Message::GainsAck => kind::GAINS_ACK,
        }
    }

    /// Writes `[type][payload]` into `out`; returns the body length, `None` if `out` is too small.
    pub fn write_body(&self, out: &mut [u8]) -> Option<usize> {
        let mut w = W { buf: out, at: 0 };
        w.put(&[self.kind()])?;
        match self {
            Message::Hello { protocol_version } => w.put(&protocol_version.to_le_bytes())?,
            Message::Start | Message::Stop | Message::Stopped | Message::GainsAck => {}
            Message::SetVoltage { seq, u_v } => {
                w.put(&seq.to_le_bytes())?;
                w.put(&u_v.to_le_bytes())?;
            }
            Message::LoopGains(g) => {
                for v in [g.kp, g.ki, g.kd, g.tau_f_s] {
                    w.put(&v.to_le_bytes())?;
                }
            }
            Message::LoopReference { seq, ref_rad } => {
                w.put(&seq.to_le_bytes())?;
                w.put(&ref_rad.to_le_bytes())?;
            }
            Message::HelloAck(h) => {
                w.put(&h.protocol_version.to_le_bytes())?;
                w.put(&h.firmware)?;
                w.put(&h.counts_per_rev.to_le_bytes())?;
                w.put(&h.current_scale_a_per_lsb.to_le_bytes())?;
                w.put(&h.voltage_limit_v.to_le_bytes())?;
                w.put(&h.sample_period_us.to_le_bytes())?;
                w.put(&h.watchdog_ms.to_le_bytes())?;
            }
            Message::Sample(s) => {
                w.put(&s.seq.to_le_bytes())?;
                w.put(&s.time_us.to_le_bytes())?;
                w.put(&s.encoder_count.to_le_bytes())?;
                w.put(&s.current_raw.to_le_bytes())?;
                w.put(&s.u_applied_v.to_le_bytes())?;
                w.put(&s.rtt_us.to_le_bytes())?;
                w.put(&[s.flags])?;
            }
            Message::Fault(f) => {
                w.put(&f.code.to_u16().to_le_bytes())?;
                w.put(&f.text)?;
            }
        }
        Some(w.at)
    }

    /// Parses a body `[type][payload]`. Never panics.
    pub fn parse(body: &[u8]) -> Result<Message, ParseError> {
        let (&k, payload) = body.split_first().ok_or(ParseError::Empty)?;
        let expected = payload_len(k).ok_or(ParseError::UnknownType(k))?;
        if payload.len() != expected {
            return Err(ParseError::BadLength {
                kind: k,
                expected,
                got: payload.len(),
            });
        }
        let bad = ParseError::BadLength {
            kind: k,
            expected,
            got: payload.len(),
        };
        Self::parse_payload(k, payload).ok_or(bad)
    }

    fn parse_payload(k: u8, payload: &[u8]) -> Option<Message> {
        let mut r = R {
            buf: payload,
            at: 0,
        };
        Some(match k {
            kind::HELLO => Message::Hello {
                protocol_version: r.u16()?,
            },
            kind::START => Message::Start,
            kind::STOP => Message::Stop,
            kind::STOPPED => Message::Stopped,
            kind::GAINS_ACK => Message::GainsAck,
            kind::SET_VOLTAGE => Message::SetVoltage {
                seq: r.u32()?,
                u_v: r.f32()?,
            },
            kind::LOOP_GAINS => Message::LoopGains(LoopGains {
                kp: r.f32()?,
                ki: r.f32()?,
                kd: r.f32()?,
                tau_f_s: r.f32()?,
            }),
            kind::LOOP_REFERENCE => Message::LoopReference {
                seq: r.u32()?,
                ref_rad: r.f32()?,
            },
            kind::HELLO_ACK => Message::HelloAck(HelloAck {
                protocol_version: r.u16()?,
                firmware: r.take()?,
                counts_per_rev: r.u32()?,
                current_scale_a_per_lsb: r.f32()?,
                voltage_limit_v: r.f32()?,
                sample_period_us: r.u32()?,
                watchdog_ms: r.u16()?,
            }),
            kind::SAMPLE => Message::Sample(Sample {
                seq: r.u32()?,
                time_us: r.u32()?,
                encoder_count: r.i32()?,
                current_raw: r.i16()?,
                u_applied_v: r.f32()?,
                rtt_us: r.u16()?,
                flags: r.u8()?,
            }),
            kind::FAULT => Message::Fault(Fault {
                code: FaultCode::from_u16(r.u16()?),
                text: r.take()?,
            }),
            _ => return None,
        })
    }
}

/// `buf` up to its first NUL, as UTF-8 (truncated at the first invalid byte).
fn text_of(buf: &[u8]) -> &str {
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    let bytes = &buf[..end];
    match core::str::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => core::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or(""),
    }
}

/// `text` NUL-padded into a fixed buffer (truncated at a char boundary).
pub fn fixed_text<const N: usize>(text: &str) -> [u8; N] {
    let mut buf = [0u8; N];
    let mut n = text.len().min(N);
    while n > 0 && !text.is_char_boundary(n) {
        n -= 1;
    }
    buf[..n].copy_from_slice(&text.as_bytes()[..n]);
    buf
}

impl From<crate::safety::Trip> for FaultCode {
    fn from(t: crate::safety::Trip) -> FaultCode {
        match t {
            crate::safety::Trip::OverCurrent { .. } => FaultCode::OverCurrent,
            crate::safety::Trip::PositionLimit { .. } => FaultCode::PositionLimit,
            crate::safety::Trip::NonFinite => FaultCode::Other,
        }
    }
}
