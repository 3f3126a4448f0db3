//! The serial transport against real pseudo-terminals: the pty's slave is
//! the autopilot's serial port (reached through a symlink, as udev names
//! it), the master is the autopilot. Frames cross in both directions split
//! anywhere and among garbage; the autopilot unplugged and plugged back
//! (master closed, a new pair behind the link) is survived.

mod common;

use common::{estimate, spawn_mavlink, wait_until};
use lightpose_core::Angle;
use lightpose_testkit::pty::Pty;
use lightpose_vehicle::mav::inbound::Refusal;
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::{Hub, MavlinkSettings, Site};
use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
use mavlink::{MAVLinkV2MessageRaw, MavHeader};
use std::fs::File;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

fn attitude_frame(pitch: f32, seq: u8) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    let h = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: seq,
    };
    raw.serialize_message(
        h,
        &MavMessage::ATTITUDE(ATTITUDE_DATA {
            pitch,
            ..Default::default()
        }),
    );
    raw.raw_bytes().to_vec()
}

/// Read from the master until frames with all these ids have come (the
/// component's heartbeats keep the reads from blocking for long).
fn read_until(master: &mut File, ids: &[u32], timeout: Duration) -> bool {
    let mut sc = Scanner::new(Framing::Stream);
    let mut seen = vec![false; ids.len()];
    let end = Instant::now() + timeout;
    while Instant::now() < end && !seen.iter().all(|s| *s) {
        let n = master.read(sc.spare()).unwrap_or(0);
        sc.commit(n);
        while let Some(e) = sc.next_frame() {
            if let Scanned::Frame(f) = e {
                for (k, id) in ids.iter().enumerate() {
                    seen[k] |= f.msg_id == *id;
                }
            }
        }
    }
    seen.iter().all(|s| *s)
}

#[test]
fn mavlink_over_a_serial_port_both_ways_and_through_an_unplug() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyAUTOPILOT");
    let mut ap = Pty::plug(&link);
    let hub = Hub::new();
    let mut s = MavlinkSettings::new(
        format!("serial:{}:115200", link.display()).parse().unwrap(),
        Site::new(Angle::ZERO, 3.0),
    );
    s.heartbeat_period = Duration::from_millis(50);
    s.reopen_max = Duration::from_millis(200);
    // The autopilot configured: its ATTITUDEs are taken without a
    // HEARTBEAT first.
    s.input.autopilot_system = Some(1);
    let _running = spawn_mavlink(s, hub.clone());

    // In: attitudes split across writes, garbage and a broken CRC between,
    // and line noise that reads as the start of a message no dialect has,
    // long enough to span the last frame (which must not be lost in it).
    let mut stream = b"\x00\x13garbage".to_vec();
    stream.extend(attitude_frame(0.1, 1));
    let mut broken = attitude_frame(0.9, 2);
    let n = broken.len();
    broken[n - 1] ^= 0xFF;
    stream.extend(broken);
    stream.extend([0xFD, 40, 0, 0, 0, 1, 1, 0x21, 0x43, 0x0F]);
    stream.extend(attitude_frame(0.2, 3));
    // The noise claims 52 bytes: until they have come it is undecided.
    stream.extend([0u8; 32]);
    for part in stream.chunks(7) {
        ap.master.write_all(part).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    let pitch_is = |p: f64| {
        hub.readings
            .attitude(Instant::now(), Duration::from_secs(60))
            .is_some_and(|a| (a.pitch.rad() - p).abs() < 1e-6)
    };
    assert!(
        wait_until(Duration::from_secs(5), || pitch_is(0.2)),
        "{:?}",
        hub.mavlink.status(Instant::now())
    );
    assert_eq!(hub.mavlink.used(0), 2);
    assert!(hub.mavlink.refused(Refusal::BadCrc) >= 1);
    assert!(hub.mavlink.refused(Refusal::UnknownMessage) >= 1);

    // Out: heartbeats and poses reach the autopilot.
    hub.outbox.offer(&estimate(1, 5.0), 0);
    assert!(read_until(
        &mut ap.master,
        &[0, 102, 103],
        Duration::from_secs(2)
    ));

    // Unplug: the link is lost and retried, counted; plug back in.
    drop(ap);
    assert!(wait_until(Duration::from_secs(5), || {
        hub.mavlink.status(Instant::now()).link_failures >= 2
    }));
    let mut ap = Pty::plug(&link);
    assert!(wait_until(Duration::from_secs(5), || {
        hub.mavlink.status(Instant::now()).link_opens >= 2
    }));
    ap.master.write_all(&attitude_frame(-0.3, 4)).unwrap();
    assert!(wait_until(Duration::from_secs(5), || pitch_is(-0.3)));
    let st = hub.mavlink.status(Instant::now());
    assert!(st.last_error.is_some(), "{st:?}");
}
