//! Any text as the daemon's configuration: refused with a one-line error or
//! accepted.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Err(e) = lightposed::config::Config::parse(text, "fuzz.toml", None) {
            assert!(!e.to_string().contains('\n'), "{e}");
        }
    }
});
