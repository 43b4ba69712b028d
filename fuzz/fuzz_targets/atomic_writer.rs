#![no_main]
use libfuzzer_sys::fuzz_target;

// The atomic writer (`servo_io::output`): the target is always the old or the new bytes, a
// previous file with other bytes is kept under the first free `NAME.N`, older backups are never
// touched, no temporary file is left. The check panics on a violation.
fuzz_target!(|data: &[u8]| {
    servo_cli::io::output::check_atomic_writer(data);
});
