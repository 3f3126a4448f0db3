//! Results printed to a reader that has gone (`lightpose crb … | head`,
//! `| true`): the audit found a panic ("failed printing to stdout: Broken
//! pipe", exit 101). Now the command ends quietly with success, as Unix
//! tools do. The real binary, its stdout a pipe whose reader is closed.

mod common;

use common::{root, s};
use std::process::{Command, Output, Stdio};

/// Run `lightpose args` with stdout a pipe nobody reads.
fn into_closed_pipe(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_lightpose"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .stdout(writer)
        .output()
        .expect("runs lightpose")
}

/// Exit 0 and nothing on stderr of a panic or a write.
fn quiet_success(args: &[&str]) -> String {
    let out = into_closed_pipe(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert!(!err.contains("Broken pipe"), "{args:?}: {err}");
    err
}

#[test]
fn crb_into_a_closed_pipe_ends_quietly() {
    let (sc, tr) = (
        root().join("config/scenes/tank.toml"),
        root().join("config/trajectories/zigzag.csv"),
    );
    quiet_success(&["crb", "--scene", s(&sc), "--trajectory", s(&tr)]);
}

/// The table is still written to `--out`: the file comes before stdout.
#[test]
fn bench_into_a_closed_pipe_ends_quietly_and_writes_its_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let md = dir.path().join("bench.md");
    let r = root();
    quiet_success(&[
        "bench",
        "--root",
        s(&r),
        "--runs",
        "3",
        "--case",
        "dive-tank",
        "--estimators",
        "moments",
        "--sensors",
        "none",
        "--timing-runs",
        "1",
        "--out",
        s(&md),
    ]);
    let table = std::fs::read_to_string(&md).expect("the --out table");
    assert!(table.contains("moments"), "{table}");
}

#[test]
fn montecarlo_into_a_closed_pipe_ends_quietly_with_its_results() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("mc");
    let (sc, tr, cal) = (
        root().join("config/scenes/tank.toml"),
        root().join("config/trajectories/dive.csv"),
        root().join("config/calibration/tank.toml"),
    );
    quiet_success(&[
        "montecarlo",
        "--scene",
        s(&sc),
        "--trajectory",
        s(&tr),
        "--calibration",
        s(&cal),
        "--runs",
        "4",
        "--out",
        s(&out),
    ]);
    assert!(out.join("summary.md").is_file());
}
