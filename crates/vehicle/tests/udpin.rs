//! `udpin` over real UDP on loopback: the poses and heartbeats go to the
//! last sender of a valid MAVLink frame from the autopilot we accept, not
//! to whoever sent the last datagram. A stray sender's garbage, a frame
//! with a broken CRC and another system's valid frame are counted and
//! redirect nothing; the autopilot moving to another port is followed.

mod common;

use common::{estimate, spawn_mavlink, wait_until};
use lightpose_core::Angle;
use lightpose_vehicle::mav::inbound::Refusal;
use lightpose_vehicle::mav::outbound::Encoder;
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::standin::autopilot_heartbeat;
use lightpose_vehicle::{Hub, MavlinkSettings, Site};
use mavlink::dialects::ardupilotmega::{HEARTBEAT_DATA, VISION_POSITION_ESTIMATE_DATA};
use mavlink::MessageData;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

const HEARTBEAT: u32 = HEARTBEAT_DATA::ID;
const POSITION: u32 = VISION_POSITION_ESTIMATE_DATA::ID;

fn socket() -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").expect("bind");
    s.set_read_timeout(Some(Duration::from_millis(20)))
        .expect("timeout");
    s
}

/// A heartbeat of system `system`, as an autopilot sends it.
fn beat(system: u8) -> Vec<u8> {
    Encoder::new(system, 1)
        .encode(&autopilot_heartbeat())
        .to_vec()
}

/// The message ids `sock` hears for `how_long`.
fn hear(sock: &UdpSocket, how_long: Duration) -> Vec<u32> {
    let (mut sc, mut buf, mut ids) = (Scanner::new(Framing::Datagram), [0u8; 2048], Vec::new());
    let end = Instant::now() + how_long;
    while Instant::now() < end {
        if let Ok(n) = sock.recv(&mut buf) {
            sc.push(&buf[..n]);
            while let Some(ev) = sc.next_frame() {
                if let Scanned::Frame(f) = ev {
                    ids.push(f.msg_id);
                }
            }
            sc.end_of_datagram();
        }
    }
    ids
}

/// Send `beat(1)` from `sock` until it hears the daemon's heartbeat.
fn announce(sock: &UdpSocket, daemon: SocketAddr) -> bool {
    let end = Instant::now() + Duration::from_secs(10);
    while Instant::now() < end {
        sock.send_to(&beat(1), daemon).expect("send");
        if hear(sock, Duration::from_millis(60)).contains(&HEARTBEAT) {
            return true;
        }
    }
    false
}

/// Offer `ok` poses every 10 ms for `how_long` while `sock` listens.
fn poses_heard(hub: &Hub, sock: &UdpSocket, how_long: Duration, seq: &mut u64) -> Vec<u32> {
    let (end, mut ids) = (Instant::now() + how_long, Vec::new());
    while Instant::now() < end {
        *seq += 1;
        hub.outbox.offer(&estimate(*seq, *seq as f64 * 0.01), 0);
        ids.extend(hear(sock, Duration::from_millis(10)));
    }
    ids
}

#[test]
fn only_a_valid_frame_from_the_autopilot_chooses_where_poses_go() {
    let port = socket().local_addr().unwrap().port();
    let daemon: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let mut s = MavlinkSettings::new(
        format!("udpin:{daemon}").parse().unwrap(),
        Site::new(Angle::from_deg(30.0), 3.0),
    );
    s.input.autopilot_system = Some(1);
    s.heartbeat_period = Duration::from_millis(50);
    let hub = Hub::new();
    let _task = spawn_mavlink(s, hub.clone());

    let autopilot = socket();
    assert!(announce(&autopilot, daemon), "the autopilot is greeted");

    // A stray sender: garbage, the autopilot's own heartbeat with a broken
    // CRC, and a valid heartbeat of system 2.
    let stray = socket();
    let mut broken = beat(1);
    if let Some(b) = broken.last_mut() {
        *b ^= 0xFF;
    }
    for d in [b"not mavlink at all".to_vec(), broken, beat(2)] {
        stray.send_to(&d, daemon).expect("send");
    }
    let counted = wait_until(Duration::from_secs(5), || {
        let m = &hub.mavlink;
        m.refused(Refusal::BadCrc) >= 1
            && m.refused(Refusal::OtherSystem) >= 1
            && m.status(Instant::now()).garbage_bytes >= 18
    });
    assert!(counted, "{:?}", hub.mavlink.status(Instant::now()));

    let mut seq = 0;
    let stray_heard = poses_heard(&hub, &stray, Duration::from_millis(400), &mut seq);
    assert!(
        stray_heard.is_empty(),
        "the stray sender got {stray_heard:?}"
    );
    let ap_heard = poses_heard(&hub, &autopilot, Duration::from_millis(400), &mut seq);
    assert!(ap_heard.contains(&POSITION), "{ap_heard:?}");
    assert!(ap_heard.contains(&HEARTBEAT), "{ap_heard:?}");

    // The autopilot (or its router) on another port: followed at its first
    // valid frame.
    let moved = socket();
    assert!(announce(&moved, daemon), "the moved autopilot is greeted");
    let moved_heard = poses_heard(&hub, &moved, Duration::from_millis(300), &mut seq);
    assert!(moved_heard.contains(&POSITION), "{moved_heard:?}");
    let _ = hear(&autopilot, Duration::from_millis(50));
    let old_heard = poses_heard(&hub, &autopilot, Duration::from_millis(200), &mut seq);
    assert!(old_heard.is_empty(), "the old port got {old_heard:?}");
}
