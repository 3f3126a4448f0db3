//! The messages of a frame, an estimate and a STATUS on every channel of
//! [`crate::schema`], formatted in one place for both things that carry
//! them: the MCAP writer and the daemon's live view (Foxglove's WebSocket
//! protocol). So a recording and the live view cannot drift apart: the
//! same channels, the same bytes.
//!
//! Buffers are reused: once warm, a frame costs no allocation here.

use crate::foxglove::{self, Stamp};
use crate::schema::{self, name, topic};
use crate::write::WriteError;
use lightpose_core::{
    Angle, Burst, Demodulated, Frame, LogHeader, LogWriter, Pose, PoseEstimate, NDET,
};
use std::io;

/// The channels of a recording and of the live view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    Frame,
    Pose,
    Status,
    Image,
    VehiclePose,
    TruthPose,
    Tf,
    /// Spec v3: raw samples, binary (recordings only: see [`Channel::V3`]).
    Burst,
    /// Spec v3: demodulated frames, their JSONL lines.
    Demodulated,
}

impl Channel {
    /// Every channel, in the order they are announced (an MCAP's channel
    /// records, the live view's channel ids 1..=7).
    pub const ALL: [Channel; 7] = [
        Channel::Frame,
        Channel::Pose,
        Channel::Status,
        Channel::Image,
        Channel::VehiclePose,
        Channel::TruthPose,
        Channel::Tf,
    ];

    /// Spec v3's channels, after [`Channel::ALL`]: a recording declares
    /// each at its first message (a v1/v2 recording has neither, as
    /// before); the live view does not serve them (Foxglove has no panel
    /// for a packed sample block, and a burst is tens of kilobytes).
    pub const V3: [Channel; 2] = [Channel::Burst, Channel::Demodulated];

    /// Its place in [`Channel::ALL`], then [`Channel::V3`].
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn topic(self) -> &'static str {
        match self {
            Channel::Frame => topic::FRAME,
            Channel::Pose => topic::POSE,
            Channel::Status => topic::STATUS,
            Channel::Image => topic::IMAGE,
            Channel::VehiclePose => topic::VEHICLE_POSE,
            Channel::TruthPose => topic::TRUTH_POSE,
            Channel::Tf => topic::TF,
            Channel::Burst => topic::BURST,
            Channel::Demodulated => topic::DEMODULATED,
        }
    }

    pub fn schema_name(self) -> &'static str {
        match self {
            Channel::Frame => name::FRAME,
            Channel::Pose => name::POSE,
            Channel::Status => name::STATUS,
            Channel::Image => name::RAW_IMAGE,
            Channel::VehiclePose | Channel::TruthPose => name::POSE_IN_FRAME,
            Channel::Tf => name::FRAME_TRANSFORM,
            Channel::Burst => name::BURST,
            Channel::Demodulated => name::DEMODULATED,
        }
    }

    /// Its schema's encoding: [`schema::SCHEMA_ENCODING`] but for the
    /// binary burst's.
    pub fn schema_encoding(self) -> &'static str {
        match self {
            Channel::Burst => schema::BURST_SCHEMA_ENCODING,
            _ => schema::SCHEMA_ENCODING,
        }
    }

    /// Its message encoding: [`schema::MESSAGE_ENCODING`] but for the
    /// binary burst's.
    pub fn message_encoding(self) -> &'static str {
        match self {
            Channel::Burst => schema::BURST_MESSAGE_ENCODING,
            _ => schema::MESSAGE_ENCODING,
        }
    }

    /// Its schema (a JSON Schema; the burst's layout in words).
    pub fn schema(self) -> &'static str {
        match self {
            Channel::Frame => schema::FRAME,
            Channel::Pose => schema::POSE,
            Channel::Status => schema::STATUS,
            Channel::Image => schema::RAW_IMAGE,
            Channel::VehiclePose | Channel::TruthPose => schema::POSE_IN_FRAME,
            Channel::Tf => schema::FRAME_TRANSFORM,
            Channel::Burst => schema::BURST_LAYOUT,
            Channel::Demodulated => schema::DEMODULATED,
        }
    }

    /// One of Foxglove's well-known types (the same data again, for its
    /// panels), rather than one of the project's own objects.
    pub fn is_foxglove(self) -> bool {
        !matches!(
            self,
            Channel::Frame
                | Channel::Pose
                | Channel::Status
                | Channel::Burst
                | Channel::Demodulated
        )
    }
}

/// One message: its channel, its sequence number (the frame's seq, or a
/// count for STATUS), its log time (nanoseconds in the log's epoch) and its
/// JSON text.
#[derive(Debug, Clone, Copy)]
pub struct Message<'a> {
    pub channel: Channel,
    pub sequence: u32,
    pub log_time: u64,
    pub data: &'a [u8],
}

