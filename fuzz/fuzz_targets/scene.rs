//! Any text as a scene file: refused with a one-line error or accepted as a
//! scene whose numbers are all finite.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        match lightpose_sim::Scene::parse(text, "fuzz.toml") {
            Ok(s) => assert!(s.light.v1.is_finite() && s.light.k_d >= 0.0),
            Err(e) => assert!(!e.to_string().contains('\n')),
        }
    }
});
