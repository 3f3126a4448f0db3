//! The ROS 2 node (`[ros2]`, docs/ros2.md): each `ok` estimate as
//! `<ns>/pose`, `<ns>/odom` and `/tf`, the site as `/tf_static`, each STATUS
//! as `/diagnostics`, through a DDS participant of our own (ros2-client on
//! rustdds: pure Rust, no ROS install). As for the web page, no subscriber
//! can slow a frame:
//! 1. the frame thread ([`Ros2Out::emit`]) copies the estimate into a
//!    bounded queue whose slots were allocated at start; a full queue drops
//!    it (counted, `handoff_dropped`);
//! 2. the node's thread builds the messages and publishes them: DDS
//!    serialization, its allocations and a reliable writer's waits happen
//!    there.
//!
//! Only `ok` estimates with a complete pose and finite 1σ become messages
//! (`lightpose_logs::ros2msg::solve`); the others are counted (`not_ok`)
//! and seen in `/diagnostics`.

use super::{Output, StatusTap};
use crate::config::ros2::{QosKind, Ros2};
use crate::engine::Acquired;
use crate::inputs::attitude::AttitudeCell;
use lightpose_core::PoseEstimate;
use lightpose_logs::ros2msg::{self as msg, Frames};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Context, MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use serde::Serialize;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;

/// Estimates that may wait for the node's thread (a reliable writer may
/// wait up to [`WhenFull`]'s 100 ms for its window: 10 frames at 100 Hz).
const HANDOFF_QUEUE: usize = 32;

/// A reliable writer's wait for its window, at most: then the sample is
/// dropped and counted, the thread goes on.
const RELIABLE_WAIT: std::time::Duration = std::time::Duration::from_millis(20);

/// What reaches the node's thread. The estimate goes by value: boxing it
/// would allocate on the frame thread.
#[allow(clippy::large_enum_variant)]
enum Item {
    /// All Copy: no allocation on the frame thread.
    Estimate(PoseEstimate, f64),
    /// A STATUS (JSON), from the async side.
    Status(Vec<u8>),
}

/// What the node did, for STATUS's `ros2` object.
#[derive(Default)]
pub struct Ros2Stats {
    pub handed: AtomicU64,
    pub handoff_dropped: AtomicU64,
    /// Estimates published as pose, odom and tf.
    pub published: AtomicU64,
    /// Estimates not `ok` (or incomplete): no pose sent.
    pub not_ok: AtomicU64,
    /// Writes refused by DDS (a reliable window full past its wait).
    pub write_errors: AtomicU64,
    pub diagnostics: AtomicU64,
    pub status_dropped: AtomicU64,
}

/// The node as the daemon holds it: its counters, its queue's sending end
/// for STATUS, its thread.
pub struct Ros2Node {
    pub stats: Arc<Ros2Stats>,
    status_tx: SyncSender<Item>,
    pub namespace: String,
    pub domain_id: u16,
    /// The IMU input's cell (`imu_topic`), read by the frame thread.
    pub imu: Option<Arc<AttitudeCell>>,
    /// Raised when the daemon lets go of the node: the IMU thread ends.
    closed: Arc<AtomicBool>,
}

impl Drop for Ros2Node {
    fn drop(&mut self) {
        self.closed.store(true, Relaxed);
    }
}

impl Ros2Node {
    /// STATUS's `ros2` object.
    pub fn report(&self) -> Value {
        let s = &self.stats;
        json!({
            "enabled": true,
            "domain_id": self.domain_id,
            "namespace": self.namespace,
            "handed": s.handed.load(Relaxed),
            "handoff_dropped": s.handoff_dropped.load(Relaxed),
            "published": s.published.load(Relaxed),
            "not_ok": s.not_ok.load(Relaxed),
            "write_errors": s.write_errors.load(Relaxed),
            "diagnostics": s.diagnostics.load(Relaxed),
        })
    }
}

impl StatusTap for Arc<Ros2Node> {
    fn status(&self, json: &[u8]) {
        if self
            .status_tx
            .try_send(Item::Status(json.to_vec()))
            .is_err()
        {
            self.stats.status_dropped.fetch_add(1, Relaxed);
        }
    }
}

/// The frame thread's end.
pub struct Ros2Out {
    tx: Option<SyncSender<Item>>,
    stats: Arc<Ros2Stats>,
    /// Not joined: the thread ends when the frame thread's end and the
    /// STATUS end are both dropped.
    _join: JoinHandle<()>,
}

