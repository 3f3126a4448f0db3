//! The intensity log of FORMATS.md: JSON Lines, a HEADER then one FRAME per
//! line. Read and written as a stream, so a log of a million frames never
//! sits in memory whole. The reader names the line of anything it refuses,
//! and treats a cut-short last line (power loss) as the end of the log.
//! Lines are read bounded ([`MAX_LOG_LINE_BYTES`]), errors quote
//! at most an excerpt, and the order of frames follows [`FrameOrder`].

use crate::frame::{DepthReading, VelocityReading};
use crate::samples::{Burst, Demodulated, Record, RecordKind, MAX_SAMPLES_PER_FRAME};
use crate::textfile::{excerpt, one_line, read_line_bounded, LineRead, MAX_LINE_BYTES};
use crate::{AttitudeReading, Frame, Truth, NDET};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::path::Path;

mod framelog;
pub use framelog::{ByteError, Cut, FrameLog};
mod header;
mod lines;
mod order;
mod rawline;
mod readings;
mod writer;
pub use header::{LogHeader, DEFAULT_BEACON_ID};
pub use order::{plausible_t, FrameOrder, DEFAULT_MAX_GAP_S, MAX_ABS_T_S};
use rawline::RawLine;
pub use readings::as_logged;
pub use writer::LogWriter;

pub const FORMAT: &str = "lightpose-intensity";
pub const VERSION: u32 = 1;
/// A header's frame rate: one frame in 1000 s to a megahertz (a scene's
/// own limit). A recorded pace waits a period per frame, and 1e-19 Hz made
/// that wait overflow the clock.
pub const HEADER_RATE_HZ: std::ops::RangeInclusive<f64> = 1e-3..=1e6;
/// Longest line of an intensity log: a BURST of the most samples a frame
/// may have (25 × [`MAX_SAMPLES_PER_FRAME`] counts of up to five digits and
/// a comma: 8 kHz at 2 Hz frames) with every reading beside it. A FRAME
/// line is under 1 kB; the text files' 64 KiB bound refused a BURST line
/// of 8 kHz at 5 Hz frames (180 kB).
pub const MAX_LOG_LINE_BYTES: usize = NDET * MAX_SAMPLES_PER_FRAME * 6 + MAX_LINE_BYTES;

#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("{name}: {err}")]
    Io { name: String, err: io::Error },
    #[error("{name}:{line}: {msg}")]
    Line {
        name: String,
        line: usize,
        msg: String,
    },
    #[error("{name}: empty log (no HEADER line)")]
    Empty { name: String },
    /// A line after which the log is not read on: it mixes kinds of frame,
    /// or holds a kind its reader's consumer cannot take (spec v3).
    #[error("{name}:{line}: {msg}")]
    Refused {
        name: String,
        line: usize,
        msg: String,
    },
    /// A binary container (MCAP) refused something at a byte offset.
    #[error(transparent)]
    At(ByteError),
}

#[derive(Deserialize, Serialize)]
struct RawTruth {
    x: f64,
    y: f64,
    z: f64,
    pitch: f64,
    yaw: f64,
    /// Spec v3: absent means 0, and a roll of 0 is not written, so that
    /// v1/v2 logs pass through byte for byte.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    roll: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    surge: Option<f64>,
}

/// Streaming reader. Iterate to get frames; an `Err` names a line that was
/// refused, and iteration may go on past it.
pub struct LogReader<R> {
    src: R,
    name: String,
    header: LogHeader,
    line_no: usize,
    buf: Vec<u8>,
    truncated_at: Option<usize>,
    done: bool,
    other_lines: u64,
    first_other: Option<String>,
    order: FrameOrder,
    bad_readings: u64,
    last_bad_reading: Option<String>,
    /// The kind of the log's first frame line, and its number.
    kind: Option<(RecordKind, usize)>,
    /// The last BURST read (its buffer reused).
    burst: Burst,
    /// The last demodulated frame read (boxed: 3.6 kB).
    demod: Box<Demodulated>,
}

impl LogReader<BufReader<File>> {
    /// Open a log file and read its header.
    pub fn open(path: &Path) -> Result<Self, LogError> {
        let name = path.display().to_string();
        let f = File::open(path).map_err(|err| LogError::Io {
            name: name.clone(),
            err,
        })?;
        LogReader::new(BufReader::with_capacity(1 << 16, f), name)
    }
}

