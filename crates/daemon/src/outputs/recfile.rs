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
//! and the file reads (and `lightpose convert` recovers it) up to its last
//! complete chunk.

use crate::config::RecFormat;
use lightpose_core::{Frame, LogHeader, LogWriter, PoseEstimate};
use lightpose_logs::{LogSink, McapOptions, McapWriter, WriteError};
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Arc;

/// The file under a sink, counting what reaches it.
struct Counted {
    file: File,
    bytes: Arc<AtomicU64>,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.file.write(buf)?;
        self.bytes.fetch_add(n as u64, Relaxed);
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// An open recording.
pub struct RecFile {
    pub path: PathBuf,
    sink: Box<dyn LogSink + Send>,
    /// The same file, to sync it (the sink owns the first handle).
    sync: File,
    bytes: Arc<AtomicU64>,
    /// Frames written, and frames known to be on the disk (synced).
    frames: u64,
    synced: u64,
    #[cfg(test)]
    sink_fd: std::os::fd::RawFd,
}

/// The extension of a recording in `format`.
pub fn extension(format: RecFormat) -> &'static str {
    match format {
        RecFormat::Jsonl => "jsonl",
        RecFormat::Mcap => "mcap",
    }
}

/// One line naming the file.
fn named(path: &Path, e: impl std::fmt::Display) -> String {
    format!("{}: {e}", path.display())
}

impl RecFile {
    /// Create `path` (which must not exist) and write its header; MCAP
    /// chunks close at `chunk_bytes` (and on the recorder's timer).
    pub fn create(
        path: PathBuf,
        format: RecFormat,
        header: &LogHeader,
        chunk_bytes: u64,
    ) -> Result<RecFile, String> {
        let file = File::options()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| named(&path, e))?;
        let sync = file.try_clone().map_err(|e| named(&path, e))?;
        #[cfg(test)]
        let sink_fd = std::os::fd::AsRawFd::as_raw_fd(&file);
        let bytes = Arc::new(AtomicU64::new(0));
        let counted = Counted {
            file,
            bytes: bytes.clone(),
        };
        let sink: Box<dyn LogSink + Send> = match format {
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
        };
        Ok(RecFile {
            path,
            sink,
            sync,
            bytes,
            frames: 0,
            synced: 0,
            #[cfg(test)]
            sink_fd,
        })
    }

    /// A frame and its estimate (JSONL keeps the frame only).
    pub fn write(&mut self, f: &Frame, est: &PoseEstimate, wall: f64) -> Result<(), String> {
        self.sink
            .write_frame(f)
            .and_then(|()| {
                if self.sink.keeps_poses() {
                    self.sink.write_pose(est, Some(wall))
                } else {
                    Ok(())
                }
            })
            .map_err(|e| self.err(e))?;
        self.frames += 1;
        Ok(())
    }

    /// A STATUS object at the log time `t` (MCAP; JSONL keeps none).
    pub fn status(&mut self, t: f64, json: &[u8]) -> Result<(), String> {
        self.sink.write_status(t, json).map_err(|e| self.err(e))
    }

    /// Close the open chunk, write it and sync the file: what was written
    /// so far survives a power loss.
    pub fn flush(&mut self) -> Result<(), String> {
        self.sink.flush().map_err(|e| self.err(e))?;
        self.sync.sync_data().map_err(|e| named(&self.path, e))?;
        self.synced = self.frames;
        Ok(())
    }

    /// Complete the file (MCAP: its summary and footer) and sync it.
    pub fn close(self) -> Result<(), String> {
        let path = self.path;
        let report = |e: WriteError| named(&path, crate::error::report(&e));
        self.sink.finish().map_err(report)?;
        self.sync.sync_all().map_err(|e| named(&path, e))
    }

    pub fn bytes(&self) -> u64 {
        self.bytes.load(Relaxed)
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
}
