//! MAVLink over TCP (`tcpout`, `tcpin`: what mavlink-router and BlueOS
//! offer) against pymavlink 2.4.50 (tools/pyenv.sh) as the autopilot, over
//! real TCP on loopback: frames cross both ways on a stream; a `tcpout`
//! whose server closes the connection reconnects (the task's back-off)
//! and goes on; a `tcpin` holds one connection, and a second one while the
//! first speaks is closed at once and counted.

mod common;

use common::{estimate, spawn_mavlink, wait_until, PyPeer};
use lightpose_core::Angle;
use lightpose_vehicle::{Hub, MavlinkSettings, Site};
use serde_json::Value;
use std::io::Read;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn settings(endpoint: String) -> MavlinkSettings {
    let mut s = MavlinkSettings::new(endpoint.parse().unwrap(), Site::new(Angle::ZERO, 3.0));
    s.heartbeat_period = Duration::from_millis(50);
    s.reopen_max = Duration::from_millis(200);
    s
}

/// Play the frame thread (an `ok` pose every 10 ms) until the peer's
/// summary comes.
fn until_done(hub: &Arc<Hub>, peer: &PyPeer, timeout: Duration) -> Value {
    let start = Instant::now();
    for k in 0u64.. {
        hub.outbox.offer(&estimate(k, 1000.0 + k as f64 * 0.01), 0);
        if let Ok(v) = peer.lines.recv_timeout(Duration::from_millis(10)) {
            if v.get("done").is_some() {
                return v;
            }
        }
        assert!(start.elapsed() < timeout, "no summary from the peer");
    }
    unreachable!()
}

#[test]
fn tcpout_to_a_pymavlink_server_reconnects_when_it_closes() {
    let args = ["server", "20", "30", "10"].map(String::from);
    let mut peer = PyPeer::spawn_script("tcp_peer.py", &args, &[]);
    let hub = Hub::new();
    let task = spawn_mavlink(
        settings(format!("tcpout:127.0.0.1:{}", peer.port)),
        hub.clone(),
    );
    let done = until_done(&hub, &peer, Duration::from_secs(60));
    let st = hub.mavlink.status(Instant::now());
    drop(task);
    assert!(peer.child.wait().expect("python ends").success());
    // The first connection closed after 10 estimates, the second got 20.
    let per = done["positions"].as_array().expect("positions");
    assert_eq!(per.len(), 2, "{done}");
    assert!(
        per[0].as_u64() >= Some(10) && per[1].as_u64() >= Some(20),
        "{done}"
    );
    assert_eq!(
        (done["bad_data"].as_u64(), done["receive_errors"].as_u64()),
        (Some(0), Some(0))
    );
    assert!(st.link_opens >= 2 && st.link_failures >= 1, "{st:?}");
    // pymavlink's heartbeats and attitudes (one of each every 50 ms) were
    // read off the stream.
    assert!(
        hub.mavlink.used(0) >= 2 && hub.mavlink.used(3) >= 2,
        "{st:?}"
    );
    assert_eq!((st.refused.len(), st.garbage_bytes), (0, 0), "{st:?}");
    let a = hub
        .readings
        .attitude(Instant::now(), Duration::from_secs(60))
        .expect("attitude");
    assert!((a.pitch.rad() - 0.1).abs() < 1e-6);
}

#[test]
fn tcpin_holds_one_pymavlink_client_and_closes_a_second() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let hub = Hub::new();
    let _task = spawn_mavlink(settings(format!("tcpin:127.0.0.1:{port}")), hub.clone());
    assert!(wait_until(Duration::from_secs(5), || {
        hub.mavlink.status(Instant::now()).link_opens >= 1
    }));
    let args = ["client", &port.to_string(), "40", "30"].map(String::from);
    let mut peer = PyPeer::spawn_script("tcp_peer.py", &args, &[]);
    // Once the client's frames are taken, a second connection is closed.
    assert!(wait_until(Duration::from_secs(10), || hub.mavlink.used(0) >= 3));
    let mut second = std::net::TcpStream::connect(("127.0.0.1", port)).expect("connects");
    second
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut buf = [0u8; 64];
    assert_eq!(second.read(&mut buf).ok(), Some(0), "closed without a byte");
    let done = until_done(&hub, &peer, Duration::from_secs(60));
    assert!(peer.child.wait().expect("python ends").success());
    assert!(done["positions"][0].as_u64() >= Some(40), "{done}");
    assert_eq!(done["bad_data"], 0, "{done}");
    let st = hub.mavlink.status(Instant::now());
    assert!(st.refused_connections >= 1, "{st:?}");
    assert!(st.peer.is_some(), "{st:?}");
}
