//! `lightpose convert --ros2` end to end: the tank scene simulated along a
//! trajectory, replayed to POSE lines, converted to a ROS 2 bag, and the
//! bag read by the PyPI `rosbags` (its types from the bag's own schemas)
//! and `mcap` packages (tests/python/ros2bag_check.py): every `ok` pose,
//! odometry and transform equal to its POSE line, none other; an MCAP
//! recording's own poses give the same bag. Bad input: one line.

mod common;

use common::{replay, root, run, s};
use std::path::{Path, PathBuf};

/// A simulated log of the tank along `trajectory` and its POSE lines.
fn simulated(dir: &Path, trajectory: &str) -> (PathBuf, PathBuf) {
    let (log, poses) = (dir.join("sim.jsonl"), dir.join("sim.poses.jsonl"));
    let scene = root().join("config/scenes/tank.toml");
    let traj = root().join("config/trajectories").join(trajectory);
    let (ok, _, err) = run(&[
        "simulate",
        "--scene",
        s(&scene),
        "--trajectory",
        s(&traj),
        "--out",
        s(&log),
        "--seed",
        "7",
    ]);
    assert!(ok, "{err}");
    let r = replay(&log, &poses, &[]);
    assert_eq!(r.code, Some(0), "{}", r.err);
    (log, poses)
}

/// POSE lines of `poses` whose status is ok.
fn ok_poses(poses: &Path) -> usize {
    std::fs::read_to_string(poses)
        .unwrap()
        .lines()
        .filter(|l| l.contains("\"class\":\"POSE\"") && l.contains("\"status\":\"ok\""))
        .count()
}

fn convert(log: &Path, bag: &Path, poses: Option<&Path>) -> (bool, String) {
    let mut a = vec!["convert", "--ros2", "--in", s(log), "--out", s(bag)];
    if let Some(p) = poses {
        a.extend(["--poses", s(p)]);
    }
    let (ok, _, err) = run(&a);
    (ok, err)
}

#[test]
fn rosbags_reads_every_ok_pose_intact() {
    let py = lightpose_testkit::python::python();
    let dir = tempfile::tempdir().unwrap();
    let (log, poses) = simulated(dir.path(), "zigzag.csv");
    let bag = dir.path().join("sim.mcap");
    let (ok, err) = convert(&log, &bag, Some(&poses));
    assert!(ok, "{err}");
    let n = ok_poses(&poses);
    assert!(n > 10, "{n} ok poses: too few to test");
    assert!(
        err.contains(&format!(" {n} ok written as pose, odom and /tf")),
        "{err}"
    );
    let script = root().join("tests/python/ros2bag_check.py");
    let line = lightpose_testkit::python::run_python(&py, &script, &[&bag, &poses]);
    assert_eq!(
        line,
        format!("pose={n} odom={n} tf={n} ok={n} static=0 diag=0")
    );

    // The daemon's POSE lines carry the capture's wall clock, `time`: the
    // stamp and the log time.
    let text = std::fs::read_to_string(&poses).unwrap();
    let mut timed = String::new();
    for line in text.lines() {
        let mut v: serde_json::Value = serde_json::from_str(line).unwrap();
        let t = v["t"].as_f64().unwrap();
        v["time"] = (1_764_700_000.123_456_7 + t).into();
        timed.push_str(&format!("{v}\n"));
    }
    let (wall, wall_bag) = (dir.path().join("wall.jsonl"), dir.path().join("wall.mcap"));
    std::fs::write(&wall, timed).unwrap();
    let (ok, err) = convert(&log, &wall_bag, Some(&wall));
    assert!(ok, "{err}");
    let line = lightpose_testkit::python::run_python(&py, &script, &[&wall_bag, &wall]);
    assert_eq!(
        line,
        format!("pose={n} odom={n} tf={n} ok={n} static=0 diag=0")
    );

    // A lightpose MCAP recording holds its poses: the same bag from it
    // alone, byte for byte.
    // (The same file name: the bag's metadata record names it.)
    std::fs::create_dir(dir.path().join("again")).unwrap();
    let (rec, bag2) = (
        dir.path().join("rec.mcap"),
        dir.path().join("again/sim.mcap"),
    );
    let (ok, _, err) = run(&[
        "convert",
        "--in",
        s(&log),
        "--out",
        s(&rec),
        "--poses",
        s(&poses),
    ]);
    assert!(ok, "{err}");
    let (ok, err) = convert(&rec, &bag2, None);
    assert!(ok, "{err}");
    assert!(
        std::fs::read(&bag).unwrap() == std::fs::read(&bag2).unwrap(),
        "{err}"
    );
}

