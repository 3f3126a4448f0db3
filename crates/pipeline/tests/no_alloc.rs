//! The moments estimator must not touch the heap per frame (the daemon's
//! hot path): counted here with a global allocator that tallies every
//! allocation while frames are estimated.

use lightpose_core::{Estimator, Frame};
use lightpose_pipeline::{Calibration, MomentsEstimator};
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;
static ALLOCS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        System.alloc(l)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        System.realloc(p, l, n)
    }
}

#[global_allocator]
static A: Counting = Counting;

#[test]
fn estimating_a_log_allocates_nothing() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cal = Calibration::load(&root.join("config/calibration/tank.toml")).expect("calibration");
    // Every path: lit, initialising, dark and saturated frames.
    let frames: Vec<Frame> = ["dive", "hard"]
        .iter()
        .flat_map(|n| {
            lightpose_core::LogReader::open(&root.join(format!("tests/data/{n}.jsonl")))
                .expect("log")
                .filter_map(Result::ok)
                .collect::<Vec<_>>()
        })
        .collect();
    let mut est = MomentsEstimator::new(&cal);
    let mut statuses = 0u64;
    let before = ALLOCS.load(Ordering::Relaxed);
    for f in &frames {
        statuses += est.estimate(f).status as u64;
    }
    let after = ALLOCS.load(Ordering::Relaxed);
    assert!(statuses > 0);
    assert_eq!(
        after - before,
        0,
        "{} allocations over {} frames",
        after - before,
        frames.len()
    );
}
