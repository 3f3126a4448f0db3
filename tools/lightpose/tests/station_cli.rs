//! `lightpose calibrate --station` (issue 41 item 2, spec v3) end to end:
//! `lightpose sweep` of `shared/spec/dock-example.toml` spans a docking
//! approach (243 poses, BURST lines), the station file is read and
//! checked before any sweep, and the calibration written carries
//! `[station]` with each beacon's fitted light and survey check, and a
//! `[physical]` the estimators load.

mod common;

use common::{root, run, s};
use std::path::{Path, PathBuf};

/// `shared/spec/dock-example.toml` beside the repository (a worktree sits
/// deeper than main).
fn dock() -> PathBuf {
    root()
        .ancestors()
        .map(|a| a.join("shared/spec/dock-example.toml"))
        .find(|p| p.exists())
        .expect("shared/spec/dock-example.toml beside the repository")
}

const STATION: &str = r#"name = "dock"

[[beacons]]
id = "top"
position_m = [0.0, 0.0, 0.5]
mod_hz = 200.0

[[beacons]]
id = "starboard"
position_m = [0.0, 0.5, 0.0]
mod_hz = 250.0

[[beacons]]
id = "bottom"
position_m = [0.0, 0.0, -0.5]
mod_hz = 400.0

[[beacons]]
id = "port"
position_m = [0.0, -0.5, 0.0]
axis_yaw_deg = -5.0
mod_hz = 500.0
"#;

fn sweep(dir: &Path) -> PathBuf {
    let log = dir.join("dock-sweep.jsonl");
    let (ok, _, err) = run(&[
        "sweep",
        "--scene",
        s(&dock()),
        "--samples",
        "3",
        "--out",
        s(&log),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("729 frames (all sweep)"), "{err}");
    log
}

#[test]
fn a_station_is_calibrated_from_its_sweep() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = sweep(dir.path());
    let station = dir.path().join("station.toml");
    std::fs::write(&station, STATION).expect("write");
    let cal = dir.path().join("cal.toml");
    let (ok, _, err) = run(&[
        "calibrate",
        "--station",
        s(&station),
        "--sweep",
        s(&log),
        "--out",
        s(&cal),
    ]);
    eprintln!("{err}");
    assert!(ok, "{err}");
    assert!(
        err.contains("station dock (4 beacons, 243 poses, 729 frames"),
        "{err}"
    );
    for id in ["top", "starboard", "bottom", "port"] {
        assert!(err.contains(&format!("beacon {id}: residual")), "{err}");
    }
    assert!(
        !err.contains("warning"),
        "a true survey is consistent: {err}"
    );
    // The estimators are ok where the sweeps went (1.5–8 m, a tenth
    // wider), not the single beacon's default [3, 12] m.
    assert!(
        err.contains("x_range: [1.36, 8.80] m (the sweeps' span"),
        "{err}"
    );
    let text = std::fs::read_to_string(&cal).expect("calibration");
    let table: toml::Table = text.parse().expect("calibration TOML");
    for part in ["model", "tracker"] {
        let r = &table["estimator"][part]["x_range"];
        assert_eq!(r.as_array().map(Vec::len), Some(2), "{part}: {r}");
        let lo = r[0].as_float().unwrap_or(f64::NAN);
        assert!((lo - 1.5 / 1.1).abs() < 1e-9, "{part}: {r}");
    }
    for t in [
        "[physical]",
        "[station]",
        "[[station.beacons]]",
        "[station.beacons.survey_check]",
    ] {
        assert!(text.contains(t), "{t} missing");
    }
    // The calibration loads where every estimator reads it: replay.
    let poses = dir.path().join("poses.jsonl");
    let (ok, _, err) = run(&[
        "replay",
        "--calibration",
        s(&cal),
        "--log",
        s(&log),
        "--out",
        s(&poses),
    ]);
    assert!(ok, "{err}");

    // A docking approach replayed on it: the tracker on every beacon's
    // image, its POSE lines in the station's frame with the beacons seen.
    let (approach, poses) = (
        dir.path().join("approach.jsonl"),
        dir.path().join("a.jsonl"),
    );
    let traj = root().join("config/trajectories/dock.csv");
    let (ok, _, err) = run(&[
        "simulate",
        "--scene",
        s(&dock()),
        "--trajectory",
        s(&traj),
        "--out",
        s(&approach),
        "--seed",
        "3",
    ]);
    assert!(ok, "{err}");
    let (ok, _, err) = run(&[
        "replay",
        "--calibration",
        s(&cal),
        "--log",
        s(&approach),
        "--out",
        s(&poses),
    ]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&poses).expect("poses");
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("POSE json"))
        .collect();
    assert!(lines.len() > 20, "{} poses", lines.len());
    let ok_poses: Vec<&serde_json::Value> = lines.iter().filter(|p| p["status"] == "ok").collect();
    assert!(
        ok_poses.len() * 10 >= lines.len() * 8,
        "{} of {} ok",
        ok_poses.len(),
        lines.len()
    );
    for p in &lines {
        assert_eq!(p["estimator"], "tracker", "{p}");
        assert_eq!(p["frame"], "dock", "{p}");
    }
    for p in &ok_poses {
        let seen = p["beacons_seen"].as_array().expect("beacons_seen");
        // Far out (7–8 m) a dim beacon may fall under the threshold;
        // nearer every one is seen.
        let near = p["x"].as_f64().is_some_and(|x| x < 6.5);
        assert!(seen.len() >= if near { 4 } else { 1 }, "{p}");
        assert!(seen
            .iter()
            .all(|b| ["top", "starboard", "bottom", "port"].contains(&b.as_str().unwrap_or(""))));
        assert!(p["roll"].is_number() && p["std"]["roll"].is_number(), "{p}");
    }
}

#[test]
fn a_bad_station_file_is_refused_before_any_sweep() {
    let dir = tempfile::tempdir().expect("tempdir");
    let station = dir.path().join("station.toml");
    std::fs::write(
        &station,
        STATION.replace("mod_hz = 400.0", "mod_hz = 250.0"),
    )
    .expect("write");
    let cal = dir.path().join("cal.toml");
    let missing = dir.path().join("no-such-sweep.jsonl");
    let (ok, _, err) = run(&[
        "calibrate",
        "--station",
        s(&station),
        "--sweep",
        s(&missing),
        "--out",
        s(&cal),
    ]);
    assert!(!ok);
    let want = format!(
        "{}:16: [[beacons]] #3 mod_hz: 250 Hz is also beacon #2's",
        station.display()
    );
    assert!(err.contains(&want), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!cal.exists());
}

#[test]
fn a_station_the_log_does_not_have_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = sweep(dir.path());
    let station = dir.path().join("station.toml");
    std::fs::write(&station, STATION.replace("\"port\"", "\"portside\"")).expect("write");
    let cal = dir.path().join("cal.toml");
    let (ok, _, err) = run(&[
        "calibrate",
        "--station",
        s(&station),
        "--sweep",
        s(&log),
        "--out",
        s(&cal),
    ]);
    assert!(!ok);
    assert!(
        err.contains("the log has no beacon \"portside\" of station dock"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}
