//! One recording file in its format, for the recorder thread: created with
//! its header, written through lightpose-logs' [`LogSink`], counted (for
//! rotation by size and STATUS), pushed to the disk on the recorder's
//! timer and completed at close.
//!
//! JSON Lines (the default, FORMATS.md): frames only, each line in one
//! `write(2)` on an unbuffered file, so a kill -9 leaves every line
//! written. MCAP: frames, estimates and STATUS on the channels of
//! docs/foxglove.md, in chunks held in memory until they are full or the
//! timer closes them; a power loss or kill -9 loses the open chunk only,
//! and the file reads here up to its last complete chunk (`lightpose
//! recover` finishes it for readers that need its footer; a footer
//! written at each flush would make the file rewritten in place, no longer
//! append-only: docs/daemon.md).
//!
//! A file whose writing failed (a full disk) is not left as the error cut
//! it: it is cut back to its last whole point (JSONL: its last complete
//! line; MCAP: its last sync, a chunk's end) and, in MCAP, completed there
//! with a Data End and a Footer, so every reader takes it whole; a file
//! left without a frame is removed.

use crate::config::RecFormat;
use lightpose_core::samples::{Burst, Demodulated};
use lightpose_core::{Frame, LogHeader, LogWriter, PoseEstimate};
use lightpose_logs::foxglove::Stamp;
use lightpose_logs::{
    LogSink, McapOptions, McapWriter, Ros2Bag, Ros2BagOptions, Ros2Recording, WriteError,
};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::Arc;

/// Creates a recording's file (which must not exist yet); tests put one
/// under it that fails as a full disk does.
pub type Opener = fn(&Path) -> io::Result<File>;

/// The opener of the daemon: a new file, never one that exists.
pub fn create_new(path: &Path) -> io::Result<File> {
    File::options().write(true).create_new(true).open(path)
}

/// The file under a sink, counting what reaches it and whether a write
/// failed (then the bytes that reached the file are no longer known to
/// end where a record ends).
struct Counted {
    file: File,
    bytes: Arc<AtomicU64>,
    failed: Arc<AtomicBool>,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self.file.write(buf) {
            Ok(n) => {
                self.bytes.fetch_add(n as u64, Relaxed);
                Ok(n)
            }
            Err(e) => {
                if e.kind() != io::ErrorKind::Interrupted {
                    self.failed.store(true, Relaxed);
                }
                Err(e)
            }
        }
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// Why a frame was not written.
#[derive(Debug)]
pub enum RecError {
    /// The frame cannot be held in this format (MCAP: t has no log time):
    /// that frame only is passed over, the file goes on.
    Skip(WriteError),
    /// The disk refused: the file is ended.
    Disk(String),
}

/// Why `f` and `est` cannot be recorded in `format`, if they cannot: an
/// MCAP log time is the frame's t, which must be ≥ 0 (a replayed log whose
/// epoch is not its start, say).
pub fn unencodable(format: RecFormat, f: &Frame, est: &PoseEstimate) -> Option<WriteError> {
    if !format.is_mcap() {
        return None;
    }
    let time = |what, seq, t| {
        Stamp::of(t)
            .is_none()
            .then_some(WriteError::Time { what, seq, t })
    };
    time("frame", f.seq, f.t).or_else(|| time("pose", est.seq, est.t))
}

/// How a file ended.
#[derive(Debug, Default, PartialEq)]
pub struct Closed {
    /// Frames the file keeps.
    pub kept: u64,
    /// Frames written to it but cut off after its last whole point.
    pub lost: u64,
    /// It kept no frame and is gone: removed here, or (with `error`
    /// saying so) removed or replaced by someone else while written.
    pub removed: bool,
    /// Why it could not be completed (it is cut back, and sealed in MCAP).
    pub error: Option<String>,
}

/// An open recording.
pub struct RecFile {
    pub path: PathBuf,
    format: RecFormat,
    sink: Box<dyn LogSink + Send>,
    /// The same file, to sync it, and to cut it back if writing fails (the
    /// sink owns the first handle).
    sync: File,
    bytes: Arc<AtomicU64>,
    failed: Arc<AtomicBool>,
    /// Frames written, and frames known to be on the disk (synced), and
    /// the file's length at that sync.
    frames: u64,
    synced: u64,
    synced_len: u64,
    /// The file's length at its last whole point (JSONL: after a line;
    /// MCAP: after a sync, at a chunk's end), and the frames up to it.
    good_len: u64,
    good_frames: u64,
    /// MCAP: the chunk size, and the flushes so far (each closes a chunk):
    /// what [`RecFile::chunks`] counts from.
    chunk_bytes: u64,
    flushes: u64,
    #[cfg(test)]
    sink_fd: std::os::fd::RawFd,
}

/// The extension of a recording in `format`.
pub fn extension(format: RecFormat) -> &'static str {
    match format {
        RecFormat::Jsonl => "jsonl",
        RecFormat::Mcap | RecFormat::Ros2 => "mcap",
    }
}

