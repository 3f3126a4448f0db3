//! Intensity logs in every container lightpose reads and writes — JSON
//! Lines (FORMATS.md, core's `LogReader`/`LogWriter`) and MCAP, the
//! robotics world's recording format that Foxglove opens — behind one
//! reader interface (core's [`FrameLog`]), one opener ([`open`]) and one
//! writer interface ([`LogSink`], [`create`]).
//!
//! It sits between core and everything that reads or records logs (hal,
//! pipeline, daemon, tools), so that each of them reads MCAP as it reads
//! JSONL: the same frames, bit for bit.
//!
//! MCAP layout (see [`schema`] for the channels): the HEADER line in a
//! metadata record; each frame on `/lightpose/frame` as exactly its JSONL
//! line, each estimate on `/lightpose/pose` as its POSE object, the daemon's
//! STATUS on `/lightpose/status`, all JSON with jsonschema schemas; and the
//! same data in Foxglove's well-known types (`foxglove.RawImage`,
//! `foxglove.PoseInFrame`, `foxglove.FrameTransform`) so that Foxglove's
//! panels show a recording as it is (docs/foxglove.md). Log time is the
//! frame's t in nanoseconds; t < 0 is refused. Spec v3's frames have
//! channels of their own, declared at their first message: a BURST's raw
//! samples binary on `/lightpose/burst` ([`burst`]: 2 bytes a sample where
//! its JSON line spends 4–5), a demodulated frame's line on
//! `/lightpose/demodulated`.
//!
//! Chunks are uncompressed. The `mcap` crate's zstd and lz4 are C libraries
//! that the ARM cross builds would have to compile; a frame is a few
//! hundred bytes of JSON, a day at 5 Hz about 0.6 GB uncompressed, and a
//! recording that needs to be small compresses well afterwards (`mcap
//! compress`, or gzip). Uncompressed chunks also cost no CPU on a small
//! board and cannot be lost to a torn compression stream. Writing is
//! append-only and chunked, so a file cut by a power loss is readable up
//! to its last complete chunk.

pub mod burst;
pub mod convert;
pub mod encode;
pub mod foxglove;
mod lines;
pub mod read;
pub mod recover;
pub mod ros2bag;
pub mod ros2msg;
pub mod schema;
pub mod sink;
mod tap;
pub mod write;

pub use convert::{convert, ConvertError, ConvertSummary};
pub use encode::{Channel, Encoder, Message};
pub use lightpose_core::{Cut, FrameLog, LogError};
pub use lines::RECORD_LIMIT;
pub use read::McapReader;
pub use recover::{recover, RecoverError, RecoverOptions, RecoverSummary};
pub use ros2bag::convert::{convert_ros2, Ros2Summary};
pub use ros2bag::recording::Ros2Recording;
pub use ros2bag::{Ros2Bag, Ros2BagOptions};
pub use sink::{create, LogSink};
pub use tap::LineTap;
pub use write::{mcap_end, McapOptions, McapWriter, WriteError, MCAP_END_BYTES};

use lightpose_core::{Frame, LogHeader, LogReader};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

/// Whether `a` and `b` name one existing file, however spelled (`./a`, a
/// symlink, a hard link): a command must refuse to write its output over
/// its own input, since creating the output truncates it before a line is
/// read. A path that does not exist (yet) is no other file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    // Device and inode: also catches a hard link, which canonical paths miss.
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        match (a.canonicalize(), b.canonicalize()) {
            (Ok(x), Ok(y)) => x == y,
            _ => false,
        }
    }
}

/// Whether `a` and `b` name one file, or one place for a file not yet
/// written (the same name in the same folder): two outputs given the same
/// name would each truncate the other's lines.
pub fn same_place(a: &Path, b: &Path) -> bool {
    let resolved = |p: &Path| {
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        Some(dir.canonicalize().ok()?.join(p.file_name()?))
    };
    same_file(a, b) || resolved(a).is_some_and(|x| Some(x) == resolved(b))
}

/// The containers of an intensity log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Jsonl,
    Mcap,
}

impl Format {
    /// The container a path's extension names (`.jsonl`, `.mcap`).
    pub fn of_path(path: &Path) -> Option<Format> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "jsonl" => Some(Format::Jsonl),
            "mcap" => Some(Format::Mcap),
            _ => None,
        }
    }
}

