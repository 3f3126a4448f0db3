//! `[recording] format = "ros2"`: the daemon records a ROS 2 bag of what
//! its ROS 2 node would publish, rotated and flushed as any MCAP
//! recording, and the PyPI `rosbags` (types from the bag's own schemas)
//! and `mcap` read it: every `ok` POSE datagram the daemon sent is in it as
//! pose, odometry and `/tf`, equal field by field
//! (tests/python/ros2bag_check.py), and each STATUS as `/diagnostics`;
//! its topics and frames are `[ros2]`'s (the node off: its names still
//! name the bag) and `[site]` gives its `/tf_static`.

mod common;
use common::run::{collect_raw, files_in, run_in_process, sim_config};
use common::{root, subscriber};
use lightpose_testkit::python::{python, run_python};
use lightposed::Config;
use std::time::Duration;

#[test]
fn a_ros2_recording_holds_every_ok_pose_the_daemon_sent() {
    let py = python();
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sub, addr) = subscriber();
    let extra = format!(
        "[recording]\ndir = \"{}\"\nformat = \"ros2\"\nflush_s = 0.5\n\
         [ros2]\nenabled = false\nnamespace = \"/auv1/lightpose\"\n\
         [ros2.frames]\nbeacon = \"dock_light\"\nbase_link = \"auv1/base_link\"\nmap = \"world\"\n\
         [site]\nbeacon_heading_deg = -30.0\nbeacon_depth_m = 3.25\nbeacon_ned_m = [12.5, -4.0, 3.25]\n",
        rec.display()
    );
    // The tracker: on the tank zigzag most of its estimates are `ok`.
    let text = sim_config(20.0, &[addr], "", &extra)
        .replace("estimator = \"moments\"", "estimator = \"tracker\"");
    let cfg = Config::parse(&text, "ros2rec.toml", None).expect("valid config");
    let h = run_in_process(cfg, Duration::from_secs(4));
    let got = collect_raw(&sub, Duration::from_millis(5500));
    let summary = h.join().expect("daemon");
    assert!(summary.frames > 40, "{} frames", summary.frames);

    let poses: Vec<&[u8]> = got
        .iter()
        .filter(|d| d.starts_with(b"{\"class\":\"POSE\""))
        .map(|d| d.as_slice())
        .collect();
    let ok = poses
        .iter()
        .filter(|d| d.windows(13).any(|w| w == b"\"status\":\"ok\""))
        .count();
    assert!(
        ok > 20,
        "{ok} ok poses of {}: {}",
        poses.len(),
        String::from_utf8_lossy(poses.last().copied().unwrap_or_default())
    );
    let lines = dir.path().join("poses.jsonl");
    let mut text = poses.join(&b'\n');
    text.push(b'\n');
    std::fs::write(&lines, text).expect("write");

    let files = files_in(&rec);
    assert_eq!(files.len(), 1, "{files:?}");
    assert_eq!(files[0].extension().and_then(|e| e.to_str()), Some("mcap"));
    let check = root().join("tests/python/ros2bag_check.py");
    let (bag, lines) = (files[0].display().to_string(), lines.display().to_string());
    let args = [
        bag.as_str(),
        &lines,
        "--namespace",
        "/auv1/lightpose",
        "--frames",
        "dock_light,auv1/base_link,world",
        // (= : argparse takes "-30" for an option.)
        "--site=-30,12.5,-4,3.25",
    ];
    let line = run_python(&py, &check, &args);
    let (head, tail) = line.split_once(" static=").expect("static=");
    assert_eq!(head, format!("pose={ok} odom={ok} tf={ok} ok={ok}"));
    assert!(tail.starts_with("1 diag="), "{line}");

    let topics = root().join("tests/python/ros2bag_topics.py");
    let out = run_python(&py, &topics, &[&files[0]]);
    let diagnostics = out
        .lines()
        .find_map(|l| l.strip_prefix("/diagnostics="))
        .and_then(|n| n.parse::<u32>().ok())
        .unwrap_or(0);
    // STATUS every 0.2 s over 4 s, from the first estimate on.
    assert!(diagnostics >= 10, "{out}");
    assert!(out.contains("diagnostics_levels=0"), "{out}");
}
