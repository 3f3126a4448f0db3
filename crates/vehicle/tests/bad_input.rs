//! Bad MAVLink input over real UDP: wrong CRCs, unknown messages, NaN and
//! out-of-range attitudes, another system's messages, garbage, and a flood
//! of 10 000 messages in a second. Every one is counted by its reason,
//! nothing panics, poses keep going out, and the latest valid reading is
//! the one that counts.

mod common;

use common::{estimate, spawn_mavlink, wait_until};
use lightpose_core::{Angle, Frame, NDET};
use lightpose_vehicle::mav::inbound::Refusal;
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::{Hub, MavlinkSettings, MaxAge, Site};
use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
use mavlink::{MAVLinkV1MessageRaw, MAVLinkV2MessageRaw, MavHeader};
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn attitude(pitch: f32, yaw: f32) -> MavMessage {
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        pitch,
        yaw,
        ..Default::default()
    })
}

fn v2(msg: &MavMessage, system: u8, seq: u8) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    let h = MavHeader {
        system_id: system as u32,
        component_id: 1,
        sequence: seq,
    };
    raw.serialize_message(h, msg);
    raw.raw_bytes().to_vec()
}

fn bad_crc(msg: &MavMessage) -> Vec<u8> {
    let mut f = v2(msg, 1, 0);
    let n = f.len();
    f[n - 2] ^= 0x5A;
    f
}

fn unknown_id() -> Vec<u8> {
    let mut f = v2(&attitude(0.0, 0.0), 1, 0);
    f[7..10].copy_from_slice(&[0x77, 0x77, 0x07]);
    f
}

/// The link's other end: a socket the component sends to, which answers
/// from the same port and counts the poses it gets.
struct Autopilot {
    sock: UdpSocket,
    component: std::net::SocketAddr,
    poses: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
}

impl Autopilot {
    fn start(hub: &Arc<Hub>) -> (Autopilot, common::Running) {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        let port = sock.local_addr().unwrap().port();
        let mut s = MavlinkSettings::new(
            format!("udpout:127.0.0.1:{port}").parse().unwrap(),
            Site::new(Angle::ZERO, 3.0),
        );
        s.heartbeat_period = Duration::from_millis(50);
        s.input.autopilot_system = Some(1);
        let running = spawn_mavlink(s, hub.clone());
        sock.set_read_timeout(Some(Duration::from_secs(10)))
            .unwrap();
        let mut buf = [0u8; 2048];
        let (_, component) = sock.recv_from(&mut buf).expect("the component's heartbeat");
        let poses = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let rsock = sock.try_clone().unwrap();
        rsock
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let (p, st) = (poses.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut sc = Scanner::new(Framing::Datagram);
            while !st.load(Ordering::Relaxed) {
                if let Ok(n) = rsock.recv(sc.spare()) {
                    sc.commit(n);
                    while let Some(e) = sc.next_frame() {
                        if let Scanned::Frame(f) = e {
                            if f.msg_id == 102 {
                                p.fetch_add(1, Ordering::Relaxed);
                            }
                        }
                    }
                    sc.end_of_datagram();
                }
            }
        });
        let a = Autopilot {
            sock,
            component,
            poses,
            stop,
        };
        (a, running)
    }

    fn send(&self, bytes: &[u8]) {
        self.sock.send_to(bytes, self.component).unwrap();
    }
}

