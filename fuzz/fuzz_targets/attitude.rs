//! Any bytes as an ATTITUDE datagram: a reading within range (pitch within
//! ±90°, yaw in the beam frame within ±180°) or a refusal with its reason
//! and a bounded one-line message.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match lightposed::inputs::attitude::parse(data, 37.5) {
        Ok(r) => {
            assert!(r.pitch.deg().abs() <= 90.0, "{r:?}");
            assert!(r.yaw.deg().abs() <= 180.0 + 1e-9, "{r:?}");
        }
        Err(e) => {
            assert!(!e.msg.contains('\n') && e.msg.len() < 400, "{e}");
        }
    }
});
