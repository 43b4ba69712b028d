//! Round trips and a deterministic randomized fuzz of the codec (seeded PRNG, many cases).

use super::frame::{MAX_ENCODED, MAX_FRAME};
use super::message::kind;
use super::*;
use crate::sim::sensors::SplitMix64;

fn all_messages() -> [Message; 11] {
    [
        Message::Hello {
            protocol_version: PROTOCOL_VERSION,
        },
        Message::Start,
        Message::SetVoltage {
            seq: 0xDEAD_BEEF,
            u_v: -3.25,
        },
        Message::Stop,
        Message::LoopGains(LoopGains {
            kp: 12.5,
            ki: 40.0,
            kd: 0.25,
            tau_f_s: 0.002,
        }),
        Message::LoopReference {
            seq: 7,
            ref_rad: 1.5,
        },
        Message::HelloAck(HelloAck {
            protocol_version: PROTOCOL_VERSION,
            firmware: fixed_text("servo-vboard 0.1.0"),
            counts_per_rev: 4096,
            current_scale_a_per_lsb: 1e-3,
            voltage_limit_v: 10.0,
            sample_period_us: 1000,
            watchdog_ms: 50,
        }),
        Message::Sample(Sample {
            seq: u32::MAX,
            time_us: 123_456_789,
            encoder_count: -1_000_000,
            current_raw: -32768,
            u_applied_v: 9.99,
            rtt_us: 0xFFFF,
            flags: 0x07,
        }),
        Message::Fault(Fault::new(
            FaultCode::Watchdog,
            "no voltage command for 50 ms, going to 0 V",
        )),
        Message::Stopped,
        Message::GainsAck,
    ]
}

fn decode_all(bytes: &[u8]) -> (Vec<Message>, Vec<FrameError>) {
    let mut d = Decoder::new();
    let (mut ok, mut err) = (Vec::new(), Vec::new());
    d.feed(bytes, |r| match r {
        Ok(m) => ok.push(m),
        Err(e) => err.push(e),
    });
    (ok, err)
}

#[test]
fn every_message_round_trips() {
    for m in all_messages() {
        let f = Frame::new(&m);
        assert!(!f.as_bytes().is_empty() && f.as_bytes().len() <= MAX_FRAME);
        assert_eq!(
            f.as_bytes().iter().filter(|&&b| b == 0).count(),
            1,
            "one delimiter in {m:?}"
        );
        assert_eq!(*f.as_bytes().last().unwrap(), 0);
        let (ok, err) = decode_all(f.as_bytes());
        assert_eq!(ok, vec![m]);
        assert!(err.is_empty());
        assert_eq!(
            message::payload_len(m.kind()),
            Some(m.write_body(&mut [0; 64]).unwrap() - 1)
        );
    }
}

#[test]
fn fault_text_is_truncated_at_a_char_boundary() {
    let f = Fault::new(FaultCode::OverCurrent, "ééééééééééééééééééééééééé"); // 50 bytes
    assert_eq!(f.text_str().len(), 32);
    let f = Fault::new(FaultCode::OverCurrent, "aéééééééééééééééééééééééé");
    assert_eq!(f.text_str().len(), 31);
    assert_eq!(FaultCode::from_u16(999), FaultCode::Other);
}

#[test]
fn wrong_lengths_and_types_are_rejected() {
    assert_eq!(Message::parse(&[]), Err(ParseError::Empty));
    assert_eq!(Message::parse(&[0x7F]), Err(ParseError::UnknownType(0x7F)));
    assert_eq!(
        Message::parse(&[kind::SET_VOLTAGE, 1, 2, 3]),
        Err(ParseError::BadLength {
            kind: kind::SET_VOLTAGE,
            expected: 8,
            got: 3
        })
    );
    // A valid CRC around an invalid message is a parse error, not a crash.
    let body = [kind::START, 0xAA];
    let crc = crc::crc16(&body).to_le_bytes();
    let mut enc = [0u8; 16];
    let n = cobs::encode(&[body[0], body[1], crc[0], crc[1]], &mut enc).unwrap();
    assert!(matches!(
        Decoder::decode_block(&enc[..n]),
        Err(FrameError::Parse(_))
    ));
}

#[test]
fn overlong_garbage_is_reported_then_decoding_resumes() {
    let mut bytes = vec![0x55u8; 3 * MAX_ENCODED];
    bytes.push(0);
    bytes.extend_from_slice(Frame::new(&Message::Stop).as_bytes());
    let (ok, err) = decode_all(&bytes);
    assert_eq!(ok, vec![Message::Stop]);
    assert_eq!(err, vec![FrameError::TooLong]);
}

