//! One reading interface for intensity logs in any container: JSON Lines
//! here ([`LogReader`]), MCAP in lightpose-logs, so that replay,
//! calibration and the daemon's replay backend take `&mut dyn FrameLog`.
//! A child of `log` so that its line readers' sources can be reached.

use super::{FrameOrder, LogError, LogHeader, LogReader};
use crate::samples::Record;
use crate::Frame;
use std::io::BufRead;

/// What a binary container (MCAP) refused, at the byte offset of its
/// record. With `ends`, the container's structure is broken there and the
/// log ends; without, only that record (one frame, or one chunk's frames)
/// was skipped and reading goes on.
#[derive(Debug, thiserror::Error)]
#[error("{name}: byte {offset}: {msg}")]
pub struct ByteError {
    pub name: String,
    pub offset: u64,
    pub msg: String,
    pub ends: bool,
}

impl LogError {
    /// `name: byte offset: msg` (see [`ByteError`]).
    pub fn at(name: impl Into<String>, offset: u64, msg: impl Into<String>, ends: bool) -> Self {
        LogError::At(ByteError {
            name: name.into(),
            offset,
            msg: msg.into(),
            ends,
        })
    }

    /// Whether reading goes on past this error: a refused line or record
    /// costs its frame only.
    pub fn skippable(&self) -> bool {
        match self {
            LogError::Line { .. } => true,
            LogError::At(e) => !e.ends,
            _ => false,
        }
    }
}

/// Where a log that was cut short (power loss, kill -9) ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cut {
    /// JSON Lines: the number of the last line, which was written in part.
    Line(usize),
    /// A binary container (MCAP): the offset after the last complete record
    /// (chunk), and how many bytes after it were dropped.
    Bytes { offset: u64, dropped: u64 },
}

impl std::fmt::Display for Cut {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Cut::Line(l) => write!(f, "line {l}: last line cut short; the log ends there"),
            Cut::Bytes { offset, dropped: 0 } => write!(
                f,
                "byte {offset}: recording never finished (no summary); it ends there, nothing after it"
            ),
            Cut::Bytes { offset, dropped } => write!(
                f,
                "byte {offset}: recording never finished; it ends there, {dropped} bytes after it (an incomplete record) dropped"
            ),
        }
    }
}

/// An intensity log read frame by frame, whatever its container: JSON Lines
/// ([`LogReader`]) or MCAP (`lightpose-logs`), so that replay, calibration
/// and the daemon's replay backend take `&mut dyn FrameLog` and read both
/// alike.
pub trait FrameLog {
    fn header(&self) -> &LogHeader;
    /// How errors name the log (its path).
    fn name(&self) -> &str;
    /// The number of the line read last, in a container of lines (JSON
    /// Lines); None in one of records (MCAP), whose errors name bytes.
    fn line_no(&self) -> Option<usize> {
        None
    }
    /// The next frame, `None` at the end of the log. An error that is
    /// [`LogError::skippable`] cost one frame and reading may go on; after
    /// any other, the log ends.
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>>;
    /// The next frame of any kind (spec v3: counts, BURST or demodulated),
    /// `None` at the end. A container that reads only counts so far serves
    /// them here, and refuses the other kinds in `next_frame`.
    fn next_record(&mut self) -> Option<Result<Record<'_>, LogError>> {
        self.next_frame().map(|r| r.map(Record::Frame))
    }
    /// Where the log was cut short, if it ended so (known at its end).
    fn cut(&self) -> Option<Cut>;
    /// Lines or messages of other kinds that were passed over.
    fn other_records(&self) -> u64;
    /// The first line of another class, named with its place, if any.
    fn first_other(&self) -> Option<&str>;
    /// The ordering rule's account: frames skipped out of order, forward
    /// jumps of `t` kept.
    fn order(&self) -> &FrameOrder;
    /// Number of gaps in `seq`, and the frames they lost.
    fn seq_gaps(&self) -> (u64, u64);
    /// Malformed sensor readings left off their (kept) frames, and the last
    /// one's reason with its place.
    fn bad_readings(&self) -> (u64, Option<&str>);
}

