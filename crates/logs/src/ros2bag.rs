//! ROS 2 bags: an MCAP that `ros2 bag play` and ROS 2 readers without ROS
//! (the PyPI `rosbags`, Foxglove) read, holding the messages lightposed's
//! ROS 2 node publishes ([`crate::ros2msg`], one definition of each): the
//! MCAP profile `ros2`, each schema the type's complete `.msg` text
//! (encoding `ros2msg`, [`msgdef`]), each message CDR little-endian after
//! its 4-byte encapsulation header (encoding `cdr`), and each channel the
//! `offered_qos_profiles` metadata rosbag2 writes, with the node's QoS, so
//! that a bag played back offers what the node offered (`/tf_static`
//! transient local).
//!
//! A lightpose recording (`McapWriter`) cannot be this file: its channels
//! are JSON with jsonschema schemas, which rosbags refuses, and its
//! `/lightpose/pose` is the POSE object. Message indexes are on here (the
//! recorder's writer turns them off to save a chunk's allocation): rosbags
//! finds a chunk's messages through them.

pub mod convert;
pub mod info;
pub mod msgdef;
pub mod recording;

use crate::ros2msg::{
    DiagnosticArray, Frames, SiteTf, Solved, TFMessage, TypeName, DIAG_TYPE, ODOM_TYPE, POSE_TYPE,
    TF_TYPE,
};
use crate::write::WriteError;
use mcap::records::MessageHeader;
use mcap::write::NoSeek;
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::Write;

/// The bag's topics: the node's (pose and odometry under its namespace,
/// [`Ros2BagOptions::namespace`]; these are the default's).
pub mod topic {
    pub const NAMESPACE: &str = "/lightpose";
    pub const POSE: &str = "/lightpose/pose";
    pub const ODOM: &str = "/lightpose/odom";
    pub const TF: &str = "/tf";
    pub const TF_STATIC: &str = "/tf_static";
    pub const DIAGNOSTICS: &str = "/diagnostics";
}

/// MCAP profile, schema and message encodings of a ROS 2 bag.
pub const PROFILE: &str = "ros2";
pub const SCHEMA_ENCODING: &str = "ros2msg";
pub const MESSAGE_ENCODING: &str = "cdr";
/// CDR little-endian (CDR_LE), options 0: the header of every message.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// The QoS a topic was offered with, as rosbag2 records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Qos {
    /// `sensor_data`: best effort, volatile (the poses).
    SensorData,
    /// Reliable, volatile (`/tf`, `/diagnostics`).
    Reliable,
    /// Reliable, transient local (`/tf_static`: late joiners get it).
    TransientLocal,
}

impl Qos {
    /// ROS 2's profile name (`[ros2.qos]`'s words).
    pub fn name(self) -> &'static str {
        match self {
            Qos::SensorData => "sensor_data",
            Qos::Reliable => "reliable",
            Qos::TransientLocal => "transient_local",
        }
    }

    /// The `offered_qos_profiles` value: a YAML list of one profile in the
    /// numeric form of rmw's enums (reliability 1 reliable, 2 best effort;
    /// durability 1 transient local, 2 volatile; history 1 keep last),
    /// durations 0 (none), as rosbag2 writes it and rosbags reads it.
    pub fn offered_profiles(self, depth: u32) -> String {
        let (reliability, durability) = match self {
            Qos::SensorData => (2, 2),
            Qos::Reliable => (1, 2),
            Qos::TransientLocal => (1, 1),
        };
        let zero = "\n    sec: 0\n    nsec: 0";
        format!(
            "- history: 1\n  depth: {depth}\n  reliability: {reliability}\n  durability: {durability}\n  \
             deadline:{zero}\n  lifespan:{zero}\n  liveliness: 1\n  liveliness_lease_duration:{zero}\n  \
             avoid_ros_namespace_conventions: false"
        )
    }
}

/// Each topic's QoS as the node offers it (`[ros2.qos]`; the default is
/// its default), and the keep-last depth of every topic but `/tf_static`
/// (1: its one message).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicQos {
    pub pose: Qos,
    pub odom: Qos,
    pub tf: Qos,
    pub diagnostics: Qos,
    pub depth: usize,
}

impl Default for TopicQos {
    fn default() -> Self {
        TopicQos {
            pose: Qos::SensorData,
            odom: Qos::SensorData,
            // tf2's TransformListener subscribes reliable: a best-effort
            // /tf would match no listener.
            tf: Qos::Reliable,
            diagnostics: Qos::Reliable,
            depth: 10,
        }
    }
}

