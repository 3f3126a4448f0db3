//! Where the keys that name something outside the file are written: a
//! scene or trajectory, a replayed log, the recording directory, an
//! address to listen on. What is wrong with those shows only against this
//! machine (at `--check-config` and at a start, `wiring::check` and
//! [`super::machine`]), and is then said at the key's line like every
//! refusal of the file itself.

use super::KeyAt;
use std::collections::BTreeMap;

/// `[backend] scene`.
pub const SCENE: &str = "backend.scene";
/// `[backend] trajectory`.
pub const TRAJECTORY: &str = "backend.trajectory";
/// `[backend] log` (replay).
pub const LOG: &str = "backend.log";
/// `[recording] dir` (the table's line when the default is taken).
pub const RECORDING_DIR: &str = "recording.dir";
/// `[attitude] listen` (the table's line when the default is taken).
pub const ATTITUDE_LISTEN: &str = "attitude.listen";
/// `[foxglove] listen` (the table's line when the default is taken).
pub const FOXGLOVE_LISTEN: &str = "foxglove.listen";
/// `[web] listen`.
pub const WEB_LISTEN: &str = "web.listen";
/// `[mavlink] connection`.
pub const MAVLINK: &str = "mavlink.connection";
/// `[outputs.multicast] group`.
pub const MULTICAST_GROUP: &str = "outputs.multicast.group";
/// `[outputs.multicast] interface`.
pub const MULTICAST_INTERFACE: &str = "outputs.multicast.interface";

/// The key of the `i`th of `outputs.destinations`, for [`Places::of`].
pub fn destination(i: usize) -> String {
    format!("outputs.destinations[{i}]")
}

/// The lines of such keys in one file.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Places {
    file: String,
    lines: BTreeMap<String, usize>,
}

impl Places {
    pub(super) fn new(file: &str) -> Places {
        Places {
            file: file.to_string(),
            lines: BTreeMap::new(),
        }
    }

    pub(super) fn set(&mut self, key: impl Into<String>, line: usize) {
        self.lines.insert(key.into(), line);
    }

    /// Where `key` is written: `FILE:LINE`, or the file alone for a key
    /// the file does not hold.
    pub fn of(&self, key: &str) -> KeyAt {
        KeyAt {
            file: self.file.clone(),
            line: self.lines.get(key).copied(),
        }
    }
}

/// A table with an `enabled` key: checked whether it is on or off, so that
/// a mistake in it is met now and not on the day it is switched on, and
/// kept only when on. The places of a table that is off are not kept:
/// nothing of it is bound or opened.
pub(super) fn when_on<T, E>(
    enabled: bool,
    at: &mut Places,
    check: impl FnOnce(&mut Places) -> Result<T, E>,
) -> Result<Option<T>, E> {
    let mut off = Places::default();
    let checked = check(if enabled { at } else { &mut off })?;
    Ok(enabled.then_some(checked))
}
