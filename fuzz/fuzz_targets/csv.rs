#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = servo_cli::io::csv_read::parse_csv(text, "fuzz.csv", None);
        let _ = servo_cli::io::csv_read::parse_csv(
            text,
            "fuzz.csv",
            Some("time=t_ms:ms,theta_l=pos_deg:deg,i_a=I_mA:mA,u=u_V"),
        );
    }
});