impl<R: BufRead> LogReader<R> {
    /// Read the header from `src`; `name` is how errors refer to it.
    pub fn new(mut src: R, name: impl Into<String>) -> Result<Self, LogError> {
        let name = name.into();
        let mut buf = Vec::new();
        let mut line_no = 0;
        let text = loop {
            let text = match read_line(&mut src, &mut buf, &name, line_no + 1)? {
                None => return Err(LogError::Empty { name }),
                Some(text) => text,
            };
            line_no += 1;
            if !text.trim().is_empty() {
                break crate::textfile::strip_bom(text.trim());
            }
        };
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| LogError::Line {
            name: name.clone(),
            line: line_no,
            msg: format!("header is not valid JSON: {}", one_line(&e.to_string())),
        })?;
        let header = LogHeader::parse(v).map_err(|msg| LogError::Line {
            name: name.clone(),
            line: line_no,
            msg,
        })?;
        Ok(LogReader {
            src,
            name,
            header,
            line_no,
            buf,
            truncated_at: None,
            done: false,
            other_lines: 0,
            first_other: None,
            order: FrameOrder::default(),
            bad_readings: 0,
            last_bad_reading: None,
            kind: None,
            burst: Burst::default(),
            demod: Box::default(),
        })
    }

    pub fn header(&self) -> &LogHeader {
        &self.header
    }
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Line number of a last line that was cut short, if the log ended so.
    pub fn truncated_at(&self) -> Option<usize> {
        self.truncated_at
    }
    /// Lines of other classes that were passed over.
    pub fn other_lines(&self) -> u64 {
        self.other_lines
    }
    /// The first of them, named: `file:line: class "POSE"`.
    pub fn first_other(&self) -> Option<&str> {
        self.first_other.as_deref()
    }
    /// Number of gaps in `seq`, and the frames they lost.
    pub fn seq_gaps(&self) -> (u64, u64) {
        self.order.seq_gaps()
    }
    /// The order of frames so far: skips, gaps, jumps of `t`.
    pub fn order(&self) -> &FrameOrder {
        &self.order
    }
    /// Flag forward steps of `t` above `max_gap_s` as jumps (default
    /// [`DEFAULT_MAX_GAP_S`]).
    pub fn with_max_gap_s(mut self, max_gap_s: f64) -> Self {
        self.set_max_gap_s(max_gap_s);
        self
    }
    /// [`LogReader::with_max_gap_s`] on a reader already in hand (before
    /// its first frame).
    pub fn set_max_gap_s(&mut self, max_gap_s: f64) {
        self.order = FrameOrder::new(max_gap_s);
    }
    /// Sensor readings (attitude, depth, velocity) that were malformed and
    /// left off their frame, which was kept; and the last one's reason with
    /// its line.
    pub fn bad_readings(&self) -> (u64, Option<&str>) {
        (self.bad_readings, self.last_bad_reading.as_deref())
    }

    /// The number of the line read last (1 is the header): where an error
    /// about the frame just read is, for a consumer that finds one.
    pub fn line_no(&self) -> usize {
        self.line_no
    }

    fn line_err(&self, msg: impl Into<String>) -> LogError {
        LogError::Line {
            name: self.name.clone(),
            line: self.line_no,
            msg: msg.into(),
        }
    }

    /// The next frame of counts, `None` at the end of the log. A log of
    /// BURST or demodulated lines (spec v3) is refused at its first such
    /// line with an error that ends it ([`LogReader::next_record`] reads
    /// them): a consumer of counts must not drop them unseen.
    pub fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        match self.next_got()? {
            Ok(Got::Frame(f)) => Some(Ok(f)),
            Ok(other) => {
                self.done = true;
                let kind = match other {
                    Got::Burst => RecordKind::Burst,
                    _ => RecordKind::Demodulated,
                };
                Some(Err(self.refused(format!(
                    "a {} (spec v3): this reader takes FRAME lines of counts only",
                    kind.describe()
                ))))
            }
            Err(e) => Some(Err(e)),
        }
    }

    /// The next frame of whichever kind the log holds (counts, BURST or
    /// demodulated), `None` at the end. A burst or a demodulated frame is
    /// lent from the reader until the next call; their buffers are reused.
    pub fn next_record(&mut self) -> Option<Result<Record<'_>, LogError>> {
        Some(self.next_got()?.map(|g| match g {
            Got::Frame(f) => Record::Frame(f),
            Got::Burst => Record::Burst(&self.burst),
            Got::Demod => Record::Demodulated(&self.demod),
        }))
    }

    /// The next frame line parsed, into `self.burst` or `self.demod` where
    /// it is of those kinds.
    fn next_got(&mut self) -> Option<Result<Got, LogError>> {
        // The line is parsed in place (its fields borrowed from it, no
        // allocation per frame): the buffer is out of `self` meanwhile.
        let mut buf = std::mem::take(&mut self.buf);
        let r = self.next_frame_in(&mut buf);
        self.buf = buf;
        r
    }

    /// An error after which the log is not read on.
    fn refused(&self, msg: impl Into<String>) -> LogError {
        LogError::Refused {
            name: self.name.clone(),
            line: self.line_no,
            msg: msg.into(),
        }
    }

    fn next_frame_in(&mut self, buf: &mut Vec<u8>) -> Option<Result<Got, LogError>> {
        loop {
            if self.done {
                return None;
            }
            let line = self.line_no + 1;
            let text = match read_line(&mut self.src, buf, &self.name, line) {
                Ok(Some(text)) => text,
                Ok(None) => {
                    self.done = true;
                    return None;
                }
                Err(e @ LogError::Line { .. }) => {
                    self.line_no = line;
                    return Some(Err(e));
                }
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            };
            self.line_no = line;
            let complete = text.ends_with('\n');
            let text = text.trim();
            if text.is_empty() {
                continue;
            }
            let raw: RawLine = match serde_json::from_str(text) {
                Ok(r) => r,
                Err(e) => {
                    if !complete && at_eof(&mut self.src) {
                        // A last line without its newline that does not parse
                        // is a write cut short by a power loss: the log ends.
                        self.truncated_at = Some(self.line_no);
                        self.done = true;
                        return None;
                    }
                    let msg = format!("not valid JSON: {}", one_line(&e.to_string()));
                    return Some(Err(self.line_err(msg)));
                }
            };
            let kind = match raw.class.as_ref().map(|c| &*c.0) {
                Some("FRAME") if raw.counts.is_none() && raw.beacons.is_some() => {
                    RecordKind::Demodulated
                }
                Some("FRAME") => RecordKind::Frame,
                Some("BURST") => RecordKind::Burst,
                Some(other) => {
                    self.other_lines += 1;
                    if self.first_other.is_none() {
                        let other = excerpt(other, 40);
                        self.first_other =
                            Some(format!("{}:{}: class \"{other}\"", self.name, self.line_no));
                    }
                    continue;
                }
                None => return Some(Err(self.line_err("line has no class field"))),
            };
            // One kind of frame per log (FORMATS.md): the first line of
            // another kind ends it, named.
            match self.kind {
                None => self.kind = Some((kind, self.line_no)),
                Some((first, at)) if first != kind => {
                    self.done = true;
                    return Some(Err(self.refused(format!(
                        "a {} in a log of {}s (the first at line {at}): a log holds one kind of frame",
                        kind.describe(),
                        first.describe()
                    ))));
                }
                Some(_) => {}
            }
            let r = match kind {
                RecordKind::Frame => self.frame_from(raw).map(Got::Frame),
                RecordKind::Burst => self.burst_from(raw).map(|()| Got::Burst),
                RecordKind::Demodulated => self.demod_from(raw).map(|()| Got::Demod),
            };
            let r = r.and_then(|g| {
                let (seq, t) = match &g {
                    Got::Frame(f) => (f.seq, f.t),
                    Got::Burst => (self.burst.seq, self.burst.t),
                    Got::Demod => (self.demod.seq, self.demod.t),
                };
                match self.order.admit(seq, t) {
                    Ok(()) => Ok(g),
                    Err(why) => Err(self.line_err(why)),
                }
            });
            return Some(r);
        }
    }
}

