//! The intensity log of FORMATS.md: JSON Lines, a HEADER then one FRAME per
//! line. Read and written as a stream, so a log of a million frames never
//! sits in memory whole. The reader names the line of anything it refuses,
//! and treats a cut-short last line (power loss) as the end of the log.
//! Lines are read bounded ([`crate::textfile::MAX_LINE_BYTES`]), errors quote
//! at most an excerpt, and the order of frames follows [`FrameOrder`].

use crate::frame::full_scale;
use crate::frame::{DepthReading, VelocityReading};
use crate::textfile::{excerpt, one_line, read_line_bounded, LineRead, MAX_LINE_BYTES};
use crate::{Angle, AttitudeReading, Frame, Pose, Truth, COLS, NDET, ROWS};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Write};
use std::path::Path;

mod framelog;
pub use framelog::{ByteError, Cut, FrameLog};
mod order;
mod rawline;
mod readings;
pub use order::{plausible_t, FrameOrder, DEFAULT_MAX_GAP_S, MAX_ABS_T_S};
use rawline::{RawLine, Reading, Std};
pub use readings::as_logged;
use readings::{parse_attitude, parse_depth, parse_velocity};

pub const FORMAT: &str = "lightpose-intensity";
pub const VERSION: u32 = 1;
/// A header's frame rate: one frame in 1000 s to a megahertz (a scene's
/// own limit). A recorded pace waits a period per frame, and 1e-19 Hz made
/// that wait overflow the clock.
pub const HEADER_RATE_HZ: std::ops::RangeInclusive<f64> = 1e-3..=1e6;

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
    /// A binary container (MCAP) refused something at a byte offset.
    #[error(transparent)]
    At(ByteError),
}

/// The first line of a log. Fields this reader does not know are kept and
/// written back, so a log passes through unchanged.
#[derive(Debug, Clone, PartialEq)]
pub struct LogHeader {
    pub adc_bits: u8,
    pub rate_hz: f64,
    /// Everything else the header carried (scene, board, date, notes).
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl LogHeader {
    pub fn new(adc_bits: u8, rate_hz: f64) -> Self {
        LogHeader {
            adc_bits,
            rate_hz,
            extra: serde_json::Map::new(),
        }
    }

    fn to_json(&self) -> serde_json::Value {
        let mut m = serde_json::Map::new();
        m.insert("class".into(), "HEADER".into());
        m.insert("format".into(), FORMAT.into());
        m.insert("version".into(), VERSION.into());
        m.insert("rows".into(), ROWS.into());
        m.insert("cols".into(), COLS.into());
        m.insert("adc_bits".into(), self.adc_bits.into());
        m.insert(
            "rate_hz".into(),
            crate::finite(self.rate_hz).map_or(serde_json::Value::Null, Into::into),
        );
        for (k, v) in &self.extra {
            m.entry(k.clone()).or_insert_with(|| v.clone());
        }
        serde_json::Value::Object(m)
    }

    fn parse(v: serde_json::Value) -> Result<Self, String> {
        let serde_json::Value::Object(mut m) = v else {
            return Err("header is not a JSON object".into());
        };
        let class = m.remove("class");
        if class.as_ref().and_then(|c| c.as_str()) != Some("HEADER") {
            return Err(format!(
                "first line must be class HEADER, found {}",
                class.map_or("no class".to_string(), |c| excerpt(&c.to_string(), 40))
            ));
        }
        let format = m.remove("format");
        if format.as_ref().and_then(|c| c.as_str()) != Some(FORMAT) {
            return Err(format!("header format must be \"{FORMAT}\""));
        }
        // The spec's header says 1 and its v2 added only optional fields,
        // so a writer that calls such a log version 2 is read alike (we
        // write 1: every v1 reader passes over the fields it does not know).
        match m.remove("version").and_then(|v| v.as_u64()) {
            Some(1 | 2) => {}
            Some(v) => return Err(format!("header version {v} is not supported (only 1 or 2)")),
            None => return Err("header has no integer version".into()),
        }
        for (key, want) in [("rows", ROWS), ("cols", COLS)] {
            match m.remove(key).and_then(|v| v.as_u64()) {
                Some(v) if v as usize == want => {}
                Some(v) => {
                    return Err(format!(
                        "header {key} = {v}: only a 5 × 5 array is supported"
                    ))
                }
                None => return Err(format!("header has no integer {key}")),
            }
        }
        let adc_bits = match m.remove("adc_bits").and_then(|v| v.as_u64()) {
            Some(b @ 1..=16) => b as u8,
            Some(b) => return Err(format!("header adc_bits = {b}: must be 1..16")),
            None => return Err("header has no integer adc_bits".into()),
        };
        let rate_hz = match m.remove("rate_hz").and_then(|v| v.as_f64()) {
            Some(r) if HEADER_RATE_HZ.contains(&r) => r,
            Some(r) => {
                return Err(format!(
                    "header rate_hz = {r}: must be in {}..={} Hz",
                    HEADER_RATE_HZ.start(),
                    HEADER_RATE_HZ.end()
                ))
            }
            None => return Err("header has no number rate_hz".into()),
        };
        Ok(LogHeader {
            adc_bits,
            rate_hz,
            extra: m,
        })
    }
}

#[derive(Deserialize, Serialize)]
struct RawTruth {
    x: f64,
    y: f64,
    z: f64,
    pitch: f64,
    yaw: f64,
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

