#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = servo_cli::cmd::log::recover_bytes(data, std::io::Cursor::new(Vec::new()));
});
