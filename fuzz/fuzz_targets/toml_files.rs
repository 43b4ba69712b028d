#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = servo_cli::model_file::ModelFile::parse(text).and_then(|m| m.plant());
        let _ = servo_cli::gains_file::GainsFile::parse(text);
        let _ = servo_cli::reference_file::Experiment::parse(text, "fuzz.toml");
        let _ = servo_core::control::Reference::parse(text);
    }
});