impl Output for Ros2Out {
    #[inline]
    fn emit(&mut self, frame: &Acquired, est: &PoseEstimate) {
        let Some(tx) = &self.tx else { return };
        match tx.try_send(Item::Estimate(*est, frame.wall_unix)) {
            Ok(()) => self.stats.handed.fetch_add(1, Relaxed),
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.stats.handoff_dropped.fetch_add(1, Relaxed)
            }
        };
    }

    fn finish(&mut self) {
        self.tx = None;
    }
}

/// Why the node could not start.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    #[error("ros2: {0}")]
    Dds(String),
    #[error("ros2: node thread: {0}")]
    Thread(#[from] std::io::Error),
}

fn dds<E: std::fmt::Debug>(what: &str) -> impl Fn(E) -> Ros2Error + '_ {
    move |e| Ros2Error::Dds(format!("{what}: {e:?}"))
}

fn profile(kind: QosKind, depth: usize) -> QosProfile {
    let p = QosProfile::publisher_default().history(History::KeepLast { depth });
    match kind {
        QosKind::SensorData => p.reliability_best_effort().durability(Durability::Volatile),
        QosKind::Reliable => p
            .reliability_reliable(WhenFull::Wait(RELIABLE_WAIT))
            .durability(Durability::Volatile),
        QosKind::TransientLocal => p
            .reliability_reliable(WhenFull::Wait(RELIABLE_WAIT))
            .durability(Durability::TransientLocal),
    }
}

/// The participant, its node and its writers, owned by the node's thread.
struct Writers {
    // Kept: dropping them ends the participant.
    _context: Context,
    _node: ros2_client::dds::Node,
    pose: ros2_client::dds::Publisher<msg::PoseWithCovarianceStamped>,
    odom: ros2_client::dds::Publisher<msg::Odometry>,
    tf: ros2_client::dds::Publisher<msg::TFMessage>,
    tf_static: ros2_client::dds::Publisher<msg::TFMessage>,
    diagnostics: ros2_client::dds::Publisher<msg::DiagnosticArray>,
    imu: Option<ros2_client::dds::Subscription<msg::Imu>>,
}

fn writers(cfg: &Ros2) -> Result<Writers, Ros2Error> {
    let mut b = ros2_client::dds::rustdds::DomainParticipantBuilder::new(cfg.domain_id);
    if !cfg.networks.is_empty() {
        b = b.with_only_networks(cfg.networks.iter().copied());
    }
    let participant = b.build().map_err(dds("participant"))?;
    let context = Context::from_domain_participant(participant).map_err(dds("context"))?;
    let (ns, name) = (cfg.namespace.as_str(), cfg.node_name.as_str());
    let mut node = context
        .new_node(
            NodeName::new(ns, name).map_err(dds("node name"))?,
            NodeOptions::new().enable_rosout(false),
        )
        .map_err(dds("node"))?;
    let q = &cfg.qos;
    let topic = |ns: &str, name: &str, t: msg::TypeName, kind: QosKind, depth: usize| {
        let qos = profile(kind, depth);
        let n = Name::new(ns, name).map_err(dds("topic name"))?;
        let topic = node
            .create_topic(&n, MessageTypeName::new(t.package, t.name), &qos)
            .map_err(dds("topic"))?;
        Ok::<_, Ros2Error>((topic, qos))
    };
    let (pose_t, pose_q) = topic(ns, "pose", msg::POSE_TYPE, q.pose, q.depth)?;
    let (odom_t, odom_q) = topic(ns, "odom", msg::ODOM_TYPE, q.odom, q.depth)?;
    let (tf_t, tf_q) = topic("/", "tf", msg::TF_TYPE, q.tf, q.depth)?;
    let (st_t, st_q) = topic("/", "tf_static", msg::TF_TYPE, QosKind::TransientLocal, 1)?;
    let (d_t, d_q) = topic("/", "diagnostics", msg::DIAG_TYPE, q.diagnostics, q.depth)?;
    let imu = match &cfg.imu {
        Some(i) => {
            let (ns, name) = i.topic.rsplit_once('/').unwrap_or(("/", &i.topic));
            let ns = if ns.is_empty() { "/" } else { ns };
            // Best effort: it matches a reliable writer too.
            let (t, q) = topic(ns, name, msg::IMU_TYPE, QosKind::SensorData, 10)?;
            Some(node.create_subscription(&t, Some(q)).map_err(dds("imu"))?)
        }
        None => None,
    };
    Ok(Writers {
        imu,
        pose: node
            .create_publisher(&pose_t, Some(pose_q))
            .map_err(dds("pose"))?,
        odom: node
            .create_publisher(&odom_t, Some(odom_q))
            .map_err(dds("odom"))?,
        tf: node
            .create_publisher(&tf_t, Some(tf_q))
            .map_err(dds("tf"))?,
        tf_static: node
            .create_publisher(&st_t, Some(st_q))
            .map_err(dds("tf_static"))?,
        diagnostics: node
            .create_publisher(&d_t, Some(d_q))
            .map_err(dds("diagnostics"))?,
        _node: node,
        _context: context,
    })
}

