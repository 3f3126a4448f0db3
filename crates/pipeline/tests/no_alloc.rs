//! The moments estimator and the tracker must not touch the heap per frame
//! (the daemon's hot path): counted here with a global allocator that
//! tallies every allocation while frames are estimated.

use lightpose_core::{Estimator, Frame};
use lightpose_pipeline::{Calibration, MomentsEstimator};
use lightpose_testkit::alloc::Counting;
use std::path::Path;

// Counted per thread (`A.this_thread`): the test harness allocates on
// threads of its own (printing results) while a test runs.
#[global_allocator]
static A: Counting = Counting::new();

/// The shipped tank calibration and the frames of the regression logs
/// `names` (tests/data), read before any counting starts.
fn calibration_and_frames(names: &[&str]) -> (Calibration, Vec<Frame>) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cal = Calibration::load(&root.join("config/calibration/tank.toml")).expect("calibration");
    let frames = names
        .iter()
        .flat_map(|n| {
            lightpose_core::LogReader::open(&root.join(format!("tests/data/{n}.jsonl")))
                .expect("log")
                .filter_map(Result::ok)
                .collect::<Vec<_>>()
        })
        .collect();
    (cal, frames)
}

#[test]
fn estimating_a_log_allocates_nothing() {
    // Every path: lit, initialising, dark and saturated frames.
    let (cal, frames) = calibration_and_frames(&["dive", "hard"]);
    let mut est = MomentsEstimator::new(&cal);
    let mut statuses = 0u64;
    let ((), n) = A.this_thread(|| {
        for f in &frames {
            statuses += est.estimate(f).status as u64;
        }
    });
    assert!(statuses > 0);
    assert_eq!(n, 0, "{n} allocations over {} frames", frames.len());
}

/// The tracker, with the vehicle's own sensors (good and refused readings)
/// and without (the paper's range, the sigma-point update), must not touch
/// the heap per frame either once built; nor must the bank of waters it
/// becomes when told a wide doubt about the water (`k_d_sigma = 0.3`).
#[test]
fn tracking_with_and_without_own_sensors_allocates_nothing() {
    let (cal, frames) = calibration_and_frames(&["fusion-all", "fusion-depth", "dive", "hard"]);
    let mut wide = cal.clone();
    let mut settings = wide.estimator.clone().unwrap_or_default();
    settings.tracker.k_d_sigma = Some(0.3);
    wide.estimator = Some(settings);
    for cal in [&cal, &wide] {
        let mut est = lightpose_pipeline::build_estimator("tracker", cal).expect("tracker");
        let mut used = 0u64;
        let ((), n) = A.this_thread(|| {
            for f in &frames {
                let e = est.estimate(f);
                used += u64::from(e.readings.depth == lightpose_core::ReadingUse::Used);
            }
        });
        assert_eq!(n, 0, "{n} allocations over {} frames", frames.len());
        assert!(used >= 38);
    }
}
