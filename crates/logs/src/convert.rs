//! `lightpose convert`'s work: an intensity log from one container to the
//! other (or to the same one, which rewrites it: an MCAP cut by a power
//! loss comes out finished, with every frame of its complete chunks).
//!
//! Frames go through `Frame` (f64 exactly, serde_json's float_roundtrip),
//! so JSONL → MCAP → JSONL gives back a log written by lightpose byte for
//! byte. Poses: a JSONL intensity log holds frames only, so the POSE lines
//! of the JSONL side are a file of their own (`lightpose replay`'s output).
//! Into MCAP that file is read and its lines go, as they are, on
//! `/lightpose/pose` after the frame they belong to; out of MCAP the
//! `/lightpose/pose` messages are written to it one per line. MCAP → MCAP
//! carries the poses itself, and every channel it does not make from
//! frames and poses (`/lightpose/status`, any other program's) and every
//! metadata record (`lightpose-clock`, any other) as they were: the same
//! declarations, message bytes, sequence numbers and times. The Foxglove
//! channels are made anew from the frames and poses (and left out with
//! `foxglove` off). A JSONL log holds frames only (FORMATS.md): MCAP →
//! JSONL passes STATUS and metadata over, counted. Spec v3: frames of any
//! kind (counts, BURST, demodulated) are carried as their lines, a BURST
//! into MCAP as the binary `/lightpose/burst` that gives its line back
//! byte for byte ([`crate::burst`]), so that BURST JSONL → MCAP → JSONL is
//! exact too.

use crate::read::Carried;
use crate::write::{McapOptions, McapWriter, WriteError};
use crate::{Format, LogFile};
use lightpose_core::textfile::{read_line_bounded, LineRead, MAX_LINE_BYTES};
use lightpose_core::{Burst, Cut, Demodulated, Frame, FrameLog, LogError, Record};
use std::fs::File;
use std::io::{self, BufReader, BufWriter, Write};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error("{0}")]
    Usage(String),
    #[error(transparent)]
    Read(#[from] LogError),
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("{file}: {err}")]
    File { file: String, err: io::Error },
    #[error("{file}:{line}: {msg}")]
    PoseLine {
        file: String,
        line: usize,
        msg: String,
    },
}

/// What a conversion did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConvertSummary {
    pub frames: u64,
    pub poses: u64,
    /// Frames (lines, messages, chunks) and POSE lines (longer than
    /// core's bound) refused and skipped.
    pub skipped: u64,
    /// Where the input was cut short, if it was.
    pub cut: Option<Cut>,
    /// Records of other kinds read and not carried as they are (poses,
    /// Foxglove messages, which are made anew from frames and poses;
    /// into JSONL, STATUS and metadata too).
    pub other: u64,
    /// MCAP → MCAP: messages of the other channels carried as they were
    /// (STATUS, other programs'), and metadata records carried.
    pub carried: u64,
    pub metadata: u64,
    pub seq_gaps: (u64, u64),
}

enum Out {
    /// Lines are written as they were read.
    Jsonl(String, BufWriter<File>),
    Mcap(Box<McapWriter<BufWriter<File>>>),
}

/// POSE lines read in step with the frames (JSONL → MCAP, and a ROS 2
/// bag's poses), each bounded as core bounds a log's lines.
pub(crate) struct PoseFeed {
    src: BufReader<File>,
    file: String,
    line_no: usize,
    buf: Vec<u8>,
    /// A line read ahead: its seq and text.
    next: Option<(u64, Vec<u8>)>,
    ended: bool,
    /// Lines refused unread (too long), not yet handed to the caller.
    pub(crate) refused: Vec<LogError>,
}

#[derive(serde::Deserialize)]
struct PoseSeq {
    class: Option<String>,
    seq: Option<u64>,
}

impl PoseFeed {
    pub(crate) fn open(path: &Path) -> Result<Self, ConvertError> {
        let file = path.display().to_string();
        let f = File::open(path).map_err(|err| ConvertError::File {
            file: file.clone(),
            err,
        })?;
        Ok(PoseFeed {
            src: BufReader::new(f),
            file,
            line_no: 0,
            buf: Vec::new(),
            next: None,
            ended: false,
            refused: Vec::new(),
        })
    }

    /// An error at the line last read.
    pub(crate) fn bad(&self, msg: impl Into<String>) -> ConvertError {
        ConvertError::PoseLine {
            file: self.file.clone(),
            line: self.line_no,
            msg: msg.into(),
        }
    }

