//! One writer interface for both containers, for a recorder that is told
//! its format by configuration.

use crate::write::{McapOptions, McapWriter, WriteError};
use crate::Format;
use lightpose_core::{Burst, Demodulated, Frame, LogHeader, LogWriter, PoseEstimate};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Where frames (and, in MCAP, poses and status) are recorded.
pub trait LogSink {
    fn write_frame(&mut self, f: &Frame) -> Result<(), WriteError>;
    /// Spec v3: a frame's raw samples (JSONL: a BURST line; MCAP: the
    /// binary `/lightpose/burst`). A log holds one kind of frame.
    fn write_burst(&mut self, b: &Burst) -> Result<(), WriteError>;
    /// Spec v3: a demodulated frame.
    fn write_demodulated(&mut self, d: &Demodulated) -> Result<(), WriteError>;
    /// An estimate with its wall-clock capture time (Unix seconds). JSONL
    /// intensity logs hold frames only (FORMATS.md): there, nothing.
    fn write_pose(&mut self, p: &PoseEstimate, wall_unix: Option<f64>) -> Result<(), WriteError>;
    /// A STATUS object at `t` in the log's epoch. JSONL: nothing.
    fn write_status(&mut self, t: f64, json: &[u8]) -> Result<(), WriteError>;
    /// A metadata record (MCAP; it closes the open chunk). JSONL: nothing.
    fn write_metadata(
        &mut self,
        name: &str,
        pairs: BTreeMap<String, String>,
    ) -> Result<(), WriteError>;
    /// Whether poses and status are kept (MCAP) or passed over (JSONL).
    fn keeps_poses(&self) -> bool;
    /// Push everything written so far to the file (MCAP: close the chunk).
    fn flush(&mut self) -> Result<(), WriteError>;
    fn frames_written(&self) -> u64;
    /// Complete the file (MCAP: summary and footer) and flush it.
    fn finish(self: Box<Self>) -> Result<(), WriteError>;
}

impl<W: Write> LogSink for McapWriter<W> {
    fn write_frame(&mut self, f: &Frame) -> Result<(), WriteError> {
        McapWriter::write_frame(self, f)
    }
    fn write_burst(&mut self, b: &Burst) -> Result<(), WriteError> {
        McapWriter::write_burst(self, b)
    }
    fn write_demodulated(&mut self, d: &Demodulated) -> Result<(), WriteError> {
        McapWriter::write_demodulated(self, d)
    }
    fn write_pose(&mut self, p: &PoseEstimate, wall_unix: Option<f64>) -> Result<(), WriteError> {
        McapWriter::write_pose(self, p, wall_unix)
    }
    fn write_status(&mut self, t: f64, json: &[u8]) -> Result<(), WriteError> {
        McapWriter::write_status(self, t, json)
    }
    fn write_metadata(
        &mut self,
        name: &str,
        pairs: BTreeMap<String, String>,
    ) -> Result<(), WriteError> {
        McapWriter::write_metadata(self, name, pairs)
    }
    fn keeps_poses(&self) -> bool {
        true
    }
    fn flush(&mut self) -> Result<(), WriteError> {
        McapWriter::flush(self)
    }
    fn frames_written(&self) -> u64 {
        McapWriter::frames_written(self)
    }
    fn finish(self: Box<Self>) -> Result<(), WriteError> {
        McapWriter::finish(*self).map(drop)
    }
}

impl<W: Write> LogSink for LogWriter<W> {
    fn write_frame(&mut self, f: &Frame) -> Result<(), WriteError> {
        Ok(LogWriter::write_frame(self, f)?)
    }
    fn write_burst(&mut self, b: &Burst) -> Result<(), WriteError> {
        Ok(LogWriter::write_burst(self, b)?)
    }
    fn write_demodulated(&mut self, d: &Demodulated) -> Result<(), WriteError> {
        Ok(LogWriter::write_demodulated(self, d)?)
    }
    fn write_pose(&mut self, _: &PoseEstimate, _: Option<f64>) -> Result<(), WriteError> {
        Ok(())
    }
    fn write_status(&mut self, _: f64, _: &[u8]) -> Result<(), WriteError> {
        Ok(())
    }
    fn write_metadata(&mut self, _: &str, _: BTreeMap<String, String>) -> Result<(), WriteError> {
        Ok(())
    }
    fn keeps_poses(&self) -> bool {
        false
    }
    fn flush(&mut self) -> Result<(), WriteError> {
        Ok(LogWriter::flush(self)?)
    }
    fn frames_written(&self) -> u64 {
        LogWriter::frames_written(self)
    }
    fn finish(mut self: Box<Self>) -> Result<(), WriteError> {
        Ok(LogWriter::flush(&mut self)?)
    }
}

/// Create (truncate) a log file in the container its extension names
/// (`.mcap`, else JSONL) and write its header.
pub fn create(
    path: &Path,
    header: &LogHeader,
    opts: &McapOptions,
) -> Result<Box<dyn LogSink + Send>, WriteError> {
    let file = |e| WriteError::File {
        file: path.display().to_string(),
        err: e,
    };
    let f = BufWriter::with_capacity(1 << 16, File::create(path).map_err(file)?);
    Ok(match Format::of_path(path) {
        Some(Format::Mcap) => Box::new(McapWriter::new(f, header, opts)?),
        _ => Box::new(LogWriter::new(f, header).map_err(file)?),
    })
}
