//! Any bytes as one line of the DVL's TCP stream: a velocity within the
//! limit with a finite, non-negative std, another report, or a refusal
//! with its reason; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lightpose_vehicle::dvl::{parse_line, DvlLine};

fuzz_target!(|data: &[u8]| {
    if let Ok(DvlLine::Velocity(v)) = parse_line(data, 5.0) {
        assert!(v.reading.v.0.iter().all(|c| c.is_finite() && c.abs() <= 5.0));
        if let Some(std) = v.reading.std {
            assert!(std.0.iter().all(|s| s.is_finite() && *s >= 0.0), "{std:?}");
        }
    }
});