/// What a [`Ros2Bag`] holds beside the poses.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2BagOptions {
    pub frames: Frames,
    /// The node's namespace (`[ros2] namespace`): the pose's and the
    /// odometry's topics are `<namespace>/pose` and `<namespace>/odom`.
    pub namespace: String,
    /// `[site]`: the beacon's (or station's) frame in `map`, written as
    /// `/tf_static` before the first pose, and again when the poses'
    /// frame changes (a station's calibration loaded).
    pub site: Option<SiteTf>,
    /// The QoS each topic's channel records as offered.
    pub qos: TopicQos,
    /// A chunk is closed once it holds this many bytes.
    pub chunk_bytes: u64,
    /// The bag's file name, for its `rosbag2` metadata record.
    pub file_name: String,
}

impl Default for Ros2BagOptions {
    fn default() -> Self {
        Ros2BagOptions {
            frames: Frames::default(),
            namespace: topic::NAMESPACE.into(),
            site: None,
            qos: TopicQos::default(),
            chunk_bytes: 1 << 20,
            file_name: "lightpose.mcap".into(),
        }
    }
}

/// Channel ids of a bag's topics.
struct Ids {
    pose: u16,
    odom: u16,
    tf: u16,
    tf_static: Option<u16>,
    diagnostics: Option<u16>,
}

/// A ROS 2 bag being written (see the module docs).
pub struct Ros2Bag<W: Write> {
    mcap: mcap::Writer<NoSeek<W>>,
    frames: Frames,
    site: Option<SiteTf>,
    /// The child of the `/tf_static` written last (the poses' frame then).
    site_child: Option<String>,
    qos: TopicQos,
    ids: Ids,
    /// One message's CDR, reused.
    buf: Vec<u8>,
    seq: u32,
    estimates: u64,
    file_name: String,
    declared: Vec<info::Declared>,
    /// First and last log time written.
    span: Option<(u64, u64)>,
}

impl<W: Write> Ros2Bag<W> {
    /// Start a bag on `sink`: magic, header (profile `ros2`), the schemas
    /// and channels of pose, odometry and `/tf` (`/tf_static` and
    /// `/diagnostics` are declared at their first message).
    pub fn new(sink: W, opts: &Ros2BagOptions) -> Result<Self, WriteError> {
        let wopts = mcap::WriteOptions::new()
            .compression(None)
            .chunk_size(Some(opts.chunk_bytes))
            .disable_seeking(true)
            .profile(PROFILE)
            .library(format!(
                "lightpose-logs/{} ({})",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            ));
        let mut mcap = wopts.create(NoSeek::new(sink))?;
        let mut declared = Vec::new();
        let q = opts.qos;
        let depth = q.depth as u32;
        let mut d = |t, topic, qos| declare(&mut mcap, &mut declared, t, topic, (qos, depth));
        let ns = opts.namespace.trim_end_matches('/');
        let pose = d(POSE_TYPE, format!("{ns}/pose"), q.pose)?;
        let odom = d(ODOM_TYPE, format!("{ns}/odom"), q.odom)?;
        let tf = d(TF_TYPE, topic::TF.into(), q.tf)?;
        Ok(Ros2Bag {
            mcap,
            frames: opts.frames.clone(),
            site: opts.site,
            site_child: None,
            qos: q,
            ids: Ids {
                pose,
                odom,
                tf,
                tf_static: None,
                diagnostics: None,
            },
            buf: Vec::with_capacity(1024),
            seq: 0,
            estimates: 0,
            file_name: opts.file_name.clone(),
            declared,
            span: None,
        })
    }

    /// One `ok` estimate as the node publishes it: pose, odometry and its
    /// `/tf`, at `log_time` (nanoseconds, the frame's capture); before it,
    /// with a site, `/tf_static` when its frame is new.
    pub fn write_estimate(&mut self, s: &Solved, log_time: u64) -> Result<(), WriteError> {
        if let Some(site) = self.site {
            let parent = s.parent(&self.frames);
            if self.site_child.as_deref() != Some(parent) {
                let tf = site.message(&self.frames, parent, s.stamp);
                self.site_child = Some(parent.to_string());
                self.write_site(&tf, log_time)?;
            }
        }
        let (pose, odom, tf) = (self.ids.pose, self.ids.odom, self.ids.tf);
        self.write(pose, log_time, &s.pose(&self.frames))?;
        self.write(odom, log_time, &s.odometry(&self.frames))?;
        self.write(tf, log_time, &s.tf(&self.frames))?;
        self.seq = self.seq.wrapping_add(1);
        self.estimates += 1;
        Ok(())
    }

    /// The site's `/tf_static` (`map` → beacon, [`crate::ros2msg::site_tf`]).
    pub fn write_site(&mut self, tf: &TFMessage, log_time: u64) -> Result<(), WriteError> {
        let id = self.lazy(
            |ids| &mut ids.tf_static,
            &TF_TYPE,
            topic::TF_STATIC,
            // The node's: its one message, kept for late joiners.
            (Qos::TransientLocal, 1),
        )?;
        self.write(id, log_time, tf)
    }

