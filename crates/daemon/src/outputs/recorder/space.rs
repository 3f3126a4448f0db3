//! Room on the recording's disk: free space (`statvfs`, what the daemon's
//! user may still write) is checked before a file starts and every
//! [`EVERY`] while one is open. Below the free space to keep
//! (`keep_free_mb`, else [`default_floor`] of the filesystem's size), no
//! file is started and the open one is completed while it still can be, so
//! a full disk never leaves a recording cut nor empty files behind. With
//! `keep_free_mb` or `max_total_mb` the oldest recordings in the directory
//! (this daemon's names, `lightposed-*.jsonl` / `.mcap`) are deleted first
//! to make room, oldest by the counter in their names, not by their time
//! (the wall clock may step back: [`super::names`]); the open file never is.

use super::names::{self, Rank};
use super::RecStats;
use crate::config::Recording;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::time::Duration;

/// The least free space kept when `keep_free_mb` is not given: far more
/// than a few seconds of recording, an MCAP chunk and a summary.
pub const MIN_FREE: u64 = 32 << 20;

/// The most kept free then: room enough for the system's own writes.
pub const MAX_FLOOR: u64 = 1 << 30;

/// Free space kept when `keep_free_mb` is not given (recording pauses
/// there; nothing is pruned unasked): 2 % of the filesystem, within
/// [`MIN_FREE`]..=[`MAX_FLOOR`]. A fixed 32 MiB on a vehicle's SD-card root
/// (8–64 GB, shared with journald, BlueOS and docker) left the system
/// nothing: 2 % is 160 MB of 8 GB, 640 MB of 32 GB; past 50 GB the 1 GiB
/// cap, as a big disk's system needs no more.
pub fn default_floor(fs_bytes: u64) -> u64 {
    (fs_bytes / 50).clamp(MIN_FREE, MAX_FLOOR)
}

/// How often the room is checked while a file is open.
pub const EVERY: Duration = Duration::from_secs(2);

const MIB: f64 = 1024.0 * 1024.0;

pub(crate) struct Space {
    dir: PathBuf,
    /// Bytes to keep free: below, nothing is written (0: no check);
    /// `None`: [`default_floor`] of the filesystem.
    /// Set (not 0), the oldest recordings are deleted to keep it free.
    pub(crate) keep_free: Option<u64>,
    /// The recordings' total kept under this, oldest deleted first.
    max_total: Option<u64>,
    /// A recording could not be deleted (said once, not every check).
    stuck: AtomicBool,
}

/// A recording in the directory.
struct Old {
    path: PathBuf,
    size: u64,
}

impl Space {
    pub(crate) fn new(cfg: &Recording) -> Space {
        Space {
            dir: cfg.dir.clone(),
            keep_free: cfg.keep_free_bytes,
            max_total: cfg.max_total_bytes,
            stuck: AtomicBool::new(false),
        }
    }

    /// Prune as configured (never `current`), then whether a file may be
    /// written: why not, when it may not.
    pub(crate) fn make_room(&self, current: Option<&Path>, stats: &RecStats) -> Result<(), String> {
        if let Some(max) = self.max_total {
            let all = recordings(&self.dir);
            let mut total: u64 = all.iter().map(|o| o.size).sum();
            for old in all.iter().filter(|o| Some(o.path.as_path()) != current) {
                if total <= max {
                    break;
                }
                if self.prune(old, "max_total_mb", stats) {
                    total -= old.size;
                }
            }
        }
        if self.keep_free == Some(0) {
            return Ok(());
        }
        // Unknown: the disk says so itself when it is full.
        let Ok((mut free, keep)) = self.room() else {
            return Ok(());
        };
        if free < keep && self.keep_free.is_some_and(|b| b > 0) {
            for old in recordings(&self.dir) {
                if free >= keep {
                    break;
                }
                if Some(old.path.as_path()) != current && self.prune(&old, "keep_free_mb", stats) {
                    free = free_bytes(&self.dir).unwrap_or(free.saturating_add(old.size));
                }
            }
        }
        if free >= keep {
            return Ok(());
        }
        let key = match self.keep_free {
            Some(_) => "recording.keep_free_mb",
            None => "recording.keep_free_mb unset: 2 % of the disk, 32 MiB..1 GiB",
        };
        Err(format!(
            "{}: {:.1} MiB free, less than the {:.1} MiB kept free ({key}): no recording until there is room",
            self.dir.display(),
            free as f64 / MIB,
            keep as f64 / MIB
        ))
    }

    /// Bytes free on the disk now, and bytes to keep free there.
    pub(crate) fn room(&self) -> io::Result<(u64, u64)> {
        let (free, size) = free_and_size(&self.dir)?;
        Ok((free, self.keep_free.unwrap_or_else(|| default_floor(size))))
    }
}

impl Space {
    /// Delete `old` (for `key`); whether it went.
    fn prune(&self, old: &Old, key: &str, stats: &RecStats) -> bool {
        match std::fs::remove_file(&old.path) {
            Ok(()) => {
                stats.pruned.fetch_add(1, Relaxed);
                tracing::info!(
                    "recording: deleted {} ({:.1} MiB) for {key}",
                    old.path.display(),
                    old.size as f64 / MIB
                );
                true
            }
            Err(e) => {
                let what = format!(
                    "recording: cannot delete {} for {key}: {e}",
                    old.path.display()
                );
                if self.stuck.swap(true, Relaxed) {
                    tracing::debug!("{what}");
                } else {
                    tracing::warn!("{what}");
                }
                false
            }
        }
    }
}

/// Bytes the daemon's user may still write on the filesystem of `dir`.
pub fn free_bytes(dir: &Path) -> io::Result<u64> {
    free_and_size(dir).map(|(free, _)| free)
}

/// Bytes the daemon's user may still write on the filesystem of `dir`, and
/// the filesystem's size.
fn free_and_size(dir: &Path) -> io::Result<(u64, u64)> {
    let s = nix::sys::statvfs::statvfs(dir).map_err(io::Error::from)?;
    // 32-bit types on 32-bit ARM, 64-bit here.
    #[allow(clippy::useless_conversion)]
    let (avail, blocks, unit) = (
        u64::from(s.blocks_available()),
        u64::from(s.blocks()),
        u64::from(s.fragment_size()),
    );
    Ok((avail.saturating_mul(unit), blocks.saturating_mul(unit)))
}

/// This daemon's recordings in `dir`, oldest first: by their counter
/// (after those of the old naming, which had none), see [`Rank`].
fn recordings(dir: &Path) -> Vec<Old> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut found: Vec<(Rank, Old)> = entries
        .flatten()
        .filter_map(|e| {
            let rank = names::rank(e.file_name().to_str()?)?;
            let meta = e.metadata().ok().filter(|m| m.is_file())?;
            let old = Old {
                path: e.path(),
                size: meta.len(),
            };
            Some((rank, old))
        })
        .collect();
    found.sort_by(|a, b| a.0.cmp(&b.0));
    found.into_iter().map(|(_, o)| o).collect()
}