/// Cut `file` back to `len`, a whole point, and seal an MCAP there; synced.
fn cut_back(file: &File, format: RecFormat, len: u64) -> io::Result<()> {
    file.set_len(len)?;
    if format.is_mcap() {
        if let Err(e) = file.write_all_at(&lightpose_logs::mcap_end(), len) {
            // Readable up to `len` still: no half-written end.
            let _ = file.set_len(len);
            return Err(e);
        }
    }
    file.sync_all()
}

/// One line naming the file.
fn named(path: &Path, e: impl std::fmt::Display) -> String {
    format!("{}: {e}", path.display())
}

impl RecFile {
    /// Start a recording in `file`, just created at `path` (by an
    /// [`Opener`]: a new file): its header written; MCAP chunks close at
    /// `chunk_bytes` (and on the recorder's timer); a ROS 2 bag names what
    /// `bag` says. A file that could not be started is removed.
    pub fn create(
        path: PathBuf,
        file: File,
        format: RecFormat,
        header: &LogHeader,
        chunk_bytes: u64,
        bag: &Ros2BagOptions,
    ) -> Result<RecFile, String> {
        let started = RecFile::start(path.clone(), format, header, chunk_bytes, bag, file);
        if started.is_err() {
            let _ = std::fs::remove_file(&path);
        }
        started
    }

    fn start(
        path: PathBuf,
        format: RecFormat,
        header: &LogHeader,
        chunk_bytes: u64,
        bag: &Ros2BagOptions,
        file: File,
    ) -> Result<RecFile, String> {
        let sync = file.try_clone().map_err(|e| named(&path, e))?;
        #[cfg(test)]
        let sink_fd = std::os::fd::AsRawFd::as_raw_fd(&file);
        let bytes = Arc::new(AtomicU64::new(0));
        let failed = Arc::new(AtomicBool::new(false));
        let counted = Counted {
            file,
            bytes: bytes.clone(),
            failed: failed.clone(),
        };
        let mut sink: Box<dyn LogSink + Send> = match format {
            RecFormat::Jsonl => {
                Box::new(LogWriter::new(counted, header).map_err(|e| named(&path, e))?)
            }
            RecFormat::Mcap => {
                let opts = McapOptions {
                    chunk_bytes,
                    foxglove: true,
                };
                // Chunks are written whole from memory; the buffer only
                // gathers the small records around them into few writes.
                let w = BufWriter::with_capacity(1 << 16, counted);
                Box::new(McapWriter::new(w, header, &opts).map_err(|e| named(&path, e))?)
            }
            RecFormat::Ros2 => {
                let opts = Ros2BagOptions {
                    chunk_bytes,
                    file_name: path
                        .file_name()
                        .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
                    ..bag.clone()
                };
                let w = BufWriter::with_capacity(1 << 16, counted);
                let bag = Ros2Bag::new(w, &opts).map_err(|e| named(&path, e))?;
                Box::new(Ros2Recording::new(bag))
            }
        };
        if format.is_mcap() {
            // The header leaves the buffer, and reaches the disk, now: a
            // file killed before its first chunk read as no MCAP at all.
            sink.flush()
                .map_err(|e| named(&path, crate::error::report(&e)))?;
            sync.sync_data().map_err(|e| named(&path, e))?;
        }
        // The header is on the file.
        let good_len = bytes.load(Relaxed);
        Ok(RecFile {
            path,
            format,
            sink,
            sync,
            bytes,
            failed,
            frames: 0,
            synced: 0,
            synced_len: good_len,
            good_len,
            good_frames: 0,
            chunk_bytes: chunk_bytes.max(1),
            flushes: 0,
            #[cfg(test)]
            sink_fd,
        })
    }

