//! Any bytes as one line from a serial ADC board: a sample or a named error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = lightpose_hal::serial::protocol::parse_line(data);
});
