//! Framing: `COBS([type][payload][crc16 LE]) 0x00`.
//!
//! The CRC-16/CCITT-FALSE ([`super::crc::crc16`]) covers the type byte and the payload and is
//! appended little-endian before COBS encoding. 0x00 appears on the wire only as the delimiter.

use super::cobs;
use super::crc::crc16;
use super::message::{Message, MAX_PAYLOAD};

/// Largest body: type byte, payload, CRC [bytes].
pub const MAX_BODY: usize = 1 + MAX_PAYLOAD + 2;
/// Largest COBS-encoded body, without the delimiter [bytes].
pub const MAX_ENCODED: usize = cobs::max_encoded_len(MAX_BODY);
/// Largest frame on the wire, delimiter included [bytes].
pub const MAX_FRAME: usize = MAX_ENCODED + 1;

/// Encodes `msg` as a complete frame (delimiter included) into `out`; returns its length, or
/// `None` if `out` is shorter than the frame (`MAX_FRAME` always suffices).
pub fn encode_frame(msg: &Message, out: &mut [u8]) -> Option<usize> {
    let mut body = [0u8; MAX_BODY];
    let n = msg.write_body(&mut body)?;
    let crc = crc16(body.get(..n)?);
    body.get_mut(n..n + 2)?.copy_from_slice(&crc.to_le_bytes());
    let m = cobs::encode(body.get(..n + 2)?, out)?;
    *out.get_mut(m)? = 0x00;
    Some(m + 1)
}

/// A frame as a fixed array, for callers without a buffer at hand.
#[derive(Clone, Copy)]
pub struct Frame {
    buf: [u8; MAX_FRAME],
    len: usize,
}

impl Frame {
    /// Encodes `msg`. Every [`Message`] fits, so this cannot fail; an (impossible) overflow yields
    /// an empty frame rather than a panic.
    pub fn new(msg: &Message) -> Frame {
        let mut buf = [0u8; MAX_FRAME];
        let len = encode_frame(msg, &mut buf).unwrap_or(0);
        Frame { buf, len }
    }
    /// The bytes to send.
    pub fn as_bytes(&self) -> &[u8] {
        &self.buf[..self.len]
    }
}

impl core::fmt::Debug for Frame {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Frame({:02X?})", self.as_bytes())
    }
}