/// What [`LogReader::next_frame_in`] parsed: a frame of counts, or a line
/// held in the reader's burst or demodulated frame. On the stack per line:
/// boxing the frame would allocate per frame.
#[allow(clippy::large_enum_variant)]
enum Got {
    Frame(Frame),
    Burst,
    Demod,
}

/// A frame line's fields beside its light.
struct Meta {
    temp_c: Option<f64>,
    truth: Option<Truth>,
    attitude: Option<AttitudeReading>,
    depth: Option<DepthReading>,
    velocity: Option<VelocityReading>,
}

impl<R: BufRead> Iterator for LogReader<R> {
    type Item = Result<Frame, LogError>;
    fn next(&mut self) -> Option<Self::Item> {
        self.next_frame()
    }
}

/// The next line as text (`None` at the end), read bounded: a line too long
/// or not UTF-8 is an error naming it, and reading may go on after it.
fn read_line<'b, R: BufRead>(
    src: &mut R,
    buf: &'b mut Vec<u8>,
    name: &str,
    line: usize,
) -> Result<Option<&'b str>, LogError> {
    let refused = |msg: String| LogError::Line {
        name: name.to_string(),
        line,
        msg,
    };
    match read_line_bounded(src, buf, MAX_LOG_LINE_BYTES) {
        Err(err) => Err(LogError::Io {
            name: name.to_string(),
            err,
        }),
        Ok(LineRead::Eof) => Ok(None),
        Ok(LineRead::TooLong) => Err(refused(format!(
            "line longer than {MAX_LOG_LINE_BYTES} bytes: refused unread (a FRAME line is under 1 kB, a BURST line of the most samples a frame may have under that)"
        ))),
        Ok(LineRead::Line) => std::str::from_utf8(buf)
            .map(Some)
            .map_err(|_| refused("not valid UTF-8".into())),
    }
}

