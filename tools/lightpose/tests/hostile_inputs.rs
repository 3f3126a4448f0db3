//! The `lightpose` binary against inputs a careless or hostile user gives
//! it (issue 16): a trajectory that would write forever, a log with frames
//! out of order and lines of other classes.

mod common;

use common::{replay, root, s};
use std::time::Duration;

/// Run `lightpose args` within `within`: its exit code and stderr.
fn lightpose(args: &[&str], within: Duration) -> (Option<i32>, String) {
    let r = common::lightpose(args, within);
    (r.code, r.err)
}

#[test]
fn simulate_refuses_a_trajectory_past_the_frame_bound_unless_asked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let far = dir.path().join("far.csv");
    // Two knots 1e9 s apart: 5e9 frames at the tank's 5 Hz.
    std::fs::write(&far, "t,x,y,z,pitch,yaw\n0,8,0,0,0,0\n1e9,4,0,0,0,0\n").expect("write");
    let scene = root().join("config/scenes/tank.toml");
    let out = dir.path().join("far.jsonl");
    let (code, err) = lightpose(
        &[
            "simulate",
            "--scene",
            s(&scene),
            "--trajectory",
            s(&far),
            "--out",
            s(&out),
        ],
        Duration::from_secs(10),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("far.csv") && err.contains("--max-frames"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(!out.exists(), "nothing written");
    // The bound is the user's to move: the dive (41 frames) under 40 is
    // refused, at 41 written.
    let dive = root().join("config/trajectories/dive.csv");
    let args = |n: &'static str| {
        vec![
            "simulate".to_string(),
            "--scene".into(),
            s(&scene).into(),
            "--trajectory".into(),
            s(&dive).into(),
            "--out".into(),
            s(&out).into(),
            "--max-frames".into(),
            n.into(),
        ]
    };
    let a40 = args("40");
    let (code, err) = lightpose(
        &a40.iter().map(String::as_str).collect::<Vec<_>>(),
        Duration::from_secs(30),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("41 frames"), "{err}");
    let a41 = args("41");
    let (code, err) = lightpose(
        &a41.iter().map(String::as_str).collect::<Vec<_>>(),
        Duration::from_secs(30),
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("41 frames"), "{err}");
}

#[test]
fn replay_names_frames_out_of_order_and_lines_of_other_classes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(root().join("tests/data/dive.jsonl")).expect("dive log");
    let lines: Vec<&str> = text.lines().collect();
    // Header, frames 0 and 1, frame 1 again, a POSE line, the rest.
    let mut bad: Vec<&str> = lines[..3].to_vec();
    bad.push(lines[2]);
    bad.push(r#"{"class":"POSE","seq":1,"t":0.2,"status":"ok"}"#);
    bad.extend_from_slice(&lines[3..]);
    let log = dir.path().join("bad.jsonl");
    std::fs::write(&log, bad.join("\n") + "\n").expect("write");
    let out = dir.path().join("poses.jsonl");
    let r = replay(&log, &out, &["--estimator", "moments"]);
    let (code, err) = (r.code, r.err);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("skipped") && err.contains("bad.jsonl:4: seq 1 repeats"),
        "{err}"
    );
    assert!(
        err.contains("1 line of another class passed over (first: ")
            && err.contains("bad.jsonl:5: class \"POSE\""),
        "{err}"
    );
    assert!(err.contains("41 poses"), "{err}");
    let poses = std::fs::read_to_string(&out).expect("poses");
    assert_eq!(poses.lines().count(), 41, "the duplicate is not replayed");
}