    /// Read ahead to the next POSE line.
    fn fill(&mut self) -> Result<(), ConvertError> {
        while self.next.is_none() && !self.ended {
            let read = read_line_bounded(&mut self.src, &mut self.buf, MAX_LINE_BYTES);
            let read = read.map_err(|err| ConvertError::File {
                file: self.file.clone(),
                err,
            })?;
            match read {
                LineRead::Eof => {
                    self.ended = true;
                    break;
                }
                LineRead::TooLong => {
                    // As core refuses a log's line: counted, skipped.
                    self.line_no += 1;
                    self.refused.push(LogError::Line {
                        name: self.file.clone(),
                        line: self.line_no,
                        msg: format!(
                            "line longer than {MAX_LINE_BYTES} bytes: refused unread (a POSE line is under 1 kB)"
                        ),
                    });
                    continue;
                }
                LineRead::Line => self.line_no += 1,
            }
            let text = std::str::from_utf8(&self.buf).map_err(|_| self.bad("not valid UTF-8"))?;
            if text.trim().is_empty() {
                continue;
            }
            let p: PoseSeq = serde_json::from_str(text.trim())
                .map_err(|e| self.bad(format!("not valid JSON: {e}")))?;
            match (p.class.as_deref(), p.seq) {
                (Some("POSE"), Some(seq)) => self.next = Some((seq, std::mem::take(&mut self.buf))),
                (Some("POSE"), None) => return Err(self.bad("POSE has no integer seq")),
                _ => {} // other classes beside POSE: not poses
            }
        }
        Ok(())
    }

    /// Write the POSE lines up to frame `seq` (all, with `None`).
    fn write_through(
        &mut self,
        seq: Option<u64>,
        out: &mut McapWriter<BufWriter<File>>,
    ) -> Result<u64, ConvertError> {
        self.take_through(seq, |feed, _, text| {
            out.write_pose_line(text)
                .map_err(|e| feed.bad(e.to_string()))
        })
    }

    /// Hand each POSE line up to frame `seq` (all, with `None`) to `f`
    /// with its seq; how many.
    pub(crate) fn take_through(
        &mut self,
        seq: Option<u64>,
        mut f: impl FnMut(&Self, u64, &[u8]) -> Result<(), ConvertError>,
    ) -> Result<u64, ConvertError> {
        let mut n = 0;
        loop {
            self.fill()?;
            match self.next.take() {
                Some((s, text)) if seq.is_none_or(|limit| s <= limit) => {
                    f(self, s, &text)?;
                    n += 1;
                }
                other => {
                    self.next = other;
                    return Ok(n);
                }
            }
        }
    }
}

/// A line as it was read, newline-terminated.
fn write_line(w: &mut impl Write, line: &[u8], file: &str) -> Result<(), ConvertError> {
    let r = w.write_all(line);
    let r = r.and_then(|()| match line.last() {
        Some(b'\n') => Ok(()),
        _ => w.write_all(b"\n"),
    });
    r.map_err(|err| ConvertError::File {
        file: file.to_string(),
        err,
    })
}

fn create_file(path: &Path) -> Result<BufWriter<File>, ConvertError> {
    let f = File::create(path).map_err(|err| ConvertError::File {
        file: path.display().to_string(),
        err,
    })?;
    Ok(BufWriter::with_capacity(1 << 16, f))
}

/// Where the POSE lines go or come from, by direction.
enum Poses {
    None,
    /// JSONL → MCAP: read from this file.
    Feed(PoseFeed),
    /// MCAP → JSONL: kept by the reader, written to this file.
    ToFile(String, BufWriter<File>),
    /// MCAP → MCAP: kept by the reader, rewritten on the pose channel;
    /// with them, what is carried as it was.
    Carry(Box<Carry>),
}

/// MCAP → MCAP: the POSE lines' buffer, the output id of each input
/// channel carried, and the counts.
#[derive(Default)]
struct Carry {
    buf: Vec<u8>,
    ids: std::collections::HashMap<u16, u16>,
    messages: u64,
    metadata: u64,
}

/// Where the POSE lines go, by the direction of the conversion.
fn route_poses(
    log: &mut LogFile,
    out: Format,
    poses: Option<&Path>,
) -> Result<Poses, ConvertError> {
    let route = match (log.format(), out, poses) {
        (Format::Jsonl, Format::Mcap, Some(p)) => Poses::Feed(PoseFeed::open(p)?),
        (Format::Mcap, Format::Jsonl, Some(p)) => {
            Poses::ToFile(p.display().to_string(), create_file(p)?)
        }
        (Format::Mcap, Format::Mcap, None) => Poses::Carry(Box::default()),
        (_, _, None) => Poses::None,
        (Format::Mcap, Format::Mcap, Some(_)) => {
            return Err(ConvertError::Usage(
                "--poses: MCAP to MCAP carries the poses itself".into(),
            ))
        }
        (Format::Jsonl, Format::Jsonl, Some(_)) => {
            return Err(ConvertError::Usage(
                "--poses: a JSONL to JSONL conversion has no poses to carry".into(),
            ))
        }
    };
    if let (LogFile::Mcap(r), false) = (&mut *log, matches!(route, Poses::None)) {
        r.keep_poses(true);
    }
    if let (LogFile::Mcap(r), Poses::Carry(_)) = (log, &route) {
        r.keep_carried(true);
    }
    Ok(route)
}

