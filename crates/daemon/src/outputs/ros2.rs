//! The ROS 2 node (`[ros2]`, docs/ros2.md): each `ok` estimate as
//! `<ns>/pose`, `<ns>/odom` and `/tf`, the site as `/tf_static`, each STATUS
//! as `/diagnostics`, through a DDS participant of our own (ros2-client on
//! rustdds: pure Rust, no ROS install). As for the web page, no subscriber
//! can slow a frame:
//! 1. the frame thread ([`Ros2Out::emit`]) copies the estimate into a
//!    lock-free ring whose slots were allocated at start ([`super::spsc`]),
//!    waking the node only when it finds it in a long sleep (counted,
//!    `woken`); a full ring drops it (counted, `handoff_dropped`);
//! 2. the node's thread polls the ring, often when the next estimate is
//!    due and sleeps otherwise ([`spsc::Cadence`]; capture → wire p99
//!    goal 1 ms, docs/ros2.md), builds the messages and publishes them:
//!    DDS serialization, its allocations and a reliable writer's waits
//!    happen there. STATUS comes on a channel of
//!    its own (the async side may block a moment, the frame thread not).
//!
//! The depth, DVL and IMU subscriptions are read by a thread of their own
//! (crate::inputs::ros2_readings).
//!
//! Only `ok` estimates with a complete pose and finite 1σ become messages
//! (`lightpose_logs::ros2msg::solve`); the others are counted (`not_ok`)
//! and seen in `/diagnostics`.

// `ros2` alone would be ros2-client's oldest distro (Galactic's GID).
#[cfg(not(any(feature = "jazzy", feature = "humble")))]
compile_error!("the ros2 feature needs its distro: --features jazzy (the default) or humble");

use super::spsc;
use super::{Output, StatusTap};
use crate::config::ros2::{QosKind, Ros2};
use crate::config::ros2in::DepthKind;
use crate::engine::Acquired;
use crate::inputs::attitude::AttitudeCell;
use crate::inputs::ros2_readings::{DepthSub, OtherTypes, Ros2Readings, Subs};
use lightpose_core::PoseEstimate;
use lightpose_logs::ros2msg::{self as msg, Frames};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Context, MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use serde::Serialize;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError};
use std::sync::Arc;
use std::thread::JoinHandle;

/// Estimates that may wait for the node's thread (a reliable writer may
/// wait up to [`RELIABLE_WAIT`] for its window, ×3 writers: 6 frames at
/// 100 Hz).
const HANDOFF_QUEUE: usize = 32;

/// STATUS items that may wait (one a second).
const STATUS_QUEUE: usize = 4;

/// A reliable writer's wait for its window, at most: then the sample is
/// dropped and counted, the thread goes on.
const RELIABLE_WAIT: std::time::Duration = std::time::Duration::from_millis(20);

/// What the frame thread hands over: all Copy, so no allocation there.
type Handed = (PoseEstimate, f64);

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
    /// Estimates that found the node asleep away from their cadence and
    /// woke it (the frame thread paid a wake-up: a few in a thousand).
    pub woken: AtomicU64,
    /// Writers of another type on an input's topic (discovery's names).
    pub other_type_writers: Arc<std::sync::Mutex<Vec<String>>>,
}

/// The node as the daemon holds it: its counters, its queue's sending end
/// for STATUS, its thread.
pub struct Ros2Node {
    pub stats: Arc<Ros2Stats>,
    status_tx: SyncSender<Vec<u8>>,
    pub namespace: String,
    pub domain_id: u16,
    /// The IMU input's cell (`imu_topic`), read by the frame thread.
    pub imu: Option<Arc<AttitudeCell>>,
    /// The depth and DVL inputs' hub and counters (`depth_topic`,
    /// `dvl_topic`), attached from by the frame thread.
    pub readings: Option<Arc<Ros2Readings>>,
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
            "distro": ros2_client::COMPILED_ROS_DISTRO.as_str(),
            "domain_id": self.domain_id,
            "namespace": self.namespace,
            "handed": s.handed.load(Relaxed),
            "handoff_dropped": s.handoff_dropped.load(Relaxed),
            "published": s.published.load(Relaxed),
            "not_ok": s.not_ok.load(Relaxed),
            "write_errors": s.write_errors.load(Relaxed),
            "diagnostics": s.diagnostics.load(Relaxed),
            "status_dropped": s.status_dropped.load(Relaxed),
            "woken": s.woken.load(Relaxed),
            "other_type_writers": s
                .other_type_writers
                .lock()
                .map_or_else(|p| p.into_inner().clone(), |v| v.clone()),
            "inputs": self.readings.as_ref().map_or(json!({}), |r| r.report()),
        })
    }
}

impl StatusTap for Arc<Ros2Node> {
    fn status(&self, json: &[u8]) {
        if self.status_tx.try_send(json.to_vec()).is_err() {
            self.stats.status_dropped.fetch_add(1, Relaxed);
        }
    }
}

/// The frame thread's end.
pub struct Ros2Out {
    tx: Option<spsc::Producer<Handed>>,
    stats: Arc<Ros2Stats>,
    /// Not joined: the thread ends when the frame thread's end and the
    /// STATUS end are both dropped.
    _join: JoinHandle<()>,
}

