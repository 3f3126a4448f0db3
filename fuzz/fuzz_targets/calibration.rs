//! Any text as a calibration file: refused with a one-line error or loaded.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Err(e) = lightpose_pipeline::Calibration::parse(text, "fuzz.toml") {
            assert!(!e.to_string().contains('\n'));
        }
    }
});
