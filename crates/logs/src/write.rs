//! The MCAP writer: frames, poses and status on the channels of
//! [`crate::schema`], made for a recorder thread. Each FRAME message is the
//! JSONL line that core's `LogWriter` writes for the frame (formatted by it,
//! so the two containers cannot drift apart); poses are POSE objects as the
//! daemon publishes them. Buffers are reused: once warm, a frame costs no
//! allocation here, and the `mcap` crate allocates only per chunk (message
//! indexes are off for that reason: see [`McapOptions`]). It still keeps
//! one chunk index (about 104 B) per chunk in memory until [`McapWriter::finish`]:
//! a writer that runs for days must start new files (the daemon rotates
//! MCAP by default for this).
//!
//! The file is written append-only (the `mcap` writer never seeks back):
//! every prefix of it is what a power loss at that moment leaves, and the
//! reader recovers every chunk that was complete.

use crate::encode::{trim_newline, Channel, Encoder, Message};
use crate::schema;
use lightpose_core::{
    Burst, Demodulated, Frame, LogHeader, LogReader, LogWriter, PoseEstimate, Record,
};
use mcap::records::{MessageHeader, Metadata};
use mcap::write::NoSeek;
use std::collections::BTreeMap;
use std::io::{self, Write};

#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// MCAP log times are unsigned nanoseconds since the log's epoch.
    #[error("{what} seq {seq}: t = {t} s has no MCAP log time (it must be finite, ≥ 0 and before year 2554 in Unix time)")]
    Time {
        what: &'static str,
        seq: u64,
        t: f64,
    },
    /// A POSE line handed to [`McapWriter::write_pose_line`] was refused.
    #[error("{0}")]
    PoseLine(String),
    /// The file could not be created or written.
    #[error("{file}: {err}")]
    File { file: String, err: io::Error },
    /// A HEADER line handed to [`McapWriter::with_header_line`] was refused.
    #[error(transparent)]
    Header(lightpose_core::LogError),
    #[error(transparent)]
    Mcap(#[from] mcap::McapError),
    #[error(transparent)]
    Io(#[from] io::Error),
}

/// How the MCAP is laid out.
#[derive(Debug, Clone)]
pub struct McapOptions {
    /// A chunk is closed once it holds this many bytes (or at
    /// [`McapWriter::flush`]). Chunks are the unit that survives a power
    /// loss: a recorder wants them small (the default, 64 KiB, is about ten
    /// seconds at 5 Hz with every channel) and flushes on a timer; a
    /// conversion may take larger ones.
    pub chunk_bytes: u64,
    /// Also write the Foxglove channels (image, vehicle and truth pose,
    /// transform).
    pub foxglove: bool,
}

impl Default for McapOptions {
    fn default() -> Self {
        McapOptions {
            chunk_bytes: 64 << 10,
            foxglove: true,
        }
    }
}

/// Channel ids by [`Channel::index`] (the seven of [`Channel::ALL`],
/// then [`Channel::V3`]).
type Ids = [Option<u16>; 9];

pub struct McapWriter<W: Write> {
    mcap: mcap::Writer<NoSeek<W>>,
    /// The MCAP channel id of each [`Channel`] (by its index); `None` for
    /// the Foxglove channels when they are left out, and for spec v3's
    /// ([`Channel::V3`]) until their first message declares them.
    ids: Ids,
    enc: Encoder,
    frames: u64,
    poses: u64,
}

/// Bytes of [`mcap_end`].
pub const MCAP_END_BYTES: usize = 50;

/// What completes an MCAP whose writing stopped (a full disk) once it is
/// cut back to the end of a whole record of its data section: a Data End
/// (CRC 0: not computed) and a Footer without a summary section (offsets
/// 0), then the closing magic. The summary is optional in MCAP: with these
/// the file is complete for every reader, which reads it from the start.
pub fn mcap_end() -> [u8; MCAP_END_BYTES] {
    let mut b = [0u8; MCAP_END_BYTES];
    b[0] = mcap::records::op::DATA_END;
    b[1..9].copy_from_slice(&4u64.to_le_bytes());
    // b[9..13]: data_section_crc 0.
    b[13] = mcap::records::op::FOOTER;
    b[14..22].copy_from_slice(&20u64.to_le_bytes());
    // b[22..42]: summary_start, summary_offset_start, summary_crc, all 0.
    b[42..].copy_from_slice(mcap::MAGIC);
    b
}

/// The HEADER line that a JSONL log of `header` starts with (no newline).
pub(crate) fn header_line(header: &LogHeader) -> io::Result<String> {
    let mut w = LogWriter::new(Vec::new(), header)?;
    let mut bytes = std::mem::take(w.get_mut());
    while bytes.last() == Some(&b'\n') {
        bytes.pop();
    }
    String::from_utf8(bytes).map_err(io::Error::other)
}

impl<W: Write> McapWriter<W> {
    /// Start an MCAP on `sink`: magic, header record, the log's HEADER as
    /// metadata, then the schemas and channels. Chunks are uncompressed:
    /// the `mcap` crate's compressors are C libraries, and the project
    /// cross-builds for ARM (a 5 × 5 frame is small; see the crate docs).
    pub fn new(sink: W, header: &LogHeader, opts: &McapOptions) -> Result<Self, WriteError> {
        McapWriter::with_header_line(sink, &header_line(header)?, opts)
    }

    /// As [`McapWriter::new`], with the HEADER as the text of its line (a
    /// conversion carries it as it is); the line is checked as a log
    /// reader checks it.
    pub fn with_header_line(sink: W, line: &str, opts: &McapOptions) -> Result<Self, WriteError> {
        let line = std::str::from_utf8(trim_newline(line.as_bytes())).unwrap_or(line);
        let header = LogReader::new(line.as_bytes(), "HEADER")
            .map_err(WriteError::Header)?
            .header()
            .clone();
        let wopts = mcap::WriteOptions::new()
            .compression(None)
            .chunk_size(Some(opts.chunk_bytes))
            .disable_seeking(true)
            .emit_message_indexes(false)
            .profile("")
            .library(format!(
                "lightpose-logs/{} ({})",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            ));
        let mut mcap = wopts.create(NoSeek::new(sink))?;
        let mut meta = BTreeMap::new();
        meta.insert(schema::HEADER_KEY.to_string(), line.to_string());
        mcap.write_metadata(&Metadata {
            name: schema::HEADER_METADATA.into(),
            metadata: meta,
        })?;
        let mut ids: Ids = [None; 9];
        // Schemas by name: the two PoseInFrame channels share theirs.
        let mut schemas: BTreeMap<&str, u16> = BTreeMap::new();
        for c in Channel::ALL {
            if c.is_foxglove() && !opts.foxglove {
                continue;
            }
            let sid = match schemas.get(c.schema_name()) {
                Some(&id) => id,
                None => {
                    let id = mcap.add_schema(
                        c.schema_name(),
                        schema::SCHEMA_ENCODING,
                        c.schema().as_bytes(),
                    )?;
                    schemas.insert(c.schema_name(), id);
                    id
                }
            };
            let topic = c.topic();
            let enc = schema::MESSAGE_ENCODING;
            ids[c.index()] = Some(mcap.add_channel(sid, topic, enc, &BTreeMap::new())?);
        }
        Ok(McapWriter {
            mcap,
            ids,
            enc: Encoder::new(&header, opts.foxglove)?,
            frames: 0,
            poses: 0,
        })
    }

    /// The closure that writes each message the encoder makes; a spec v3
    /// channel is declared at its first message, so that a v1/v2
    /// recording is laid out as before.
    fn sink<'a>(
        mcap: &'a mut mcap::Writer<NoSeek<W>>,
        ids: &'a mut Ids,
    ) -> impl FnMut(Message) -> Result<(), WriteError> + 'a {
        move |m: Message| {
            let c = m.channel;
            if ids[c.index()].is_none() && Channel::V3.contains(&c) {
                let sid =
                    mcap.add_schema(c.schema_name(), c.schema_encoding(), c.schema().as_bytes())?;
                ids[c.index()] = Some(mcap.add_channel(
                    sid,
                    c.topic(),
                    c.message_encoding(),
                    &BTreeMap::new(),
                )?);
            }
            let Some(channel_id) = ids[c.index()] else {
                return Ok(());
            };
            let h = MessageHeader {
                channel_id,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.log_time,
            };
            mcap.write_to_known_channel(&h, m.data)?;
            Ok(())
        }
    }

    /// Append one frame: its FRAME line, and with Foxglove channels its
    /// image and, when it has one, its truth (see [`Encoder::frame`]). Log
    /// time is the frame's t; a negative t (an epoch that is not the log's
    /// start, say) is refused.
    pub fn write_frame(&mut self, f: &Frame) -> Result<(), WriteError> {
        self.enc
            .frame(f, &mut Self::sink(&mut self.mcap, &mut self.ids))?;
        self.frames += 1;
        Ok(())
    }

    /// As [`McapWriter::write_frame`], with the FRAME object as the text
    /// that a log held for `f` (a conversion carries lines as they are;
    /// the Foxglove messages are made from `f`).
    pub fn write_frame_line(&mut self, f: &Frame, line: &[u8]) -> Result<(), WriteError> {
        self.enc
            .frame_line(f, line, &mut Self::sink(&mut self.mcap, &mut self.ids))?;
        self.frames += 1;
        Ok(())
    }

    /// Spec v3: append one BURST, binary on `/lightpose/burst` (with
    /// Foxglove channels, each channel's mean sample as the image, and its
    /// truth); log time its t, its first sample's.
    pub fn write_burst(&mut self, b: &Burst) -> Result<(), WriteError> {
        self.enc
            .burst(b, None, &mut Self::sink(&mut self.mcap, &mut self.ids))?;
        self.frames += 1;
        Ok(())
    }

    /// As [`McapWriter::write_burst`], with the BURST as the text of the
    /// line a log held for it (kept byte for byte: [`crate::burst`]).
    pub fn write_burst_line(&mut self, b: &Burst, line: &[u8]) -> Result<(), WriteError> {
        self.enc.burst(
            b,
            Some(line),
            &mut Self::sink(&mut self.mcap, &mut self.ids),
        )?;
        self.frames += 1;
        Ok(())
    }

    /// Spec v3: append one demodulated frame, its line on
    /// `/lightpose/demodulated` (with Foxglove channels, its mean levels as
    /// the image, and its truth).
    pub fn write_demodulated(&mut self, d: &Demodulated) -> Result<(), WriteError> {
        self.enc
            .demodulated(d, None, &mut Self::sink(&mut self.mcap, &mut self.ids))?;
        self.frames += 1;
        Ok(())
    }

    /// As [`McapWriter::write_demodulated`], with the line a log held.
    pub fn write_demodulated_line(
        &mut self,
        d: &Demodulated,
        line: &[u8],
    ) -> Result<(), WriteError> {
        self.enc.demodulated(
            d,
            Some(line),
            &mut Self::sink(&mut self.mcap, &mut self.ids),
        )?;
        self.frames += 1;
        Ok(())
    }

    /// Append one frame of any kind ([`Record`]) with the text of the line
    /// a log held for it.
    pub fn write_record_line(&mut self, r: &Record, line: &[u8]) -> Result<(), WriteError> {
        match r {
            Record::Frame(f) => self.write_frame_line(f, line),
            Record::Burst(b) => self.write_burst_line(b, line),
            Record::Demodulated(d) => self.write_demodulated_line(d, line),
        }
    }

    /// Append one estimate as its POSE object (with the wall-clock capture
    /// time, Unix seconds, when given), at its frame's t; with Foxglove
    /// channels, also as a pose and a transform (see [`Encoder::pose`]).
    pub fn write_pose(
        &mut self,
        p: &PoseEstimate,
        wall_unix: Option<f64>,
    ) -> Result<(), WriteError> {
        self.enc
            .pose(p, wall_unix, &mut Self::sink(&mut self.mcap, &mut self.ids))?;
        self.poses += 1;
        Ok(())
    }

    /// Append one POSE line as it is (e.g. from `lightpose replay`'s
    /// output), with its Foxglove messages. The line must be a POSE object
    /// with its frame's `seq` and a `t` ≥ 0.
    pub fn write_pose_line(&mut self, line: &[u8]) -> Result<(), WriteError> {
        self.enc
            .pose_line(line, &mut Self::sink(&mut self.mcap, &mut self.ids))?;
        self.poses += 1;
        Ok(())
    }

    /// Append one STATUS object (the daemon's JSON, as it is) at `t`, in
    /// the log's epoch: the recorder gives the last frame's t, so that
    /// status sits among the frames it describes.
    pub fn write_status(&mut self, t: f64, json: &[u8]) -> Result<(), WriteError> {
        self.enc
            .status(t, json, &mut Self::sink(&mut self.mcap, &mut self.ids))
    }

    /// Declare a channel as another file declared it (a conversion carries
    /// the channels it does not make): its schema (name, encoding, data;
    /// `None`: no schema), topic, message encoding and metadata; its MCAP
    /// id. A declaration equal to one made before (this writer's own
    /// `/lightpose/status`, say) gives that channel's id.
    pub fn add_channel(
        &mut self,
        schema: Option<(&str, &str, &[u8])>,
        topic: &str,
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<u16, WriteError> {
        let sid = match schema {
            Some((name, encoding, data)) => self.mcap.add_schema(name, encoding, data)?,
            None => 0,
        };
        Ok(self
            .mcap
            .add_channel(sid, topic, message_encoding, metadata)?)
    }

    /// Append a message on a channel of [`McapWriter::add_channel`] as it
    /// was: its sequence, log and publish times and bytes unchanged.
    pub fn write_raw(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), WriteError> {
        let h = MessageHeader {
            channel_id,
            sequence,
            log_time,
            publish_time,
        };
        self.mcap.write_to_known_channel(&h, data)?;
        Ok(())
    }

    /// Append a metadata record `name` of `pairs` (it closes the open
    /// chunk: metadata sits between chunks). Readers here pass over every
    /// metadata record but the HEADER's.
    pub fn write_metadata(
        &mut self,
        name: &str,
        pairs: BTreeMap<String, String>,
    ) -> Result<(), WriteError> {
        self.mcap.write_metadata(&Metadata {
            name: name.into(),
            metadata: pairs,
        })?;
        Ok(())
    }

    /// Close the open chunk and flush the sink: everything written so far
    /// survives a power loss once the sink has it on disk.
    pub fn flush(&mut self) -> Result<(), WriteError> {
        self.mcap.flush()?;
        Ok(())
    }

    pub fn frames_written(&self) -> u64 {
        self.frames
    }
    pub fn poses_written(&self) -> u64 {
        self.poses
    }

    /// Write the summary and footer, flush, and hand the sink back.
    pub fn finish(mut self) -> Result<W, WriteError> {
        self.mcap.finish()?;
        let mut sink = self.mcap.into_inner().into_inner();
        sink.flush()?;
        Ok(sink)
    }
}
