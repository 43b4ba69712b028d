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
        // Lines capped at 64 bytes (1 MiB by default), so that small inputs reach the cap: the
        // error quotes a short excerpt, never the input.
        if let Err(e) = servo_cli::io::csv_read::parse_csv_capped(text, "fuzz.csv", None, 64) {
            let m = format!("{e:#}");
            assert!(m.len() < 2000, "{} bytes of message", m.len());
        }
    }
});