    /// A frame and its estimate (JSONL keeps the frame only).
    pub fn write(&mut self, f: &Frame, est: &PoseEstimate, wall: f64) -> Result<(), RecError> {
        self.write_of(f, None, est, wall)
    }

    /// A frame as the recording keeps it (spec v3): `raw`, the samples it
    /// was demodulated from, as a BURST line; a frame with amplitudes as a
    /// demodulated frame; else its counts.
    pub fn write_of(
        &mut self,
        f: &Frame,
        raw: Option<&Burst>,
        est: &PoseEstimate,
        wall: f64,
    ) -> Result<(), RecError> {
        if let Some(e) = unencodable(self.format, f, est) {
            return Err(RecError::Skip(e));
        }
        let written = match (raw, f.amplitudes) {
            (Some(b), _) => self.sink.write_burst(b),
            (None, Some(light)) => self.sink.write_demodulated(&Demodulated {
                seq: f.seq,
                t: f.t,
                adc_bits: f.adc_bits,
                light,
                temp_c: f.temp_c,
                truth: f.truth,
                attitude: f.attitude,
                depth: f.depth,
                velocity: f.velocity,
            }),
            (None, None) => self.sink.write_frame(f),
        };
        written
            .and_then(|()| {
                if self.sink.keeps_poses() {
                    self.sink.write_pose(est, Some(wall))
                } else {
                    Ok(())
                }
            })
            .map_err(|e| RecError::Disk(self.err(e)))?;
        self.frames += 1;
        if self.format == RecFormat::Jsonl {
            // Each line in one write: the file ends with it.
            self.good_len = self.bytes();
            self.good_frames = self.frames;
        }
        Ok(())
    }

    /// A STATUS object at the log time `t` (MCAP; JSONL keeps none).
    pub fn status(&mut self, t: f64, json: &[u8]) -> Result<(), String> {
        self.sink.write_status(t, json).map_err(|e| self.err(e))
    }

    /// A metadata record (MCAP: it closes the open chunk; JSONL keeps
    /// none).
    pub fn metadata(&mut self, name: &str, pairs: BTreeMap<String, String>) -> Result<(), String> {
        if !self.format.is_mcap() {
            return Ok(());
        }
        self.sink
            .write_metadata(name, pairs)
            .map_err(|e| self.err(e))?;
        // The chunk it closed, as a flush's (none before the first frame).
        if self.frames > 0 {
            self.flushes += 1;
        }
        Ok(())
    }

    /// Close the open chunk, write it and sync the file: what was written
    /// so far survives a power loss.
    pub fn flush(&mut self) -> Result<(), String> {
        self.sink.flush().map_err(|e| self.err(e))?;
        if let Err(e) = self.sync.sync_data() {
            self.sync_failed();
            return Err(named(&self.path, e));
        }
        self.flushes += 1;
        self.synced = self.frames;
        self.good_len = self.bytes();
        self.synced_len = self.good_len;
        self.good_frames = self.frames;
        Ok(())
    }

    /// A sync failed (EIO: the device lost pages it had taken): what was
    /// written since the last good sync is not known to be on the disk,
    /// and the kernel says so once only (a second sync would succeed), so
    /// the file ends here, cut back to that sync.
    fn sync_failed(&mut self) {
        self.failed.store(true, Relaxed);
        self.good_len = self.synced_len;
        self.good_frames = self.synced;
    }