/// The site's transform for `/tf_static`, when `[site]` is given.
pub fn site_tf(frames: &Frames, site: &lightpose_vehicle::Site) -> msg::TFMessage {
    let n = site.beacon_ned.0;
    // With no position in the autopilot's frame, the beacon is at its depth.
    let ned = if n == [0.0; 3] {
        [0.0, 0.0, site.beacon_depth_m]
    } else {
        n
    };
    let now = msg::Time::from_unix(crate::status::unix_now());
    msg::site_tf(frames, site.axis_heading, ned, now)
}

/// Open the participant (refused here, before the frame thread, if it
/// cannot be) and start the node's thread.
pub fn start(
    cfg: &Ros2,
    site: Option<&lightpose_vehicle::Site>,
) -> Result<(Ros2Out, Arc<Ros2Node>), Ros2Error> {
    let (tx, rx) = sync_channel::<Item>(HANDOFF_QUEUE);
    let stats = Arc::new(Ros2Stats::default());
    let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel::<Result<(), Ros2Error>>(1);
    let (c, st, site_msg) = (
        cfg.clone(),
        stats.clone(),
        site.map(|s| site_tf(&cfg.frames, s)),
    );
    let imu_cell = cfg.imu.as_ref().map(|_| Arc::new(AttitudeCell::default()));
    let closed = Arc::new(AtomicBool::new(false));
    let (cell, shut) = (imu_cell.clone(), closed.clone());
    let join = std::thread::Builder::new()
        .name("lightposed-ros2".into())
        .spawn(move || match writers(&c) {
            Ok(mut w) => {
                let imu = match (w.imu.take(), cell, &c.imu) {
                    (Some(sub), Some(cell), Some(i)) => {
                        spawn_imu(sub, cell, i.beacon_axis_heading_deg, shut).map(Some)
                    }
                    _ => Ok(None),
                };
                if let Err(e) = imu {
                    let _ = ready_tx.send(Err(Ros2Error::Thread(e)));
                    return;
                }
                let _ = ready_tx.send(Ok(()));
                run(&rx, &w, &c.frames, &st, site_msg);
            }
            Err(e) => {
                let _ = ready_tx.send(Err(e));
            }
        })?;
    match ready_rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(e),
        Err(_) => return Err(Ros2Error::Dds("node thread ended at start".into())),
    }
    tracing::info!(
        "ros2: node {}/{} on domain {}: {}/pose, {}/odom, /tf{}, /diagnostics",
        cfg.namespace.trim_end_matches('/'),
        cfg.node_name,
        cfg.domain_id,
        cfg.namespace.trim_end_matches('/'),
        cfg.namespace.trim_end_matches('/'),
        if site.is_some() { ", /tf_static" } else { "" },
    );
    let node = Arc::new(Ros2Node {
        stats: stats.clone(),
        status_tx: tx.clone(),
        namespace: cfg.namespace.clone(),
        domain_id: cfg.domain_id,
        imu: imu_cell,
        closed,
    });
    let out = Ros2Out {
        tx: Some(tx),
        stats,
        _join: join,
    };
    Ok((out, node))
}

/// The IMU thread: each sample into the attitude cell, until `closed`.
fn spawn_imu(
    sub: ros2_client::dds::Subscription<msg::Imu>,
    cell: Arc<AttitudeCell>,
    heading_deg: f64,
    closed: Arc<AtomicBool>,
) -> std::io::Result<JoinHandle<()>> {
    std::thread::Builder::new()
        .name("lightposed-ros2-imu".into())
        .spawn(move || {
            while !closed.load(Relaxed) {
                match sub.take() {
                    Ok(Some((m, _))) => crate::inputs::ros2::take(&cell, Ok(m), heading_deg),
                    // Polled: an IMU at 100 Hz is read within 2 ms of its sample.
                    Ok(None) => std::thread::sleep(std::time::Duration::from_millis(2)),
                    Err(e) => crate::inputs::ros2::take(&cell, Err(format!("{e:?}")), heading_deg),
                }
            }
        })
}

fn write<M: Serialize + std::fmt::Debug>(
    p: &ros2_client::dds::Publisher<M>,
    m: M,
    stats: &Ros2Stats,
) -> bool {
    match p.publish(m) {
        Ok(()) => true,
        Err(e) => {
            if stats.write_errors.fetch_add(1, Relaxed) == 0 {
                tracing::warn!(
                    "ros2: a write refused (counted in STATUS ros2.write_errors): {e:?}"
                );
            }
            false
        }
    }
}