/// Formats messages into reused buffers and hands each to a closure
/// (which writes it into an MCAP, or queues it for live clients).
pub struct Encoder {
    /// Formats FRAME lines exactly as the JSONL log does; emptied after each.
    lines: LogWriter<Vec<u8>>,
    buf: Vec<u8>,
    /// A burst's message and the codec's scratch (spec v3).
    burst: Vec<u8>,
    scratch: Vec<u8>,
    foxglove: bool,
    status_seq: u32,
}

/// What a closure given each message returns.
pub type Emit<'e> = &'e mut dyn FnMut(Message) -> Result<(), WriteError>;

impl Encoder {
    /// An encoder for frames of `header`'s log; with `foxglove`, the
    /// Foxglove channels are made too.
    pub fn new(header: &LogHeader, foxglove: bool) -> io::Result<Encoder> {
        let mut lines = LogWriter::new(Vec::with_capacity(1024), header)?;
        lines.get_mut().clear();
        Ok(Encoder {
            lines,
            buf: Vec::with_capacity(1024),
            burst: Vec::new(),
            scratch: Vec::new(),
            foxglove,
            status_seq: 0,
        })
    }

    /// A frame's messages: its FRAME line (as the JSONL log writes it) and,
    /// with Foxglove channels, its image and, when it has one, its truth.
    /// Log time is the frame's t; a negative t is refused.
    pub fn frame(&mut self, f: &Frame, out: Emit) -> Result<(), WriteError> {
        self.lines.write_frame(f)?;
        let line = std::mem::take(self.lines.get_mut());
        let r = self.frame_line(f, &line, out);
        // Give the buffer back (emptied) whatever happened.
        *self.lines.get_mut() = line;
        self.lines.get_mut().clear();
        r
    }

    /// As [`Encoder::frame`], with the FRAME object as the text that a log
    /// held for `f` (a conversion carries lines as they are; the Foxglove
    /// messages are made from `f`).
    pub fn frame_line(&mut self, f: &Frame, line: &[u8], out: Emit) -> Result<(), WriteError> {
        let stamp = Stamp::of(f.t).ok_or(WriteError::Time {
            what: "frame",
            seq: f.seq,
            t: f.t,
        })?;
        let at = At(f.seq as u32, stamp.nanos());
        out(at.msg(Channel::Frame, trim_newline(line)))?;
        if !self.foxglove {
            return Ok(());
        }
        foxglove::raw_image(stamp, &f.counts, &mut self.buf);
        emit_buf(out, at.msg(Channel::Image, &self.buf))?;
        if let Some(tr) = f.truth.filter(|tr| finite_pose(&tr.pose)) {
            foxglove::pose_in_frame(stamp, &tr.pose, &mut self.buf);
            emit_buf(out, at.msg(Channel::TruthPose, &self.buf))?;
        }
        Ok(())
    }

    /// Spec v3: a BURST's messages: the binary burst on `/lightpose/burst`
    /// (its line as `LogWriter` writes it, or `line` as a log held it:
    /// see [`crate::burst`]) and, with Foxglove channels, each channel's
    /// mean sample as the image and its truth. Log time is its t (its first
    /// sample's).
    pub fn burst(&mut self, b: &Burst, line: Option<&[u8]>, out: Emit) -> Result<(), WriteError> {
        if let Some(l) = line {
            return self.burst_line(b, l, out);
        }
        self.lines.write_burst(b)?;
        let own = std::mem::take(self.lines.get_mut());
        let r = self.burst_line(b, &own, out);
        *self.lines.get_mut() = own;
        self.lines.get_mut().clear();
        r
    }

    fn burst_line(&mut self, b: &Burst, line: &[u8], out: Emit) -> Result<(), WriteError> {
        let stamp = Stamp::of(b.t).ok_or(WriteError::Time {
            what: "burst",
            seq: b.seq,
            t: b.t,
        })?;
        crate::burst::encode(b, trim_newline(line), &mut self.burst, &mut self.scratch);
        let at = At(b.seq as u32, stamp.nanos());
        out(at.msg(Channel::Burst, &self.burst))?;
        if !self.foxglove {
            return Ok(());
        }
        let n = b.n().max(1) as u64;
        let counts: [u16; NDET] = std::array::from_fn(|k| {
            let sum: u64 = b.channel(k).iter().map(|&v| v as u64).sum();
            ((sum + n / 2) / n) as u16
        });
        foxglove::raw_image(stamp, &counts, &mut self.buf);
        emit_buf(out, at.msg(Channel::Image, &self.buf))?;
        if let Some(tr) = b.truth.filter(|tr| finite_pose(&tr.pose)) {
            foxglove::pose_in_frame(stamp, &tr.pose, &mut self.buf);
            emit_buf(out, at.msg(Channel::TruthPose, &self.buf))?;
        }
        Ok(())
    }

