//! An MCAP file read record by record and served as the lines of a JSONL
//! log: first the HEADER line held in the `lightpose-header` metadata, then
//! each message of `/lightpose/frame`. Core's `LogReader` reads these lines,
//! so a FRAME means the same in both containers, by one parser. For a
//! conversion it also keeps, when asked, the POSE messages, and the
//! messages of every other channel it does not make anew (with their
//! declarations) and the metadata records, to be carried as they are.
//!
//! Streaming: one top-level record (at most one chunk) is in memory at a
//! time. A chunk is taken whole or not at all: it is read to its end and
//! its CRC checked before any of its records is used, so a file cut by a
//! power loss gives every complete chunk and nothing of the one it was
//! writing. The record layer is parsed here, bounds-checked against the
//! bytes present: the `mcap` crate's record parser reserves as much memory
//! as a string's length field says (up to 4 GiB) before it looks at the
//! bytes, which a corrupt file must not be able to make us do.

use crate::schema::{self, name, topic};
use lightpose_core::{Cut, LogError};
use mcap::records::op;
use std::collections::{BTreeMap, VecDeque};
use std::io::{self, BufRead, Read, Seek, SeekFrom};

mod records;

/// The summary section of a finished MCAP file of `size` bytes (from its
/// summary start to its summary offsets or footer), if its footer says it
/// has one; `None` for a file cut short (no footer), without a summary, or
/// with a footer that points outside the file.
pub fn summary_of<R: Read + Seek>(src: &mut R, size: u64) -> Option<Vec<u8>> {
    const FOOTER: usize = HEAD + 20 + 8;
    let footer_at = size.checked_sub(FOOTER as u64).filter(|&at| at >= 8)?;
    src.seek(SeekFrom::Start(footer_at)).ok()?;
    let mut b = [0u8; FOOTER];
    read_full(src, &mut b).ok().filter(|&n| n == FOOTER)?;
    let mut f = Fields::new(&b[1..]);
    let (len, start, offsets) = (f.u64().ok()?, f.u64().ok()?, f.u64().ok()?);
    if b[0] != op::FOOTER || len != 20 || b[HEAD + 20..] != mcap::MAGIC[..] {
        return None;
    }
    let end = if offsets != 0 { offsets } else { footer_at };
    if start < 8 || start >= end || end > footer_at || end - start > RECORD_LIMIT {
        return None;
    }
    src.seek(SeekFrom::Start(start)).ok()?;
    let mut s = vec![0u8; usize::try_from(end - start).ok()?];
    read_full(src, &mut s).ok().filter(|&n| n == s.len())?;
    Some(s)
}

/// Largest record (chunk) read: far above what any lightpose writer makes
/// (64 KiB chunks by default) and what usual MCAP writers make (a few MiB).
pub const RECORD_LIMIT: u64 = 64 << 20;

/// Bytes of a record's head: opcode and length.
pub(crate) const HEAD: usize = 9;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Frame,
    /// Spec v3: a BURST in binary (`crate::burst`), served as its line.
    Burst,
    /// Spec v3: a demodulated frame's line.
    Demodulated,
    Pose,
    /// A Foxglove channel, which a writer makes anew from frames and poses.
    Derived,
    Other,
    /// The header metadata (not a message; found once).
    Header,
}

/// A message found: what it is, where its data sits in `body`, the file
/// offset of its record, and its header (channel, sequence, log and
/// publish times).
struct Msg {
    kind: Kind,
    start: usize,
    end: usize,
    offset: u64,
    header: mcap::records::MessageHeader,
}

/// A channel that is neither frames, poses nor one that a writer makes
/// from them (the Foxglove channels), as its file declared it: what a
/// conversion carries to its output as it is (`/lightpose/status`, any
/// other program's channel).
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelDecl {
    pub topic: String,
    pub message_encoding: String,
    pub metadata: BTreeMap<String, String>,
    /// Its schema's name, encoding and data; `None`: no schema (id 0, or
    /// one the file never declared).
    pub schema: Option<(String, String, Vec<u8>)>,
}

/// What a conversion carries, in the order of the file: messages of the
/// channels of [`ChannelDecl`], and metadata records other than the
/// HEADER's.
#[derive(Debug, Clone, PartialEq)]
pub enum Carried {
    Message {
        /// The input's channel id (see `McapReader::channel_decl`).
        channel: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: Vec<u8>,
    },
    Metadata {
        name: String,
        pairs: BTreeMap<String, String>,
    },
}

/// A bounds-checked little-endian cursor over a record's body.
pub(crate) struct Fields<'a> {
    pub(crate) b: &'a [u8],
    pub(crate) pos: usize,
}

