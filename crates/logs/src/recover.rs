//! `lightpose recover`'s work: an MCAP whose writing stopped anywhere
//! (kill -9 or a power loss: mid-chunk, mid-record, no summary, no footer,
//! a zero-filled tail) rewritten as a finished MCAP with its summary and
//! indexes, which every reader opens. The reference Python library's
//! default reader looks for the footer at the end of the file and fails on
//! a cut one (RecordLengthLimitExceeded, reading a record head out of the
//! middle of a chunk); its streaming reader stops at the cut with an error.
//!
//! Any MCAP with uncompressed chunks, not only lightpose's: it works on
//! records, not on frames. Kept, in the order of the file: the Header's
//! profile and library, every schema and channel (ids kept), every
//! message of every complete chunk whose CRC holds (or is 0, not
//! computed), every metadata record and attachment, private records; and,
//! of the chunk the cut fell in, every record that is whole and well
//! formed up to the first that is not (its CRC covers bytes never written,
//! so it cannot be checked: these messages are counted `unverified`). On a
//! finished input the summary's declarations stand in for those lost in a
//! damaged chunk. Lost, counted and named: a complete chunk that fails its
//! CRC (all of it: a flipped bit may be anywhere in it), an attachment that
//! fails its CRC, a message on a channel never declared, the incomplete
//! record at the cut and everything after it, garbage (a record that
//! cannot be one) and everything after it. Indexes, statistics and the
//! summary are not carried: the writer makes them anew. A compressed chunk
//! is refused (lightpose reads and writes uncompressed chunks only; the
//! C compressors do not cross-build): nothing is written.
//!
//! Streaming, one record (at most [`RECORD_LIMIT`](crate::lines::RECORD_LIMIT)) in memory; parsed here,
//! bounds-checked, as `lines.rs` does, never by the `mcap` crate's parser,
//! which reserves what a corrupt length field says.

mod chunk;
mod input;
use input::{count_messages, kind, Input, Next};

use crate::lines::{read_full, summary_of, Fields, HEAD};
use lightpose_core::Cut;
use mcap::records::{op, MessageHeader, Metadata};
use mcap::Attachment;
use std::borrow::Cow;
use std::collections::HashMap;
use std::fmt;
use std::fs::File;
use std::io::{self, BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum RecoverError {
    #[error("{0}")]
    Usage(String),
    /// The input cannot be recovered at all (not MCAP, compressed chunks).
    #[error("{file}: byte {offset}: {msg}")]
    Input {
        file: String,
        offset: u64,
        msg: String,
    },
    #[error("{file}: {err}")]
    File { file: String, err: io::Error },
    #[error("{file}: {err}")]
    Write { file: String, err: mcap::McapError },
}

/// What a recovery kept and lost. Input bytes are either kept (records
/// carried), lost (records dropped, the cut tail) or remade (indexes,
/// statistics, summary, footer).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecoverSummary {
    /// Messages carried.
    pub messages: u64,
    /// Of `messages`, those of the chunk the cut fell in: each record whole
    /// and well formed, the chunk's CRC not checkable.
    pub unverified: u64,
    /// Complete chunks carried (CRC checked where recorded).
    pub chunks: u64,
    pub schemas: u64,
    pub channels: u64,
    pub metadata: u64,
    pub attachments: u64,
    /// Input bytes of the records carried.
    pub kept_bytes: u64,
    /// Messages seen and not carried (in a chunk that failed its CRC, on a
    /// channel never declared, the one the cut fell in).
    pub lost_messages: u64,
    /// Input bytes of the data section not carried.
    pub lost_bytes: u64,
    /// Where the input's data section ended without its Data End record;
    /// `None` for a finished file.
    pub cut: Option<Cut>,
    /// The first loss, named by its byte offset.
    pub first_loss: Option<String>,
    /// Bytes of the recovered file.
    pub out_bytes: u64,
}

impl fmt::Display for RecoverSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "kept {} messages", self.messages)?;
        if self.unverified > 0 {
            write!(
                f,
                " ({} of them from the chunk cut short: whole records, its CRC not checkable)",
                self.unverified
            )?;
        }
        write!(
            f,
            ", {} chunks, {} schemas, {} channels, {} metadata, {} attachments ({} bytes); lost {} messages, {} bytes",
            self.chunks,
            self.schemas,
            self.channels,
            self.metadata,
            self.attachments,
            self.kept_bytes,
            self.lost_messages,
            self.lost_bytes
        )?;
        match (&self.first_loss, self.cut) {
            (Some(why), _) => write!(f, " (first: {why})"),
            (None, Some(_)) => write!(f, " (the file was never finished)"),
            (None, None) => Ok(()),
        }
    }
}