/// The output file, started with the input's HEADER line as it was read.
fn create_output(
    log: &LogFile,
    output: &Path,
    format: Format,
    opts: &McapOptions,
) -> Result<Out, ConvertError> {
    let mut sink = create_file(output)?;
    let header = String::from_utf8_lossy(log.last_line()).into_owned();
    Ok(match format {
        Format::Jsonl => {
            let file = output.display().to_string();
            write_line(&mut sink, header.as_bytes(), &file)?;
            Out::Jsonl(file, sink)
        }
        Format::Mcap => Out::Mcap(Box::new(McapWriter::with_header_line(sink, &header, opts)?)),
    })
}

/// Convert `input` to `output` (containers by extension), with the POSE
/// lines of `poses` as the module docs say. Each refused frame is handed to
/// `on_skip` and skipped; a broken input or any write error ends it.
pub fn convert(
    input: &Path,
    output: &Path,
    poses: Option<&Path>,
    opts: &McapOptions,
    mut on_skip: impl FnMut(&LogError),
) -> Result<ConvertSummary, ConvertError> {
    let out_format = Format::of_path(output).ok_or_else(|| {
        ConvertError::Usage(format!(
            "{}: the output must be named .jsonl or .mcap",
            output.display()
        ))
    })?;
    if crate::same_file(input, output) {
        return Err(ConvertError::Usage(format!(
            "{}: input and output are the same file",
            input.display()
        )));
    }
    // `--poses` is written when the output is JSONL (the poses of an MCAP
    // recording), else read: written as the input, it had truncated the
    // recording being read (an audit: the input MCAP left at 0 bytes,
    // exit 0); as the output, two writers' lines interleaved, or the
    // output truncated the poses before they were read.
    if let Some(p) = poses {
        let written = out_format == Format::Jsonl;
        for (flag, other, clash) in [("--in", input, written), ("--out", output, true)] {
            if clash && crate::same_place(p, other) {
                return Err(ConvertError::Usage(format!(
                    "{}: --poses and {flag} are the same file",
                    p.display()
                )));
            }
        }
    }
    let mut log = LogFile::open(input)?;
    let mut poses = route_poses(&mut log, out_format, poses)?;
    let mut out = create_output(&log, output, out_format, opts)?;
    let mut s = ConvertSummary::default();
    // Spec v3: frames of any of the three kinds, each carried as its line
    // (into MCAP, a BURST as the binary `/lightpose/burst`, which gives
    // its line back byte for byte); a burst or demodulated frame is copied
    // out of the reader into buffers reused frame after frame.
    let mut burst = Burst::default();
    let mut demod = Box::<Demodulated>::default();
    // A frame by value, as everywhere (no heap per frame).
    #[allow(clippy::large_enum_variant)]
    enum Got {
        Frame(Frame),
        Burst,
        Demod,
    }
    while let Some(r) = log.next_record() {
        let got = match r {
            Ok(Record::Frame(f)) => Got::Frame(f),
            Ok(Record::Burst(b)) => {
                burst.clone_from(b);
                Got::Burst
            }
            Ok(Record::Demodulated(d)) => {
                *demod = *d;
                Got::Demod
            }
            Err(e) if e.skippable() => {
                s.skipped += 1;
                on_skip(&e);
                continue;
            }
            Err(e) => return Err(e.into()),
        };
        let rec = match &got {
            Got::Frame(f) => Record::Frame(*f),
            Got::Burst => Record::Burst(&burst),
            Got::Demod => Record::Demodulated(&demod),
        };
        // Poses kept while reading up to this frame belong before it.
        s.poses += pass_poses(&mut log, &mut poses, &mut out, Due::BeforeFrame)?;
        match &mut out {
            Out::Jsonl(file, w) => write_line(w, log.last_line(), file)?,
            Out::Mcap(w) => w.write_record_line(&rec, log.last_line())?,
        }
        s.frames += 1;
        s.poses += pass_poses(&mut log, &mut poses, &mut out, Due::AfterFrame(rec.seq()))?;
        s.skipped += refused_poses(&mut poses, &mut on_skip);
    }
    s.poses += pass_poses(&mut log, &mut poses, &mut out, Due::End)?;
    s.skipped += refused_poses(&mut poses, &mut on_skip);
    if let Poses::Carry(c) = &poses {
        (s.carried, s.metadata) = (c.messages, c.metadata);
    }
    finish(out, poses)?;
    s.cut = log.cut();
    s.other = log.other_records().saturating_sub(s.carried + s.metadata);
    s.seq_gaps = log.seq_gaps();
    Ok(s)
}

