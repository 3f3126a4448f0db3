//! A replayed log's seq as the daemon counts it: frames lost at the
//! source agree with what the log reader admits.

mod common;
use common::run::{of_class, replay_config, run_to_end};
use common::subscriber;
use lightpose_testkit::data::dive_with_a_corrupt_seq;
use lightposed::Config;
use std::time::Duration;

/// Audit: one corrupt seq (500 for 4, among 41 frames) is a lone glitch to
/// the log reader, which takes its gap back; the daemon's engine still
/// counted 496 frames lost. STATUS says none lost and the glitch counted.
#[test]
fn a_lone_corrupt_seq_in_a_replay_loses_no_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (log, frames) = dive_with_a_corrupt_seq(dir.path());
    let (sub, dest) = subscriber();
    let cfg = Config::parse(&replay_config(&log, dest), "t.toml", None).expect("valid");
    let (summary, msgs) = run_to_end(cfg, Duration::from_secs(20), &sub);
    let frames = frames as u64;
    assert!(summary.source_ended, "{summary:?}");
    assert_eq!((summary.frames, summary.lost), (frames, 0), "{summary:?}");
    let st = of_class(&msgs, "STATUS");
    let st = st.last().expect("a last STATUS");
    assert_eq!(st["frames"].as_u64(), Some(frames), "{st}");
    assert_eq!(st["lost"].as_u64(), Some(0), "{st}");
    assert_eq!(
        st["backend"]["health"]["glitches"].as_u64(),
        Some(1),
        "{st}"
    );
    assert_eq!(st["last_seq"].as_u64(), Some(frames - 1), "{st}");
}
