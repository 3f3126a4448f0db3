//! What the `lightpose` binary's integration tests share: running it
//! (to its end, or with a time limit) and keeping what it printed.
#![allow(dead_code)]

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

pub fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

/// A temporary path as an argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// Run `lightpose args` to its end: (success, stdout, stderr).
pub fn run(args: &[impl AsRef<OsStr>]) -> (bool, String, String) {
    finished(Command::new(env!("CARGO_BIN_EXE_lightpose")).args(args))
}

/// [`run`] in the directory `dir`.
pub fn run_in(dir: &Path, args: &[impl AsRef<OsStr>]) -> (bool, String, String) {
    finished(
        Command::new(env!("CARGO_BIN_EXE_lightpose"))
            .args(args)
            .current_dir(dir),
    )
}

fn finished(c: &mut Command) -> (bool, String, String) {
    let out = c.output().expect("runs lightpose");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// What a run printed and how it ended.
pub struct Run {
    pub code: Option<i32>,
    pub out: String,
    pub err: String,
}

/// Run `lightpose args`, killed if it runs longer than `within` (then the
/// test fails: a refusal must come at once).
pub fn lightpose(args: &[&str], within: Duration) -> Run {
    let dir = tempfile::tempdir().expect("tempdir");
    let (out_path, err_path) = (dir.path().join("stdout"), dir.path().join("stderr"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_lightpose"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .stdout(std::fs::File::create(&out_path).expect("stdout file"))
        .stderr(std::fs::File::create(&err_path).expect("stderr file"))
        .stdin(Stdio::null())
        .spawn()
        .expect("runs lightpose");
    let t0 = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().expect("wait") {
            break st;
        }
        if t0.elapsed() > within {
            let _ = child.kill();
            let _ = child.wait();
            panic!("lightpose {args:?} still running after {within:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Run {
        code: status.code(),
        out: std::fs::read_to_string(&out_path).unwrap_or_default(),
        err: std::fs::read_to_string(&err_path).unwrap_or_default(),
    }
}

/// A small sweep of `scene` into `dir`, as (sweep, dark) paths.
pub fn sweep(dir: &Path, scene: &Path) -> (PathBuf, PathBuf) {
    let sw = dir.join("sweep.jsonl");
    let dk = dir.join("dark.jsonl");
    for (kind, n, out) in [("all", "8", &sw), ("dark", "200", &dk)] {
        let (ok, _, err) = run(&[
            "sweep",
            "--scene",
            s(scene),
            "--kind",
            kind,
            "--samples",
            n,
            "--seed",
            "5",
            "--out",
            s(out),
        ]);
        assert!(ok, "{err}");
    }
    (sw, dk)
}

/// A replay of `log` into `out` with the tank's calibration and `extra`
/// options, within 30 s.
pub fn replay(log: &Path, out: &Path, extra: &[&str]) -> Run {
    let c = root().join("config/calibration/tank.toml");
    let mut a = vec![
        "replay",
        "--calibration",
        s(&c),
        "--log",
        s(log),
        "--out",
        s(out),
    ];
    a.extend_from_slice(extra);
    lightpose(&a, Duration::from_secs(30))
}
