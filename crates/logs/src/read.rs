//! The MCAP reader: the same interface as the JSONL reader (a header, then
//! frames one at a time, [`FrameLog`]), over the line source of `lines.rs`.
//! Errors name the file and the byte offset of the record: a FRAME message
//! that is refused costs that frame (as a refused JSONL line does), a chunk
//! that fails its CRC costs its frames, and anything that breaks the file's
//! structure ends the log with one line. A file cut short (no footer) ends
//! quietly at its last complete chunk; [`FrameLog::cut`] says where and
//! what was dropped.

use crate::lines::McapLines;
pub use crate::lines::{Carried, ChannelDecl};
use lightpose_core::{
    Burst, Cut, Demodulated, Frame, FrameLog, FrameOrder, LogError, LogHeader, LogReader, Record,
};
use std::collections::VecDeque;
use std::fs::File;
use std::io::{self, BufReader, Read, Seek, SeekFrom, Write};
use std::path::Path;

pub struct McapReader<R: Read> {
    inner: LogReader<McapLines<R>>,
    name: String,
    /// Results held back behind skippable errors met on the way to them.
    queue: VecDeque<Result<Frame, LogError>>,
    ended: bool,
    /// Bad sensor readings: count seen, and the last one named by offset.
    bad_seen: u64,
    last_bad: Option<String>,
    /// The last burst or demodulated frame of [`McapReader::next_record`],
    /// lent out until the next call (buffers reused).
    burst: Burst,
    demod: Box<Demodulated>,
}

impl McapReader<BufReader<File>> {
    /// Open an MCAP file and read up to its header.
    pub fn open(path: &Path) -> Result<Self, LogError> {
        let name = path.display().to_string();
        let io = |err| LogError::Io {
            name: name.clone(),
            err,
        };
        let mut f = File::open(path).map_err(io)?;
        let size = f.metadata().map_err(io)?.len();
        // A finished file's summary declares its channels again: read
        // first, a chunk that fails its CRC takes only its own frames even
        // when it held the declarations (the first chunk does).
        let summary = crate::lines::summary_of(&mut f, size);
        f.seek(SeekFrom::Start(0)).map_err(io)?;
        let src = BufReader::with_capacity(1 << 16, f);
        McapReader::with_summary(src, name, Some(size), summary)
    }
}

impl<R: Read> McapReader<R> {
    /// Read the magic and the records up to the header from `src`; `name`
    /// is how errors refer to it, `size` (when known) tells a file cut by a
    /// power loss from one with garbage at its end.
    pub fn new(src: R, name: impl Into<String>, size: Option<u64>) -> Result<Self, LogError> {
        Self::with_summary(src, name, size, None)
    }

    /// As [`McapReader::new`], with the channels that `summary` (the file's
    /// summary section, `lines::summary_of`) declares known from the start.
    fn with_summary(
        src: R,
        name: impl Into<String>,
        size: Option<u64>,
        summary: Option<Vec<u8>>,
    ) -> Result<Self, LogError> {
        let name = name.into();
        let mut lines = McapLines::new(src, name.clone(), size)?;
        if let Some(s) = summary {
            lines.declare_from_summary(s);
        }
        let offset = lines.find_header()?;
        let inner = LogReader::new(lines, name.clone()).map_err(|e| match e {
            LogError::Line { msg, .. } => LogError::at(
                name.clone(),
                offset,
                format!("{} metadata: {msg}", crate::schema::HEADER_METADATA),
                true,
            ),
            e => e,
        })?;
        Ok(McapReader {
            inner,
            name,
            queue: VecDeque::new(),
            ended: false,
            bad_seen: 0,
            last_bad: None,
            burst: Burst::default(),
            demod: Box::default(),
        })
    }

    /// Keep the POSE messages met while reading (for a conversion), to be
    /// taken with [`McapReader::take_poses`].
    pub fn keep_poses(&mut self, on: bool) {
        self.inner.get_mut().keep_poses = on;
    }

    /// Keep the messages of the channels a conversion carries as they are
    /// (every channel but frames, poses and the Foxglove ones: see
    /// [`ChannelDecl`]) and the metadata records other than the HEADER's,
    /// to be taken with [`McapReader::take_carried`].
    pub fn keep_carried(&mut self, on: bool) {
        self.inner.get_mut().keep_carried = on;
    }

    /// What was kept so far for carrying, in the order of the file.
    pub fn take_carried(&mut self) -> Vec<Carried> {
        std::mem::take(&mut self.inner.get_mut().carried)
    }

    /// How the input declared channel `id`, if it is one that is carried.
    pub fn channel_decl(&self, id: u16) -> Option<&ChannelDecl> {
        let decls = &self.inner.get_ref().decls;
        decls.iter().find(|d| d.0 == id).map(|d| &d.1)
    }

    /// Write the POSE messages kept so far, one per line, and forget them.
    pub fn take_poses(&mut self, out: &mut impl Write) -> io::Result<usize> {
        let lines = self.inner.get_mut();
        out.write_all(&lines.poses)?;
        let n = lines.poses.iter().filter(|&&b| b == b'\n').count();
        lines.poses.clear();
        Ok(n)
    }