    /// Why the open file is no longer the recording at its path (removed,
    /// or its directory; replaced), if it is not: frames written to it
    /// from then on reach no file anyone can read.
    pub fn gone(&self) -> Option<String> {
        use std::os::unix::fs::MetadataExt;
        let open = match self.sync.metadata() {
            Ok(m) => m,
            Err(e) => return Some(named(&self.path, e)),
        };
        let why = match std::fs::metadata(&self.path) {
            _ if open.nlink() == 0 => "removed while being written".to_string(),
            Ok(m) if (m.dev(), m.ino()) != (open.dev(), open.ino()) => {
                "replaced by another file while being written".to_string()
            }
            Ok(_) => return None,
            Err(e) => format!("no longer there while being written ({e})"),
        };
        Some(named(&self.path, why))
    }

    /// Complete the file (MCAP: its summary and footer) and sync it. When
    /// it cannot be (a write failed, now or before), it is cut back to its
    /// last whole point and, in MCAP, sealed there; a file without a frame
    /// is removed. A file no longer at its path ([`RecFile::gone`]) loses
    /// every frame written to it.
    pub fn close(self) -> Closed {
        let gone = self.gone();
        let RecFile {
            path,
            format,
            sink,
            sync,
            failed,
            frames,
            synced,
            synced_len,
            good_len,
            good_frames,
            ..
        } = self;
        let mut error = None;
        if let Some(why) = gone {
            // Nothing of it can be read: every frame in it is lost.
            drop(sink);
            return Closed {
                kept: 0,
                lost: frames,
                removed: true,
                error: Some(why),
            };
        }
        let (mut good_len, mut good_frames) = (good_len, good_frames);
        if frames > 0 && !failed.load(Relaxed) {
            let report = |e: WriteError| named(&path, crate::error::report(&e));
            match sink.finish().map_err(report) {
                Ok(()) => match sync.sync_all() {
                    Ok(()) => {
                        return Closed {
                            kept: frames,
                            ..Closed::default()
                        }
                    }
                    Err(e) => {
                        // As in `sync_failed`: the last good sync is all
                        // that is known to be there.
                        (good_len, good_frames) = (synced_len, synced);
                        error = Some(named(&path, e));
                    }
                },
                Err(e) => error = Some(e),
            }
        } else {
            // Whatever its drop still writes is cut off below.
            drop(sink);
        }
        let mut closed = Closed {
            kept: good_frames,
            lost: frames - good_frames,
            removed: good_frames == 0,
            error,
        };
        let cut = if closed.removed {
            std::fs::remove_file(&path).map_err(|e| named(&path, e))
        } else {
            cut_back(&sync, format, good_len).map_err(|e| named(&path, e))
        };
        if let Err(e) = cut {
            closed.error.get_or_insert(e);
        }
        closed
    }

    pub fn bytes(&self) -> u64 {
        self.bytes.load(Relaxed)
    }
    /// MCAP chunks written so far, at most (JSONL: 0): each flush closes
    /// one, and a chunk closed full holds more than `chunk_bytes`. The
    /// `mcap` writer keeps an index entry per chunk until the file closes.
    pub fn chunks(&self) -> u64 {
        match self.format {
            RecFormat::Jsonl => 0,
            RecFormat::Mcap | RecFormat::Ros2 => self.flushes + self.bytes() / self.chunk_bytes,
        }
    }

    /// Frames written since the last sync.
    pub fn unsynced(&self) -> u64 {
        self.frames - self.synced
    }

    /// The error and its causes (the mcap crate keeps the I/O error's
    /// text in its source), naming the file.
    fn err(&self, e: WriteError) -> String {
        named(&self.path, crate::error::report(&e))
    }

    /// The descriptor the sink writes to, for tests that put a failing
    /// file under it (dup2).
    #[cfg(test)]
    pub(crate) fn sink_fd(&self) -> std::os::fd::RawFd {
        self.sink_fd
    }

    /// The descriptor the file is synced through, for tests that make a
    /// sync fail (dup2).
    #[cfg(test)]
    pub(crate) fn sync_fd(&self) -> std::os::fd::RawFd {
        std::os::fd::AsRawFd::as_raw_fd(&self.sync)
    }
}