    /// Spec v3: a demodulated frame's messages: its line (as `LogWriter`
    /// writes it, or `line` as a log held it) on `/lightpose/demodulated`
    /// and, with Foxglove channels, each channel's mean level as the image
    /// ([`Demodulated::to_frame`]'s counts) and its truth.
    pub fn demodulated(
        &mut self,
        d: &Demodulated,
        line: Option<&[u8]>,
        out: Emit,
    ) -> Result<(), WriteError> {
        if let Some(l) = line {
            return self.demodulated_line(d, l, out);
        }
        self.lines.write_demodulated(d)?;
        let own = std::mem::take(self.lines.get_mut());
        let r = self.demodulated_line(d, &own, out);
        *self.lines.get_mut() = own;
        self.lines.get_mut().clear();
        r
    }

    fn demodulated_line(
        &mut self,
        d: &Demodulated,
        line: &[u8],
        out: Emit,
    ) -> Result<(), WriteError> {
        let stamp = Stamp::of(d.t).ok_or(WriteError::Time {
            what: "demodulated frame",
            seq: d.seq,
            t: d.t,
        })?;
        let at = At(d.seq as u32, stamp.nanos());
        out(at.msg(Channel::Demodulated, trim_newline(line)))?;
        if !self.foxglove {
            return Ok(());
        }
        let f = d.to_frame();
        foxglove::raw_image(stamp, &f.counts, &mut self.buf);
        emit_buf(out, at.msg(Channel::Image, &self.buf))?;
        if let Some(tr) = d.truth.filter(|tr| finite_pose(&tr.pose)) {
            foxglove::pose_in_frame(stamp, &tr.pose, &mut self.buf);
            emit_buf(out, at.msg(Channel::TruthPose, &self.buf))?;
        }
        Ok(())
    }

    /// An estimate's messages: its POSE object (with the wall-clock capture
    /// time, Unix seconds, when given) at its frame's t; with Foxglove
    /// channels, also a pose and a transform when x, y, z, pitch and yaw
    /// are all known, whatever its status (which the POSE object carries).
    pub fn pose(
        &mut self,
        p: &PoseEstimate,
        wall_unix: Option<f64>,
        out: Emit,
    ) -> Result<(), WriteError> {
        let stamp = pose_stamp(p.seq, p.t)?;
        p.write_json(wall_unix, &mut self.buf);
        let at = At(p.seq as u32, stamp.nanos());
        emit_buf(out, at.msg(Channel::Pose, &self.buf))?;
        let pose = pose_of(p.x, p.y, p.z, p.pitch_deg, p.yaw_deg, p.roll_deg);
        self.foxglove_pose(p.seq, stamp, pose, out)
    }

    /// One POSE line as it is (e.g. from `lightpose replay`'s output), with
    /// its Foxglove messages. The line must be a POSE object with its
    /// frame's `seq` and a `t` ≥ 0.
    pub fn pose_line(&mut self, line: &[u8], out: Emit) -> Result<(), WriteError> {
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
        let stamp = pose_stamp(seq, t)?;
        out(At(seq as u32, stamp.nanos()).msg(Channel::Pose, text))?;
        let pose = pose_of(p.x, p.y, p.z, p.pitch, p.yaw, p.roll);
        self.foxglove_pose(seq, stamp, pose, out)
    }

    fn foxglove_pose(
        &mut self,
        seq: u64,
        stamp: Stamp,
        pose: Option<Pose>,
        out: Emit,
    ) -> Result<(), WriteError> {
        let Some(pose) = pose.filter(|p| self.foxglove && finite_pose(p)) else {
            return Ok(());
        };
        let at = At(seq as u32, stamp.nanos());
        foxglove::pose_in_frame(stamp, &pose, &mut self.buf);
        emit_buf(out, at.msg(Channel::VehiclePose, &self.buf))?;
        foxglove::frame_transform(stamp, &pose, &mut self.buf);
        emit_buf(out, at.msg(Channel::Tf, &self.buf))
    }

    /// One STATUS object (the daemon's JSON, as it is) at `t` in the log's
    /// epoch (the last frame's t, so that it sits among the frames it
    /// describes); numbered in order.
    pub fn status(&mut self, t: f64, json: &[u8], out: Emit) -> Result<(), WriteError> {
        let seq = self.status_seq;
        let stamp = Stamp::of(t).ok_or(WriteError::Time {
            what: "status",
            seq: seq as u64,
            t,
        })?;
        self.status_seq = seq.wrapping_add(1);
        out(At(seq, stamp.nanos()).msg(Channel::Status, trim_newline(json)))
    }
}

