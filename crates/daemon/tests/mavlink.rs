//! The daemon as a MAVLink component, end to end over UDP on loopback: it
//! replays a log that has no attitude, depth or temperature of its own,
//! a stand-in autopilot sends those readings from the log's truth in step
//! with the replay, and what the daemon sends back is judged against the
//! truth. The stand-in is pymavlink (an independent implementation,
//! tests/python/autopilot_replay.py) or, for machines without Python,
//! lightpose-vehicle's own; then bad MAVLink input into the running daemon.

mod common;

use common::run::{collect, of_class, python, run_in_process, run_python};
use common::subscriber;
use common::vehicle::{free_port, judge, mavlink_config, stand_in, write_bare_log};
use common::vehicle::{BEACON_DEPTH_M, HEADING_DEG, WATER_C};
use lightposed::Config;
use serde_json::Value;
use std::net::UdpSocket;
use std::time::Duration;

/// The bounds on the p95 errors: north, east, down (m), pitch,
/// heading (degrees).
const BOUNDS: [f64; 5] = [0.25, 0.25, 0.1, 1.5, 4.0];
/// The log: the zigzag at 20 Hz (8 s, 161 frames), replayed at its pace.
const RATE_HZ: f64 = 20.0;
const SECONDS: f64 = 8.0;
/// Coverage is counted after the first second of the log.
const COVER_AFTER_S: f64 = 1.0;
/// Errors are judged once the tracker has settled. Its track starts at
/// the first frame; its y–yaw mode (a lateral offset looks like a turn)
/// is pulled in by the attitude reading, weighed with the pipeline's
/// 1.5° attitude noise, within about two seconds (measured: the east
/// error last exceeds 0.25 m at t ≈ 1.4 s, also with the vehicle at rest
/// for its first second). The MAVLink path itself adds nothing to that.
const P95_AFTER_S: f64 = 2.0;

fn check_p95(who: &str, p95: [f64; 5]) {
    eprintln!(
        "{who}: p95 north {:.3} m, east {:.3} m, down {:.3} m, pitch {:.2}°, heading {:.2}°",
        p95[0], p95[1], p95[2], p95[3], p95[4]
    );
    for (k, (v, b)) in p95.iter().zip(BOUNDS).enumerate() {
        assert!(
            v.is_finite() && *v <= b,
            "{who}: p95 of {} is {v} > {b}",
            ["north", "east", "down", "pitch", "heading"][k]
        );
    }
}

/// The last STATUS's `vehicle` object.
fn last_vehicle_status(msgs: &[Value]) -> Value {
    let st = of_class(msgs, "STATUS");
    st.last().expect("STATUS arrives")["vehicle"].clone()
}

#[test]
fn pymavlink_autopilot_gets_poses_within_bounds() {
    let py = python();
    let dir = tempfile::tempdir().expect("tmp");
    let log = dir.path().join("bare.jsonl");
    write_bare_log(&log, RATE_HZ, SECONDS);
    let (sub, dest) = subscriber();
    let port = free_port();
    let conn = format!("udpin:127.0.0.1:{port}");
    let cfg = Config::parse(&mavlink_config(&log, dest, &conn, ""), "t.toml", None).expect("valid");
    let script = common::root().join("tests/python/autopilot_replay.py");
    let args: Vec<std::ffi::OsString> = [
        log.display().to_string(),
        port.to_string(),
        HEADING_DEG.to_string(),
        BEACON_DEPTH_M.to_string(),
        WATER_C.to_string(),
        COVER_AFTER_S.to_string(),
        P95_AFTER_S.to_string(),
        "1.5".into(),
        "25".into(),
    ]
    .into_iter()
    .map(Into::into)
    .collect();
    let stand_in = std::thread::spawn(move || {
        let a: Vec<&std::ffi::OsStr> = args.iter().map(|s| s.as_os_str()).collect();
        run_python(&py, &script, &a)
    });
    let summary = run_in_process(cfg, Duration::from_secs(30))
        .join()
        .expect("daemon");
    let out = stand_in.join().expect("python thread");
    assert!(summary.source_ended, "{summary:?}");
    let r: Value = serde_json::from_str(out.lines().last().unwrap_or("")).expect("one JSON line");
    eprintln!("pymavlink stand-in: {r}");
    assert_eq!(
        (r["bad"].as_u64(), r["v1"].as_u64()),
        (Some(0), Some(0)),
        "{r}"
    );
    assert_eq!(r["covariance_finite"], true, "{r}");
    assert!(r["counts"]["HEARTBEAT"].as_u64() >= Some(1), "{r}");
    let (covered, frames) = (
        r["covered"].as_u64().unwrap_or(0),
        r["frames"].as_u64().unwrap_or(1),
    );
    assert!(covered * 10 >= frames * 8, "{covered} of {frames}: {r}");
    let p95: Vec<f64> = ["north", "east", "down", "pitch", "heading"]
        .iter()
        .map(|k| r["p95"][k].as_f64().unwrap_or(f64::NAN))
        .collect();
    check_p95(
        "pymavlink stand-in",
        [p95[0], p95[1], p95[2], p95[3], p95[4]],
    );
    let v = last_vehicle_status(&collect(&sub, Duration::from_millis(100)));
    let used = &v["mavlink"];
    assert!(
        v["readings"]["temperature"]["attached"]
            .as_u64()
            .unwrap_or(0)
            > 0,
        "{v}"
    );
    assert!(
        v["readings"]["depth"]["attached"].as_u64().unwrap_or(0) > 0,
        "{used}"
    );
}

#[test]
fn rust_stand_in_autopilot_gets_poses_within_bounds() {
    let dir = tempfile::tempdir().expect("tmp");
    let log = dir.path().join("bare.jsonl");
    let truth = write_bare_log(&log, RATE_HZ, SECONDS);
    let ap = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let (sub, dest) = subscriber();
    let port = free_port();
    let conn = format!("udpin:127.0.0.1:{port}");
    let cfg = Config::parse(&mavlink_config(&log, dest, &conn, ""), "t.toml", None).expect("valid");
    let daemon = run_in_process(cfg, Duration::from_secs(30));
    let to = Some(([127, 0, 0, 1], port).into());
    let heard = stand_in(
        &ap,
        to,
        &truth,
        Duration::from_millis(1500),
        Duration::from_secs(20),
    );
    let summary = daemon.join().expect("daemon thread");
    assert!(summary.source_ended, "{summary:?}");
    assert_eq!((heard.not_v2, heard.bad), (0, 0), "{heard:?}");
    assert!(heard.heartbeats >= 1);
    assert!(heard
        .positions
        .iter()
        .all(|p| p.covariance.iter().all(|c| c.is_finite())));
    let (_, covered, frames) = judge(&heard.positions, &truth, COVER_AFTER_S);
    eprintln!("rust stand-in: {covered} of {frames} frames after the first second answered");
    assert!(covered * 10 >= frames * 8, "{covered} of {frames}");
    let (stats, _, _) = judge(&heard.positions, &truth, P95_AFTER_S);
    check_p95("rust stand-in", stats.p95());
    let msgs = collect(&sub, Duration::from_millis(100));
    let v = last_vehicle_status(&msgs);
    assert_eq!(v["enabled"], true, "{v}");
    assert!(
        v["readings"]["attitude"]["attached"].as_u64().unwrap_or(0) > 0,
        "{v}"
    );
}
