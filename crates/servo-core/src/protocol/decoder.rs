//! Streaming frame decoder: bytes in, messages out, resynchronising on the next 0x00 after
//! garbage. Fixed buffer, no allocation, never panics.

use super::cobs;
use super::crc::crc16;
use super::frame::{MAX_BODY, MAX_ENCODED};
use super::message::{Message, ParseError};

/// Why a frame was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// More than [`MAX_ENCODED`] bytes before a delimiter (garbage or a lost delimiter).
    TooLong,
    /// Not valid COBS.
    Cobs,
    /// Shorter than a type byte and a CRC.
    TooShort,
    /// CRC mismatch: the frame was corrupted.
    Crc { expected: u16, got: u16 },
    /// Good CRC but not a valid message.
    Parse(ParseError),
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FrameError::TooLong => write!(f, "frame longer than {MAX_ENCODED} bytes"),
            FrameError::Cobs => write!(f, "invalid COBS encoding"),
            FrameError::TooShort => write!(f, "frame too short"),
            FrameError::Crc { expected, got } => {
                write!(
                    f,
                    "CRC mismatch: computed 0x{expected:04X}, frame says 0x{got:04X}"
                )
            }
            FrameError::Parse(e) => write!(f, "{e}"),
        }
    }
}

/// Counters of a [`Decoder`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecoderStats {
    /// Frames decoded into a message.
    pub frames_ok: u64,
    /// Frames rejected by the CRC.
    pub crc_errors: u64,
    /// Frames rejected for COBS, length or parse errors.
    pub framing_errors: u64,
    /// Bytes received (delimiters included).
    pub bytes: u64,
}

/// The streaming decoder.
#[derive(Debug, Clone)]
pub struct Decoder {
    buf: [u8; MAX_ENCODED],
    len: usize,
    overflow: bool,
    stats: DecoderStats,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Decoder {
    pub const fn new() -> Decoder {
        Decoder {
            buf: [0; MAX_ENCODED],
            len: 0,
            overflow: false,
            stats: DecoderStats {
                frames_ok: 0,
                crc_errors: 0,
                framing_errors: 0,
                bytes: 0,
            },
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Drops any partial frame (e.g. after reopening a port).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    /// Feeds one byte; returns a result when the byte completes a frame. Empty frames (two
    /// delimiters in a row) are skipped silently.
    pub fn push(&mut self, byte: u8) -> Option<Result<Message, FrameError>> {
        self.stats.bytes += 1;
        if byte != 0 {
            if self.len < MAX_ENCODED {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.reset();
        if len == 0 && !overflow {
            return None;
        }
        let r = if overflow {
            Err(FrameError::TooLong)
        } else {
            Self::decode_block(&self.buf[..len])
        };
        match r {
            Ok(_) => self.stats.frames_ok += 1,
            Err(FrameError::Crc { .. }) => self.stats.crc_errors += 1,
            Err(_) => self.stats.framing_errors += 1,
        }
        Some(r)
    }

    /// Feeds `bytes`, calling `on_frame` for every completed frame; returns the bytes consumed
    /// (always all of them).
    pub fn feed(
        &mut self,
        bytes: &[u8],
        mut on_frame: impl FnMut(Result<Message, FrameError>),
    ) -> usize {
        for &b in bytes {
            if let Some(r) = self.push(b) {
                on_frame(r);
            }
        }
        bytes.len()
    }

    /// Decodes one COBS block (no delimiter) into a message.
    pub fn decode_block(block: &[u8]) -> Result<Message, FrameError> {
        let mut body = [0u8; MAX_BODY];
        let n = cobs::decode(block, &mut body).ok_or(FrameError::Cobs)?;
        if n < 3 {
            return Err(FrameError::TooShort);
        }
        let (data, crc) = body[..n].split_at(n - 2);
        let got = u16::from_le_bytes([crc[0], crc[1]]);
        let expected = crc16(data);
        if got != expected {
            return Err(FrameError::Crc { expected, got });
        }
        Message::parse(data).map_err(FrameError::Parse)
    }
}