fn at_eof<R: BufRead>(src: &mut R) -> bool {
    src.fill_buf().map(|b| b.is_empty()).unwrap_or(true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::AttitudeStd;
    use crate::{Angle, Pose};

    fn frame(seq: u64) -> Frame {
        let mut counts = [0u16; NDET];
        for (k, c) in counts.iter_mut().enumerate() {
            *c = (k * 40) as u16;
        }
        Frame {
            seq,
            t: seq as f64 * 0.2,
            adc_bits: 10,
            counts,
            // An awkward value: it must read back to the same bits.
            temp_c: Some(19.937845150646073 + seq as f64 * 1e-13),
            truth: Some(Truth {
                pose: Pose::new(7.8, 0.0, 0.12, Angle::from_deg(9.6), Angle::ZERO),
                surge: Some(0.5),
            }),
            attitude: None,
            depth: None,
            velocity: None,
            amplitudes: None,
        }
    }

    fn write(frames: &[Frame]) -> Vec<u8> {
        let mut w = LogWriter::new(Vec::new(), &LogHeader::new(10, 5.0)).unwrap();
        for f in frames {
            w.write_frame(f).unwrap();
        }
        w.into_inner()
    }

    fn read_all(bytes: &[u8]) -> (Vec<Result<Frame, LogError>>, Option<usize>) {
        let mut r = LogReader::new(bytes, "test.jsonl").unwrap();
        let v: Vec<_> = r.by_ref().collect();
        (v, r.truncated_at())
    }

    #[test]
    fn round_trip() {
        let frames: Vec<_> = (0..5).map(frame).collect();
        let bytes = write(&frames);
        let (got, trunc) = read_all(&bytes);
        assert_eq!(trunc, None);
        let got: Vec<Frame> = got.into_iter().map(|r| r.unwrap()).collect();
        assert_eq!(got.len(), 5);
        for (a, b) in got.iter().zip(&frames) {
            assert_eq!(a.counts, b.counts);
            assert_eq!(a.seq, b.seq);
            assert_eq!(a.temp_c, b.temp_c);
            let (ta, tb) = (a.truth.unwrap().pose, b.truth.unwrap().pose);
            assert!((ta.pitch.deg() - tb.pitch.deg()).abs() < 1e-12);
        }
    }

    #[test]
    fn cut_short_last_line_ends_the_log() {
        let mut bytes = write(&(0..3).map(frame).collect::<Vec<_>>());
        bytes.truncate(bytes.len() - 20);
        let (got, trunc) = read_all(&bytes);
        assert_eq!(got.len(), 2);
        assert!(got.iter().all(|r| r.is_ok()));
        assert_eq!(trunc, Some(4));
    }

    /// Counts a writer kept in floats (46.0) are the integers they are;
    /// one with a fraction, negative or over full scale is refused as before.
    #[test]
    fn whole_float_counts_are_integers() {
        let mut bytes = write(&[]);
        let line = |seq: u64, last: &str| {
            let c: Vec<String> = (1..NDET).map(|k| format!("{k}.0")).collect();
            format!(
                "{{\"class\":\"FRAME\",\"seq\":{seq},\"t\":{seq}.0,\"counts\":[{},{last}]}}\n",
                c.join(",")
            )
        };
        for (seq, last) in [
            (0, "25.0"),
            (1, "1e3"),
            (2, "25.5"),
            (3, "-1.0"),
            (4, "1024.0"),
        ] {
            bytes.extend_from_slice(line(seq, last).as_bytes());
        }
        let got: Vec<_> = LogReader::new(&bytes[..], "f.jsonl").unwrap().collect();
        let ok: Vec<&Frame> = got.iter().filter_map(|g| g.as_ref().ok()).collect();
        assert_eq!(ok.len(), 2, "{got:?}");
        assert_eq!(ok[0].counts[..3], [1, 2, 3]);
        assert_eq!((ok[0].counts[24], ok[1].counts[24]), (25, 1000));
        let errs: Vec<String> = got
            .iter()
            .filter_map(|g| g.as_ref().err().map(|e| e.to_string()))
            .collect();
        assert!(
            errs[0].starts_with("f.jsonl:4: counts[24] = 25.5 is not an integer"),
            "{errs:?}"
        );
        assert!(
            errs[1].starts_with("f.jsonl:5: counts[24] = -1.0"),
            "{errs:?}"
        );
        assert!(
            errs[2].starts_with("f.jsonl:6: counts[24] = 1024"),
            "{errs:?}"
        );
    }

    #[test]
    fn bad_lines_are_named_and_reading_goes_on() {
        let mut bytes = write(&[frame(0)]);
        bytes.extend_from_slice(b"\n{\"class\":\"FRAME\",\"seq\":1,\"t\":0.2,\"counts\":[1,2]}\n");
        bytes.extend_from_slice(b"{\"class\":\"FRAME\",\"seq\":2,\"t\":0.4,\"counts\":[1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,2000]}\n");
        bytes.extend_from_slice(b"garbage\n");
        bytes.extend_from_slice(b"{\"class\":\"STATUS\",\"seq\":9}\n");
        let good = write(&[frame(5)]);
        bytes.extend_from_slice(good.split(|&b| b == b'\n').nth(1).unwrap());
        bytes.push(b'\n');
        let mut r = LogReader::new(&bytes[..], "x.jsonl").unwrap();
        let got: Vec<_> = r.by_ref().collect();
        assert_eq!(got.len(), 5);
        let msgs: Vec<String> = got
            .iter()
            .filter_map(|g| g.as_ref().err().map(|e| e.to_string()))
            .collect();
        assert_eq!(msgs.len(), 3);
        assert!(
            msgs[0].starts_with("x.jsonl:4: counts has 2 values"),
            "{}",
            msgs[0]
        );
        assert!(
            msgs[1].starts_with("x.jsonl:5: counts[24] = 2000"),
            "{}",
            msgs[1]
        );
        assert!(
            msgs[2].starts_with("x.jsonl:6: not valid JSON"),
            "{}",
            msgs[2]
        );
        assert_eq!(r.other_lines(), 1);
        assert_eq!(r.seq_gaps(), (1, 4));
    }

    #[test]
    fn a_header_of_version_2_is_read_as_1() {
        let text = "{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":2,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":5}\n{\"class\":\"FRAME\",\"seq\":0,\"t\":0.0,\"counts\":[1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,25],\"depth\":{\"z\":0.4}}\n";
        let (got, _) = read_all(text.as_bytes());
        let f = got[0].as_ref().expect("a v2 frame");
        assert_eq!(f.depth, Some(DepthReading::new(0.4)));
    }

    #[test]
    fn bad_headers_are_refused() {
        for (text, want) in [
            ("", "empty log"),
            ("{\"class\":\"FRAME\"}\n", "class HEADER"),
            ("{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":3,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":5}\n", "version 3"),
            ("{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":4,\"cols\":5,\"adc_bits\":10,\"rate_hz\":5}\n", "rows = 4"),
            ("{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":0,\"rate_hz\":5}\n", "adc_bits = 0"),
            ("{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":1e-19}\n", "rate_hz = 0.0000000000000000001: must be in 0.001..=1000000 Hz"),
            ("{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":0}\n", "rate_hz = 0: must be in 0.001..=1000000 Hz"),
            ("{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":2e6}\n", "rate_hz = 2000000: must be in 0.001..=1000000 Hz"),
        ] {
            let e = LogReader::new(text.as_bytes(), "h.jsonl").err().expect(text);
            assert!(e.to_string().contains(want), "{e} lacks {want}");
        }
    }

    #[test]
    fn sensor_readings_and_their_std_round_trip() {
        let mut f = frame(0);
        f.attitude = Some(AttitudeReading {
            pitch: Angle::from_deg(9.5),
            yaw: Angle::from_deg(-1.25),
            roll: None,
            std: Some(AttitudeStd {
                pitch: Angle::from_deg(0.3),
                yaw: Angle::from_deg(1.5),
            }),
        });
        f.depth = Some(DepthReading {
            z: 0.123456789,
            std: Some(0.02),
        });
        f.velocity = Some(VelocityReading::new(0.5, -0.01, 0.02));
        let mut g = frame(1);
        g.depth = Some(DepthReading::new(-0.5));
        let bytes = write(&[f, g]);
        let text = String::from_utf8(bytes.clone()).unwrap();
        assert!(
            text.contains(r#""depth":{"z":0.123456789,"std":{"z":0.02}}"#),
            "{text}"
        );
        assert!(
            text.contains(r#""velocity":{"fwd":0.5,"right":-0.01,"down":0.02}"#),
            "{text}"
        );
        let (got, _) = read_all(&bytes);
        let got: Vec<Frame> = got.into_iter().map(|r| r.unwrap()).collect();
        assert_eq!(got[0].depth, f.depth);
        assert_eq!(got[0].velocity, f.velocity);
        let (a, b) = (got[0].attitude.unwrap(), f.attitude.unwrap());
        assert!((a.pitch.deg() - b.pitch.deg()).abs() < 1e-12);
        assert!((a.std.unwrap().yaw.deg() - 1.5).abs() < 1e-12);
        assert_eq!(got[1].depth, Some(DepthReading::new(-0.5)));
        assert_eq!(got[1].velocity, None);
    }

    proptest::proptest! {
        /// A frame taken `as_logged` reads back from its line bit for bit
        /// (the record-then-replay promise), and moves by at most an ulp or
        /// two: radians written as degrees do not round-trip by themselves
        /// (10.029° did not, on the daemon's live path).
        #[test]
        fn an_attitude_as_logged_reads_back_bit_for_bit(
            p in -89.9f64..89.9, y in -179.9f64..179.9,
            sp in 1e-3f64..10.0, sy in 1e-3f64..10.0,
        ) {
            let mut f = frame(0);
            let std = AttitudeStd { pitch: Angle::from_rad(sp.to_radians()), yaw: Angle::from_rad(sy.to_radians()) };
            f.attitude = Some(AttitudeReading {
                pitch: Angle::from_rad(p.to_radians()),
                yaw: Angle::from_rad(y.to_radians()),
                roll: None,
                std: Some(std),
            });
            let before = f.attitude.unwrap();
            as_logged(&mut f);
            let (got, _) = read_all(&write(&[f]));
            let a = got[0].as_ref().unwrap().attitude.unwrap();
            let want = f.attitude.unwrap();
            let bits = |r: AttitudeReading| {
                let s = r.std.unwrap();
                [r.pitch, r.yaw, s.pitch, s.yaw].map(|x| x.rad().to_bits())
            };
            proptest::prop_assert_eq!(bits(a), bits(want));
            for (x, y) in [(want.pitch, before.pitch), (want.yaw, before.yaw)] {
                proptest::prop_assert!((x.rad() - y.rad()).abs() <= 4.0 * f64::EPSILON * y.rad().abs().max(1e-300));
            }
        }
    }

    #[test]
    fn a_malformed_reading_is_dropped_and_counted_and_the_frame_kept() {
        let mut bytes = write(&[]);
        let c = "[1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,25]";
        for (seq, extra) in [
            (0, r#""depth":{"z":"deep"}"#),
            (1, r#""velocity":{"fwd":1.0,"right":0.0}"#),
            (
                2,
                r#""depth":{"z":1.0},"std":{"z":0.05,"fwd":0.1,"right":0.1,"down":0.1}"#,
            ),
            (
                3,
                r#""velocity":{"fwd":1.0,"right":0.0,"down":0.0,"std":{"fwd":0.1}}"#,
            ),
            (4, r#""attitude":{"pitch":1.0,"yaw":2.0},"depth":null"#),
        ] {
            let line = format!(
                "{{\"class\":\"FRAME\",\"seq\":{seq},\"t\":{seq}.0,\"counts\":{c},{extra}}}\n"
            );
            bytes.extend_from_slice(line.as_bytes());
        }
        let mut r = LogReader::new(&bytes[..], "s.jsonl").unwrap();
        let got: Vec<Frame> = r.by_ref().map(|x| x.unwrap()).collect();
        assert_eq!(got.len(), 5, "every frame kept");
        assert_eq!(got[0].depth, None);
        assert_eq!(got[1].velocity, None);
        assert_eq!(
            got[2].depth,
            Some(DepthReading {
                z: 1.0,
                std: Some(0.05)
            }),
            "a frame-level std applies"
        );
        assert_eq!(got[3].velocity, None, "a partial std is refused");
        assert!(got[4].attitude.is_some() && got[4].depth.is_none());
        let (n, last) = r.bad_readings();
        assert_eq!(n, 3);
        assert!(
            last.unwrap().starts_with("s.jsonl:5: velocity std"),
            "{last:?}"
        );
    }

    #[test]
    fn header_extras_pass_through() {
        let mut h = LogHeader::new(12, 5.0);
        h.extra.insert("scene".into(), "tank".into());
        let w = LogWriter::new(Vec::new(), &h).unwrap();
        let bytes = w.into_inner();
        let r = LogReader::new(&bytes[..], "h").unwrap();
        assert_eq!(r.header(), &h);
    }
}

#[cfg(test)]
mod hardening_tests {
    //! Issue 16: bounded lines, bounded quotes, and the order of frames.
    use super::*;

    const HEADER: &str = "{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":5}\n";
    const COUNTS: &str = "[1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,25]";

    fn frame_line(seq: impl std::fmt::Display, t: impl std::fmt::Display) -> String {
        format!("{{\"class\":\"FRAME\",\"seq\":{seq},\"t\":{t},\"counts\":{COUNTS}}}\n")
    }

    /// (seq of each frame read, each error's text) of a log.
    fn read(text: &str) -> (Vec<u64>, Vec<String>, LogReader<&[u8]>) {
        let mut r = LogReader::new(text.as_bytes(), "o.jsonl").unwrap();
        let (mut seqs, mut errs) = (Vec::new(), Vec::new());
        while let Some(item) = r.next_frame() {
            match item {
                Ok(f) => seqs.push(f.seq),
                Err(e) => errs.push(e.to_string()),
            }
        }
        (seqs, errs, r)
    }

    #[test]
    fn a_line_past_the_bound_is_refused_by_its_number_and_reading_goes_on() {
        let mut text = HEADER.to_string();
        text.push_str(&frame_line(0, 0.0));
        text.push_str(&"x".repeat(MAX_LOG_LINE_BYTES * 3));
        text.push('\n');
        text.push_str(&frame_line(1, 0.2));
        let (seqs, errs, _) = read(&text);
        assert_eq!(seqs, vec![0, 1]);
        assert_eq!(errs.len(), 1, "{errs:?}");
        assert!(
            errs[0].starts_with("o.jsonl:3: line longer than"),
            "{}",
            errs[0]
        );
        assert!(errs[0].len() < 200, "{}", errs[0]);
    }

    #[test]
    fn errors_quote_at_most_an_excerpt_of_the_line() {
        let long = "y".repeat(100_000);
        let mut text = HEADER.to_string();
        text.push_str(&frame_line(0, format!("\"{long}\"")));
        text.push_str(&format!(
            "{{\"class\":\"FRAME\",\"seq\":1,\"t\":1,\"counts\":[\"{long}\"]}}\n"
        ));
        let (_, errs, _) = read(&text);
        assert_eq!(errs.len(), 2, "{errs:?}");
        for e in &errs {
            assert!(e.chars().count() < 400, "{} chars: {}…", e.len(), &e[..200]);
        }
        let h = format!("{{\"class\":\"{long}\"}}\n");
        let e = LogReader::new(h.as_bytes(), "h.jsonl")
            .err()
            .unwrap()
            .to_string();
        assert!(e.chars().count() < 400, "{} chars", e.len());
    }

    #[test]
    fn a_byte_order_mark_before_the_header_is_accepted() {
        let text = format!("\u{feff}{HEADER}{}", frame_line(0, 0.0));
        let (seqs, errs, _) = read(&text);
        assert_eq!((seqs, errs), (vec![0], vec![]));
    }

    #[test]
    fn frames_out_of_order_are_skipped_counted_and_named() {
        let mut text = HEADER.to_string();
        for (seq, t) in [
            (0, "0"),
            (1, "0.2"),
            (1, "0.4"),
            (0, "0.6"),
            (2, "0.1"),
            (3, "0.8"),
        ] {
            text.push_str(&frame_line(seq, t));
        }
        text.push_str("{\"class\":\"POSE\",\"seq\":3,\"t\":0.8}\n");
        text.push_str(&frame_line(4, "1e300"));
        text.push_str(&frame_line(5, "1.0"));
        text.push_str(&frame_line(6, "100.0"));
        let (seqs, errs, r) = read(&text);
        assert_eq!(seqs, vec![0, 1, 3, 5, 6]);
        assert_eq!(errs.len(), 4, "{errs:?}");
        assert!(
            errs[0].starts_with("o.jsonl:4: seq 1 repeats"),
            "{}",
            errs[0]
        );
        assert!(
            errs[1].starts_with("o.jsonl:5: seq 0 after seq 1"),
            "{}",
            errs[1]
        );
        assert!(
            errs[2].starts_with("o.jsonl:6: t = 0.1 after t = 0.2"),
            "{}",
            errs[2]
        );
        assert!(errs[3].starts_with("o.jsonl:9: t = 1e300"), "{}", errs[3]);
        assert_eq!(r.order().skipped(), 4);
        // A backward seq is a skip, not frames lost: 1 → 3 lost seq 2 only,
        // and 3 → 5 lost 4, which was refused.
        assert_eq!(r.seq_gaps(), (2, 2));
        // 1.0 → 100.0 is past the gap bound: kept and flagged.
        assert_eq!(r.order().jumps(), 1);
        assert_eq!(r.order().last_jump(), Some(99.0));
        assert_eq!(r.other_lines(), 1);
        assert_eq!(r.first_other(), Some("o.jsonl:8: class \"POSE\""));
    }
}

#[cfg(test)]
mod v3_tests {
    //! Spec v3: roll, the header's sample rate and beacons, BURST lines and
    //! demodulated frames.
    use super::*;
    use crate::samples::{BeaconAmplitude, BeaconInfo};
    use crate::{Angle, Pose};

    fn header() -> LogHeader {
        let mut h = LogHeader::new(10, 5.0);
        h.sample_hz = Some(20.0);
        h.channel_skew_s = Some(1e-5);
        h.beacons = vec![
            BeaconInfo {
                id: "top".into(),
                mod_hz: 10.0,
            },
            BeaconInfo {
                id: "port".into(),
                mod_hz: 5.0,
            },
        ];
        h
    }

    fn burst(seq: u64) -> Burst {
        let mut b = Burst::new(4);
        b.seq = seq;
        b.t = seq as f64 * 0.2;
        b.adc_bits = 10;
        for (j, c) in b.samples_mut().iter_mut().enumerate() {
            *c = ((j * 37 + seq as usize) % 1024) as u16;
        }
        b.temp_c = Some(14.5);
        b.truth = Some(Truth {
            pose: Pose::new(3.0, 0.1, -0.2, Angle::from_deg(2.0), Angle::ZERO)
                .with_roll(Angle::from_deg(-7.5)),
            surge: None,
        });
        b.attitude = Some(AttitudeReading {
            roll: Some(Angle::from_deg(-7.25)),
            ..AttitudeReading::new(Angle::from_deg(2.5), Angle::from_deg(0.5))
        });
        b
    }

    fn records(bytes: &[u8]) -> (Vec<Result<String, LogError>>, LogReader<&[u8]>) {
        let mut r = LogReader::new(bytes, "v3.jsonl").unwrap();
        let mut out = Vec::new();
        while let Some(x) = r.next_record() {
            out.push(x.map(|rec| format!("{rec:?}")));
        }
        (out, r)
    }

    #[test]
    fn roll_round_trips_and_a_v2_frame_is_written_as_before() {
        let mut f = Frame::new(0, 0.0, 10, [7; NDET]);
        f.truth = Some(Truth {
            pose: Pose::new(5.0, 0.0, 0.0, Angle::ZERO, Angle::ZERO),
            surge: None,
        });
        f.attitude = Some(AttitudeReading::new(Angle::from_deg(1.0), Angle::ZERO));
        let mut w = LogWriter::new(Vec::new(), &LogHeader::new(10, 5.0)).unwrap();
        w.write_frame(&f).unwrap();
        let mut g = f;
        g.seq = 1;
        g.t = 0.2;
        g.truth.as_mut().unwrap().pose.roll = Angle::from_deg(12.5);
        g.attitude.as_mut().unwrap().roll = Some(Angle::from_deg(12.0));
        w.write_frame(&g).unwrap();
        let bytes = w.into_inner();
        let text = String::from_utf8(bytes.clone()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert!(!lines[0].contains("sample_hz") && !lines[0].contains("beacons"));
        assert!(!lines[1].contains("roll"), "{}", lines[1]);
        assert!(
            lines[2].contains(r#""yaw":0.0,"roll":12.5"#),
            "{}",
            lines[2]
        );
        assert!(lines[2].contains(r#""roll":12.0"#), "{}", lines[2]);
        let got: Vec<Frame> = LogReader::new(&bytes[..], "r")
            .unwrap()
            .map(|r| r.unwrap())
            .collect();
        assert_eq!(got[0].truth.unwrap().pose.roll, Angle::ZERO);
        assert_eq!(got[0].attitude.unwrap().roll, None);
        assert!((got[1].truth.unwrap().pose.roll.deg() - 12.5).abs() < 1e-12);
        assert!((got[1].attitude.unwrap().roll.unwrap().deg() - 12.0).abs() < 1e-12);
        // A v2 line read and written again is the same bytes.
        let mut again = LogWriter::new(Vec::new(), &LogHeader::new(10, 5.0)).unwrap();
        again.write_frame(&got[0]).unwrap();
        let again = String::from_utf8(again.into_inner()).unwrap();
        assert_eq!(again.lines().nth(1), Some(lines[1]));
        let bad = "{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":5}\n{\"class\":\"FRAME\",\"seq\":0,\"t\":0,\"counts\":[0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0],\"attitude\":{\"pitch\":1,\"yaw\":2,\"roll\":\"x\"}}\n";
        let mut r = LogReader::new(bad.as_bytes(), "b").unwrap();
        assert!(r.next_frame().unwrap().unwrap().attitude.is_none());
        assert_eq!(
            r.bad_readings().1,
            Some("b:2: attitude roll is not a number")
        );
    }

    #[test]
    fn bursts_and_their_header_round_trip() {
        let h = header();
        let mut w = LogWriter::new(Vec::new(), &h).unwrap();
        let bursts: Vec<Burst> = (0..3).map(burst).collect();
        for b in &bursts {
            w.write_burst(b).unwrap();
        }
        let bytes = w.into_inner();
        let mut r = LogReader::new(&bytes[..], "b.jsonl").unwrap();
        assert_eq!(r.header(), &h);
        assert_eq!(r.header().samples_per_frame(), 4);
        for want in &bursts {
            match r.next_record() {
                Some(Ok(Record::Burst(b))) => {
                    assert_eq!(b.samples(), want.samples());
                    assert_eq!(
                        (b.seq, b.t, b.n(), b.temp_c),
                        (want.seq, want.t, 4, want.temp_c)
                    );
                    let roll = b.truth.unwrap().pose.roll.deg();
                    assert!((roll + 7.5).abs() < 1e-12, "{roll}");
                    assert!((b.attitude.unwrap().roll.unwrap().deg() + 7.25).abs() < 1e-12);
                }
                other => panic!("{other:?}"),
            }
        }
        assert!(r.next_record().is_none());
        // A reader of counts refuses a BURST log, and the log ends.
        let mut r = LogReader::new(&bytes[..], "b.jsonl").unwrap();
        let e = r.next_frame().unwrap().unwrap_err();
        assert!(!e.skippable());
        assert!(
            e.to_string().starts_with("b.jsonl:2: a BURST line (raw samples) (spec v3): this reader takes FRAME lines of counts only"),
            "{e}"
        );
        assert!(r.next_frame().is_none());
    }

    /// The longest BURST a frame may have (4096 samples of 25 channels at
    /// full scale) reads back: the text files' 64 KiB line bound had
    /// refused 8 kHz at 5 Hz frames.
    #[test]
    fn a_burst_of_the_most_samples_a_frame_may_have_reads_back() {
        let mut h = LogHeader::new(16, 2.0);
        h.sample_hz = Some(2.0 * MAX_SAMPLES_PER_FRAME as f64);
        h.beacons = vec![BeaconInfo {
            id: "top".into(),
            mod_hz: 512.0,
        }];
        let mut b = Burst::new(MAX_SAMPLES_PER_FRAME);
        b.adc_bits = 16;
        b.samples_mut().fill(65535);
        b.truth = Some(Truth {
            pose: Pose::new(1.0, 2.0, 3.0, Angle::ZERO, Angle::ZERO),
            surge: Some(0.5),
        });
        let mut w = LogWriter::new(Vec::new(), &h).unwrap();
        w.write_burst(&b).unwrap();
        let bytes = w.into_inner();
        assert!(bytes.len() > 600_000 && bytes.len() < MAX_LOG_LINE_BYTES);
        let mut r = LogReader::new(&bytes[..], "long.jsonl").unwrap();
        match r.next_record() {
            Some(Ok(Record::Burst(got))) => assert_eq!(got.samples(), b.samples()),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn demodulated_frames_round_trip() {
        let h = header();
        let mut d = Demodulated {
            seq: 4,
            t: 0.875,
            ..Demodulated::default()
        };
        d.light.n_beacons = 2;
        d.light.beacons[0] = BeaconAmplitude {
            beacon: 1,
            amplitude: [12.5; NDET],
            std: [0.25; NDET],
        };
        d.light.beacons[1].beacon = 0;
        d.light.beacons[1].amplitude[3] = -0.5;
        d.light.ambient = [31.0; NDET];
        d.light.clipped[7] = 4;
        let mut w = LogWriter::new(Vec::new(), &h).unwrap();
        w.write_demodulated(&d).unwrap();
        let bytes = w.into_inner();
        let text = String::from_utf8(bytes.clone()).unwrap();
        assert!(
            text.contains(r#""beacons":[{"id":"port","amplitude":[12.5,"#),
            "{text}"
        );
        let mut r = LogReader::new(&bytes[..], "d.jsonl").unwrap();
        match r.next_record() {
            Some(Ok(Record::Demodulated(got))) => assert_eq!(*got, d),
            other => panic!("{other:?}"),
        }
    }

    fn line(class: &str, seq: u64, body: &str) -> String {
        format!("{{\"class\":\"{class}\",\"seq\":{seq},\"t\":{seq}.0,{body}}}\n")
    }

    fn samples(n: usize, last: &str) -> String {
        let one = format!("[{}]", vec!["1"; n].join(","));
        let mut v = vec![one; NDET - 1];
        v.push(last.to_string());
        format!("\"samples\":[{}]", v.join(","))
    }

    #[test]
    fn bad_bursts_are_named_and_a_mixed_log_is_refused_at_its_first_other_line() {
        let mut text =
            String::from_utf8(LogWriter::new(Vec::new(), &header()).unwrap().into_inner()).unwrap();
        text += &line("BURST", 0, &samples(4, "[1,2,3,4]"));
        text += &line("BURST", 1, &samples(4, "[1,2,3]"));
        text += &line("BURST", 2, &samples(4, "[1,2,3,1024]"));
        text += &line("BURST", 3, &samples(4, "[1,2,3,-1]"));
        text += &line("BURST", 4, "\"samples\":[[1,1,1,1]]");
        text += &line("BURST", 5, "\"counts\":[]");
        text += &line("BURST", 6, &samples(4, "[4,3,2,1]"));
        text += &line(
            "FRAME",
            7,
            &format!("\"counts\":[{}]", vec!["0"; NDET].join(",")),
        );
        text += &line("BURST", 8, &samples(4, "[4,3,2,1]"));
        let (got, _) = records(text.as_bytes());
        let errs: Vec<String> = got
            .iter()
            .filter_map(|g| g.as_ref().err().map(|e| e.to_string()))
            .collect();
        assert_eq!(got.len(), 8, "{got:?}");
        assert!(got[0].is_ok() && got[6].is_ok());
        for (e, want) in errs.iter().zip([
            "v3.jsonl:3: samples[24] has 3 values, expected N = 4",
            "v3.jsonl:4: samples[24][3] = 1024 is not an integer in 0..1023",
            "v3.jsonl:5: samples[24][3] = -1 is not an integer in 0..1023",
            "v3.jsonl:6: samples has 1 arrays, expected 25",
            "v3.jsonl:7: BURST has no samples",
            "v3.jsonl:9: a FRAME line of counts in a log of BURST line (raw samples)s (the first at line 2)",
        ]) {
            assert!(e.starts_with(want), "{e} is not {want}");
        }
        assert_eq!(errs.len(), 6);
    }

    #[test]
    fn bad_demodulated_frames_are_named() {
        let mut text =
            String::from_utf8(LogWriter::new(Vec::new(), &header()).unwrap().into_inner()).unwrap();
        let n25 = |x: &str| format!("[{}]", vec![x; NDET].join(","));
        let frame = |seq: u64, id: &str, clipped: &str| {
            let body = format!(
                "\"beacons\":[{{\"id\":\"{id}\",\"amplitude\":{},\"std\":{}}}],\"ambient\":{},\"clipped\":{}",
                n25("1.5"),
                n25("0.1"),
                n25("30"),
                n25(clipped)
            );
            line("FRAME", seq, &body)
        };
        text += &frame(0, "top", "0");
        text += &frame(1, "starboard", "0");
        text += &frame(2, "top", "5");
        text += &frame(3, "port", "4");
        let (got, _) = records(text.as_bytes());
        let errs: Vec<String> = got
            .iter()
            .filter_map(|g| g.as_ref().err().map(|e| e.to_string()))
            .collect();
        assert!(got[0].is_ok() && got[3].is_ok(), "{got:?}");
        assert!(
            errs[0].starts_with(
                "v3.jsonl:3: beacons[0]: id \"starboard\" is not among the header's beacons"
            ),
            "{}",
            errs[0]
        );
        assert!(
            errs[1].starts_with("v3.jsonl:4: clipped[0] is not an integer in 0..=4"),
            "{}",
            errs[1]
        );
    }

    #[test]
    fn bad_v3_headers_are_refused() {
        let h = |extra: &str| {
            format!("{{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":10{extra}}}\n")
        };
        for (extra, want) in [
            (",\"sample_hz\":25", "h:1: header sample_hz = 25 is not a whole multiple of rate_hz = 10"),
            (",\"sample_hz\":4000", "no beacon blinks"),
            (",\"sample_hz\":4800,\"beacons\":[{\"id\":\"a\",\"mod_hz\":200},{\"id\":\"b\",\"mod_hz\":600}]", "ratio 1 : 3"),
            (",\"sample_hz\":4000,\"beacons\":[{\"id\":\"a\",\"mod_hz\":200},{\"id\":\"a\",\"mod_hz\":250}]", "id \"a\" repeats"),
            (",\"beacons\":[{\"mod_hz\":200}]", "beacons[0] has no id"),
            (",\"channel_skew_s\":-1", "channel_skew_s = -1"),
        ] {
            let e = LogReader::new(h(extra).as_bytes(), "h").err().expect(extra).to_string();
            assert!(e.contains(want), "{e} lacks {want}");
        }
    }
}