    fn line_err(&self, msg: impl Into<String>) -> LogError {
        LogError::Line {
            name: self.name.clone(),
            line: self.line_no,
            msg: msg.into(),
        }
    }

    /// The next frame, `None` at the end of the log.
    pub fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        // The line is parsed in place (its fields borrowed from it, no
        // allocation per frame): the buffer is out of `self` meanwhile.
        let mut buf = std::mem::take(&mut self.buf);
        let r = self.next_frame_in(&mut buf);
        self.buf = buf;
        r
    }

    fn next_frame_in(&mut self, buf: &mut Vec<u8>) -> Option<Result<Frame, LogError>> {
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
            match raw.class.as_ref().map(|c| &*c.0) {
                Some("FRAME") => {}
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
            }
            let r = self
                .frame_from(raw)
                .and_then(|f| match self.order.admit(f.seq, f.t) {
                    Ok(()) => Ok(f),
                    Err(why) => Err(self.line_err(why)),
                });
            return Some(r);
        }
    }

    /// A reading of the frame, or none when it is absent or malformed (then
    /// counted and named: the frame keeps its light).
    fn reading<T>(
        &mut self,
        v: Option<&Reading>,
        fs: Option<&Std>,
        parse: fn(&Reading, Option<&Std>) -> Result<T, String>,
    ) -> Option<T> {
        // A null reading is `None` here (serde's `Option`).
        match v {
            None => None,
            Some(v) => match parse(v, fs) {
                Ok(r) => Some(r),
                Err(msg) => {
                    self.bad_readings += 1;
                    self.last_bad_reading = Some(format!("{}:{}: {msg}", self.name, self.line_no));
                    None
                }
            },
        }
    }

    fn frame_from(&mut self, raw: RawLine<'_>) -> Result<Frame, LogError> {
        let seq = raw
            .seq
            .as_ref()
            .and_then(|v| v.as_u64())
            .ok_or_else(|| self.line_err("FRAME needs a non-negative integer seq"))?;
        let t = raw
            .t
            .filter(|t| t.is_finite())
            .ok_or_else(|| self.line_err("FRAME needs a finite number t"))?;
        let values = raw
            .counts
            .ok_or_else(|| self.line_err("FRAME has no counts"))?;
        if values.len != NDET {
            return Err(self.line_err(format!("counts has {} values, expected {NDET}", values.len)));
        }
        let fs = full_scale(self.header.adc_bits) as u64;
        let mut counts = [0u16; NDET];
        for (k, (v, c)) in values.values.iter().zip(counts.iter_mut()).enumerate() {
            match *v {
                Some(n) if n <= fs => *c = n as u16,
                _ => {
                    // The first value that is no integer is the one kept.
                    let v = match (v, &values.first_other) {
                        (Some(n), _) => n.to_string(),
                        (None, Some(other)) => other.to_string(),
                        (None, None) => String::new(),
                    };
                    let v = excerpt(&v, 40);
                    return Err(
                        self.line_err(format!("counts[{k}] = {v} is not an integer in 0..{fs}"))
                    );
                }
            }
        }
        if let Some(tc) = raw.temp_c {
            if !tc.is_finite() {
                return Err(self.line_err("temp_c is not finite"));
            }
        }
        let truth = match raw.truth {
            None => None,
            Some(tr) => {
                let vals = [tr.x, tr.y, tr.z, tr.pitch, tr.yaw];
                if vals.iter().any(|v| !v.is_finite()) || tr.surge.is_some_and(|s| !s.is_finite()) {
                    return Err(self.line_err("truth has a value that is not finite"));
                }
                Some(Truth {
                    pose: Pose::new(
                        tr.x,
                        tr.y,
                        tr.z,
                        Angle::from_deg(tr.pitch),
                        Angle::from_deg(tr.yaw),
                    ),
                    surge: tr.surge,
                })
            }
        };
        let fs = raw.std.as_ref();
        let attitude = self.reading(raw.attitude.as_ref(), fs, parse_attitude);
        let depth = self.reading(raw.depth.as_ref(), fs, parse_depth);
        let velocity = self.reading(raw.velocity.as_ref(), fs, parse_velocity);
        Ok(Frame {
            seq,
            t,
            adc_bits: self.header.adc_bits,
            counts,
            temp_c: raw.temp_c,
            truth,
            attitude,
            depth,
            velocity,
        })
    }
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
    match read_line_bounded(src, buf, MAX_LINE_BYTES) {
        Err(err) => Err(LogError::Io {
            name: name.to_string(),
            err,
        }),
        Ok(LineRead::Eof) => Ok(None),
        Ok(LineRead::TooLong) => Err(refused(format!(
            "line longer than {MAX_LINE_BYTES} bytes: refused unread (a FRAME line is under 1 kB)"
        ))),
        Ok(LineRead::Line) => std::str::from_utf8(buf)
            .map(Some)
            .map_err(|_| refused("not valid UTF-8".into())),
    }
}

