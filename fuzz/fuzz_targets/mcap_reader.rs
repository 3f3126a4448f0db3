//! Any bytes as an MCAP recording: the reader must name a byte or stop,
//! never panic, never allocate what a length field claims without the bytes
//! behind it, and never hand out a frame that breaks the format's
//! invariants; with and without the file's size (which tells a cut from
//! garbage).
#![no_main]
use libfuzzer_sys::fuzz_target;
use lightpose_core::FrameLog;
use lightpose_logs::McapReader;

fuzz_target!(|data: &[u8]| {
    for size in [Some(data.len() as u64), None] {
        if let Ok(mut r) = McapReader::new(data, "fuzz.mcap", size) {
            let fs = (1u32 << r.header().adc_bits) - 1;
            for f in r.by_ref().flatten() {
                assert!(f.t.is_finite());
                assert!(f.counts.iter().all(|&c| c as u32 <= fs));
            }
            if let Some(lightpose_core::Cut::Bytes { offset, dropped }) = r.cut() {
                assert!(offset + dropped <= data.len() as u64);
            }
        }
    }
});