/// The node's thread: until the frame thread's end and the STATUS end
/// are both gone.
fn run(
    rx: &Receiver<Item>,
    w: &Writers,
    frames: &Frames,
    stats: &Ros2Stats,
    site: Option<msg::TFMessage>,
) {
    if let Some(s) = site {
        write(&w.tf_static, s, stats);
    }
    let mut last = LastEstimate::default();
    while let Ok(item) = rx.recv() {
        match item {
            Item::Estimate(est, wall) => {
                last.observe(&est);
                let Some(s) = msg::solve(&est, wall) else {
                    stats.not_ok.fetch_add(1, Relaxed);
                    continue;
                };
                let ok = write(&w.pose, s.pose(frames), stats)
                    & write(&w.odom, s.odometry(frames), stats)
                    & write(&w.tf, s.tf(frames), stats);
                if ok {
                    stats.published.fetch_add(1, Relaxed);
                }
            }
            Item::Status(json) => {
                if write(&w.diagnostics, diagnostics(&json, &last), stats) {
                    stats.diagnostics.fetch_add(1, Relaxed);
                }
            }
        }
    }
}

/// The latest estimate's status, for the diagnostics' level.
#[derive(Default)]
struct LastEstimate {
    status: Option<lightpose_core::Status>,
    seq: u64,
}

impl LastEstimate {
    fn observe(&mut self, est: &PoseEstimate) {
        self.status = Some(est.status);
        self.seq = est.seq;
    }
}

/// One DiagnosticStatus from a STATUS: its scalars flattened to `a.b`
/// keys; OK while the latest estimate is `ok`, WARN otherwise, ERROR
/// before any frame.
fn diagnostics(json: &[u8], last: &LastEstimate) -> msg::DiagnosticArray {
    let mut values = Vec::new();
    if let Ok(v) = serde_json::from_slice::<Value>(json) {
        flatten("", &v, &mut values, 0);
    }
    let (level, message) = match last.status {
        Some(lightpose_core::Status::Ok) => (msg::DIAG_OK, format!("ok (frame {})", last.seq)),
        Some(s) => (
            msg::DIAG_WARN,
            format!("{} (frame {})", s.as_str(), last.seq),
        ),
        None => (msg::DIAG_ERROR, "no frame yet".to_string()),
    };
    msg::DiagnosticArray {
        header: msg::Header {
            stamp: msg::Time::from_unix(crate::status::unix_now()),
            frame_id: String::new(),
        },
        status: vec![msg::DiagnosticStatus {
            level,
            name: "lightposed".into(),
            message,
            hardware_id: "lightpose".into(),
            values,
        }],
    }
}

fn flatten(prefix: &str, v: &Value, out: &mut Vec<msg::KeyValue>, depth: usize) {
    let key = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        Value::Object(m) if depth < 3 => {
            for (k, x) in m {
                flatten(&key(k), x, out, depth + 1);
            }
        }
        Value::Object(_) | Value::Array(_) => {}
        Value::String(s) => out.push(msg::KeyValue {
            key: prefix.to_string(),
            value: s.clone(),
        }),
        other => out.push(msg::KeyValue {
            key: prefix.to_string(),
            value: other.to_string(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diagnostics_flatten_status_and_say_the_last_status() {
        let status = br#"{"class":"STATUS","frames":12,"latency":{"p99_ms":0.2},"backend":{"kind":"sim"},"list":[1]}"#;
        let mut last = LastEstimate::default();
        let d = diagnostics(status, &last);
        assert_eq!(d.status[0].level, msg::DIAG_ERROR);
        last.status = Some(lightpose_core::Status::Ok);
        last.seq = 12;
        let d = diagnostics(status, &last);
        let s = &d.status[0];
        assert_eq!(
            (s.level, s.message.as_str()),
            (msg::DIAG_OK, "ok (frame 12)")
        );
        let kv: Vec<(&str, &str)> = s
            .values
            .iter()
            .map(|k| (k.key.as_str(), k.value.as_str()))
            .collect();
        assert!(kv.contains(&("frames", "12")), "{kv:?}");
        assert!(kv.contains(&("latency.p99_ms", "0.2")), "{kv:?}");
        assert!(kv.contains(&("backend.kind", "sim")), "{kv:?}");
        assert!(!kv.iter().any(|(k, _)| *k == "list"));
        // Not JSON: no values, still a diagnostic.
        assert!(diagnostics(b"garbage", &last).status[0].values.is_empty());
    }
}
