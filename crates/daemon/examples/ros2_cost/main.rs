//! The ROS 2 output's cost (issue 42's bench row), printed as a table:
//! the frame thread's part per estimate (`Ros2Out::emit`: a copy into the
//! node's ring); capture → on the wire, the pose's RTPS DATA as the
//! kernel timestamps it on loopback (a packet socket: needs root, as in
//! `unshare -n`); and capture → received, the pose heard by a second
//! participant in this process (that adds the receiving side's DDS).
//!
//! `cargo run --release -p lightposed --example ros2_cost [-- ESTIMATES [HZ]]`
//! (default 2000 estimates at 200 Hz). Run where DDS may bind 127.0.0.1
//! with multicast (a host's loopback, or `unshare -n` with lo set up as
//! tests/ros2.rs does).

mod wire;

use lightpose_core::{Frame, PoseEstimate, Status, StdDev, NDET};
use lightpose_logs::ros2msg::{Frames, PoseWithCovarianceStamped, POSE_TYPE};
use lightposed::config::ros2::{QosKind, Ros2, TopicQos};
use lightposed::engine::Acquired;
use lightposed::outputs::Output;
use ros2_client::qos::{Durability, History};
use ros2_client::{Context, MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn estimate(seq: u64) -> PoseEstimate {
    let mut e = PoseEstimate::empty(seq, seq as f64 * 0.005, Status::Ok, "bench");
    (e.x, e.y, e.z, e.pitch_deg, e.yaw_deg, e.surge) = (
        Some(5.0),
        Some(0.1),
        Some(-0.2),
        Some(2.0),
        Some(-3.0),
        Some(0.2),
    );
    e.std = StdDev {
        x: Some(0.05),
        y: Some(0.05),
        z: Some(0.02),
        pitch: Some(1.0),
        yaw: Some(1.0),
        surge: Some(0.05),
        roll: None,
    };
    e
}

fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() as f64 - 1.0) * p).round() as usize]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let n: u64 = args.get(1).map_or(Ok(2000), |s| s.parse())?;
    let hz: f64 = args.get(2).map_or(Ok(200.0), |s| s.parse())?;
    let cfg = Ros2 {
        domain_id: 77,
        namespace: "/lightpose".into(),
        node_name: "lightposed_bench".into(),
        frames: Frames::default(),
        qos: TopicQos {
            pose: QosKind::SensorData,
            odom: QosKind::SensorData,
            tf: QosKind::Reliable,
            diagnostics: QosKind::Reliable,
            depth: 10,
        },
        networks: vec!["127.0.0.1".parse()?],
        imu: None,
        depth: None,
        dvl: None,
    };
    // The listener first, so that discovery is done before the count.
    let participant = ros2_client::dds::rustdds::DomainParticipantBuilder::new(cfg.domain_id)
        .with_only_networks(["127.0.0.1".parse::<std::net::IpAddr>()?])
        .build()
        .map_err(|e| anyhow::anyhow!("participant: {e:?}"))?;
    let ctx =
        Context::from_domain_participant(participant).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut node = ctx
        .new_node(NodeName::new("/", "bench_listener")?, NodeOptions::new())
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let qos = QosProfile::subscription_default()
        .reliability_best_effort()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 100 });
    let topic = node
        .create_topic(
            &Name::new("/lightpose", "pose")?,
            MessageTypeName::new(POSE_TYPE.package, POSE_TYPE.name),
            &qos,
        )
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let sub = node
        .create_subscription::<PoseWithCovarianceStamped>(&topic, Some(qos))
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let sniffer = wire::Sniffer::open(&cfg.frames.beacon);
    if let Err(e) = &sniffer {
        eprintln!("no packet socket ({e}): capture → on the wire not measured (needs root)");
    }
    let sniffed = sniffer.ok().map(|s| {
        let secs = n as f64 / hz + 4.0;
        std::thread::spawn(move || s.collect(Duration::from_secs_f64(secs)))
    });
    let (mut out, node_out) = lightposed::outputs::ros2::start(&cfg, None)?;
    let listener = std::thread::spawn(move || {
        let mut lat = Vec::new();
        let end = Instant::now() + Duration::from_secs_f64(n as f64 / hz + 5.0);
        while Instant::now() < end {
            match sub.take() {
                Ok(Some((m, _))) => lat.push((unix_now() - m.header.stamp.unix()) * 1e6),
                _ => std::thread::sleep(Duration::from_micros(50)),
            }
        }
        lat
    });
    std::thread::sleep(Duration::from_secs(2)); // discovery
                                                // Paced as the daemon's pacer paces frames: on a fixed schedule, so
                                                // that the rate does not drift with the time a frame takes.
    let period = Duration::from_secs_f64(1.0 / hz);
    let t0 = Instant::now();
    let mut cost = Vec::with_capacity(n as usize);
    for seq in 0..n {
        let acq = Acquired {
            frame: Frame::new(seq, seq as f64 / hz, 12, [0; NDET]),
            arrival: Instant::now(),
            capture: Instant::now(),
            wall_unix: unix_now(),
        };
        let est = estimate(seq);
        let t = Instant::now();
        out.emit(&acq, &est);
        cost.push(t.elapsed().as_secs_f64() * 1e6);
        let due = t0 + period * (seq as u32 + 1);
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
    }
    let mut lat = listener
        .join()
        .map_err(|_| anyhow::anyhow!("listener panicked"))?;
    let wire = match sniffed {
        Some(h) => h.join().map_err(|_| anyhow::anyhow!("sniffer panicked"))?,
        None => Vec::new(),
    };
    let s = &node_out.stats;
    println!("| ros2 output ({n} estimates at {hz} Hz) | median | p99 | max |");
    println!("|---|---|---|---|");
    let (m, p, x) = (
        pct(&mut cost, 0.5),
        pct(&mut cost, 0.99),
        pct(&mut cost, 1.0),
    );
    println!("| frame thread per estimate (µs) | {m:.2} | {p:.2} | {x:.2} |");
    if wire.is_empty() {
        println!("| capture → on the wire (µs) | not seen | | |");
    } else {
        let mut w = wire.clone();
        let (m, p, x) = (pct(&mut w, 0.5), pct(&mut w, 0.99), pct(&mut w, 1.0));
        println!("| capture → on the wire (µs) | {m:.0} | {p:.0} | {x:.0} |");
    }
    if lat.is_empty() {
        println!("| capture → received (µs) | none received | | |");
    } else {
        let (m, p, x) = (pct(&mut lat, 0.5), pct(&mut lat, 0.99), pct(&mut lat, 1.0));
        println!("| capture → received (µs) | {m:.0} | {p:.0} | {x:.0} |");
    }
    println!(
        "on the wire {} of {n}, received {} of {n}; handed {}, dropped {}, published {}, node woken {}",
        wire.len(),
        lat.len(),
        s.handed.load(Relaxed),
        s.handoff_dropped.load(Relaxed),
        s.published.load(Relaxed),
        s.woken.load(Relaxed)
    );
    Ok(())
}