impl Drop for Autopilot {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn refused(hub: &Hub, r: Refusal) -> u64 {
    hub.mavlink.refused(r)
}

#[test]
fn every_kind_of_bad_input_is_counted_by_its_reason() {
    let hub = Hub::new();
    let (ap, _running) = Autopilot::start(&hub);
    for _ in 0..5 {
        ap.send(&bad_crc(&attitude(0.1, 0.2)));
    }
    for _ in 0..3 {
        ap.send(&unknown_id());
    }
    for _ in 0..4 {
        ap.send(&v2(&attitude(f32::NAN, 0.0), 1, 0));
    }
    ap.send(&v2(&attitude(0.0, f32::INFINITY), 1, 0));
    ap.send(&v2(&attitude(2.0, 0.0), 1, 0));
    ap.send(&v2(&attitude(0.0, 9.0), 1, 0));
    ap.send(&v2(&attitude(0.2, 0.3), 7, 0)); // another system
    ap.send(b"\x00\x01\x02 no frame here \x10\x11");
    // A valid MAVLink 1 frame after all that.
    let mut v1 = MAVLinkV1MessageRaw::new();
    v1.serialize_message(
        MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        },
        &attitude(0.25, 3.0),
    );
    ap.send(v1.raw_bytes());
    let c = &hub.mavlink;
    let all = || {
        refused(&hub, Refusal::BadCrc) == 5
            && refused(&hub, Refusal::UnknownMessage) == 3
            && refused(&hub, Refusal::NotFinite) == 5
            && refused(&hub, Refusal::AngleOutOfRange) == 2
            && refused(&hub, Refusal::OtherSystem) == 1
            && c.used(0) == 1
    };
    assert!(
        wait_until(Duration::from_secs(5), all),
        "{:?}",
        c.status(Instant::now())
    );
    let st = c.status(Instant::now());
    assert_eq!(st.garbage_bytes, 20, "{st:?}");
    assert!(st.last_error.is_some());
    // Only the valid one (MAVLink 1, pitch 0.25) became the reading.
    let a = hub
        .readings
        .attitude(Instant::now(), Duration::from_secs(60))
        .unwrap();
    assert!((a.pitch.rad() - 0.25).abs() < 1e-7);
}