/// Options of a recovery.
#[derive(Debug, Clone)]
pub struct RecoverOptions {
    /// Chunks of the output close at this many bytes.
    pub chunk_bytes: u64,
}

impl Default for RecoverOptions {
    fn default() -> Self {
        RecoverOptions {
            chunk_bytes: 1 << 20,
        }
    }
}

/// A schema or channel declared in a finished input's summary, for a
/// message whose own declaration was lost with a damaged chunk.
#[derive(Default)]
struct Declared {
    schemas: HashMap<u16, Vec<u8>>,
    channels: HashMap<u16, Vec<u8>>,
}

type Out = mcap::Writer<BufWriter<File>>;

struct Salvage {
    name: String,
    out_name: String,
    size: u64,
    /// Input id → output id (the same unless an input redeclared an id
    /// with other content).
    schemas: HashMap<u16, u16>,
    channels: HashMap<u16, u16>,
    declared: Declared,
    s: RecoverSummary,
}

/// How the records of a chunk are taken.
#[derive(Clone, Copy, PartialEq)]
enum Whole {
    /// A complete chunk, its CRC checked.
    Yes,
    /// The chunk the cut fell in.
    Cut,
}

/// Recover `input` into `output`: see the module docs. The input is only
/// read; the output is written from the start.
pub fn recover(
    input: &Path,
    output: &Path,
    opts: &RecoverOptions,
) -> Result<RecoverSummary, RecoverError> {
    let name = input.display().to_string();
    let out_name = output.display().to_string();
    if crate::same_file(input, output) {
        return Err(RecoverError::Usage(format!(
            "{name}: input and output are the same file"
        )));
    }
    let file_err = |file: &str| {
        let file = file.to_string();
        move |err| RecoverError::File { file, err }
    };
    let mut f = File::open(input).map_err(file_err(&name))?;
    let size = f.metadata().map_err(file_err(&name))?.len();
    let summary = summary_of(&mut f, size);
    f.seek(SeekFrom::Start(0)).map_err(file_err(&name))?;
    let mut src = BufReader::with_capacity(1 << 16, f);
    let mut magic = [0u8; 8];
    let n = read_full(&mut src, &mut magic).map_err(file_err(&name))?;
    if n < magic.len() || magic != *mcap::MAGIC {
        return Err(RecoverError::Input {
            file: name,
            offset: 0,
            msg: "not an MCAP file (no MCAP magic): nothing to recover".into(),
        });
    }
    let mut sv = Salvage {
        name,
        out_name,
        size,
        schemas: HashMap::new(),
        channels: HashMap::new(),
        declared: Declared::default(),
        s: RecoverSummary::default(),
    };
    if let Some(bytes) = summary {
        sv.declared = declarations(&bytes);
    }
    let sink = File::create(output).map_err(file_err(&sv.out_name))?;
    sv.run(&mut src, BufWriter::with_capacity(1 << 16, sink), opts)
}

/// The Schema and Channel records of a summary section, by id, unparsed.
fn declarations(summary: &[u8]) -> Declared {
    let mut d = Declared::default();
    let mut f = Fields::new(summary);
    while let (Ok(o), Ok(len)) = (f.take(1), f.u64()) {
        let Some(body) = usize::try_from(len).ok().and_then(|n| f.take(n).ok()) else {
            break;
        };
        let id = Fields::new(body).u16();
        match (o[0], id) {
            (op::SCHEMA, Ok(id)) => d.schemas.entry(id).or_insert_with(|| body.to_vec()),
            (op::CHANNEL, Ok(id)) => d.channels.entry(id).or_insert_with(|| body.to_vec()),
            _ => continue,
        };
    }
    d
}