/// The POSE lines refused since the last call, each handed to `on_skip`;
/// how many.
fn refused_poses(poses: &mut Poses, on_skip: &mut impl FnMut(&LogError)) -> u64 {
    let Poses::Feed(feed) = poses else { return 0 };
    let n = feed.refused.len() as u64;
    for e in feed.refused.drain(..) {
        on_skip(&e);
    }
    n
}

/// When POSE lines are moved, relative to a frame.
#[derive(Clone, Copy)]
enum Due {
    BeforeFrame,
    AfterFrame(u64),
    End,
}

/// Move the POSE lines that are due: from the feed, those up to the frame
/// just written; from the MCAP reader, those it kept while reading up to
/// the next frame (they belong before it).
fn pass_poses(
    log: &mut LogFile,
    poses: &mut Poses,
    out: &mut Out,
    due: Due,
) -> Result<u64, ConvertError> {
    match (poses, due) {
        (Poses::Feed(feed), Due::AfterFrame(seq)) => match out {
            Out::Mcap(w) => feed.write_through(Some(seq), w),
            Out::Jsonl(..) => Ok(0),
        },
        (Poses::Feed(feed), Due::End) => match out {
            Out::Mcap(w) => feed.write_through(None, w),
            Out::Jsonl(..) => Ok(0),
        },
        (Poses::ToFile(file, w), Due::BeforeFrame | Due::End) => match log {
            LogFile::Mcap(r) => {
                r.take_poses(w)
                    .map(|n| n as u64)
                    .map_err(|err| ConvertError::File {
                        file: file.clone(),
                        err,
                    })
            }
            LogFile::Jsonl(_) => Ok(0),
        },
        (Poses::Carry(c), Due::BeforeFrame | Due::End) => match (log, out) {
            (LogFile::Mcap(r), Out::Mcap(w)) => {
                c.buf.clear();
                r.take_poses(&mut c.buf).map_err(WriteError::Io)?;
                let mut n = 0;
                for line in c.buf.split(|&b| b == b'\n').filter(|l| !l.is_empty()) {
                    w.write_pose_line(line)?;
                    n += 1;
                }
                carry(r, w, c)?;
                Ok(n)
            }
            _ => Ok(0),
        },
        _ => Ok(0),
    }
}

/// Write what the reader kept for carrying: each message on its channel,
/// declared in the output as the input declared it (at its first message),
/// and each metadata record.
fn carry(
    r: &mut crate::McapReader<BufReader<File>>,
    w: &mut McapWriter<BufWriter<File>>,
    c: &mut Carry,
) -> Result<(), ConvertError> {
    for item in r.take_carried() {
        match item {
            Carried::Message {
                channel,
                sequence,
                log_time,
                publish_time,
                data,
            } => {
                let id = match c.ids.get(&channel) {
                    Some(&id) => id,
                    None => {
                        // Only messages of declared channels are kept.
                        let Some(d) = r.channel_decl(channel) else {
                            continue;
                        };
                        let schema = d
                            .schema
                            .as_ref()
                            .map(|(n, e, b)| (n.as_str(), e.as_str(), b.as_slice()));
                        let id =
                            w.add_channel(schema, &d.topic, &d.message_encoding, &d.metadata)?;
                        c.ids.insert(channel, id);
                        id
                    }
                };
                w.write_raw(id, sequence, log_time, publish_time, &data)?;
                c.messages += 1;
            }
            Carried::Metadata { name, pairs } => {
                w.write_metadata(&name, pairs)?;
                c.metadata += 1;
            }
        }
    }
    Ok(())
}

fn finish(out: Out, poses: Poses) -> Result<(), ConvertError> {
    let file_err = |file: String| move |err| ConvertError::File { file, err };
    match out {
        Out::Jsonl(file, mut w) => w.flush().map_err(file_err(file))?,
        Out::Mcap(w) => {
            w.finish()?;
        }
    }
    if let Poses::ToFile(file, mut w) = poses {
        w.flush().map_err(file_err(file))?;
    }
    Ok(())
}