impl<'a> Fields<'a> {
    pub(crate) fn new(b: &'a [u8]) -> Self {
        Fields { b, pos: 0 }
    }
    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.b.len());
        let end = end.ok_or_else(|| {
            format!(
                "record ends inside a field ({n} bytes wanted at {} of {})",
                self.pos,
                self.b.len()
            )
        })?;
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    pub(crate) fn u16(&mut self) -> Result<u16, String> {
        let s = self.take(2)?;
        Ok(u16::from_le_bytes([s[0], s[1]]))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        let mut a = [0; 4];
        a.copy_from_slice(self.take(4)?);
        Ok(u32::from_le_bytes(a))
    }
    pub(crate) fn u64(&mut self) -> Result<u64, String> {
        let mut a = [0; 8];
        a.copy_from_slice(self.take(8)?);
        Ok(u64::from_le_bytes(a))
    }
    pub(crate) fn str(&mut self) -> Result<&'a str, String> {
        let n = self.u32()? as usize;
        std::str::from_utf8(self.take(n)?).map_err(|_| "a string is not UTF-8".to_string())
    }
    /// A string → string map: its byte length (u32), then key, value pairs.
    pub(crate) fn map(&mut self) -> Result<std::collections::BTreeMap<String, String>, String> {
        let len = self.u32()? as usize;
        let mut m = Fields::new(self.take(len)?);
        let mut out = std::collections::BTreeMap::new();
        while m.pos < m.b.len() {
            let (k, v) = (m.str()?, m.str()?);
            out.insert(k.to_string(), v.to_string());
        }
        Ok(out)
    }
    /// What is left of the record.
    pub(crate) fn rest(&mut self) -> &'a [u8] {
        let s = &self.b[self.pos..];
        self.pos = self.b.len();
        s
    }
}

pub struct McapLines<R> {
    src: R,
    name: String,
    size: Option<u64>,
    /// File offset of the next byte of `src`.
    pos: u64,
    /// The current top-level record's body, and the file offset of its
    /// first byte.
    body: Vec<u8>,
    body_offset: u64,
    /// Records of the current chunk not yet read: a range of `body`.
    chunk: Option<(usize, usize)>,
    seen_header_record: bool,
    /// Id, name, encoding and data of each schema declared.
    schemas: Vec<(u16, String, String, Vec<u8>)>,
    channels: Vec<(u16, Kind)>,
    /// The declarations of the channels of kind `Other`, by id.
    pub(crate) decls: Vec<(u16, ChannelDecl)>,
    header: Option<(u64, String)>,
    /// The line being served, and how much of it was consumed.
    line: Vec<u8>,
    /// A burst's samples while its line is rebuilt.
    samples: Vec<u16>,
    line_pos: usize,
    /// Offset of the record of the message last served.
    pub(crate) msg_offset: u64,
    done: bool,
    pub(crate) cut: Option<Cut>,
    /// A fatal error, held for the reader (LogReader sees an I/O error).
    pub(crate) error: Option<LogError>,
    /// Skippable errors (a chunk that failed its CRC) met while looking for
    /// the next frame, to be handed out before it.
    pub(crate) pending: VecDeque<LogError>,
    /// Messages on other channels, and unknown records, passed over.
    pub(crate) other: u64,
    /// POSE messages kept for a conversion (one per line), when asked.
    pub(crate) keep_poses: bool,
    pub(crate) poses: Vec<u8>,
    /// Messages of `Other` channels and metadata kept for a conversion,
    /// when asked.
    pub(crate) keep_carried: bool,
    pub(crate) carried: Vec<Carried>,
}

impl<R: Read> McapLines<R> {
    /// Check the magic; `size` (when known) tells a cut file from garbage.
    pub fn new(mut src: R, name: String, size: Option<u64>) -> Result<Self, LogError> {
        let mut magic = [0u8; 8];
        let n = read_full(&mut src, &mut magic).map_err(|err| LogError::Io {
            name: name.clone(),
            err,
        })?;
        if magic[..n] != mcap::MAGIC[..n] || n < magic.len() {
            return Err(LogError::at(
                name,
                0,
                "not an MCAP file (no MCAP magic)",
                true,
            ));
        }
        Ok(McapLines {
            src,
            name,
            size,
            pos: magic.len() as u64,
            body: Vec::new(),
            body_offset: 0,
            chunk: None,
            seen_header_record: false,
            schemas: Vec::new(),
            channels: Vec::new(),
            decls: Vec::new(),
            header: None,
            line: Vec::new(),
            samples: Vec::new(),
            line_pos: 0,
            msg_offset: 0,
            done: false,
            cut: None,
            error: None,
            pending: VecDeque::new(),
            other: 0,
            keep_poses: false,
            poses: Vec::new(),
            keep_carried: false,
            carried: Vec::new(),
        })
    }

