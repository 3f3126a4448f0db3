//! The Python the tests run independent implementations with (the `mcap`
//! reader, pymavlink, a WebSocket client): `tools/pyenv.sh` makes the venv
//! under target/ with the pinned packages of tests/python/requirements.txt.
//! Without Python the test fails with pyenv's one line: never a skip.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The venv's python, or a panic with tools/pyenv.sh's line of failure.
pub fn python() -> PathBuf {
    let out = Command::new(crate::root().join("tools/pyenv.sh"))
        .output()
        .expect("tools/pyenv.sh runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr).trim()
    );
    PathBuf::from(String::from_utf8_lossy(&out.stdout).trim())
}

/// Run `script` with `args` under `py`; its stdout, trimmed (it must
/// succeed, else its stderr fails the test).
pub fn run_python(py: &Path, script: &Path, args: &[impl AsRef<OsStr>]) -> String {
    let out = Command::new(py)
        .arg(script)
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}: {}",
        script.display(),
        String::from_utf8_lossy(&out.stderr).trim()
    );
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}