    /// One `/diagnostics` message (a STATUS as the node sends it).
    pub fn write_diagnostics(
        &mut self,
        d: &DiagnosticArray,
        log_time: u64,
    ) -> Result<(), WriteError> {
        let qos = (self.qos.diagnostics, self.qos.depth as u32);
        let id = self.lazy(
            |ids| &mut ids.diagnostics,
            &DIAG_TYPE,
            topic::DIAGNOSTICS,
            qos,
        )?;
        self.write(id, log_time, d)
    }

    /// The id of a channel declared at its first message.
    fn lazy(
        &mut self,
        slot: impl FnOnce(&mut Ids) -> &mut Option<u16>,
        t: &TypeName,
        topic: &'static str,
        qos: (Qos, u32),
    ) -> Result<u16, WriteError> {
        let slot = slot(&mut self.ids);
        if let Some(id) = *slot {
            return Ok(id);
        }
        let id = declare(&mut self.mcap, &mut self.declared, *t, topic.into(), qos)?;
        *slot = Some(id);
        Ok(id)
    }

    fn write<M: Serialize>(&mut self, id: u16, log_time: u64, m: &M) -> Result<(), WriteError> {
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_LE_HEADER);
        // CDR aligns relative to the byte after the encapsulation header,
        // where this serializer starts counting.
        cdr_encoding::to_writer::<M, byteorder::LittleEndian, _>(&mut self.buf, m)
            .map_err(|e| WriteError::Io(std::io::Error::other(format!("CDR: {e}"))))?;
        let h = MessageHeader {
            channel_id: id,
            sequence: self.seq,
            log_time,
            publish_time: log_time,
        };
        self.mcap.write_to_known_channel(&h, &self.buf)?;
        if let Some(d) = self.declared.iter_mut().find(|d| d.id == id) {
            d.count += 1;
        }
        self.span = Some(self.span.map_or((log_time, log_time), |(a, b)| {
            (a.min(log_time), b.max(log_time))
        }));
        Ok(())
    }

    /// A metadata record (the recorder's clock pairs): rosbag2 readers
    /// pass over records other than their own.
    pub fn write_metadata(
        &mut self,
        name: &str,
        pairs: BTreeMap<String, String>,
    ) -> Result<(), WriteError> {
        self.mcap.write_metadata(&mcap::records::Metadata {
            name: name.into(),
            metadata: pairs,
        })?;
        Ok(())
    }

    pub fn estimates_written(&self) -> u64 {
        self.estimates
    }

    /// Close the open chunk and flush the sink.
    pub fn flush(&mut self) -> Result<(), WriteError> {
        self.mcap.flush()?;
        Ok(())
    }

    /// Write the summary and footer, flush, and hand the sink back.
    /// The `rosbag2` metadata record ([`info`]) goes last, before the
    /// summary.
    pub fn finish(mut self) -> Result<W, WriteError> {
        let yaml = info::serialized_metadata(&self.file_name, &self.declared, self.span);
        let mut meta = BTreeMap::new();
        meta.insert(info::KEY.to_string(), yaml);
        self.mcap.write_metadata(&mcap::records::Metadata {
            name: info::RECORD.into(),
            metadata: meta,
        })?;
        self.mcap.finish()?;
        let mut sink = self.mcap.into_inner().into_inner();
        sink.flush()?;
        Ok(sink)
    }
}

/// A topic's schema (the type's complete definition) and channel, noted
/// in `declared`.
fn declare<W: Write>(
    mcap: &mut mcap::Writer<NoSeek<W>>,
    declared: &mut Vec<info::Declared>,
    t: TypeName,
    topic: String,
    (qos, depth): (Qos, u32),
) -> Result<u16, WriteError> {
    let text = msgdef::definition(&t).ok_or_else(|| {
        WriteError::Io(std::io::Error::other(format!(
            "{}: no message definition",
            t.ros()
        )))
    })?;
    let sid = mcap.add_schema(&t.ros(), SCHEMA_ENCODING, text.as_bytes())?;
    let mut meta = BTreeMap::new();
    meta.insert(
        "offered_qos_profiles".to_string(),
        qos.offered_profiles(depth),
    );
    let id = mcap.add_channel(sid, &topic, MESSAGE_ENCODING, &meta)?;
    declared.push(info::Declared {
        id,
        topic,
        type_name: t,
        qos,
        depth,
        count: 0,
    });
    Ok(id)
}

/// Nanoseconds of a ROS time (MCAP's log time of a message stamped so).
pub fn nanos(t: &crate::ros2msg::Time) -> u64 {
    t.sec.max(0) as u64 * 1_000_000_000 + t.nanosec as u64
}

#[cfg(test)]
mod tests;