    /// Take the Schema and Channel records of `summary` (a finished
    /// file's summary section) as declared. One that does not parse, or
    /// names a lightpose topic with another schema, is left for the data
    /// section's own record to say so.
    pub fn declare_from_summary(&mut self, summary: Vec<u8>) {
        let data = std::mem::replace(&mut self.body, summary);
        let mut pos = 0;
        while pos + HEAD <= self.body.len() {
            let mut f = Fields::new(&self.body[pos..]);
            let (Ok(o), Ok(len)) = (f.take(1), f.u64()) else {
                break;
            };
            let opcode = o[0];
            let Some(end) = usize::try_from(len)
                .ok()
                .and_then(|l| (pos + HEAD).checked_add(l))
                .filter(|&e| e <= self.body.len())
            else {
                break;
            };
            let _ = match opcode {
                op::SCHEMA => self.schema(pos + HEAD, end, 0),
                op::CHANNEL => self.channel(pos + HEAD, end, 0),
                _ => Ok(()),
            };
            pos = end;
        }
        self.body = data;
    }

    /// The line served last.
    pub fn line(&self) -> &[u8] {
        &self.line
    }

    fn err(&self, offset: u64, msg: impl Into<String>) -> LogError {
        LogError::at(self.name.clone(), offset, msg, true)
    }

    fn io_err(&self, err: io::Error) -> LogError {
        LogError::Io {
            name: self.name.clone(),
            err,
        }
    }

    /// Read records up to the `lightpose-header` metadata and queue its
    /// line; returns its offset.
    pub fn find_header(&mut self) -> Result<u64, LogError> {
        loop {
            match self.next_message()? {
                Some(m) if m.kind == Kind::Header => break,
                Some(m) if matches!(m.kind, Kind::Frame | Kind::Burst | Kind::Demodulated) => {
                    let t = match m.kind {
                        Kind::Burst => topic::BURST,
                        Kind::Demodulated => topic::DEMODULATED,
                        _ => topic::FRAME,
                    };
                    return Err(self.err(
                        m.offset,
                        format!(
                            "a {t} message before the {} metadata: not a lightpose recording",
                            schema::HEADER_METADATA
                        ),
                    ));
                }
                Some(_) => self.other += 1,
                None => {
                    let why = match self.cut {
                        Some(c) => format!(
                            "cut short before its {} metadata ({c})",
                            schema::HEADER_METADATA
                        ),
                        None => format!(
                            "no {} metadata: not a lightpose recording",
                            schema::HEADER_METADATA
                        ),
                    };
                    return Err(self.err(self.pos, why));
                }
            }
        }
        let (offset, text) = self
            .header
            .as_ref()
            .map_or((0, ""), |(o, t)| (*o, t.as_str()));
        self.line.clear();
        self.line.extend(text.bytes().map(no_newline));
        self.line.push(b'\n');
        self.line_pos = 0;
        Ok(offset)
    }

    /// The next message of any channel, or `None` at the end of the data
    /// (then `cut` says whether the file was finished).
    fn next_message(&mut self) -> Result<Option<Msg>, LogError> {
        loop {
            if let Some(m) = self.next_in_chunk()? {
                return Ok(Some(m));
            }
            let Some((opcode, offset)) = self.read_record()? else {
                return Ok(None);
            };
            let (start, end) = (0, self.body.len());
            if !self.seen_header_record {
                if opcode != op::HEADER {
                    return Err(self.err(
                        offset,
                        format!("first record has opcode {opcode:#04x}, not an MCAP Header"),
                    ));
                }
                self.seen_header_record = true;
                continue;
            }
            match opcode {
                op::CHUNK => self.open_chunk(offset)?,
                op::SCHEMA => self.schema(start, end, offset)?,
                op::CHANNEL => self.channel(start, end, offset)?,
                op::MESSAGE => return self.message(start, end, offset).map(Some),
                op::METADATA => {
                    if self.metadata(offset)? {
                        let (start, end) = (0, 0);
                        let kind = Kind::Header;
                        return Ok(Some(Msg {
                            kind,
                            start,
                            end,
                            offset,
                            header: no_header(),
                        }));
                    }
                }
                op::DATA_END | op::FOOTER => return Ok(None),
                // Indexes, attachments, statistics, private records: the
                // data section holds all a reader needs.
                _ => self.other += 1,
            }
        }
    }