/// Sequence number and log time of the messages of one frame or estimate.
#[derive(Clone, Copy)]
struct At(u32, u64);

impl At {
    fn msg(self, channel: Channel, data: &[u8]) -> Message<'_> {
        Message {
            channel,
            sequence: self.0,
            log_time: self.1,
            data,
        }
    }
}

fn pose_stamp(seq: u64, t: f64) -> Result<Stamp, WriteError> {
    Stamp::of(t).ok_or(WriteError::Time {
        what: "pose",
        seq,
        t,
    })
}

/// A formatted message (nothing when its buffer is empty: a message that
/// could not be formatted).
fn emit_buf(out: Emit, m: Message) -> Result<(), WriteError> {
    if m.data.is_empty() {
        return Ok(());
    }
    out(m)
}

/// The pose of an estimate that knows all five of its fields (degrees),
/// with its roll when it has one (spec v3; else 0, level, as spec v2 drew
/// it).
fn pose_of(
    x: Option<f64>,
    y: Option<f64>,
    z: Option<f64>,
    pitch: Option<f64>,
    yaw: Option<f64>,
    roll: Option<f64>,
) -> Option<Pose> {
    let (x, y, z, p, w) = (x?, y?, z?, pitch?, yaw?);
    let pose = Pose::new(x, y, z, Angle::from_deg(p), Angle::from_deg(w));
    Some(match roll {
        Some(r) => pose.with_roll(Angle::from_deg(r)),
        None => pose,
    })
}

fn finite_pose(p: &Pose) -> bool {
    [p.x, p.y, p.z, p.pitch.rad(), p.yaw.rad(), p.roll.rad()]
        .iter()
        .all(|v| v.is_finite())
}

pub(crate) fn trim_newline(b: &[u8]) -> &[u8] {
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
    roll: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_match_the_schema_constants() {
        for c in Channel::ALL {
            assert_eq!(Channel::ALL[c.index()], c);
            let v: serde_json::Value = serde_json::from_str(c.schema()).unwrap();
            assert_eq!(v["title"], c.schema_name(), "{c:?}");
            assert!(c.topic().starts_with("/lightpose/"));
        }
        let fox: Vec<_> = Channel::ALL.iter().filter(|c| c.is_foxglove()).collect();
        assert_eq!(fox.len(), 4);
        for c in Channel::V3 {
            assert!(!c.is_foxglove() && c.index() >= Channel::ALL.len());
            assert!(c.topic().starts_with("/lightpose/"));
        }
    }

    /// Spec v3: an estimate's roll turns its Foxglove pose and transform;
    /// without one they are spec v2's, byte for byte.
    #[test]
    fn an_estimate_s_roll_is_in_its_quaternion() {
        use lightpose_core::Status;
        let mut enc = Encoder::new(&LogHeader::new(10, 5.0), true).unwrap();
        let mut p = PoseEstimate::empty(3, 0.6, Status::Ok, "t");
        (p.x, p.y, p.z, p.pitch_deg, p.yaw_deg) =
            (Some(5.0), Some(0.1), Some(0.2), Some(4.0), Some(-6.0));
        let mut got: Vec<(Channel, Vec<u8>)> = Vec::new();
        let mut run = |enc: &mut Encoder, p: &PoseEstimate| {
            got.clear();
            enc.pose(p, None, &mut |m: Message| {
                got.push((m.channel, m.data.to_vec()));
                Ok(())
            })
            .unwrap();
            got.iter()
                .find(|(c, _)| *c == Channel::VehiclePose)
                .map(|(_, d)| serde_json::from_slice::<serde_json::Value>(d).unwrap())
                .unwrap()
        };
        let level = run(&mut enc, &p);
        p.roll_deg = Some(12.0);
        let rolled = run(&mut enc, &p);
        let q = |v: &serde_json::Value| {
            let o = &v["pose"]["orientation"];
            ["x", "y", "z", "w"].map(|k| o[k].as_f64().unwrap())
        };
        let (pitch, yaw) = (Angle::from_deg(4.0), Angle::from_deg(-6.0));
        assert_eq!(q(&level), foxglove::attitude_quaternion(pitch, yaw));
        let want = foxglove::attitude_quaternion_rolled(pitch, yaw, Angle::from_deg(12.0));
        assert_eq!(q(&rolled), want);
        assert_ne!(q(&rolled), q(&level));
    }
}
