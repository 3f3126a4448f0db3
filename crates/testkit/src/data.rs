//! Regression logs damaged on purpose, made from the shipped ones.

use std::path::{Path, PathBuf};

/// tests/data/dive.jsonl with one corrupt `seq` (frame 4, the 6th line,
/// says 500), written in `dir`: its path and its number of frames.
pub fn dive_with_a_corrupt_seq(dir: &Path) -> (PathBuf, usize) {
    let text = std::fs::read_to_string(crate::root().join("tests/data/dive.jsonl")).expect("log");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    assert!(lines[5].contains("\"seq\":4,"), "{}", lines[5]);
    lines[5] = lines[5].replacen("\"seq\":4,", "\"seq\":500,", 1);
    let log = dir.join("glitch.jsonl");
    std::fs::write(&log, lines.join("\n") + "\n").expect("write");
    (log, lines.len() - 1)
}
