//! Recording names: `lightposed-<counter>-<UTC stamp>.<ext>`. The counter
//! orders the recordings, not the stamp: the clock of a vehicle computer
//! without an RTC steps (it boots at 1970 or at a saved value, then NTP or
//! GPS sets it), so a new dive's files may carry an earlier time than an
//! old one's, or the same. The counter goes on across runs (the highest
//! in the directory + 1) and is zero-padded to [`WIDTH`] digits so that
//! names sort as their counters; past 999999 it takes more digits and is
//! compared as a number. The stamp is there to be read only.

use crate::outputs::recfile::Opener;
use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

const PREFIX: &str = "lightposed-";

/// The counter's digits at least.
pub(super) const WIDTH: usize = 6;

/// The highest counter taken as one: a name with a larger number (made by
/// hand) is unnumbered, so that the next counter can never run out.
const MAX_COUNTER: u64 = 999_999_999_999_999;

/// How many taken names a new file passes over before giving up: names
/// are only taken by a file that appears between the directory's listing
/// and the creation (another process), so one is already rare.
const CLASH_TRIES: u32 = 64;

/// Where a recording stands among the directory's, oldest first (the
/// derived order): the unnumbered ones (the old naming
/// `lightposed-YYYYmmddTHHMMSSZ-NNNN`, from before the counter), by name
/// among themselves, before every numbered one, by counter.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Rank {
    Unnumbered(String),
    Numbered(u64, String),
}

/// The rank of `name` if it is one of this daemon's recordings
/// (`lightposed-*.jsonl` / `.mcap`).
pub(super) fn rank(name: &str) -> Option<Rank> {
    let rest = name.strip_prefix(PREFIX)?;
    if !(rest.ends_with(".jsonl") || rest.ends_with(".mcap")) {
        return None;
    }
    let digits = rest.split_once('-').map_or("", |(d, _)| d);
    // parse alone would take a sign.
    let counter = digits
        .bytes()
        .all(|b| b.is_ascii_digit())
        .then(|| digits.parse::<u64>().ok())
        .flatten()
        .filter(|&n| n <= MAX_COUNTER);
    Some(match counter {
        Some(n) => Rank::Numbered(n, name.to_owned()),
        None => Rank::Unnumbered(name.to_owned()),
    })
}

/// The name of recording `counter`, opened at `stamp` (UTC).
pub(super) fn file_name(counter: u64, stamp: &str, ext: &str) -> String {
    format!("{PREFIX}{counter:0WIDTH$}-{stamp}.{ext}")
}

/// The highest counter of this daemon's recordings in `dir` (0 if none).
pub(super) fn highest(dir: &Path) -> io::Result<u64> {
    let mut top = 0;
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        if let Some(Rank::Numbered(n, _)) = e.file_name().to_str().and_then(rank) {
            top = top.max(n);
        }
    }
    Ok(top)
}

/// A new recording in `dir` with `open`, numbered from `first` on: a name
/// already taken is passed over for the next number, so no file is ever
/// overwritten and the frame waiting for the file is not lost. Its
/// counter, path and file.
pub(super) fn create(
    dir: &Path,
    first: u64,
    stamp: &str,
    ext: &str,
    open: Opener,
) -> Result<(u64, PathBuf, File), String> {
    let mut counter = first;
    for _ in 0..CLASH_TRIES {
        let path = dir.join(file_name(counter, stamp, ext));
        match open(&path) {
            Ok(f) => return Ok((counter, path, f)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                tracing::debug!(
                    "recording: {} exists, taking the next number",
                    path.display()
                );
                counter = counter.saturating_add(1);
            }
            Err(e) => return Err(format!("{}: {e}", path.display())),
        }
    }
    Err(format!(
        "{}: recordings {first} to {} all exist (another process is writing there?)",
        dir.display(),
        counter.saturating_sub(1)
    ))
}