/// Arbitrary bytes never panic; the decoder keeps counting and stays usable.
#[test]
fn fuzz_arbitrary_bytes_never_panic() {
    let mut rng = SplitMix64(0x5E2F0);
    let mut d = Decoder::new();
    let mut buf = [0u8; 512];
    for case in 0..20_000 {
        let n = (rng.next_u64() % 200) as usize;
        // Mix: fully random, sparse zeros, or mostly zeros.
        let zero_every = [2u64, 17, 255][case % 3];
        for b in buf.iter_mut().take(n) {
            let r = rng.next_u64();
            *b = if r.is_multiple_of(zero_every) {
                0
            } else {
                (r >> 8) as u8
            };
        }
        d.feed(&buf[..n], |_| {});
        let _ = Message::parse(&buf[..n]);
        let _ = Decoder::decode_block(&buf[..n]);
        let _ = cobs::decode(&buf[..n], &mut [0u8; 64]);
    }
    // Still decodes a clean frame after all that garbage (after one delimiter).
    let mut ok = Vec::new();
    d.feed(&[0], |_| {});
    d.feed(Frame::new(&Message::Start).as_bytes(), |r| ok.push(r));
    assert_eq!(ok, vec![Ok(Message::Start)]);
    assert!(d.stats().crc_errors + d.stats().framing_errors > 1000);
}

/// Corrupted frames are rejected: every single-byte corruption of every message over many seeds,
/// and random multi-byte corruption at no more than the CRC-16 false-accept rate (2^-16).
#[test]
fn fuzz_corrupted_frames_are_rejected() {
    let mut rng = SplitMix64(0xC0FFEE);
    let msgs = all_messages();
    let mut single = 0u64;
    for _ in 0..4_000 {
        for m in &msgs {
            let mut f = Frame::new(m).as_bytes().to_vec();
            let i = (rng.next_u64() % (f.len() as u64 - 1)) as usize; // not the delimiter
            let x = loop {
                let x = rng.next_u64() as u8;
                if x != 0 {
                    break x;
                }
            };
            f[i] ^= x;
            let (ok, err) = decode_all(&f);
            assert!(
                ok.is_empty(),
                "single-byte corruption accepted: {m:?} -> {ok:?}"
            );
            assert!(!err.is_empty());
            single += 1;
        }
    }
    let mut accepted = 0u64;
    let mut multi = 0u64;
    let mut crc_rejects = 0u64;
    for _ in 0..20_000 {
        for m in &msgs {
            let mut f = Frame::new(m).as_bytes().to_vec();
            let body = f.len() - 1;
            let k = 2 + (rng.next_u64() % 6) as usize;
            for _ in 0..k {
                let i = (rng.next_u64() % body as u64) as usize;
                f[i] = rng.next_u64() as u8;
            }
            let mut d = Decoder::new();
            d.feed(&f, |r| {
                if let Ok(got) = r {
                    if got != *m {
                        accepted += 1;
                    }
                }
            });
            crc_rejects += d.stats().crc_errors;
            multi += 1;
        }
    }
    assert!(single > 40_000 && multi > 200_000);
    assert!(
        crc_rejects > multi / 4,
        "many corruptions are caught by the CRC: {crc_rejects}/{multi} (accepted {accepted})"
    );
    // Expected false accepts ~ multi * 2^-16 ~ 3.4; allow a generous margin, not a vacuous one.
    assert!(
        accepted <= 20,
        "{accepted} corrupted frames accepted out of {multi}"
    );
}

/// A stream of frames with garbage, dropped and duplicated bytes in between: the decoder
/// resynchronises at the next delimiter and every untouched frame after it comes through.
#[test]
fn fuzz_stream_resynchronises() {
    let mut rng = SplitMix64(42);
    let msgs = all_messages();
    let mut stream = Vec::new();
    let mut intact = Vec::new(); // frames guaranteed decodable
    let mut prev_clean = true;
    for i in 0..5_000 {
        let m = msgs[(rng.next_u64() % msgs.len() as u64) as usize];
        let mut f = Frame::new(&m).as_bytes().to_vec();
        match rng.next_u64() % 5 {
            0 => {
                // garbage before the frame, without delimiter: merges with this frame
                for _ in 0..(1 + rng.next_u64() % 40) {
                    stream.push((rng.next_u64() as u8) | 1);
                }
                stream.extend_from_slice(&f);
                prev_clean = true;
            }
            1 => {
                // drop one byte (maybe the delimiter: then the next frame is lost too)
                let j = (rng.next_u64() % f.len() as u64) as usize;
                let dropped_delim = j == f.len() - 1;
                f.remove(j);
                stream.extend_from_slice(&f);
                prev_clean = !dropped_delim;
            }
            _ => {
                stream.extend_from_slice(&f);
                if prev_clean {
                    intact.push((i, m));
                }
                prev_clean = true;
            }
        }
    }
    let (ok, _err) = decode_all(&stream);
    // Every intact frame is recovered, in order (extra accepted frames would be CRC false accepts).
    let mut it = ok.iter();
    for (i, m) in &intact {
        assert!(it.any(|g| g == m), "intact frame #{i} {m:?} not recovered");
    }
    assert!(ok.len() <= intact.len() + 3);
    assert!(intact.len() > 2_500);
}