#[test]
fn a_flood_costs_no_frame_and_the_latest_valid_reading_wins() {
    let hub = Hub::new();
    let (ap, _running) = Autopilot::start(&hub);
    // The frame thread: attach and offer at 100 Hz throughout.
    let frames_stop = Arc::new(AtomicBool::new(false));
    let (h, fs) = (hub.clone(), frames_stop.clone());
    let frame_thread = std::thread::spawn(move || {
        let mut n = 0u64;
        while !fs.load(Ordering::Relaxed) {
            let mut f = Frame::new(n, n as f64 * 0.01, 10, [0; NDET]);
            h.readings
                .attach(&mut f, Instant::now(), &MaxAge::default());
            h.outbox.offer(&estimate(n, f.t), 0);
            n += 1;
            std::thread::sleep(Duration::from_millis(10));
        }
        n
    });
    // 10 000 messages in about a second: valid attitudes, NaN ones and
    // broken CRCs, 100 every 10 ms.
    let (bad, nan) = (
        bad_crc(&attitude(0.3, 0.3)),
        v2(&attitude(f32::NAN, 0.0), 1, 0),
    );
    let poses_before = ap.poses.load(Ordering::Relaxed);
    let start = Instant::now();
    for batch in 0..100u32 {
        for k in 0..100u32 {
            let i = batch * 100 + k;
            match i % 4 {
                0 => ap.send(&bad),
                1 => ap.send(&nan),
                _ => ap.send(&v2(&attitude(0.01 * (i % 50) as f32, 0.5), 1, i as u8)),
            }
        }
        let next = start + Duration::from_millis(10 * (batch as u64 + 1));
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let flood_s = start.elapsed().as_secs_f64();
    // Then one known attitude, until it is the reading.
    let known = v2(&attitude(-0.2, 1.0), 1, 0);
    let seen = wait_until(Duration::from_secs(5), || {
        ap.send(&known);
        std::thread::sleep(Duration::from_millis(20));
        hub.readings
            .attitude(Instant::now(), Duration::from_secs(60))
            .is_some_and(|a| (a.pitch.rad() + 0.2).abs() < 1e-7)
    });
    frames_stop.store(true, Ordering::Relaxed);
    let frames = frame_thread.join().unwrap();
    let st = hub.mavlink.status(Instant::now());
    assert!(seen, "the known attitude never became the reading: {st:?}");
    // Every message that arrived is accounted for by kind or reason.
    let (used, crc, nan_n) = (
        hub.mavlink.used(0),
        refused(&hub, Refusal::BadCrc),
        refused(&hub, Refusal::NotFinite),
    );
    eprintln!(
        "flood: {flood_s:.2} s, attitudes used {used}, bad CRC {crc}, NaN {nan_n}, frames {frames}"
    );
    assert!(used <= 5000 + 300 && crc <= 2500 && nan_n <= 2500);
    assert!(
        used + crc + nan_n >= 5000,
        "most of the flood arrived and was counted: {st:?}"
    );
    // Poses kept going out during the flood, all offers were taken.
    assert!(ap.poses.load(Ordering::Relaxed) > poses_before);
    assert_eq!(hub.outbox.status().queued, frames);
    assert!(st.sent[2].1 > 0, "heartbeats");
}

/// A `udpin` component knows its autopilot only from the first datagram
/// with the autopilot's frame (here its ATTITUDE: the system is
/// configured; unset, only its HEARTBEAT would tell); it greets it with a
/// HEARTBEAT then, not a heartbeat period later (here a minute, so that
/// only the greeting can arrive in time).
#[test]
fn a_udpin_component_greets_a_new_peer_at_once() {
    let port = UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("probe port")
        .port();
    let at = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let mut s = MavlinkSettings::new(
        lightpose_vehicle::Endpoint::UdpIn(at),
        Site::new(Angle::ZERO, 3.0),
    );
    s.heartbeat_period = Duration::from_secs(60);
    s.input.autopilot_system = Some(1);
    let hub = Arc::new(Hub::default());
    let _running = spawn_mavlink(s, hub.clone());
    let ap = UdpSocket::bind("127.0.0.1:0").expect("autopilot");
    ap.set_read_timeout(Some(Duration::from_millis(100)))
        .expect("timeout");
    let mut sc = Scanner::new(Framing::Datagram);
    let mut buf = [0u8; 2048];
    let t0 = Instant::now();
    let mut greeted = false;
    // Resend until the link is up; the first tick of a 60 s period is
    // spent before any peer is known.
    while !greeted && t0.elapsed() < Duration::from_secs(10) {
        ap.send_to(&v2(&attitude(0.0, 0.0), 1, 0), at)
            .expect("send");
        if let Ok(n) = ap.recv(&mut buf) {
            sc.push(&buf[..n]);
            while let Some(ev) = sc.next_frame() {
                greeted |= matches!(ev, Scanned::Frame(f) if f.msg_id == 0);
            }
            sc.end_of_datagram();
        }
    }
    assert!(greeted, "no HEARTBEAT within 10 s of the first datagram");
}

/// Issue 44: one datagram of 0xFD bytes, as large as UDP carries, cost a
/// frame parse per byte and was counted as 65 507 refused frames (300 a
/// second held the daemon at 101 % CPU). It is one refused datagram of
/// 65 507 bytes, one `bad_flags`, and the autopilot's next frame is read.
#[test]
fn a_datagram_of_start_bytes_is_one_refused_datagram() {
    let hub = Hub::new();
    let (ap, _running) = Autopilot::start(&hub);
    let n = 65_507;
    ap.send(&vec![0xFD; n]);
    let c = &hub.mavlink;
    let counted = wait_until(Duration::from_secs(5), || {
        c.status(Instant::now()).refused_datagrams >= 1
    });
    let st = c.status(Instant::now());
    assert!(counted, "{st:?}");
    assert_eq!((st.refused_datagrams, st.refused_bytes), (1, n as u64));
    assert_eq!(st.refused, [("bad_flags", 1)], "{st:?}");
    assert_eq!((st.frames, st.garbage_bytes), (0, 0));
    ap.send(&v2(&attitude(0.1, 0.2), 1, 0));
    assert!(wait_until(Duration::from_secs(5), || c.used(0) == 1));
    let st = c.status(Instant::now());
    assert_eq!((st.refused_datagrams, st.frames), (1, 1), "{st:?}");
}