impl Output for Ros2Out {
    #[inline]
    fn emit(&mut self, frame: &Acquired, est: &PoseEstimate) {
        let Some(tx) = &mut self.tx else { return };
        match tx.push((*est, frame.wall_unix)) {
            Ok(()) => self.stats.handed.fetch_add(1, Relaxed),
            Err(_) => self.stats.handoff_dropped.fetch_add(1, Relaxed),
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
    context: Context,
    _node: ros2_client::dds::Node,
    pose: ros2_client::dds::Publisher<msg::PoseWithCovarianceStamped>,
    odom: ros2_client::dds::Publisher<msg::Odometry>,
    tf: ros2_client::dds::Publisher<msg::TFMessage>,
    tf_static: ros2_client::dds::Publisher<msg::TFMessage>,
    diagnostics: ros2_client::dds::Publisher<msg::DiagnosticArray>,
    imu: Option<ros2_client::dds::Subscription<msg::Imu>>,
    depth: Option<DepthSub>,
    dvl: Option<ros2_client::dds::Subscription<msg::TwistWithCovarianceStamped>>,
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
    // Best effort: it matches a reliable writer too.
    let sub = |full: &str, t: msg::TypeName| {
        let (ns, name) = full.rsplit_once('/').unwrap_or(("/", full));
        let ns = if ns.is_empty() { "/" } else { ns };
        topic(ns, name, t, QosKind::SensorData, 10)
    };
    // The topics first (they borrow the node), then the subscriptions.
    let imu_t = cfg
        .imu
        .as_ref()
        .map(|i| sub(&i.topic, msg::IMU_TYPE))
        .transpose()?;
    let depth_t = match &cfg.depth {
        Some(d) => Some((sub(&d.topic, depth_type(d.kind))?, d.kind)),
        None => None,
    };
    let dvl_t = cfg
        .dvl
        .as_ref()
        .map(|d| sub(&d.topic, msg::TWIST_TYPE))
        .transpose()?;
    let imu = match imu_t {
        Some((t, q)) => Some(node.create_subscription(&t, Some(q)).map_err(dds("imu"))?),
        None => None,
    };
    let depth = match depth_t {
        Some(((t, q), DepthKind::Pose)) => Some(DepthSub::Pose(
            node.create_subscription(&t, Some(q))
                .map_err(dds("depth"))?,
        )),
        Some(((t, q), k)) => Some(DepthSub::Pressure(
            node.create_subscription(&t, Some(q))
                .map_err(dds("depth"))?,
            k,
        )),
        None => None,
    };
    let dvl = match dvl_t {
        Some((t, q)) => Some(node.create_subscription(&t, Some(q)).map_err(dds("dvl"))?),
        None => None,
    };
    Ok(Writers {
        imu,
        depth,
        dvl,
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
        context,
    })
}

/// The message a depth input reads.
fn depth_type(kind: DepthKind) -> msg::TypeName {
    match kind {
        DepthKind::Pose => msg::POSE_TYPE,
        DepthKind::FluidPressure { .. } => msg::FLUID_PRESSURE_TYPE,
    }
}

/// The input topics and the types they are read as (DDS names).
fn input_topics(cfg: &Ros2) -> Vec<(String, String)> {
    let mut v = Vec::new();
    if let Some(i) = &cfg.imu {
        v.push(OtherTypes::topic(&i.topic, msg::IMU_TYPE));
    }
    if let Some(d) = &cfg.depth {
        v.push(OtherTypes::topic(&d.topic, depth_type(d.kind)));
    }
    if let Some(d) = &cfg.dvl {
        v.push(OtherTypes::topic(&d.topic, msg::TWIST_TYPE));
    }
    v
}

/// Open the participant (refused here, before the frame thread, if it
/// cannot be) and start the node's thread (and its input thread, with
/// `imu_topic`, `depth_topic` or `dvl_topic`).
pub fn start(
    cfg: &Ros2,
    site: Option<&lightpose_vehicle::Site>,
) -> Result<(Ros2Out, Arc<Ros2Node>), Ros2Error> {
    let (tx, rx) = spsc::ring::<Handed>(HANDOFF_QUEUE);
    let (status_tx, status_rx) = sync_channel::<Vec<u8>>(STATUS_QUEUE);
    let stats = Arc::new(Ros2Stats::default());
    let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel::<Result<(), Ros2Error>>(1);
    let (c, st, site_msg) = (
        cfg.clone(),
        stats.clone(),
        site.map(crate::config::ros2::site_tf),
    );
    let imu_cell = cfg.imu.as_ref().map(|_| Arc::new(AttitudeCell::default()));
    let readings = Ros2Readings::new(cfg.depth.clone(), cfg.dvl.clone(), site).map(Arc::new);
    let closed = Arc::new(AtomicBool::new(false));
    let (cell, shut, rd) = (imu_cell.clone(), closed.clone(), readings.clone());
    let join = std::thread::Builder::new()
        .name("lightposed-ros2".into())
        .spawn(move || match writers(&c) {
            Ok(mut w) => {
                let watch = input_topics(&c);
                let subs = Subs {
                    watch: (!watch.is_empty()).then(|| OtherTypes {
                        participant: w.context.domain_participant(),
                        topics: watch,
                        found: st.other_type_writers.clone(),
                    }),
                    imu: match (w.imu.take(), cell, &c.imu) {
                        (Some(sub), Some(cell), Some(i)) => {
                            Some((sub, cell, i.beacon_axis_heading_deg))
                        }
                        _ => None,
                    },
                    depth: w.depth.take(),
                    dvl: w.dvl.take(),
                    readings: rd,
                };
                if let Err(e) = crate::inputs::ros2_readings::spawn(subs, shut) {
                    let _ = ready_tx.send(Err(Ros2Error::Thread(e)));
                    return;
                }
                let _ = ready_tx.send(Ok(()));
                run(rx, &status_rx, &w, &c.frames, &st, site_msg);
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
        "ros2: node {}/{} ({}) on domain {}: {}/pose, {}/odom, /tf{}, /diagnostics",
        cfg.namespace.trim_end_matches('/'),
        cfg.node_name,
        ros2_client::COMPILED_ROS_DISTRO,
        cfg.domain_id,
        cfg.namespace.trim_end_matches('/'),
        cfg.namespace.trim_end_matches('/'),
        if site.is_some() { ", /tf_static" } else { "" },
    );
    let node = Arc::new(Ros2Node {
        stats: stats.clone(),
        status_tx,
        namespace: cfg.namespace.clone(),
        domain_id: cfg.domain_id,
        imu: imu_cell,
        readings,
        closed,
    });
    let out = Ros2Out {
        tx: Some(tx),
        stats,
        _join: join,
    };
    Ok((out, node))
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

/// `/tf_static` of the site, and the frame it placed last: the beacon's
/// at start, a station's once its poses come (its calibration loaded).
struct SiteStatic {
    site: Option<msg::SiteTf>,
    child: Option<String>,
}

impl SiteStatic {
    /// Publish the site's transform of `child` unless it was the last.
    fn place(&mut self, child: &str, w: &Writers, frames: &Frames, stats: &Ros2Stats) {
        let Some(site) = self.site else { return };
        if self.child.as_deref() == Some(child) {
            return;
        }
        let now = msg::Time::from_unix(crate::status::unix_now());
        write(&w.tf_static, site.message(frames, child, now), stats);
        self.child = Some(child.to_string());
    }
}

/// One estimate as pose, odom and tf (or counted as not `ok`).
fn publish(
    est: &PoseEstimate,
    wall: f64,
    w: &Writers,
    frames: &Frames,
    stats: &Ros2Stats,
    site: &mut SiteStatic,
) {
    let Some(s) = msg::solve(est, wall) else {
        stats.not_ok.fetch_add(1, Relaxed);
        return;
    };
    site.place(s.parent(frames), w, frames, stats);
    let ok = write(&w.pose, s.pose(frames), stats)
        & write(&w.odom, s.odometry(frames), stats)
        & write(&w.tf, s.tf(frames), stats);
    if ok {
        stats.published.fetch_add(1, Relaxed);
    }
}

/// The node's thread: polls the ring where an estimate is due (the frame
/// thread wakes it only out of a sleep elsewhere) and the STATUS channel,
/// until the frame thread's end and the STATUS end are both gone.
fn run(
    mut ring: spsc::Consumer<Handed>,
    status: &Receiver<Vec<u8>>,
    w: &Writers,
    frames: &Frames,
    stats: &Ros2Stats,
    site: Option<msg::SiteTf>,
) {
    // Its sleeps end when asked, not up to the default 50 µs later.
    let _ = nix::sys::prctl::set_timerslack(1_000);
    let mut site = SiteStatic { site, child: None };
    site.place(&frames.beacon, w, frames, stats);
    let mut last = msg::LastEstimate::default();
    let mut status_gone = false;
    let mut cadence = spsc::Cadence::new();
    loop {
        // Read before the pops: an estimate pushed before the producer
        // went is popped below, so none is lost at the end.
        let producer_gone = ring.producer_gone();
        let mut any = false;
        while let Some((est, wall)) = ring.pop() {
            cadence.came(std::time::Instant::now());
            last.observe(&est);
            publish(&est, wall, w, frames, stats, &mut site);
            any = true;
        }
        if !status_gone {
            match status.try_recv() {
                Ok(json) => {
                    if write(
                        &w.diagnostics,
                        msg::diagnostics(
                            &json,
                            &last,
                            msg::Time::from_unix(crate::status::unix_now()),
                        ),
                        stats,
                    ) {
                        stats.diagnostics.fetch_add(1, Relaxed);
                    }
                    any = true;
                }
                Err(TryRecvError::Empty) => {}
                Err(TryRecvError::Disconnected) => status_gone = true,
            }
        }
        if producer_gone && status_gone {
            return;
        }
        if !any && ring.wait(cadence.sleep(std::time::Instant::now())) {
            stats.woken.fetch_add(1, Relaxed);
        }
    }
}