/// Whether a file starts with the MCAP magic.
fn has_mcap_magic(path: &Path) -> std::io::Result<bool> {
    let mut magic = [0u8; 8];
    let mut f = std::fs::File::open(path)?;
    let mut n = 0;
    while n < magic.len() {
        match f.read(&mut magic[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n == magic.len() && magic[..] == *mcap::MAGIC)
}

/// An intensity log file opened in its container.
pub enum LogFile {
    Jsonl(Box<LogReader<LineTap<BufReader<File>>>>),
    Mcap(Box<McapReader<BufReader<File>>>),
}

impl LogFile {
    /// Open an intensity log, JSONL or MCAP by its extension (a path with
    /// another extension is told by its content). A `.mcap` without the
    /// MCAP magic, or a `.jsonl` with it, is refused with one line.
    pub fn open(path: &Path) -> Result<LogFile, LogError> {
        let name = path.display().to_string();
        let magic = has_mcap_magic(path).map_err(|err| LogError::Io {
            name: name.clone(),
            err,
        })?;
        let refuse = |msg: &str| LogError::at(name.clone(), 0, msg, true);
        match (Format::of_path(path), magic) {
            (Some(Format::Jsonl), true) => Err(refuse(
                "an MCAP file (its magic) named .jsonl: rename it .mcap",
            )),
            (Some(Format::Mcap), false) => Err(refuse(
                "not an MCAP file (no MCAP magic), though named .mcap",
            )),
            (_, true) => Ok(LogFile::Mcap(Box::new(McapReader::open(path)?))),
            (_, false) => {
                let f = File::open(path).map_err(|err| LogError::Io {
                    name: name.clone(),
                    err,
                })?;
                let src = LineTap::new(BufReader::with_capacity(1 << 16, f));
                Ok(LogFile::Jsonl(Box::new(LogReader::new(src, name.clone())?)))
            }
        }
    }

    pub fn format(&self) -> Format {
        match self {
            LogFile::Jsonl(_) => Format::Jsonl,
            LogFile::Mcap(_) => Format::Mcap,
        }
    }

    /// The text of the line or message read last (after opening: the
    /// header; after a frame: that frame), with its newline.
    pub fn last_line(&self) -> &[u8] {
        match self {
            LogFile::Jsonl(r) => r.get_ref().line(),
            LogFile::Mcap(r) => r.last_line(),
        }
    }

    /// The line number of the frame read last (JSON Lines; `None` in MCAP,
    /// whose places are byte offsets).
    pub fn line_no(&self) -> Option<usize> {
        match self {
            LogFile::Jsonl(r) => Some(r.line_no()),
            LogFile::Mcap(_) => None,
        }
    }

    /// Flag forward steps of `t` above `max_gap_s` as jumps (before the
    /// first frame; default core's `DEFAULT_MAX_GAP_S`).
    pub fn with_max_gap_s(mut self, max_gap_s: f64) -> Self {
        match &mut self {
            LogFile::Jsonl(r) => r.set_max_gap_s(max_gap_s),
            LogFile::Mcap(r) => r.set_max_gap_s(max_gap_s),
        }
        self
    }

    fn get(&self) -> &dyn FrameLog {
        match self {
            LogFile::Jsonl(r) => r.as_ref(),
            LogFile::Mcap(r) => r.as_ref(),
        }
    }
}

impl FrameLog for LogFile {
    fn header(&self) -> &LogHeader {
        self.get().header()
    }
    fn name(&self) -> &str {
        self.get().name()
    }
    fn line_no(&self) -> Option<usize> {
        LogFile::line_no(self)
    }
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        match self {
            LogFile::Jsonl(r) => FrameLog::next_frame(r.as_mut()),
            LogFile::Mcap(r) => FrameLog::next_frame(r.as_mut()),
        }
    }
    fn next_record(&mut self) -> Option<Result<lightpose_core::samples::Record<'_>, LogError>> {
        match self {
            LogFile::Jsonl(r) => FrameLog::next_record(r.as_mut()),
            LogFile::Mcap(r) => FrameLog::next_record(r.as_mut()),
        }
    }
    fn cut(&self) -> Option<Cut> {
        self.get().cut()
    }
    fn other_records(&self) -> u64 {
        self.get().other_records()
    }
    fn first_other(&self) -> Option<&str> {
        self.get().first_other()
    }
    fn order(&self) -> &lightpose_core::FrameOrder {
        self.get().order()
    }
    fn seq_gaps(&self) -> (u64, u64) {
        self.get().seq_gaps()
    }
    fn bad_readings(&self) -> (u64, Option<&str>) {
        self.get().bad_readings()
    }
}

/// Open an intensity log whatever its container ([`LogFile::open`]), for
/// code that reads frames alone.
pub fn open(path: &Path) -> Result<Box<dyn FrameLog + Send>, LogError> {
    Ok(Box::new(LogFile::open(path)?))
}
