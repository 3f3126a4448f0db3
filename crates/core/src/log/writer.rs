//! Writing a log: each line formatted whole in a reused buffer, the
//! optional readings of a frame written the same way for every kind of
//! frame line.

use super::{LogHeader, RawTruth, DEFAULT_BEACON_ID};
use crate::frame::{DepthReading, VelocityReading};
use crate::samples::{Burst, Demodulated};
use crate::{AttitudeReading, Frame, Truth, NDET};
use serde::Serialize;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

#[derive(Serialize)]
struct FrameOut<'a> {
    class: &'static str,
    seq: u64,
    t: Option<f64>,
    counts: &'a [u16; NDET],
    #[serde(flatten)]
    readings: ReadingsOut,
}

/// What every kind of frame line carries after its own fields, in the
/// same order: the temperature, the truth and the vehicle's readings,
/// each left out when absent or not finite.
#[derive(Serialize)]
struct ReadingsOut {
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

impl ReadingsOut {
    fn new(
        temp_c: Option<f64>,
        truth: Option<Truth>,
        attitude: Option<&AttitudeReading>,
        depth: Option<&DepthReading>,
        velocity: Option<&VelocityReading>,
    ) -> Self {
        ReadingsOut {
            temp_c: temp_c.and_then(crate::finite),
            truth: truth.map(raw_truth),
            attitude: attitude.and_then(attitude_out),
            depth: depth.and_then(depth_out),
            velocity: velocity.and_then(velocity_out),
        }
    }
}

#[derive(Serialize)]
struct AttitudeOut {
    pitch: f64,
    yaw: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    roll: Option<f64>,
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
    let roll = match a.roll {
        None => None,
        Some(r) => Some(crate::finite(r.deg())?),
    };
    Some(AttitudeOut {
        pitch,
        yaw,
        roll,
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

#[derive(Serialize)]
struct BurstOut<'a> {
    class: &'static str,
    seq: u64,
    t: Option<f64>,
    samples: SamplesOut<'a>,
    #[serde(flatten)]
    readings: ReadingsOut,
}

/// A burst's samples as 25 arrays of N.
struct SamplesOut<'a>(&'a Burst);

impl Serialize for SamplesOut<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = s.serialize_seq(Some(NDET))?;
        for k in 0..NDET {
            seq.serialize_element(self.0.channel(k))?;
        }
        seq.end()
    }
}

/// Numbers with each one that is not finite as null.
struct FiniteOut<'a>(&'a [f64; NDET]);

impl Serialize for FiniteOut<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = s.serialize_seq(Some(NDET))?;
        for v in self.0 {
            seq.serialize_element(&crate::finite(*v))?;
        }
        seq.end()
    }
}

#[derive(Serialize)]
struct DemodOut<'a> {
    class: &'static str,
    seq: u64,
    t: Option<f64>,
    beacons: DemodBeaconsOut<'a>,
    ambient: FiniteOut<'a>,
    clipped: &'a [u32; NDET],
    #[serde(flatten)]
    readings: ReadingsOut,
}

/// A demodulated frame's beacons by id.
struct DemodBeaconsOut<'a>(&'a Demodulated, &'a [String]);

impl Serialize for DemodBeaconsOut<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        #[derive(Serialize)]
        struct One<'a> {
            id: &'a str,
            amplitude: FiniteOut<'a>,
            std: FiniteOut<'a>,
        }
        let list = self.0.beacons();
        let mut seq = s.serialize_seq(Some(list.len()))?;
        for b in list {
            let id = self.1.get(b.beacon as usize).map_or("?", |s| s.as_str());
            seq.serialize_element(&One {
                id,
                amplitude: FiniteOut(&b.amplitude),
                std: FiniteOut(&b.std),
            })?;
        }
        seq.end()
    }
}

/// A truth as a line carries it: roll only when it is not 0 (spec v3), so
/// that a v1/v2 frame is written as before.
fn raw_truth(tr: Truth) -> RawTruth {
    let roll = tr.pose.roll.deg();
    RawTruth {
        x: tr.pose.x,
        y: tr.pose.y,
        z: tr.pose.z,
        pitch: tr.pose.pitch.deg(),
        yaw: tr.pose.yaw.deg(),
        roll: (roll != 0.0).then_some(roll).and_then(crate::finite),
        surge: tr.surge.and_then(crate::finite),
    }
}

/// Streaming writer: each line is formatted whole in a reused buffer and
/// handed to the sink in one `write_all`, so a reader never sees half a
/// frame except after a crash mid-write (which the reader handles).
pub struct LogWriter<W: Write> {
    sink: W,
    line: Vec<u8>,
    frames: u64,
    /// The header's beacon ids, by which a demodulated frame names them.
    beacon_ids: Vec<String>,
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
        let beacon_ids = if header.beacons.is_empty() {
            vec![DEFAULT_BEACON_ID.to_string()]
        } else {
            header.beacons.iter().map(|b| b.id.clone()).collect()
        };
        Ok(LogWriter {
            sink,
            line,
            frames: 0,
            beacon_ids,
        })
    }

    /// Append one BURST (spec v3) as one line: `t` its first sample's
    /// time, the samples as 25 arrays of N.
    pub fn write_burst(&mut self, b: &Burst) -> io::Result<()> {
        self.line.clear();
        let out = BurstOut {
            class: "BURST",
            seq: b.seq,
            t: crate::finite(b.t),
            samples: SamplesOut(b),
            readings: ReadingsOut::new(
                b.temp_c,
                b.truth,
                b.attitude.as_ref(),
                b.depth.as_ref(),
                b.velocity.as_ref(),
            ),
        };
        serde_json::to_writer(&mut self.line, &out)?;
        self.end_line()
    }

    /// Append one demodulated frame (spec v3) as one FRAME line with
    /// `beacons`, `ambient` and `clipped`; a number that is not finite is
    /// written as null (and refused by a reader, as it should be).
    pub fn write_demodulated(&mut self, d: &Demodulated) -> io::Result<()> {
        self.line.clear();
        let out = DemodOut {
            class: "FRAME",
            seq: d.seq,
            t: crate::finite(d.t),
            beacons: DemodBeaconsOut(d, &self.beacon_ids),
            ambient: FiniteOut(&d.light.ambient),
            clipped: &d.light.clipped,
            readings: ReadingsOut::new(
                d.temp_c,
                d.truth,
                d.attitude.as_ref(),
                d.depth.as_ref(),
                d.velocity.as_ref(),
            ),
        };
        serde_json::to_writer(&mut self.line, &out)?;
        self.end_line()
    }

    fn end_line(&mut self) -> io::Result<()> {
        self.line.push(b'\n');
        self.sink.write_all(&self.line)?;
        self.frames += 1;
        Ok(())
    }

    /// Append one frame as one line.
    pub fn write_frame(&mut self, f: &Frame) -> io::Result<()> {
        self.line.clear();
        let out = FrameOut {
            class: "FRAME",
            seq: f.seq,
            t: crate::finite(f.t),
            counts: &f.counts,
            readings: ReadingsOut::new(
                f.temp_c,
                f.truth,
                f.attitude.as_ref(),
                f.depth.as_ref(),
                f.velocity.as_ref(),
            ),
        };
        serde_json::to_writer(&mut self.line, &out)?;
        self.end_line()
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
