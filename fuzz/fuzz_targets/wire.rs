#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut d = servo_core::protocol::Decoder::default();
    d.feed(data, |_| {});
    let _ = servo_core::protocol::Decoder::decode_block(data);
});
