//! A result printed to a reader that has gone (`lightposed --bench | head`,
//! `| true`): the audit found a panic ("failed printing to stdout: Broken
//! pipe", exit 101). Now the command ends quietly with success, as Unix
//! tools do. The real binary, its stdout a pipe whose reader is closed.

mod common;
use common::shipped;

use std::process::{Command, Stdio};

/// Run `lightposed args` with stdout a pipe nobody reads: exit 0 and no
/// panic or write failure said.
fn quiet_success(args: &[&std::ffi::OsStr]) {
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_lightposed"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .stdout(writer)
        .output()
        .expect("runs lightposed");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert!(!err.contains("Broken pipe"), "{args:?}: {err}");
}

#[test]
fn bench_into_a_closed_pipe_ends_quietly() {
    quiet_success(&["--bench".as_ref(), "--frames".as_ref(), "1000".as_ref()]);
}

#[test]
fn check_config_into_a_closed_pipe_ends_quietly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (scene, traj, cal) = shipped();
    let p = dir.path().join("ok.toml");
    let text = format!(
        "rate_hz = 20.0\nestimator = \"moments\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n",
        cal.display(),
        scene.display(),
        traj.display()
    );
    std::fs::write(&p, text).expect("config");
    quiet_success(&["--check-config".as_ref(), p.as_os_str()]);
}
