#![no_main]
use libfuzzer_sys::fuzz_target;

// The MAT-file reader, then what `servo inspect` and an import through MATLAB paths do with a
// file that parses.
fuzz_target!(|data: &[u8]| {
    if let Ok(f) = servo_cli::io::mat_read::parse_mat(data) {
        let _ = servo_cli::io::mat_log::describe(&f);
        let _ = servo_cli::io::mat_log::guess(&f);
        let _ = servo_cli::io::mat_log::import(
            &f,
            "fuzz.mat",
            Some("time=thl_u.time,theta_l=thl_u.signals(1).values(:,1):deg,u=thl_u.signals(2).values"),
        );
    }
});
