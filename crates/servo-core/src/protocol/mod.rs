//! The wire protocol between the host and a servo board (documented byte by byte in
//! `docs/protocol.md`).
//!
//! * [`cobs`]: COBS byte stuffing, 0x00 is the frame delimiter.
//! * [`crc`]: CRC-16/CCITT-FALSE over each frame body.
//! * [`message`]: the messages and their fixed little-endian layout.
//! * [`frame`]: message → frame bytes.
//! * [`decoder`]: streaming bytes → messages with resynchronisation after garbage.
//!
//! Everything here is `no_std`, uses no heap and never panics on any input, so the same code can
//! run in the board's firmware.

pub mod cobs;
pub mod crc;
pub mod decoder;
pub mod frame;
pub mod message;

pub use decoder::{Decoder, DecoderStats, FrameError};
pub use frame::{encode_frame, Frame, MAX_FRAME};
pub use message::{
    fixed_text, flags, kind, Fault, FaultCode, HelloAck, LoopGains, Message, ParseError, Sample,
    PROTOCOL_VERSION,
};

#[cfg(test)]
mod tests;