fn at_eof<R: BufRead>(src: &mut R) -> bool {
    src.fill_buf().map(|b| b.is_empty()).unwrap_or(true)
}

#[derive(Serialize)]
struct FrameOut<'a> {
    class: &'static str,
    seq: u64,
    t: Option<f64>,
    counts: &'a [u16; NDET],
    #[serde(skip_serializing_if = "Option::is_none")]
    temp_c: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    truth: Option<RawTruth>,
    #[serde(skip_serializing_if = "Option::is_none")]
    attitude: Option<AttitudeOut>,
    #[serde(skip_serializing_if = "Option::is_none")]
    depth: Option<DepthOut>,
    #[serde(skip_serializing_if = "Option::is_none")]
    velocity: Option<VelocityOut>,
}

#[derive(Serialize)]
struct AttitudeOut {
    pitch: f64,
    yaw: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    std: Option<AttitudeStdOut>,
}
#[derive(Serialize)]
struct AttitudeStdOut {
    pitch: f64,
    yaw: f64,
}
#[derive(Serialize)]
struct DepthOut {
    z: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    std: Option<DepthStdOut>,
}
#[derive(Serialize)]
struct DepthStdOut {
    z: f64,
}
#[derive(Serialize)]
struct VelocityOut {
    fwd: f64,
    right: f64,
    down: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    std: Option<VelocityStdOut>,
}
#[derive(Serialize)]
struct VelocityStdOut {
    fwd: f64,
    right: f64,
    down: f64,
}

