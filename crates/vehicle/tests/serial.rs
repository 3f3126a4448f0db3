//! The serial transport against real pseudo-terminals: the pty's slave is
//! the autopilot's serial port (reached through a symlink, as udev names
//! it), the master is the autopilot. Frames cross in both directions split
//! anywhere and among garbage; the autopilot unplugged and plugged back
//! (master closed, a new pair behind the link) is survived; an autopilot
//! that stops reading (master kept, never read) is a lost link within the
//! write bound, and does not hold up a stop.

mod common;

use common::{estimate, spawn_mavlink, wait_until};
use lightpose_core::Angle;
use lightpose_testkit::pty::Pty;
use lightpose_vehicle::mav::inbound::Refusal;
use lightpose_vehicle::mav::link::write_bound;
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

/// Offer a new pose (`seq`, capture time `seq` × 10 ms) for the task to send.
fn offer(hub: &Hub, seq: &mut u64) {
    *seq += 1;
    hub.outbox.offer(&estimate(*seq, *seq as f64 * 0.01), 0);
}

/// Poll `cond` while offering a pose every millisecond, so that a port
/// nobody reads fills and stays full.
fn flood_until(
    hub: &Hub,
    seq: &mut u64,
    timeout: Duration,
    mut cond: impl FnMut() -> bool,
) -> bool {
    let end = Instant::now() + timeout;
    while Instant::now() < end {
        if cond() {
            return true;
        }
        offer(hub, seq);
        std::thread::sleep(Duration::from_millis(1));
    }
    cond()
}

/// An autopilot on a pty at `baud` that never reads, the hub and the
/// link's settings (heartbeats every 50 ms).
fn silent_autopilot(baud: u32) -> (tempfile::TempDir, Pty, std::sync::Arc<Hub>, MavlinkSettings) {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyAUTOPILOT");
    let ap = Pty::plug(&link);
    let mut s = MavlinkSettings::new(
        format!("serial:{}:{baud}", link.display()).parse().unwrap(),
        Site::new(Angle::ZERO, 3.0),
    );
    s.heartbeat_period = Duration::from_millis(50);
    (dir, ap, Hub::new(), s)
}

/// The autopilot stops reading but stays plugged in (a USB CDC port whose
/// firmware hangs): once the pty's buffer is full, writes wait forever.
/// The link is lost within its write bound (1 s at 115200 baud), counted
/// and reopened; the reopened link, whose buffer is still full, is lost
/// again a bound after it opened.
#[test]
fn a_serial_port_nobody_reads_is_lost_within_the_write_bound() {
    // The task is stopped after the device is gone (on a failure too: a
    // write the bound does not end would hold the stop up until then).
    let _running;
    let (_dir, _ap, hub, mut s) = silent_autopilot(115200);
    s.reopen_max = Duration::from_millis(200);
    let bound = write_bound(115200);
    _running = spawn_mavlink(s, hub.clone());

    let st = |hub: &Hub| hub.mavlink.status(Instant::now());
    let mut seq = 0;
    let lost = flood_until(&hub, &mut seq, bound + Duration::from_secs(10), || {
        st(&hub).link_failures >= 1
    });
    assert!(lost, "{:?}", st(&hub));
    let why = st(&hub).last_error.unwrap_or_default();
    let said = format!("did not go out within {} ms", bound.as_millis());
    assert!(why.contains(&said), "{why}");

    // Reopened (after the back-off) onto the same full buffer: its first
    // heartbeat waits, and the bound ends it.
    assert!(flood_until(&hub, &mut seq, Duration::from_secs(5), || {
        st(&hub).link_opens >= 2
    }));
    let opened = Instant::now();
    assert!(flood_until(&hub, &mut seq, Duration::from_secs(5), || {
        st(&hub).link_failures >= 2
    }));
    let took = opened.elapsed();
    // Seen by polling on a loaded machine: about the bound, not at once
    // and not never.
    assert!(
        took >= bound / 2 && took <= bound + Duration::from_secs(2),
        "lost {took:?} after the reopen, the bound is {bound:?}"
    );
}

/// A stop while a write waits on a port nobody reads is honoured at once,
/// not after the write bound (68 s at 1200 baud).
#[test]
fn a_stop_is_honoured_while_a_serial_write_waits() {
    let (_dir, ap, hub, s) = silent_autopilot(1200);
    assert!(write_bound(1200) > Duration::from_secs(60));
    let running = spawn_mavlink(s, hub.clone());

    // Stuck: poses keep being offered and heartbeats keep being due, but
    // nothing more goes out for 300 ms, and the link was never lost.
    let sent = |hub: &Hub| (0..3).map(|k| hub.mavlink.sent(k)).sum::<u64>();
    let (mut seq, mut last, mut since) = (0, 0, Instant::now());
    let stuck = flood_until(&hub, &mut seq, Duration::from_secs(10), || {
        let now = sent(&hub);
        if now != last {
            (last, since) = (now, Instant::now());
        }
        now > 0 && since.elapsed() > Duration::from_millis(300)
    });
    let st = hub.mavlink.status(Instant::now());
    assert!(stuck, "{st:?}");
    assert_eq!(st.link_failures, 0, "{st:?}");

    // The stop, on another thread: a task that ignored it would hang.
    let (done_tx, done_rx) = std::sync::mpsc::channel();
    let stopping = Instant::now();
    std::thread::spawn(move || {
        drop(running);
        let _ = done_tx.send(());
    });
    let stopped = done_rx.recv_timeout(Duration::from_secs(10));
    assert!(
        stopped.is_ok(),
        "the task did not stop within 10 s of the stop while a write waited"
    );
    // At once, not after the bound (68 s); a loaded machine's margin.
    assert!(
        stopping.elapsed() < Duration::from_secs(3),
        "{:?}",
        stopping.elapsed()
    );
    drop(ap);
}
