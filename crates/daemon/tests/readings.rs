//! Own-sensor readings through the daemon (issue 13): a recorded zigzag
//! with attitude, depth and DVL velocity and five bad readings spliced in
//! (tests/data/fusion-all.jsonl, the pipeline's regression log) replayed
//! with the tracker. Each bad reading is refused with its reason and
//! counted in STATUS `readings`; the light still gives every frame a pose.

mod common;

use common::run::{of_class, run_to_end};
use common::{root, subscriber};
use lightposed::Config;
use std::time::Duration;

#[test]
fn bad_readings_are_refused_by_reason_and_counted_in_status() {
    let r = root();
    let (sub, addr) = subscriber();
    let text = format!(
        "rate_hz = 5.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{addr}\"]\nstatus_interval_s = 0.2\n",
        r.join("config/calibration/tank.toml").display(),
        r.join("tests/data/fusion-all.jsonl").display(),
    );
    let cfg = Config::parse(&text, "readings.toml", None).expect("valid config");
    // The log's end stops the daemon; the time is a backstop.
    let (summary, msgs) = run_to_end(cfg, Duration::from_secs(20), &sub);
    assert_eq!(summary.frames, 41, "{summary:?}");
    assert_eq!(
        of_class(&msgs, "POSE").len(),
        41,
        "every frame has its POSE, bad readings or not"
    );
    let st = *of_class(&msgs, "STATUS").last().expect("a STATUS");
    let rd = &st["readings"];
    let n = |sensor: &str, path: &[&str]| {
        let mut v = &rd[sensor];
        for k in path {
            v = &v[*k];
        }
        v.as_u64()
            .unwrap_or_else(|| panic!("{sensor} {path:?} in {rd}"))
    };
    // The same verdicts as the pipeline's regression test on this log.
    assert_eq!(n("attitude", &["used"]), 40, "{rd}");
    assert_eq!(n("attitude", &["refused", "bad_std"]), 1, "{rd}");
    assert_eq!(n("depth", &["used"]), 38, "{rd}");
    assert_eq!(n("depth", &["refused", "bad_std"]), 1, "{rd}");
    assert_eq!(n("depth", &["refused", "implausible"]), 1, "{rd}");
    assert_eq!(n("depth", &["refused", "gate"]), 1, "{rd}");
    assert_eq!(n("velocity", &["used"]), 40, "{rd}");
    assert_eq!(n("velocity", &["refused", "implausible"]), 1, "{rd}");
    assert_eq!(n("velocity", &["ignored"]), 0, "{rd}");
}
