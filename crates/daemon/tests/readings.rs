//! Own-sensor readings through the daemon (issue 13): a recorded zigzag
//! with attitude, depth and DVL velocity and five bad readings spliced in
//! (tests/data/fusion-all.jsonl, the pipeline's regression log) replayed
//! with the tracker. Each bad reading is refused with its reason and
//! counted in STATUS `readings`; the light still gives every frame a pose.

mod common;

use common::{root, subscriber};
use lightposed::outputs::udp::Publisher;
use lightposed::Config;
use serde_json::Value;
use std::time::{Duration, Instant};

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
    let h = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        rt.block_on(async move {
            let p = Publisher::open(&cfg.outputs).expect("publisher");
            // The log's end stops the daemon; the timer is a backstop.
            lightposed::run(cfg, p, tokio::time::sleep(Duration::from_secs(20)))
                .await
                .expect("daemon runs")
        })
    });
    let mut msgs: Vec<Value> = Vec::new();
    let mut buf = vec![0u8; 65536];
    let end = Instant::now() + Duration::from_secs(20);
    while !h.is_finished() && Instant::now() < end {
        if let Ok(n) = sub.recv(&mut buf) {
            msgs.push(serde_json::from_slice(&buf[..n]).expect("JSON datagram"));
        }
    }
    // The final STATUS may still be on its way.
    while let Ok(n) = sub.recv(&mut buf) {
        msgs.push(serde_json::from_slice(&buf[..n]).expect("JSON datagram"));
    }
    let summary = h.join().expect("daemon");
    assert_eq!(summary.frames, 41, "{summary:?}");
    let poses = msgs.iter().filter(|v| v["class"] == "POSE").count();
    assert_eq!(poses, 41, "every frame has its POSE, bad readings or not");
    let st = msgs
        .iter()
        .rev()
        .find(|v| v["class"] == "STATUS")
        .expect("a STATUS");
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