    /// The text of the message read last (after opening: the HEADER line;
    /// after a frame: its FRAME object), as a line.
    /// Flag forward steps of `t` above `max_gap_s` as jumps.
    pub fn set_max_gap_s(&mut self, max_gap_s: f64) {
        self.inner.set_max_gap_s(max_gap_s);
    }

    pub fn last_line(&self) -> &[u8] {
        self.inner.get_ref().line()
    }

    /// A result of the line reader, with places as offsets.
    fn place(&mut self, r: Result<Frame, LogError>) -> Result<Frame, LogError> {
        r.map_err(|e| self.place_err(e))
    }

    /// An error of the line reader, placed by offset.
    fn place_err(&mut self, e: LogError) -> LogError {
        let lines = self.inner.get_mut();
        match e {
            LogError::Line { msg, .. } => {
                LogError::at(self.name.clone(), lines.msg_offset, msg, false)
            }
            LogError::Refused { msg, .. } => {
                LogError::at(self.name.clone(), lines.msg_offset, msg, true)
            }
            e @ LogError::Io { .. } => lines.error.take().unwrap_or(e),
            e => e,
        }
    }

    /// Spec v3: the next frame of whichever kind the recording holds
    /// (counts on `/lightpose/frame`, raw samples on `/lightpose/burst`,
    /// demodulated frames on `/lightpose/demodulated`), as core's
    /// `LogReader::next_record` gives a JSONL log's; `None` at the end. A
    /// chunk skipped (its CRC) met on the way is told at the next call.
    pub fn next_record(&mut self) -> Option<Result<Record<'_>, LogError>> {
        if let Some(r) = self.queue.pop_front() {
            return Some(r.map(Record::Frame));
        }
        if let Some(e) = self.inner.get_mut().pending.pop_front() {
            return Some(Err(e));
        }
        if self.ended {
            return None;
        }
        // A frame by value, as everywhere (no heap per frame).
        #[allow(clippy::large_enum_variant)]
        enum Got {
            Frame(Frame),
            Burst,
            Demod,
        }
        let got = match self.inner.next_record() {
            None => None,
            Some(Ok(Record::Frame(f))) => Some(Ok(Got::Frame(f))),
            Some(Ok(Record::Burst(b))) => {
                self.burst.clone_from(b);
                Some(Ok(Got::Burst))
            }
            Some(Ok(Record::Demodulated(d))) => {
                *self.demod = *d;
                Some(Ok(Got::Demod))
            }
            Some(Err(e)) => Some(Err(e)),
        };
        let got = got.map(|r| r.map_err(|e| self.place_err(e)));
        self.note_bad_reading();
        let got = match got {
            Some(g) => g,
            None => {
                let e = self.inner.get_mut().pending.pop_front();
                self.ended = e.is_none();
                return e.map(Err);
            }
        };
        Some(got.map(|g| match g {
            Got::Frame(f) => Record::Frame(f),
            Got::Burst => Record::Burst(&self.burst),
            Got::Demod => Record::Demodulated(&self.demod),
        }))
    }

    /// Name a new bad reading by the offset of its message.
    fn note_bad_reading(&mut self) {
        let (n, last) = self.inner.bad_readings();
        if n == self.bad_seen {
            return;
        }
        self.bad_seen = n;
        // LogReader says "name:line: why"; the line means nothing here.
        let why = last
            .and_then(|s| s.strip_prefix(self.name.as_str()))
            .and_then(|s| s.strip_prefix(':'))
            .and_then(|s| s.split_once(": "))
            .map_or("", |(_, why)| why);
        let offset = self.inner.get_ref().msg_offset;
        self.last_bad = Some(format!("{}: byte {offset}: {why}", self.name));
    }

    pub fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        if let Some(r) = self.queue.pop_front() {
            return Some(r);
        }
        if self.ended {
            return None;
        }
        let r = self.inner.next_frame().map(|r| self.place(r));
        self.note_bad_reading();
        let pending = &mut self.inner.get_mut().pending;
        if pending.is_empty() {
            self.ended = r.is_none();
            return r;
        }
        self.queue.extend(pending.drain(..).map(Err));
        match r {
            Some(r) => self.queue.push_back(r),
            None => self.ended = true,
        }
        self.queue.pop_front()
    }
}

impl<R: Read> Iterator for McapReader<R> {
    type Item = Result<Frame, LogError>;
    fn next(&mut self) -> Option<Self::Item> {
        McapReader::next_frame(self)
    }
}

impl<R: Read> FrameLog for McapReader<R> {
    fn header(&self) -> &LogHeader {
        self.inner.header()
    }
    fn name(&self) -> &str {
        &self.name
    }
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        McapReader::next_frame(self)
    }
    fn next_record(&mut self) -> Option<Result<Record<'_>, LogError>> {
        McapReader::next_record(self)
    }
    fn cut(&self) -> Option<Cut> {
        self.inner.get_ref().cut
    }
    fn other_records(&self) -> u64 {
        self.inner.other_lines() + self.inner.get_ref().other
    }
    fn first_other(&self) -> Option<&str> {
        self.inner.first_other()
    }
    fn order(&self) -> &FrameOrder {
        self.inner.order()
    }
    fn seq_gaps(&self) -> (u64, u64) {
        self.inner.seq_gaps()
    }
    fn bad_readings(&self) -> (u64, Option<&str>) {
        (self.bad_seen, self.last_bad.as_deref())
    }
}
