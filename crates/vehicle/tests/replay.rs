//! Issue 44: a sender without the key that plays frames signed the day
//! before (the autopilot's HEARTBEAT and ATTITUDEs, recorded) right after
//! the component starts, on `udpin`, `udpout` and serial over real
//! sockets and a real pseudo-terminal. None of the replay is used, the
//! real autopilot's fresh frames are, and on `udpin` the replayer never
//! becomes (or displaces) the peer. On `udpin` the link's signing
//! timestamp was 0 until its first send, and a new stream was judged
//! against it: 389 day-old ATTITUDEs were used and the autopilot's own
//! frames refused `other_address`.

mod common;

use common::{estimate, spawn_mavlink, wait_until};
use lightpose_core::Angle;
use lightpose_testkit::pty::Pty;
use lightpose_vehicle::mav::inbound::Refusal;
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::mav::signing::{timestamp_now, Signer, SigningConfig, SigningKey};
use lightpose_vehicle::standin::autopilot_heartbeat;
use lightpose_vehicle::{Hub, MavlinkSettings, Site};
use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
use mavlink::{MAVLinkV2MessageRaw, MavHeader};
use std::io::Write;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

/// A day in the signing timestamps' unit (10 µs).
const DAY: u64 = 86_400 * 100_000;
const HEARTBEAT: u32 = 0;

fn cfg(link_id: u8) -> SigningConfig {
    SigningConfig {
        key: SigningKey::from_passphrase("reef at night"),
        link_id,
        allow_unsigned: false,
    }
}

fn attitude(yaw: f32) -> MavMessage {
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        yaw,
        ..Default::default()
    })
}

/// `msg` from the autopilot (1, 1) signed by `sg` at `now`.
fn signed(sg: &mut Signer, msg: &MavMessage, now: u64) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    let h = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    sg.serialize(&mut raw, h, msg, now);
    raw.raw_bytes().to_vec()
}

/// What a listener recorded the day before: the autopilot's HEARTBEAT,
/// then 40 ATTITUDEs of yaw 1 rad, 10 ms apart, on the autopilot's link
/// id (the one its fresh frames carry too).
fn recording() -> Vec<Vec<u8>> {
    let mut rec = Signer::starting_at(cfg(1), 0);
    let t0 = timestamp_now() - DAY;
    let mut frames = vec![signed(&mut rec, &autopilot_heartbeat(), t0)];
    frames.extend((1..=40).map(|k| signed(&mut rec, &attitude(1.0), t0 + k * 1000)));
    frames
}

fn settings(endpoint: String) -> MavlinkSettings {
    let mut s = MavlinkSettings::new(endpoint.parse().unwrap(), Site::new(Angle::ZERO, 3.0));
    s.heartbeat_period = Duration::from_millis(50);
    s.reopen_max = Duration::from_millis(200);
    s.signing = Some(cfg(0));
    s
}

fn socket() -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").expect("bind");
    s.set_read_timeout(Some(Duration::from_millis(20)))
        .expect("timeout");
    s
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

/// The replay is refused whole, nothing of it is used or learned.
fn replay_refused(hub: &Hub, replay: &[Vec<u8>]) {
    let m = &hub.mavlink;
    let all = wait_until(Duration::from_secs(5), || {
        m.refused(Refusal::SigningClockBehind) >= replay.len() as u64
    });
    assert!(all, "{:?}", m.status(Instant::now()));
    assert_eq!(m.refused(Refusal::Replayed), 0);
    assert_eq!(m.used(0), 0, "{:?}", m.status(Instant::now()));
    assert_eq!(m.used(3), 0, "the replayed HEARTBEAT is not used");
    assert!(
        hub.readings
            .attitude(Instant::now(), Duration::from_secs(60))
            .is_none(),
        "a replayed attitude is attached"
    );
}

/// The autopilot's fresh ATTITUDEs (yaw 0) are used, after the replay,
/// and the replay's yaw of 1 rad never is.
fn fresh_used(hub: &Hub, ap: &mut Signer, mut send: impl FnMut(&[u8]), n: u64) {
    let m = &hub.mavlink;
    let before = m.used(0);
    // Its HEARTBEAT first: the replayed one taught nothing.
    send(&signed(ap, &autopilot_heartbeat(), timestamp_now()));
    for _ in 0..n {
        send(&signed(ap, &attitude(0.0), timestamp_now()));
        std::thread::sleep(Duration::from_millis(5));
    }
    let used = wait_until(Duration::from_secs(5), || m.used(0) >= before + n);
    assert!(used, "{:?}", m.status(Instant::now()));
    assert_eq!(m.used(0), before + n);
    let a = hub
        .readings
        .attitude(Instant::now(), Duration::from_secs(60))
        .expect("the autopilot's attitude");
    let want = Site::new(Angle::ZERO, 3.0).yaw_b(Angle::ZERO);
    assert!((a.yaw - want).deg().abs() < 1e-3, "{}", a.yaw.deg());
    assert_eq!(m.refused(Refusal::OtherAddress), 0);
}

