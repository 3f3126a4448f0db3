//! `udpin` over real UDP on loopback: the poses and heartbeats go to the
//! address the autopilot's own frames come from, not to whoever sent the
//! last datagram. A stray sender's garbage, a frame with a broken CRC and
//! another system's valid frame are counted and redirect nothing; a GCS's
//! or a second vehicle's readings are counted and never attached; the
//! autopilot moving to another port is followed once its old one has been
//! silent for `PEER_SILENCE`. A pose that met no peer does not take the
//! rate limit's slot.

mod common;

use common::{estimate, spawn_mavlink, wait_until};
use lightpose_core::Angle;
use lightpose_vehicle::mav::inbound::Refusal;
use lightpose_vehicle::mav::link::PEER_SILENCE;
use lightpose_vehicle::mav::outbound::Encoder;
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::standin::autopilot_heartbeat;
use lightpose_vehicle::{Hub, MavlinkSettings, Site};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavType, ATTITUDE_DATA, HEARTBEAT_DATA, VISION_POSITION_ESTIMATE_DATA,
};
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
    beat_of(system, 1)
}

/// A GCS's heartbeat (QGroundControl: system 255, component 190).
fn gcs_beat() -> Vec<u8> {
    let m = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        ..Default::default()
    });
    Encoder::new(255, 190).encode(&m).to_vec()
}

/// An ATTITUDE of yaw `yaw` rad from (system, component).
fn attitude(system: u8, component: u8, yaw: f32) -> Vec<u8> {
    let m = MavMessage::ATTITUDE(ATTITUDE_DATA {
        yaw,
        ..Default::default()
    });
    Encoder::new(system, component).encode(&m).to_vec()
}

/// A heartbeat of (system, component), as an autopilot sends it.
fn beat_of(system: u8, component: u8) -> Vec<u8> {
    Encoder::new(system, component)
        .encode(&autopilot_heartbeat())
        .to_vec()
}

/// A `udpin` link on a free loopback port, its heartbeat every 50 ms.
fn listening(configure: impl FnOnce(&mut MavlinkSettings)) -> (MavlinkSettings, SocketAddr) {
    let port = socket().local_addr().unwrap().port();
    let daemon: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let mut s = MavlinkSettings::new(
        format!("udpin:{daemon}").parse().unwrap(),
        Site::new(Angle::from_deg(30.0), 3.0),
    );
    s.heartbeat_period = Duration::from_millis(50);
    configure(&mut s);
    (s, daemon)
}

/// Wait for the task to have bound its port (a datagram before is lost).
fn bound(hub: &Hub) {
    let open = wait_until(Duration::from_secs(5), || {
        hub.mavlink.status(Instant::now()).link_opens >= 1
    });
    assert!(open, "the udpin link opens");
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

    // The autopilot (or its router) on another port: followed once the
    // old one has been silent for PEER_SILENCE (see the test below).
    std::thread::sleep(PEER_SILENCE + Duration::from_millis(100));
    let moved = socket();
    assert!(announce(&moved, daemon), "the moved autopilot is greeted");
    let moved_heard = poses_heard(&hub, &moved, Duration::from_millis(300), &mut seq);
    assert!(moved_heard.contains(&POSITION), "{moved_heard:?}");
    let _ = hear(&autopilot, Duration::from_millis(50));
    let old_heard = poses_heard(&hub, &autopilot, Duration::from_millis(200), &mut seq);
    assert!(old_heard.is_empty(), "the old port got {old_heard:?}");
}