/// All finite, or none: a reading with a non-finite value is not written
/// (FORMATS.md: writers never emit NaN or infinity).
fn all_finite<const N: usize>(v: [f64; N]) -> Option<[f64; N]> {
    v.iter().all(|x| x.is_finite()).then_some(v)
}

fn attitude_out(a: &AttitudeReading) -> Option<AttitudeOut> {
    let [pitch, yaw] = all_finite([a.pitch.deg(), a.yaw.deg()])?;
    Some(AttitudeOut {
        pitch,
        yaw,
        std: a
            .std
            .and_then(|s| all_finite([s.pitch.deg(), s.yaw.deg()]))
            .map(|[pitch, yaw]| AttitudeStdOut { pitch, yaw }),
    })
}

fn depth_out(d: &DepthReading) -> Option<DepthOut> {
    let [z] = all_finite([d.z])?;
    Some(DepthOut {
        z,
        std: d.std.and_then(crate::finite).map(|z| DepthStdOut { z }),
    })
}

fn velocity_out(v: &VelocityReading) -> Option<VelocityOut> {
    let [fwd, right, down] = all_finite(v.v.0)?;
    Some(VelocityOut {
        fwd,
        right,
        down,
        std: v
            .std
            .and_then(|s| all_finite(s.0))
            .map(|[fwd, right, down]| VelocityStdOut { fwd, right, down }),
    })
}

/// Streaming writer: each line is formatted whole in a reused buffer and
/// handed to the sink in one `write_all`, so a reader never sees half a
/// frame except after a crash mid-write (which the reader handles).
pub struct LogWriter<W: Write> {
    sink: W,
    line: Vec<u8>,
    frames: u64,
}

impl LogWriter<BufWriter<File>> {
    /// Create (truncate) a log file and write its header.
    pub fn create(path: &Path, header: &LogHeader) -> io::Result<Self> {
        let f = File::create(path)?;
        LogWriter::new(BufWriter::with_capacity(1 << 16, f), header)
    }
}

impl<W: Write> LogWriter<W> {
    pub fn new(mut sink: W, header: &LogHeader) -> io::Result<Self> {
        let mut line = serde_json::to_vec(&header.to_json())?;
        line.push(b'\n');
        sink.write_all(&line)?;
        Ok(LogWriter {
            sink,
            line,
            frames: 0,
        })
    }

    /// Append one frame as one line.
    pub fn write_frame(&mut self, f: &Frame) -> io::Result<()> {
        self.line.clear();
        let out = FrameOut {
            class: "FRAME",
            seq: f.seq,
            t: crate::finite(f.t),
            counts: &f.counts,
            temp_c: f.temp_c.and_then(crate::finite),
            truth: f.truth.map(|tr| RawTruth {
                x: tr.pose.x,
                y: tr.pose.y,
                z: tr.pose.z,
                pitch: tr.pose.pitch.deg(),
                yaw: tr.pose.yaw.deg(),
                surge: tr.surge.and_then(crate::finite),
            }),
            attitude: f.attitude.as_ref().and_then(attitude_out),
            depth: f.depth.as_ref().and_then(depth_out),
            velocity: f.velocity.as_ref().and_then(velocity_out),
        };
        serde_json::to_writer(&mut self.line, &out)?;
        self.line.push(b'\n');
        self.sink.write_all(&self.line)?;
        self.frames += 1;
        Ok(())
    }

    pub fn frames_written(&self) -> u64 {
        self.frames
    }
    pub fn flush(&mut self) -> io::Result<()> {
        self.sink.flush()
    }
    pub fn get_ref(&self) -> &W {
        &self.sink
    }
    pub fn get_mut(&mut self) -> &mut W {
        &mut self.sink
    }
    pub fn into_inner(self) -> W {
        self.sink
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::AttitudeStd;

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
        text.push_str(&"x".repeat(crate::textfile::MAX_LINE_BYTES * 3));
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