    /// The next top-level record into `body`: its opcode and offset, or
    /// `None` where the data ends without its DataEnd record (a cut).
    fn read_record(&mut self) -> Result<Option<(u8, u64)>, LogError> {
        let offset = self.pos;
        let mut head = [0u8; HEAD];
        let n = read_full(&mut self.src, &mut head).map_err(|e| self.io_err(e))?;
        self.pos += n as u64;
        if n < HEAD {
            self.cut = Some(Cut::Bytes {
                offset,
                dropped: n as u64,
            });
            return Ok(None);
        }
        let opcode = head[0];
        let mut lb = [0u8; 8];
        lb.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(lb);
        if head.iter().all(|&b| b == 0) {
            return self.zero_tail(offset).map(|()| None);
        }
        let known = (op::HEADER..=op::DATA_END).contains(&opcode);
        let total = len.checked_add(HEAD as u64);
        let past_end = match (self.size, total) {
            (Some(size), Some(t)) => offset.checked_add(t).is_none_or(|e| e > size),
            (_, None) => true,
            (None, Some(_)) => false,
        };
        if past_end && known {
            // What a power loss leaves: a record whose end was never written.
            let dropped = self.size.map_or(HEAD as u64, |s| s.saturating_sub(offset));
            self.cut = Some(Cut::Bytes { offset, dropped });
            return Ok(None);
        }
        let garbage = if opcode == 0 {
            Some("opcode 0x00 is no MCAP record: not MCAP data")
        } else if past_end {
            Some("runs past the end of the file: not MCAP data")
        } else if len > RECORD_LIMIT {
            Some("more than this reader takes (64 MiB)")
        } else {
            None
        };
        if let Some(why) = garbage {
            let msg = format!("a record (opcode {opcode:#04x}) of {len} bytes: {why}");
            return Err(self.err(offset, msg));
        }
        self.body.clear();
        let got = (&mut self.src)
            .take(len)
            .read_to_end(&mut self.body)
            .map_err(|e| self.io_err(e))?;
        self.pos += got as u64;
        if (got as u64) < len {
            self.cut = Some(Cut::Bytes {
                offset,
                dropped: (HEAD + got) as u64,
            });
            return Ok(None);
        }
        self.body_offset = offset + HEAD as u64;
        Ok(Some((opcode, offset)))
    }

    /// A record head of zeros (opcode 0 is no record). A file system that
    /// lost power may leave the end of a file zero-filled: such a tail is a
    /// cut; zeros followed by anything else are garbage.
    fn zero_tail(&mut self, offset: u64) -> Result<(), LogError> {
        let mut block = [0u8; 4096];
        let mut dropped = HEAD as u64;
        loop {
            let n = read_full(&mut self.src, &mut block).map_err(|e| self.io_err(e))?;
            if block[..n].iter().any(|&b| b != 0) {
                return Err(self.err(offset, "opcode 0x00 is no MCAP record: not MCAP data"));
            }
            dropped += n as u64;
            if n < block.len() {
                break;
            }
        }
        self.cut = Some(Cut::Bytes { offset, dropped });
        Ok(())
    }

    /// Take the chunk in `body`: uncompressed and intact, or refused.
    fn open_chunk(&mut self, offset: u64) -> Result<(), LogError> {
        let mut f = Fields::new(&self.body);
        let parsed = (|| {
            let _start_time = f.u64()?;
            let _end_time = f.u64()?;
            let _uncompressed_size = f.u64()?;
            let crc = f.u32()?;
            let compression = f.str()?;
            let size = f.u64()?;
            let start = f.pos;
            let records = usize::try_from(size).map_err(|_| "chunk size".to_string());
            let end = records.and_then(|n| f.take(n).map(|_| start + n))?;
            Ok::<_, String>((crc, compression, start, end))
        })();
        let (crc, compression, start, end) =
            parsed.map_err(|m| self.err(offset, format!("chunk: {m}")))?;
        if !compression.is_empty() {
            return Err(self.err(
                offset,
                format!("chunk compressed with {compression}: lightpose reads uncompressed chunks (`mcap decompress` rewrites the file so)"),
            ));
        }
        if crc != 0 {
            let computed = crc32fast::hash(&self.body[start..end]);
            if computed != crc {
                self.pending.push_back(LogError::at(self.name.clone(), offset, format!("chunk CRC {computed:08x} is not the recorded {crc:08x}: its {} bytes of records skipped", end - start), false));
                return Ok(());
            }
        }
        self.chunk = Some((start, end));
        Ok(())
    }

