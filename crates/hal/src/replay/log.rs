//! The seam between the replay source and a recording's file format: a
//! [`FrameLog`] gives the header, then the frames in order. JSON Lines
//! (core's [`LogReader`]) is the one format today; another (MCAP) is one
//! more implementation and one more arm in [`open_log`].

use std::io::BufRead;
use std::path::Path;

use lightpose_core::{Frame, FrameOrder, LogError, LogHeader, LogReader};

/// A recorded log as the replay source reads it.
pub trait FrameLog: Send {
    fn header(&self) -> &LogHeader;
    /// The next frame; `None` at the end; an error names the place (file
    /// and line) and the reader can go on after it.
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>>;
    /// Where the log was cut short (a last record half written), if so.
    fn truncated_at(&self) -> Option<usize>;
    /// The order of its frames so far (core's one rule): skips, jumps.
    fn order(&self) -> &FrameOrder;
    /// Records of other classes passed over, and the first one named.
    fn other_records(&self) -> (u64, Option<&str>);
}

impl<R: BufRead + Send> FrameLog for LogReader<R> {
    fn header(&self) -> &LogHeader {
        LogReader::header(self)
    }
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        LogReader::next_frame(self)
    }
    fn truncated_at(&self) -> Option<usize> {
        LogReader::truncated_at(self)
    }
    fn order(&self) -> &FrameOrder {
        LogReader::order(self)
    }
    fn other_records(&self) -> (u64, Option<&str>) {
        (self.other_lines(), self.first_other())
    }
}

/// Open the log at `path` in its format; a forward step of `t` above
/// `max_gap_s` is flagged as a jump.
pub fn open_log(path: &Path, max_gap_s: f64) -> Result<Box<dyn FrameLog>, LogError> {
    Ok(Box::new(LogReader::open(path)?.with_max_gap_s(max_gap_s)))
}
