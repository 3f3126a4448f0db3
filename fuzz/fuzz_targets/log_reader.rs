//! Any bytes as an intensity log: the reader must name a line or stop, never
//! panic, and never hand out a frame that breaks the format's invariants.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lightpose_core::LogReader;

fuzz_target!(|data: &[u8]| {
    if let Ok(mut r) = LogReader::new(data, "fuzz.jsonl") {
        let fs = (1u32 << r.header().adc_bits) - 1;
        for f in r.by_ref().flatten() {
            assert!(f.t.is_finite());
            assert!(f.counts.iter().all(|&c| c as u32 <= fs));
        }
    }
});