    fn next_in_chunk(&mut self) -> Result<Option<Msg>, LogError> {
        while let Some((pos, end)) = self.chunk {
            if pos >= end {
                self.chunk = None;
                break;
            }
            let offset = self.body_offset + pos as u64;
            let mut f = Fields::new(&self.body[pos..end]);
            let (opcode, len) = match (f.take(1), f.u64()) {
                (Ok(o), Ok(l)) => (o[0], l),
                _ => return Err(self.err(offset, "chunk ends inside a record header")),
            };
            let avail = (end - pos - HEAD) as u64;
            if len > avail {
                return Err(self.err(
                    offset,
                    format!("a record of {len} bytes in a chunk with {avail} left"),
                ));
            }
            let (s, e) = (pos + HEAD, pos + HEAD + len as usize);
            self.chunk = Some((e, end));
            match opcode {
                op::SCHEMA => self.schema(s, e, offset)?,
                op::CHANNEL => self.channel(s, e, offset)?,
                op::MESSAGE => return self.message(s, e, offset).map(Some),
                _ => self.other += 1,
            }
        }
        Ok(None)
    }

    /// Fill `line` with the next frame message; false at the end.
    fn next_line(&mut self) -> Result<bool, LogError> {
        while !self.done {
            match self.next_message()? {
                Some(m) if m.kind == Kind::Burst => {
                    let msg = &self.body[m.start..m.end];
                    match crate::burst::decode_line(msg, &mut self.line, &mut self.samples) {
                        Ok(_) => {
                            for b in self.line.iter_mut() {
                                *b = no_newline(*b);
                            }
                            self.line.push(b'\n');
                            self.msg_offset = m.offset;
                            return Ok(true);
                        }
                        // That frame is lost, as a refused FRAME line is.
                        Err(why) => {
                            self.line.clear();
                            self.pending.push_back(LogError::at(
                                self.name.clone(),
                                m.offset,
                                why,
                                false,
                            ));
                        }
                    }
                }
                Some(m) if matches!(m.kind, Kind::Frame | Kind::Demodulated) => {
                    self.line.clear();
                    self.line
                        .extend(self.body[m.start..m.end].iter().map(|&b| no_newline(b)));
                    self.line.push(b'\n');
                    self.msg_offset = m.offset;
                    return Ok(true);
                }
                Some(m) if m.kind == Kind::Header => {}
                Some(m) => {
                    self.other += 1;
                    if m.kind == Kind::Pose && self.keep_poses {
                        self.poses
                            .extend(self.body[m.start..m.end].iter().map(|&b| no_newline(b)));
                        self.poses.push(b'\n');
                    }
                    if m.kind == Kind::Other && self.keep_carried {
                        let h = m.header;
                        self.carried.push(Carried::Message {
                            channel: h.channel_id,
                            sequence: h.sequence,
                            log_time: h.log_time,
                            publish_time: h.publish_time,
                            data: self.body[m.start..m.end].to_vec(),
                        });
                    }
                }
                None => self.done = true,
            }
        }
        Ok(false)
    }
}

/// The header of what is no message (the HEADER metadata).
fn no_header() -> mcap::records::MessageHeader {
    mcap::records::MessageHeader {
        channel_id: 0,
        sequence: 0,
        log_time: 0,
        publish_time: 0,
    }
}

/// JSON allows a raw line break only as whitespace: a space serves the same.
fn no_newline(b: u8) -> u8 {
    if b == b'\n' || b == b'\r' {
        b' '
    } else {
        b
    }
}

/// Read until `buf` is full or the source ends; the count read.
pub(crate) fn read_full<R: Read>(src: &mut R, buf: &mut [u8]) -> io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match src.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

impl<R: Read> Read for McapLines<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let avail = self.fill_buf()?;
        let n = avail.len().min(buf.len());
        buf[..n].copy_from_slice(&avail[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl<R: Read> BufRead for McapLines<R> {
    fn fill_buf(&mut self) -> io::Result<&[u8]> {
        if self.line_pos >= self.line.len() && self.error.is_none() {
            self.line.clear();
            self.line_pos = 0;
            if let Err(e) = self.next_line() {
                self.done = true;
                self.error = Some(e);
            }
        }
        if self.error.is_some() {
            // The reader takes the held error; LogReader only sees that
            // reading failed.
            return Err(io::Error::other("MCAP structure"));
        }
        Ok(&self.line[self.line_pos..])
    }

    fn consume(&mut self, n: usize) {
        self.line_pos = (self.line_pos + n).min(self.line.len());
    }
}