#[test]
fn a_day_old_replay_at_start_on_udpin_is_refused_and_takes_no_peer() {
    let daemon: SocketAddr = socket().local_addr().unwrap();
    let hub = Hub::new();
    let _task = spawn_mavlink(settings(format!("udpin:{daemon}")), hub.clone());
    assert!(wait_until(Duration::from_secs(5), || {
        hub.mavlink.status(Instant::now()).link_opens >= 1
    }));
    let m = &hub.mavlink;
    let (replayer, autopilot) = (socket(), socket());
    let replay = recording();
    for f in &replay {
        replayer.send_to(f, daemon).expect("send");
    }
    replay_refused(&hub, &replay);
    assert_eq!((m.peer(), m.autopilot()), (None, None));
    assert!(
        hear(&replayer, Duration::from_millis(200)).is_empty(),
        "the replayer is sent to"
    );

    // The autopilot, fresh: greeted, learned, its readings used.
    let mut ap = Signer::new(cfg(1));
    let greeted = (0..100).any(|_| {
        let f = signed(&mut ap, &autopilot_heartbeat(), timestamp_now());
        autopilot.send_to(&f, daemon).expect("send");
        hear(&autopilot, Duration::from_millis(60)).contains(&HEARTBEAT)
    });
    assert!(greeted, "{:?}", m.status(Instant::now()));
    assert_eq!(m.peer(), autopilot.local_addr().ok());
    fresh_used(&hub, &mut ap, |f| drop(autopilot.send_to(f, daemon)), 10);

    // The replay again, interleaved with the autopilot: it never takes
    // the poses, and the autopilot's frames are never `other_address`.
    // (Its stream is known now: what is behind it is also `replayed`.)
    let mut heard = Vec::new();
    for (k, f) in replay.iter().enumerate() {
        replayer.send_to(f, daemon).expect("send");
        hub.outbox.offer(&estimate(k as u64, k as f64 * 0.1), 0);
        heard.extend(hear(&replayer, Duration::from_millis(5)));
    }
    assert!(heard.is_empty(), "the replayer got {heard:?}");
    assert!(wait_until(Duration::from_secs(5), || {
        m.refused(Refusal::SigningClockBehind) + m.refused(Refusal::Replayed)
            >= 2 * replay.len() as u64
    }));
    fresh_used(&hub, &mut ap, |f| drop(autopilot.send_to(f, daemon)), 10);
    let got = hear(&autopilot, Duration::from_millis(200));
    assert!(got.contains(&HEARTBEAT), "{got:?}");
    assert_eq!(
        (m.peer(), m.peer_changes()),
        (autopilot.local_addr().ok(), 0)
    );
    let st = m.status(Instant::now());
    assert!(st.sent[0].1 >= 1, "poses went to the autopilot: {st:?}");
}

/// On `udpout` the socket is connected: the replay comes from the
/// autopilot's own address (a host on the path, or a forged source).
#[test]
fn a_day_old_replay_at_start_on_udpout_is_refused() {
    let autopilot = socket();
    autopilot
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let port = autopilot.local_addr().unwrap().port();
    let hub = Hub::new();
    let _task = spawn_mavlink(settings(format!("udpout:127.0.0.1:{port}")), hub.clone());
    let mut buf = [0u8; 2048];
    let (_, daemon) = autopilot.recv_from(&mut buf).expect("the first heartbeat");
    let replay = recording();
    for f in &replay {
        autopilot.send_to(f, daemon).expect("send");
    }
    replay_refused(&hub, &replay);
    let mut ap = Signer::new(cfg(1));
    fresh_used(&hub, &mut ap, |f| drop(autopilot.send_to(f, daemon)), 10);
}

#[test]
fn a_day_old_replay_at_start_on_serial_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyAUTOPILOT");
    let mut pty = Pty::plug(&link);
    let hub = Hub::new();
    let s = settings(format!("serial:{}:115200", link.display()));
    let _task = spawn_mavlink(s, hub.clone());
    assert!(wait_until(Duration::from_secs(5), || {
        hub.mavlink.status(Instant::now()).link_opens >= 1
    }));
    let replay = recording();
    for f in &replay {
        pty.master.write_all(f).unwrap();
    }
    replay_refused(&hub, &replay);
    let mut ap = Signer::new(cfg(1));
    let master = &mut pty.master;
    fresh_used(&hub, &mut ap, |f| master.write_all(f).unwrap(), 10);
}