impl<R: BufRead> FrameLog for LogReader<R> {
    fn header(&self) -> &LogHeader {
        LogReader::header(self)
    }
    fn name(&self) -> &str {
        LogReader::name(self)
    }
    fn line_no(&self) -> Option<usize> {
        Some(LogReader::line_no(self))
    }
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        LogReader::next_frame(self)
    }
    fn next_record(&mut self) -> Option<Result<Record<'_>, LogError>> {
        LogReader::next_record(self)
    }
    fn cut(&self) -> Option<Cut> {
        self.truncated_at().map(Cut::Line)
    }
    fn other_records(&self) -> u64 {
        self.other_lines()
    }
    fn first_other(&self) -> Option<&str> {
        LogReader::first_other(self)
    }
    fn order(&self) -> &FrameOrder {
        LogReader::order(self)
    }
    fn seq_gaps(&self) -> (u64, u64) {
        LogReader::seq_gaps(self)
    }
    fn bad_readings(&self) -> (u64, Option<&str>) {
        LogReader::bad_readings(self)
    }
}

/// The line source, for a reader that feeds this one lines of its own
/// making (lightpose-logs serves MCAP messages as lines, so that one parser
/// reads FRAME objects in every container).
impl<R> LogReader<R> {
    pub fn get_ref(&self) -> &R {
        &self.src
    }
    pub fn get_mut(&mut self) -> &mut R {
        &mut self.src
    }
}

#[cfg(test)]
mod tests {
    /// A recording killed between chunks lost nothing: it says so, rather
    /// than "0 bytes … (an incomplete record) dropped".
    #[test]
    fn a_cut_between_records_says_nothing_was_dropped() {
        let whole = super::Cut::Bytes {
            offset: 4096,
            dropped: 0,
        }
        .to_string();
        assert!(
            whole.contains("nothing after it") && !whole.contains("dropped"),
            "{whole}"
        );
        let part = super::Cut::Bytes {
            offset: 4096,
            dropped: 17,
        }
        .to_string();
        assert!(
            part.contains("17 bytes after it (an incomplete record) dropped"),
            "{part}"
        );
    }

    use super::*;

    #[test]
    fn a_jsonl_log_through_the_trait() {
        let text = "{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":5}\n\
                    {\"class\":\"FRAME\",\"seq\":0,\"t\":0,\"counts\":[0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0]}\n\
                    {\"class\":\"POSE\",\"seq\":0}\n\
                    {\"class\":\"FRAME\",\"seq\":2,\"t\":0.4,\"counts\":[1]}\n\
                    {\"class\":\"FRAME\",\"seq\":3,\"t\":0.6,\"cou";
        let mut r = LogReader::new(text.as_bytes(), "x.jsonl").unwrap();
        let log: &mut dyn FrameLog = &mut r;
        assert_eq!(log.header().adc_bits, 10);
        assert!(log.next_frame().unwrap().is_ok());
        let e = log.next_frame().unwrap().unwrap_err();
        assert!(e.skippable(), "{e}");
        assert!(log.next_frame().is_none());
        assert_eq!(log.cut(), Some(Cut::Line(5)));
        assert_eq!(log.other_records(), 1);
        assert_eq!(log.name(), "x.jsonl");
        assert_eq!(
            LogError::at("r.mcap", 12, "bad", true).to_string(),
            "r.mcap: byte 12: bad"
        );
        assert!(!LogError::at("r.mcap", 12, "bad", true).skippable());
        assert!(LogError::at("r.mcap", 12, "bad", false).skippable());
        let cut = Cut::Bytes {
            offset: 100,
            dropped: 7,
        };
        assert!(cut.to_string().starts_with("byte 100: "), "{cut}");
    }
}
