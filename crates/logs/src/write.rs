//! The MCAP writer: frames, poses and status on the channels of
//! [`crate::schema`], made for a recorder thread. Each FRAME message is the
//! JSONL line that core's `LogWriter` writes for the frame (formatted by it,
//! so the two containers cannot drift apart); poses are POSE objects as the
//! daemon publishes them. Buffers are reused: once warm, a frame costs no
//! allocation here, and the `mcap` crate allocates only per chunk (message
//! indexes are off for that reason: see [`McapOptions`]).
//!
//! The file is written append-only (the `mcap` writer never seeks back):
//! every prefix of it is what a power loss at that moment leaves, and the
//! reader recovers every chunk that was complete.

use crate::foxglove::{self, Stamp};
use crate::schema::{self, name, topic};
use lightpose_core::{Angle, Frame, LogHeader, LogReader, LogWriter, Pose, PoseEstimate};
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

struct Channels {
    frame: u16,
    pose: u16,
    status: u16,
    image: u16,
    vehicle_pose: u16,
    truth_pose: u16,
    tf: u16,
}

/// Per-channel MCAP sequence numbers for channels without a seq of their own.
#[derive(Default)]
struct Sequences {
    status: u32,
}

pub struct McapWriter<W: Write> {
    mcap: mcap::Writer<NoSeek<W>>,
    ch: Channels,
    foxglove: bool,
    /// Formats FRAME lines exactly as the JSONL log does; emptied after each.
    lines: LogWriter<Vec<u8>>,
    buf: Vec<u8>,
    seqs: Sequences,
    frames: u64,
    poses: u64,
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
        let mut add = |schema_name: &str, schema: &str, topic: &str| {
            let id = mcap.add_schema(schema_name, schema::SCHEMA_ENCODING, schema.as_bytes())?;
            mcap.add_channel(id, topic, schema::MESSAGE_ENCODING, &BTreeMap::new())
        };
        let mut ch = Channels {
            frame: add(name::FRAME, schema::FRAME, topic::FRAME)?,
            pose: add(name::POSE, schema::POSE, topic::POSE)?,
            status: add(name::STATUS, schema::STATUS, topic::STATUS)?,
            image: 0,
            vehicle_pose: 0,
            truth_pose: 0,
            tf: 0,
        };
        if opts.foxglove {
            let pif = schema::POSE_IN_FRAME;
            ch.image = add(name::RAW_IMAGE, schema::RAW_IMAGE, topic::IMAGE)?;
            ch.vehicle_pose = add(name::POSE_IN_FRAME, pif, topic::VEHICLE_POSE)?;
            ch.truth_pose = add(name::POSE_IN_FRAME, pif, topic::TRUTH_POSE)?;
            ch.tf = add(name::FRAME_TRANSFORM, schema::FRAME_TRANSFORM, topic::TF)?;
        }
        let mut lines = LogWriter::new(Vec::with_capacity(1024), &header)?;
        lines.get_mut().clear();
        Ok(McapWriter {
            mcap,
            ch,
            foxglove: opts.foxglove,
            lines,
            buf: Vec::with_capacity(1024),
            seqs: Sequences::default(),
            frames: 0,
            poses: 0,
        })
    }

    fn put(
        &mut self,
        channel_id: u16,
        sequence: u32,
        time: u64,
        data: &[u8],
    ) -> Result<(), WriteError> {
        let h = MessageHeader {
            channel_id,
            sequence,
            log_time: time,
            publish_time: time,
        };
        self.mcap.write_to_known_channel(&h, data)?;
        Ok(())
    }

    /// Append one frame: its FRAME line, and with Foxglove channels its
    /// image and, when it has one, its truth. Log time is the frame's t; a
    /// negative t (an epoch that is not the log's start, say) is refused.
    pub fn write_frame(&mut self, f: &Frame) -> Result<(), WriteError> {
        self.lines.write_frame(f)?;
        let line = std::mem::take(self.lines.get_mut());
        let r = self.write_frame_line(f, &line);
        // Give the buffer back (emptied) whatever happened.
        *self.lines.get_mut() = line;
        self.lines.get_mut().clear();
        r
    }

    /// As [`McapWriter::write_frame`], with the FRAME object as the text
    /// that a log held for `f` (a conversion carries lines as they are;
    /// the Foxglove messages are made from `f`).
    pub fn write_frame_line(&mut self, f: &Frame, line: &[u8]) -> Result<(), WriteError> {
        let stamp = Stamp::of(f.t).ok_or(WriteError::Time {
            what: "frame",
            seq: f.seq,
            t: f.t,
        })?;
        let time = stamp.nanos();
        self.put(self.ch.frame, f.seq as u32, time, trim_newline(line))?;
        if self.foxglove {
            foxglove::raw_image(stamp, &f.counts, &mut self.buf);
            self.put_buf(self.ch.image, f.seq as u32, time)?;
            if let Some(tr) = f.truth {
                if finite_pose(&tr.pose) {
                    foxglove::pose_in_frame(stamp, &tr.pose, &mut self.buf);
                    self.put_buf(self.ch.truth_pose, f.seq as u32, time)?;
                }
            }
        }
        self.frames += 1;
        Ok(())
    }

    /// `self.buf` on a channel (nothing when it is empty: a message that
    /// could not be formatted).
    fn put_buf(&mut self, channel_id: u16, sequence: u32, time: u64) -> Result<(), WriteError> {
        if self.buf.is_empty() {
            return Ok(());
        }
        let h = MessageHeader {
            channel_id,
            sequence,
            log_time: time,
            publish_time: time,
        };
        self.mcap.write_to_known_channel(&h, &self.buf)?;
        Ok(())
    }

    /// Append one estimate as its POSE object (with the wall-clock capture
    /// time, Unix seconds, when given), at its frame's t; with Foxglove
    /// channels, also as a pose and a transform when x, y, z, pitch and yaw
    /// are all known, whatever its status (which the POSE object carries).
    pub fn write_pose(
        &mut self,
        p: &PoseEstimate,
        wall_unix: Option<f64>,
    ) -> Result<(), WriteError> {
        let stamp = Stamp::of(p.t).ok_or(WriteError::Time {
            what: "pose",
            seq: p.seq,
            t: p.t,
        })?;
        p.write_json(wall_unix, &mut self.buf);
        self.put_buf(self.ch.pose, p.seq as u32, stamp.nanos())?;
        let pose = pose_of(p.x, p.y, p.z, p.pitch_deg, p.yaw_deg);
        self.foxglove_pose(p.seq, stamp, pose)
    }

    fn foxglove_pose(
        &mut self,
        seq: u64,
        stamp: Stamp,
        pose: Option<Pose>,
    ) -> Result<(), WriteError> {
        self.poses += 1;
        let Some(pose) = pose.filter(|p| self.foxglove && finite_pose(p)) else {
            return Ok(());
        };
        foxglove::pose_in_frame(stamp, &pose, &mut self.buf);
        self.put_buf(self.ch.vehicle_pose, seq as u32, stamp.nanos())?;
        foxglove::frame_transform(stamp, &pose, &mut self.buf);
        self.put_buf(self.ch.tf, seq as u32, stamp.nanos())
    }

    /// Append one POSE line as it is (e.g. from `lightpose replay`'s
    /// output), with its Foxglove messages. The line must be a POSE object
    /// with its frame's `seq` and a `t` ≥ 0.
    pub fn write_pose_line(&mut self, line: &[u8]) -> Result<(), WriteError> {
        let text = trim_newline(line);
        let p: PoseLine = serde_json::from_slice(text)
            .map_err(|e| WriteError::PoseLine(format!("not a JSON object: {e}")))?;
        if p.class.as_deref() != Some("POSE") {
            return Err(WriteError::PoseLine("class is not POSE".into()));
        }
        let seq = p
            .seq
            .ok_or_else(|| WriteError::PoseLine("no integer seq".into()))?;
        let t =
            p.t.ok_or_else(|| WriteError::PoseLine("no number t".into()))?;
        let stamp = Stamp::of(t).ok_or(WriteError::Time {
            what: "pose",
            seq,
            t,
        })?;
        self.put(self.ch.pose, seq as u32, stamp.nanos(), text)?;
        self.foxglove_pose(seq, stamp, pose_of(p.x, p.y, p.z, p.pitch, p.yaw))
    }

    /// Append one STATUS object (the daemon's JSON, as it is) at `t`, in
    /// the log's epoch: the recorder gives the last frame's t, so that
    /// status sits among the frames it describes.
    pub fn write_status(&mut self, t: f64, json: &[u8]) -> Result<(), WriteError> {
        let seq = self.seqs.status;
        let stamp = Stamp::of(t).ok_or(WriteError::Time {
            what: "status",
            seq: seq as u64,
            t,
        })?;
        self.seqs.status = seq.wrapping_add(1);
        self.put(self.ch.status, seq, stamp.nanos(), trim_newline(json))
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

/// The pose of an estimate that knows all five of its fields (degrees).
fn pose_of(
    x: Option<f64>,
    y: Option<f64>,
    z: Option<f64>,
    pitch: Option<f64>,
    yaw: Option<f64>,
) -> Option<Pose> {
    let (x, y, z, p, w) = (x?, y?, z?, pitch?, yaw?);
    Some(Pose::new(x, y, z, Angle::from_deg(p), Angle::from_deg(w)))
}

fn finite_pose(p: &Pose) -> bool {
    [p.x, p.y, p.z, p.pitch.rad(), p.yaw.rad()]
        .iter()
        .all(|v| v.is_finite())
}

fn trim_newline(b: &[u8]) -> &[u8] {
    let mut b = b;
    while let [rest @ .., b'\n' | b'\r'] = b {
        b = rest;
    }
    b
}

/// The fields of a POSE line that its Foxglove messages need.
#[derive(serde::Deserialize)]
struct PoseLine {
    class: Option<String>,
    seq: Option<u64>,
    t: Option<f64>,
    x: Option<f64>,
    y: Option<f64>,
    z: Option<f64>,
    pitch: Option<f64>,
    yaw: Option<f64>,
}