/// The node's settings on the command line: the namespace names the
/// pose's and odometry's topics, the frames are the ones given, and the
/// site (`[site]`'s heading and position) gives the bag its `/tf_static`,
/// checked by rosbags against the transform worked out in the script.
#[test]
fn a_bag_names_the_node_s_namespace_frames_and_site() {
    let py = lightpose_testkit::python::python();
    let dir = tempfile::tempdir().unwrap();
    let (log, poses) = simulated(dir.path(), "zigzag.csv");
    let bag = dir.path().join("named.mcap");
    let (ok, _, err) = run(&[
        "convert",
        "--ros2",
        "--in",
        s(&log),
        "--out",
        s(&bag),
        "--poses",
        s(&poses),
        "--namespace",
        "/auv1/lightpose",
        "--frames",
        "dock_light,auv1/base_link,world",
        "--site-heading-deg",
        "-30",
        "--site-ned-m",
        "12.5,-4,3.25",
    ]);
    assert!(ok, "{err}");
    let n = ok_poses(&poses);
    let script = root().join("tests/python/ros2bag_check.py");
    let args = [
        s(&bag),
        s(&poses),
        "--namespace",
        "/auv1/lightpose",
        "--frames",
        "dock_light,auv1/base_link,world",
        // (= : argparse takes "-30" for an option.)
        "--site=-30,12.5,-4,3.25",
    ];
    let line = lightpose_testkit::python::run_python(&py, &script, &args);
    assert_eq!(
        line,
        format!("pose={n} odom={n} tf={n} ok={n} static=1 diag=0")
    );

    // Flags refused on one line each, no bag left.
    let bad = dir.path().join("bad.mcap");
    for (flags, want) in [
        (
            &["--namespace", "lightpose"][..],
            "no absolute ROS 2 namespace",
        ),
        (&["--frames", "a,b"][..], "three frames"),
        (&["--frames", "a,/b,c"][..], "is no tf frame id"),
        (&["--frames", "a,b,a"][..], "tf would loop"),
        (
            &["--site-heading-deg", "30"][..],
            "needs --site-depth-m or --site-ned-m",
        ),
        (
            &["--site-heading-deg", "400", "--site-depth-m", "3"][..],
            "-360..=360",
        ),
        (
            &["--site-heading-deg", "30", "--site-ned-m", "1,2"][..],
            "N,E,D",
        ),
    ] {
        let mut a = vec!["convert", "--ros2", "--in", s(&log), "--out", s(&bad)];
        a.extend(["--poses", s(&poses)]);
        a.extend(flags);
        let (ok, _, err) = run(&a);
        assert!(!ok, "{flags:?}");
        assert!(err.contains(want), "{flags:?}: {err}");
        assert!(!bad.exists(), "{flags:?}");
    }
}

#[test]
fn bad_input_is_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (log, poses) = simulated(dir.path(), "zigzag.csv");
    let bag = dir.path().join("bad.mcap");
    let one_line = |err: &str, want: &str| {
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.starts_with("lightpose: ") && err.contains(want),
            "{err}"
        );
        assert!(!bag.exists(), "a refused conversion leaves no bag: {err}");
    };
    let (ok, err) = convert(&log, &bag, None);
    assert!(!ok);
    one_line(
        &err,
        "convert --ros2 of a JSONL log needs --poses POSES.jsonl",
    );
    // An MCAP recording without poses of its own.
    let bare = dir.path().join("bare.mcap");
    let (ok, _, err) = run(&["convert", "--in", s(&log), "--out", s(&bare)]);
    assert!(ok, "{err}");
    let (ok, err) = convert(&bare, &bag, None);
    assert!(!ok);
    one_line(
        &err,
        "bare.mcap: no pose on /lightpose/pose: give its POSE lines with --poses",
    );

    // Poses of another log: a seq past this log's frames, or the t of a
    // frame changed.
    let text = std::fs::read_to_string(&poses).unwrap();
    let last: &str = text.lines().rfind(|l| l.contains("\"POSE\"")).unwrap();
    let seq: u64 = serde_json::from_str::<serde_json::Value>(last).unwrap()["seq"]
        .as_u64()
        .unwrap();
    let mut v: serde_json::Value = serde_json::from_str(last).unwrap();
    v["seq"] = (seq + 5).into();
    let past = dir.path().join("past.jsonl");
    std::fs::write(&past, format!("{text}{v}\n")).unwrap();
    let (ok, err) = convert(&log, &bag, Some(&past));
    assert!(!ok);
    let n = text.lines().count() + 1;
    one_line(
        &err,
        &format!(
            "past.jsonl:{n}: POSE seq {} names no frame of {} (after its last frame {seq})",
            seq + 5,
            log.display()
        ),
    );

    let first = text.lines().find(|l| l.contains("\"POSE\"")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(first).unwrap();
    let t = v["t"].as_f64().unwrap();
    v["t"] = (t + 0.5).into();
    let moved = dir.path().join("moved.jsonl");
    let rest: Vec<&str> = text.lines().skip(1).collect();
    std::fs::write(&moved, format!("{v}\n{}\n", rest.join("\n"))).unwrap();
    let (ok, err) = convert(&log, &bag, Some(&moved));
    assert!(!ok);
    one_line(
        &err,
        &format!("moved.jsonl:1: POSE seq {} has t = {}", v["seq"], t + 0.5),
    );

    let empty = dir.path().join("empty.jsonl");
    std::fs::write(&empty, "").unwrap();
    let (ok, err) = convert(&log, &bag, Some(&empty));
    assert!(!ok);
    one_line(&err, "empty.jsonl: no POSE line");

    let (ok, err) = convert(&log, &dir.path().join("bag.db3"), Some(&poses));
    assert!(!ok);
    one_line(&err, "bag.db3: a ROS 2 bag is an MCAP");
}
