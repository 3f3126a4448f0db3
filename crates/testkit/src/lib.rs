//! Test set-up shared by the test binaries of lightpose's crates, so that
//! each exists once instead of a copy per crate: a counting global
//! allocator, a capture of tracing's log lines, pseudo-terminals standing
//! for serial ports, the pinned Python of `tools/pyenv.sh`, a stand-in
//! DVL's reports and a damaged regression log.
//!
//! A dev-dependency only (never published, never in a shipped binary); it
//! depends on no lightpose crate, so that any of them can use it.

pub mod alloc;
pub mod data;
pub mod dvl;
pub mod logs;
pub mod pty;
pub mod python;

use std::path::{Path, PathBuf};

/// The workspace's root (the shipped configs, `tests/data`, `tools/`).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}
