//! What the `lightpose` binary says when it refuses: one line that says
//! each thing once (a missing file's cause was printed twice, bench's
//! unknown estimator twice and a missing case file three times), and the
//! names `bench` and `montecarlo` take for the paper's cases.

mod common;

use common::{root, run_in as lightpose_in};
use std::path::Path;

fn config(p: &str) -> String {
    root().join("config").join(p).display().to_string()
}

/// A refusal: exit non-zero, stderr one line holding `once` exactly once.
fn refused_once(dir: &Path, args: &[&str], once: &str) -> String {
    let (ok, _, err) = lightpose_in(dir, args);
    assert!(!ok, "{args:?} succeeded: {err}");
    assert_eq!(err.lines().count(), 1, "{args:?}: {err:?}");
    assert_eq!(err.matches(once).count(), 1, "{args:?}: {err:?}");
    err
}

#[test]
fn a_missing_file_is_said_once() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let err = refused_once(
        d,
        &[
            "replay",
            "--calibration",
            "nope.toml",
            "--log",
            "x",
            "--out",
            "y",
        ],
        "No such file",
    );
    assert!(err.starts_with("lightpose: nope.toml: "), "{err:?}");
    let (scene, dive, cal) = (
        config("scenes/tank.toml"),
        config("trajectories/dive.csv"),
        config("calibration/tank.toml"),
    );
    let others: [&[&str]; 7] = [
        &[
            "simulate",
            "--scene",
            "nope.toml",
            "--trajectory",
            &dive,
            "--out",
            "o.jsonl",
        ],
        &[
            "simulate",
            "--scene",
            &scene,
            "--trajectory",
            "nope.csv",
            "--out",
            "o.jsonl",
        ],
        &["sweep", "--scene", "nope.toml", "--out", "o.jsonl"],
        &["crb", "--scene", &scene, "--trajectory", "nope.csv"],
        &[
            "montecarlo",
            "--scene",
            "nope.toml",
            "--trajectory",
            &dive,
            "--calibration",
            &cal,
            "--runs",
            "2",
        ],
        &[
            "montecarlo",
            "--scene",
            &scene,
            "--trajectory",
            &dive,
            "--calibration",
            "nope.toml",
            "--runs",
            "2",
        ],
        &[
            "fake-autopilot",
            "--scene",
            "nope.toml",
            "--trajectory",
            &dive,
        ],
    ];
    for args in others {
        let err = refused_once(d, args, "No such file");
        assert!(err.contains("nope."), "{args:?}: {err:?}");
    }
    // bench run where there is no config/: the case, the path and the
    // cause, each once.
    let err = refused_once(
        d,
        &["bench", "--runs", "2", "--case", "dive-tank"],
        "No such file",
    );
    assert_eq!(err.matches("config/scenes/tank.toml").count(), 1, "{err:?}");
}

#[test]
fn benchs_unknown_estimator_is_said_once() {
    let root = root().display().to_string();
    let err = refused_once(
        Path::new(&root),
        &[
            "bench",
            "--runs",
            "2",
            "--timing-runs",
            "1",
            "--case",
            "dive-tank",
            "--sensors",
            "none",
            "--estimators",
            "bogus",
        ],
        "unknown estimator \"bogus\"",
    );
    assert!(err.contains("(known: "), "{err:?}");
}

/// Each command takes the other's name of a case, and bench's CRB note
/// names the sensors of its set, not attitude and depth whatever the set.
#[test]
fn case_names_are_aliases_and_the_crb_note_names_the_set() {
    let dir = tempfile::tempdir().expect("tempdir");
    let root = root().display().to_string();
    let (ok, stdout, err) = lightpose_in(
        Path::new(&root),
        &[
            "bench",
            "--runs",
            "2",
            "--timing-runs",
            "1",
            "--case",
            "dive-clear",
            "--sensors",
            "attitude+dvl,dvl,all",
            "--estimators",
            "moments",
        ],
    );
    assert!(ok, "{err}");
    assert!(
        stdout.contains("### dive-tank — attitude + DVL (2 runs)"),
        "{stdout}"
    );
    let notes: Vec<&str> = stdout.lines().filter(|l| l.starts_with("CRB:")).collect();
    assert_eq!(notes.len(), 3, "{stdout}");
    assert!(notes[0].contains("(with attitude: the DVL"), "{}", notes[0]);
    assert!(
        notes[1].contains("(with no own sensor: the DVL"),
        "{}",
        notes[1]
    );
    assert!(
        notes[2].contains("(with attitude and depth: the DVL"),
        "{}",
        notes[2]
    );

    let out = dir.path().join("mc");
    let (ok, stdout, err) = lightpose_in(
        dir.path(),
        &[
            "montecarlo",
            "--scene",
            &config("scenes/harbour.toml"),
            "--trajectory",
            &config("trajectories/zigzag.csv"),
            "--calibration",
            &config("calibration/harbour.toml"),
            "--runs",
            "2",
            "--case",
            "zigzag-harbour",
            "--out",
            out.to_str().expect("utf-8 temp path"),
        ],
    );
    assert!(ok, "{err}");
    assert!(stdout.contains("case: zigzag-turbid;"), "{stdout}");
    // The help of each says which names are aliases.
    for (cmd, alias) in [("bench", "dive-clear"), ("montecarlo", "dive-tank")] {
        let (ok, help, err) = lightpose_in(dir.path(), &[cmd, "--help"]);
        assert!(ok, "{err}");
        assert!(help.contains("aliases"), "{cmd}: {help}");
        assert!(help.contains(alias), "{cmd}: {help}");
    }
}

/// A replay whose every pose is null (here the single-frame estimator told
/// a light threshold no frame reaches: every frame `no_light`) of a log
/// with truth says so: it had said "no truth in the log". (It used a
/// start-up σ of 1e-300, which the settings' checks now refuse.)
#[test]
fn a_replay_without_a_value_to_compare_says_why_there_is_no_report() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let cal = d.join("cal.toml");
    let text = std::fs::read_to_string(config("calibration/tank.toml")).expect("calibration");
    std::fs::write(&cal, text + "\n[estimator.model]\nmin_signal_sigma = 1e6\n")
        .expect("write calibration");
    let log = d.join("dive.jsonl");
    let (ok, _, err) = lightpose_in(
        d,
        &[
            "simulate",
            "--scene",
            &config("scenes/tank.toml"),
            "--trajectory",
            &config("trajectories/dive.csv"),
            "--seed",
            "1",
            "--out",
            log.to_str().unwrap(),
        ],
    );
    assert!(ok, "{err}");
    let (ok, _, err) = lightpose_in(
        d,
        &[
            "replay",
            "--calibration",
            cal.to_str().unwrap(),
            "--log",
            log.to_str().unwrap(),
            "--out",
            d.join("poses.jsonl").to_str().unwrap(),
            "--estimator",
            "model",
            "--report",
        ],
    );
    assert!(ok, "{err}");
    assert!(
        err.contains("41 frames carry truth but no estimate gave a value to compare"),
        "{err}"
    );
    assert!(!err.contains("no truth in the log"), "{err}");
}