/// Audit: by default (no `autopilot_system_id`) a GCS's heartbeat took the
/// poses, and a second vehicle's readings were attached. The autopilot is
/// learned from its own HEARTBEAT (component 1, not a GCS); a GCS and a
/// second vehicle (system 2) neither take the peer nor give readings, and
/// are counted; before the autopilot is known nothing is attached.
#[test]
fn a_gcs_and_a_second_vehicle_neither_take_the_poses_nor_give_readings() {
    let (s, daemon) = listening(|_| {});
    let hub = Hub::new();
    let _task = spawn_mavlink(s.clone(), hub.clone());
    bound(&hub);
    let (autopilot, gcs, rov2) = (socket(), socket(), socket());

    // Before any autopilot HEARTBEAT: an ATTITUDE of (1, 1) is not taken.
    autopilot
        .send_to(&attitude(1, 1, 0.0), daemon)
        .expect("send");
    let m = &hub.mavlink;
    assert!(wait_until(Duration::from_secs(5), || m
        .refused(Refusal::AutopilotUnknown)
        >= 1));
    assert_eq!(m.used(0), 0);
    assert_eq!(m.autopilot(), None);

    // A GCS's heartbeat first: not adopted.
    gcs.send_to(&gcs_beat(), daemon).expect("send");
    assert!(wait_until(Duration::from_secs(5), || m
        .refused(Refusal::OtherComponent)
        >= 1));
    assert_eq!((m.autopilot(), m.peer()), (None, None));
    assert!(announce(&autopilot, daemon), "the autopilot is greeted");
    let id = m.autopilot().expect("learned");
    assert_eq!((id.system, id.component, id.configured), (1, 1, false));
    assert_eq!(m.peer(), autopilot.local_addr().ok());

    // The others' streams, yaw biased, while the autopilot's goes on.
    let used_before = m.used(0);
    for _ in 0..20 {
        gcs.send_to(&gcs_beat(), daemon).expect("send");
        gcs.send_to(&attitude(255, 190, 1.0), daemon).expect("send");
        rov2.send_to(&beat(2), daemon).expect("send");
        rov2.send_to(&attitude(2, 1, 1.0), daemon).expect("send");
        autopilot
            .send_to(&attitude(1, 1, 0.0), daemon)
            .expect("send");
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(wait_until(Duration::from_secs(5), || m.used(0) >= used_before + 20));
    assert_eq!(m.used(0), used_before + 20, "only the autopilot's are used");
    assert!(
        m.refused(Refusal::OtherSystem) >= 40,
        "{:?}",
        m.status(Instant::now())
    );
    assert!(m.refused(Refusal::OtherComponent) >= 40);
    let yaw = hub
        .readings
        .attitude(Instant::now(), Duration::from_secs(5))
        .expect("attached")
        .yaw;
    let want = s.site.yaw_b(Angle::ZERO);
    assert!(
        (yaw - want).deg().abs() < 1e-3,
        "{} vs {}",
        yaw.deg(),
        want.deg()
    );

    // The poses go to the autopilot only.
    let mut seq = 0;
    let heard = poses_heard(&hub, &autopilot, Duration::from_millis(300), &mut seq);
    assert!(heard.contains(&POSITION), "{heard:?}");
    for (who, sock) in [("the GCS", &gcs), ("the second vehicle", &rov2)] {
        let got = poses_heard(&hub, sock, Duration::from_millis(200), &mut seq);
        assert!(got.is_empty(), "{who} got {got:?}");
    }
    assert_eq!(m.peer_changes(), 0);
    let st = serde_json::to_value(m.status(Instant::now())).expect("json");
    assert_eq!(st["peer"], autopilot.local_addr().unwrap().to_string());
    assert_eq!(st["autopilot"]["system"], 1);
}

/// Audit: a second sender with the autopilot's own ids (a second ROV with
/// default SYSID 1) took the poses from the autopilot that was still
/// talking, and its readings were attached. Now its frames are refused
/// (`other_address`) while the autopilot speaks; once the autopilot has
/// been silent for PEER_SILENCE the new address becomes the peer.
#[test]
fn the_peer_moves_only_after_the_autopilot_fell_silent() {
    let (s, daemon) = listening(|s| s.input.autopilot_system = Some(1));
    let hub = Hub::new();
    let _task = spawn_mavlink(s, hub.clone());
    let (autopilot, twin) = (socket(), socket());
    assert!(announce(&autopilot, daemon), "the autopilot is greeted");
    let m = &hub.mavlink;
    let id = m.autopilot().expect("configured");
    assert!(id.configured);

    // The twin at 200 Hz for 1 s while the autopilot beats at 20 Hz.
    let end = Instant::now() + Duration::from_secs(1);
    let mut seq = 0;
    let mut heard = Vec::new();
    while Instant::now() < end {
        for _ in 0..10 {
            twin.send_to(&beat(1), daemon).expect("send");
            twin.send_to(&attitude(1, 1, 1.0), daemon).expect("send");
        }
        autopilot.send_to(&beat(1), daemon).expect("send");
        heard.extend(poses_heard(
            &hub,
            &autopilot,
            Duration::from_millis(50),
            &mut seq,
        ));
    }
    let n = heard.iter().filter(|id| **id == POSITION).count();
    assert!(n >= 10, "the autopilot heard {n} estimates in 1 s");
    assert!(m.refused(Refusal::OtherAddress) >= 100);
    assert_eq!(m.used(0), 0, "the twin's ATTITUDEs are not attached");
    assert_eq!(
        (m.peer(), m.peer_changes()),
        (autopilot.local_addr().ok(), 0)
    );

    // The autopilot falls silent: the twin takes over after PEER_SILENCE,
    // not before.
    let silent = Instant::now();
    let moved = wait_until(PEER_SILENCE + Duration::from_secs(3), || {
        twin.send_to(&beat(1), daemon).expect("send");
        std::thread::sleep(Duration::from_millis(20));
        m.peer() == twin.local_addr().ok()
    });
    assert!(moved && silent.elapsed() >= PEER_SILENCE - Duration::from_millis(100));
    assert_eq!(m.peer_changes(), 1);
}

/// A configured component other than 1: that component's HEARTBEAT teaches
/// the system; component 1 of the same system is another component.
#[test]
fn a_configured_component_is_the_autopilot() {
    let (s, daemon) = listening(|s| s.input.autopilot_component = 2);
    let hub = Hub::new();
    let _task = spawn_mavlink(s, hub.clone());
    bound(&hub);
    let (autopilot, other) = (socket(), socket());
    let m = &hub.mavlink;
    other.send_to(&beat_of(1, 1), daemon).expect("send");
    other.send_to(&attitude(1, 1, 1.0), daemon).expect("send");
    assert!(wait_until(Duration::from_secs(5), || m
        .refused(Refusal::OtherComponent)
        >= 2));
    assert_eq!((m.autopilot(), m.peer()), (None, None));
    autopilot.send_to(&beat_of(1, 2), daemon).expect("send");
    autopilot
        .send_to(&attitude(1, 2, 0.0), daemon)
        .expect("send");
    assert!(wait_until(Duration::from_secs(5), || m.used(0) == 1));
    let id = m.autopilot().expect("learned");
    assert_eq!((id.system, id.component), (1, 2));
    assert_eq!(m.peer(), autopilot.local_addr().ok());
}

/// How many poses the rate limit dropped.
fn decimated(hub: &Hub) -> u64 {
    let st = hub.mavlink.status(Instant::now());
    st.skipped
        .iter()
        .find(|(name, _)| *name == "decimated")
        .map_or(0, |(_, k)| *k)
}

/// A pose that could not be sent (no peer yet) does not take the rate
/// limit's slot: the next pose inside `1/position_rate_hz` of it is sent
/// once the autopilot has spoken, and only the pose after that one is
/// decimated.
#[test]
fn a_pose_not_sent_does_not_decimate_the_next() {
    let (s, daemon) = listening(|s| {
        s.output.position_rate_hz = Some(5.0);
        // One heartbeat at the start (not sent, no peer) and one greeting
        // the autopilot: `no_peer` then counts only the pose below.
        s.heartbeat_period = Duration::from_secs(60);
    });
    let hub = Hub::new();
    let _task = spawn_mavlink(s, hub.clone());
    bound(&hub);
    let no_peer = || hub.mavlink.status(Instant::now()).no_peer;
    assert!(wait_until(Duration::from_secs(5), || no_peer() >= 1));
    let before = no_peer();

    hub.outbox.offer(&estimate(1, 10.0), 0);
    assert!(
        wait_until(Duration::from_secs(5), || no_peer() > before),
        "the pose meets no peer"
    );
    assert_eq!(hub.mavlink.sent(0), 0);

    let autopilot = socket();
    assert!(announce(&autopilot, daemon), "the autopilot is greeted");
    // 50 ms after the unsent pose: inside the 200 ms limit of it.
    hub.outbox.offer(&estimate(2, 10.05), 0);
    let heard = hear(&autopilot, Duration::from_millis(300));
    assert!(heard.contains(&POSITION), "{heard:?}");
    assert_eq!(hub.mavlink.sent(0), 1);
    assert_eq!(decimated(&hub), 0);

    // The pose sent took the slot: 50 ms after it is decimated.
    hub.outbox.offer(&estimate(3, 10.1), 0);
    assert!(wait_until(Duration::from_secs(5), || decimated(&hub) == 1));
    let heard = hear(&autopilot, Duration::from_millis(100));
    assert!(!heard.contains(&POSITION), "{heard:?}");
    assert_eq!(hub.mavlink.sent(0), 1);
}

/// A datagram of 60 KB (a router that packs frames): every frame in it is
/// read. The scanner's 16 KiB took the first 61 of 246 frames and the
/// rest were counted nowhere (an audit).
#[test]
fn every_frame_of_a_64_kib_datagram_is_read() {
    let (mut s, daemon) = listening(|_| {});
    s.input.autopilot_system = Some(1);
    let hub = Hub::new();
    let _task = spawn_mavlink(s, hub.clone());
    let autopilot = socket();
    assert!(announce(&autopilot, daemon), "the autopilot is greeted");
    let frame = attitude(1, 1, 0.1);
    let n = 60_000 / frame.len();
    let datagram = frame.repeat(n);
    assert!(
        datagram.len() > 4 * 16 * 1024 - 8 * 1024,
        "{}",
        datagram.len()
    );
    let before = hub.mavlink.status(Instant::now()).frames;
    autopilot.send_to(&datagram, daemon).expect("send");
    let all = wait_until(Duration::from_secs(5), || {
        hub.mavlink.status(Instant::now()).frames >= before + n as u64
    });
    let st = hub.mavlink.status(Instant::now());
    assert!(all, "{} of {n} frames read: {st:?}", st.frames - before);
    assert_eq!(st.garbage_bytes, 0, "{st:?}");
}

/// The timestamp of a frame signed with the key, as it is on the wire.
fn signature_timestamp(frame: &[u8]) -> u64 {
    let n = frame.len();
    let mut b = [0u8; 8];
    b[..6].copy_from_slice(&frame[n - 12..n - 6]);
    u64::from_le_bytes(b)
}

/// With signing, our timestamp follows the autopilot's frames only: a
/// GCS holding the key that stamped one frame 2⁴⁸ − 1 (refused for its
/// origin) held ours at the end of the 48 bits, so every frame after was a
/// replay to the autopilot, and the autopilot's own, stamped after ours,
/// were refused as replays in turn, until a restart (an audit).
#[test]
fn a_far_future_frame_of_another_component_does_not_move_our_signing_clock() {
    use lightpose_vehicle::mav::signing::{timestamp_now, Signer, SigningConfig, SigningKey};
    use mavlink::MAVLinkV2MessageRaw;
    let key = SigningKey::from_passphrase("reef");
    let cfg = |link_id| SigningConfig {
        key: key.clone(),
        link_id,
        allow_unsigned: false,
    };
    let (mut s, daemon) = listening(|_| {});
    s.input.autopilot_system = Some(1);
    s.signing = Some(cfg(0));
    let hub = Hub::new();
    let _task = spawn_mavlink(s, hub.clone());
    bound(&hub);
    let signed = |sg: &mut Signer, system: u8, component: u8, msg: &MavMessage, now: u64| {
        let mut raw = MAVLinkV2MessageRaw::new();
        let header = mavlink::MavHeader {
            system_id: system as u32,
            component_id: component,
            sequence: 0,
        };
        sg.serialize(&mut raw, header, msg, now);
        raw.raw_bytes().to_vec()
    };
    let (mut ap, mut gcs) = (Signer::new(cfg(1)), Signer::new(cfg(7)));
    let autopilot = socket();
    let beat_msg = autopilot_heartbeat();
    let att = MavMessage::ATTITUDE(ATTITUDE_DATA {
        yaw: 0.2,
        ..Default::default()
    });
    // Greeted: the daemon's signed heartbeats come to the autopilot.
    let greeted = (0..100).any(|_| {
        let f = signed(&mut ap, 1, 1, &beat_msg, timestamp_now());
        autopilot.send_to(&f, daemon).expect("send");
        hear(&autopilot, Duration::from_millis(60)).contains(&HEARTBEAT)
    });
    assert!(greeted, "{:?}", hub.mavlink.status(Instant::now()));
    // The GCS's one frame from the end of time, from another port.
    let far = signed(&mut gcs, 255, 190, &gcs_heartbeat(), (1 << 48) - 1);
    socket().send_to(&far, daemon).expect("send");
    let refused = wait_until(Duration::from_secs(5), || {
        hub.mavlink.refused(Refusal::OtherComponent) + hub.mavlink.refused(Refusal::OtherSystem)
            >= 1
    });
    assert!(refused, "{:?}", hub.mavlink.status(Instant::now()));
    // Ours stays with the clocks (the daemon's and the autopilot's).
    let mut buf = [0u8; 2048];
    let mut stamps = Vec::new();
    let end = Instant::now() + Duration::from_millis(400);
    while Instant::now() < end {
        if let Ok(n) = autopilot.recv(&mut buf) {
            if n > 13 {
                stamps.push(signature_timestamp(&buf[..n]));
            }
        }
    }
    let limit = timestamp_now() + 100_000 * 60;
    assert!(
        !stamps.is_empty() && stamps.iter().all(|&t| t < limit),
        "{stamps:?}"
    );
    // And the autopilot's frames, stamped by its own clock, are still taken.
    for _ in 0..5 {
        let f = signed(&mut ap, 1, 1, &att, timestamp_now());
        autopilot.send_to(&f, daemon).expect("send");
        std::thread::sleep(Duration::from_millis(20));
    }
    let taken = wait_until(Duration::from_secs(2), || {
        hub.readings
            .attitude(Instant::now(), Duration::from_secs(5))
            .is_some()
    });
    assert!(taken, "{:?}", hub.mavlink.status(Instant::now()));
    assert_eq!(hub.mavlink.refused(Refusal::Replayed), 0);
}

/// A GCS's HEARTBEAT message.
fn gcs_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        ..Default::default()
    })
}