impl Salvage {
    fn write_err(&self) -> impl Fn(mcap::McapError) -> RecoverError + '_ {
        move |err| RecoverError::Write {
            file: self.out_name.clone(),
            err,
        }
    }

    /// A loss at `offset`: the first one is named in the report.
    fn lose(&mut self, offset: u64, bytes: u64, messages: u64, why: impl fmt::Display) {
        self.s.lost_bytes += bytes;
        self.s.lost_messages += messages;
        if self.s.first_loss.is_none() {
            self.s.first_loss = Some(format!("byte {offset}: {why}"));
        }
    }

    fn run(
        mut self,
        src: &mut impl Read,
        sink: BufWriter<File>,
        opts: &RecoverOptions,
    ) -> Result<RecoverSummary, RecoverError> {
        let mut rd = Input {
            src,
            name: self.name.clone(),
            pos: 8,
            size: self.size,
            body: Vec::new(),
        };
        let (mut w, mut next) = self.open_output(&mut rd, sink, opts)?;
        loop {
            match next {
                Next::End { offset, lost, why } => {
                    self.s.cut = Some(Cut::Bytes {
                        offset,
                        dropped: lost,
                    });
                    if let Some(why) = why {
                        self.lose(offset, lost, 0, why);
                    }
                    break;
                }
                Next::Cut {
                    opcode,
                    offset,
                    len,
                    avail,
                } => {
                    self.cut_record(&mut w, opcode, offset, len, avail, &rd.body)?;
                    break;
                }
                Next::TooLarge {
                    opcode,
                    offset,
                    len,
                } => {
                    let m = u64::from(opcode == op::MESSAGE);
                    let msg = format!(
                        "{} of {len} bytes: more than recover takes (64 MiB), skipped",
                        kind(opcode)
                    );
                    self.lose(offset, HEAD as u64 + len, m, msg);
                }
                Next::Record { opcode, offset } => {
                    if !self.take(&mut w, opcode, offset, &rd.body)? {
                        break;
                    }
                }
            }
            next = rd.next()?;
        }
        // Channels that only the summary declares (their records lost).
        let mut left: Vec<u16> = self.declared.channels.keys().copied().collect();
        left.sort_unstable();
        for id in left {
            if !self.channels.contains_key(&id) {
                self.declare_from_summary(&mut w, id)?;
            }
        }
        self.finish(w)
    }

    /// The output, with the input's Header's profile and library, and the
    /// first record after that Header (or the first, without one).
    fn open_output(
        &self,
        rd: &mut Input<'_, impl Read>,
        sink: BufWriter<File>,
        opts: &RecoverOptions,
    ) -> Result<(Out, Next), RecoverError> {
        let first = rd.next()?;
        let header = match first {
            Next::Record {
                opcode: op::HEADER, ..
            } => {
                let mut f = Fields::new(&rd.body);
                match (f.str(), f.str()) {
                    (Ok(p), Ok(l)) => Some((p.to_string(), l.to_string())),
                    _ => Some((String::new(), String::new())),
                }
            }
            _ => None,
        };
        let (profile, library) = header.clone().unwrap_or_default();
        let w = mcap::WriteOptions::new()
            .compression(None)
            .chunk_size(Some(opts.chunk_bytes.max(1)))
            .profile(profile)
            .library(library)
            .create(sink)
            .map_err(self.write_err())?;
        let next = match header {
            Some(_) => rd.next()?,
            None => first,
        };
        Ok((w, next))
    }

    /// What a cut leaves: a record whose end was never written. Of a
    /// chunk, the records that are whole are taken.
    fn cut_record(
        &mut self,
        w: &mut Out,
        opcode: u8,
        offset: u64,
        len: u64,
        avail: u64,
        body: &[u8],
    ) -> Result<(), RecoverError> {
        let rest = HEAD as u64 + avail;
        self.s.cut = Some(Cut::Bytes {
            offset,
            dropped: rest,
        });
        let kept = if opcode == op::CHUNK {
            self.chunk(w, offset, body, Whole::Cut)?
        } else {
            0
        };
        let lost = rest - kept;
        let msg = if kept > 0 {
            format!(
                "cut inside a chunk of {len} bytes, {avail} of them written: its whole records kept, its last {lost} bytes lost"
            )
        } else {
            format!(
                "cut inside {} of {len} bytes, {avail} of them written",
                kind(opcode)
            )
        };
        self.lose(offset, lost, u64::from(opcode == op::MESSAGE), msg);
        Ok(())
    }

    /// A whole top-level record; false where the data section ends.
    fn take(
        &mut self,
        w: &mut Out,
        opcode: u8,
        offset: u64,
        body: &[u8],
    ) -> Result<bool, RecoverError> {
        let total = HEAD as u64 + body.len() as u64;
        match opcode {
            op::DATA_END | op::FOOTER => return Ok(false),
            op::CHUNK => {
                self.chunk(w, offset, body, Whole::Yes)?;
            }
            op::SCHEMA | op::CHANNEL | op::MESSAGE => {
                let carried = self.record(w, opcode, body, offset, false)?;
                self.s.kept_bytes += if carried { total } else { 0 };
            }
            op::METADATA => {
                let mut f = Fields::new(body);
                match (f.str().map(str::to_string), f.map()) {
                    (Ok(name), Ok(metadata)) => {
                        w.write_metadata(&Metadata { name, metadata })
                            .map_err(self.write_err())?;
                        self.s.metadata += 1;
                        self.s.kept_bytes += total;
                    }
                    (Err(e), _) | (_, Err(e)) => {
                        self.lose(offset, total, 0, format!("metadata: {e}"))
                    }
                }
            }
            op::ATTACHMENT => self.attachment(w, offset, body)?,
            o if o >= 0x80 => {
                w.write_private_record(o, body, Default::default())
                    .map_err(self.write_err())?;
                self.s.kept_bytes += total;
            }
            // Indexes, statistics, summary offsets: made anew. A second
            // Header, other opcodes of the spec's reserved range: nothing
            // a reader needs (the spec has readers skip them).
            _ => {}
        }
        Ok(true)
    }

    fn finish(mut self, mut w: Out) -> Result<RecoverSummary, RecoverError> {
        w.finish().map_err(self.write_err())?;
        let mut sink = w.into_inner();
        let file_err = |err| RecoverError::File {
            file: self.out_name.clone(),
            err,
        };
        sink.flush().map_err(file_err)?;
        let file = sink.get_ref();
        file.sync_all().map_err(file_err)?;
        self.s.out_bytes = file.metadata().map_err(file_err)?.len();
        Ok(self.s)
    }

    /// A Schema, Channel or Message record; whether it was carried. A
    /// record that does not parse (or a message on a channel never
    /// declared) is lost; `quiet` leaves the naming to the caller (the cut
    /// chunk, where such a record is the cut).
    fn record(
        &mut self,
        w: &mut Out,
        opcode: u8,
        rec: &[u8],
        offset: u64,
        quiet: bool,
    ) -> Result<bool, RecoverError> {
        let r = match opcode {
            op::SCHEMA => self.schema(w, rec),
            op::CHANNEL => self.channel(w, rec),
            _ => self.message(w, rec, quiet),
        };
        match r {
            Ok(Ok(())) => Ok(true),
            Ok(Err(why)) => {
                if !quiet {
                    let m = u64::from(opcode == op::MESSAGE);
                    self.lose(offset, HEAD as u64 + rec.len() as u64, m, why);
                } else if opcode == op::MESSAGE {
                    self.s.lost_messages += 1;
                }
                Ok(false)
            }
            Err(e) => Err(e),
        }
    }

    fn schema(&mut self, w: &mut Out, rec: &[u8]) -> Result<Result<(), String>, RecoverError> {
        let mut f = Fields::new(rec);
        let parsed = (|| {
            let id = f.u16()?;
            let (name, encoding) = (f.str()?, f.str()?);
            let n = f.u32()? as usize;
            Ok::<_, String>((id, name, encoding, f.take(n)?))
        })();
        let (id, name, encoding, data) = match parsed {
            Ok(p) => p,
            Err(e) => return Ok(Err(format!("schema: {e}"))),
        };
        if id == 0 {
            return Ok(Err("schema id 0 is reserved (no schema)".into()));
        }
        let new = match w.add_schema_with_id(id, name, encoding, data) {
            Ok(id) => id,
            // The id was declared before with other content: a new id.
            Err(mcap::McapError::ConflictingSchemas(_)) => w
                .add_schema(name, encoding, data)
                .map_err(self.write_err())?,
            Err(e) => return Err(self.write_err()(e)),
        };
        if self.schemas.insert(id, new) != Some(new) {
            self.s.schemas += 1;
        }
        Ok(Ok(()))
    }

    fn channel(&mut self, w: &mut Out, rec: &[u8]) -> Result<Result<(), String>, RecoverError> {
        let mut f = Fields::new(rec);
        let parsed = (|| {
            let (id, schema_id) = (f.u16()?, f.u16()?);
            let (topic, encoding) = (f.str()?, f.str()?);
            Ok::<_, String>((id, schema_id, topic, encoding, f.map()?))
        })();
        let (id, schema_id, topic, encoding, meta) = match parsed {
            Ok(p) => p,
            Err(e) => return Ok(Err(format!("channel: {e}"))),
        };
        let schema = match schema_id {
            0 => 0,
            s => match self.schemas.get(&s) {
                Some(&s) => s,
                None => match self.declared.schemas.get(&s).cloned() {
                    Some(rec) => match self.schema(w, &rec)? {
                        Ok(()) => self.schemas.get(&s).copied().unwrap_or(0),
                        Err(e) => return Ok(Err(e)),
                    },
                    None => {
                        return Ok(Err(format!(
                            "channel {id} ({topic}) of schema {s}, which no Schema record declared"
                        )))
                    }
                },
            },
        };
        let new = match w.add_channel_with_id(id, schema, topic, encoding, &meta) {
            Ok(id) => id,
            Err(mcap::McapError::ConflictingChannels(_)) => w
                .add_channel(schema, topic, encoding, &meta)
                .map_err(self.write_err())?,
            Err(e) => return Err(self.write_err()(e)),
        };
        if self.channels.insert(id, new) != Some(new) {
            self.s.channels += 1;
        }
        Ok(Ok(()))
    }

    /// Declare channel `id` from the summary; whether it could be.
    fn declare_from_summary(&mut self, w: &mut Out, id: u16) -> Result<bool, RecoverError> {
        let Some(rec) = self.declared.channels.get(&id).cloned() else {
            return Ok(false);
        };
        Ok(self.channel(w, &rec)?.is_ok())
    }

    fn message(
        &mut self,
        w: &mut Out,
        rec: &[u8],
        quiet: bool,
    ) -> Result<Result<(), String>, RecoverError> {
        let mut f = Fields::new(rec);
        let parsed = (|| {
            let id = f.u16()?;
            let sequence = f.u32()?;
            let (log_time, publish_time) = (f.u64()?, f.u64()?);
            Ok::<_, String>((id, sequence, log_time, publish_time))
        })();
        let (id, sequence, log_time, publish_time) = match parsed {
            Ok(p) => p,
            Err(e) => return Ok(Err(format!("message: {e}"))),
        };
        let known = self.channels.get(&id).copied();
        let channel_id = match known {
            Some(c) => c,
            None if self.declare_from_summary(w, id)? => {
                self.channels.get(&id).copied().unwrap_or(id)
            }
            None => {
                return Ok(Err(format!(
                    "a message on channel {id}, which no Channel record declared"
                )))
            }
        };
        let h = MessageHeader {
            channel_id,
            sequence,
            log_time,
            publish_time,
        };
        w.write_to_known_channel(&h, f.rest())
            .map_err(self.write_err())?;
        self.s.messages += 1;
        if quiet {
            self.s.unverified += 1;
        }
        Ok(Ok(()))
    }

    fn attachment(&mut self, w: &mut Out, offset: u64, rec: &[u8]) -> Result<(), RecoverError> {
        let total = HEAD as u64 + rec.len() as u64;
        let mut f = Fields::new(rec);
        let parsed = (|| {
            let (log_time, create_time) = (f.u64()?, f.u64()?);
            let (name, media_type) = (f.str()?, f.str()?);
            let n = usize::try_from(f.u64()?).map_err(|_| "attachment size".to_string())?;
            let data = f.take(n)?;
            let covered = f.pos;
            let crc = f.u32()?;
            Ok::<_, String>((log_time, create_time, name, media_type, data, covered, crc))
        })();
        let (log_time, create_time, name, media_type, data, covered, crc) = match parsed {
            Ok(p) => p,
            Err(e) => {
                self.lose(offset, total, 0, format!("attachment: {e}"));
                return Ok(());
            }
        };
        if crc != 0 {
            let computed = crc32fast::hash(&rec[..covered]);
            if computed != crc {
                let msg = format!(
                    "attachment {name}: CRC {computed:08x} is not the recorded {crc:08x}: dropped"
                );
                self.lose(offset, total, 0, msg);
                return Ok(());
            }
        }
        let a = Attachment {
            log_time,
            create_time,
            name: name.to_string(),
            media_type: media_type.to_string(),
            data: Cow::Borrowed(data),
        };
        w.attach(&a).map_err(self.write_err())?;
        self.s.attachments += 1;
        self.s.kept_bytes += total;
        Ok(())
    }
}
