//! MAVLink 2 signing against pymavlink 2.4.50 (tools/pyenv.sh), over real
//! UDP on loopback: with the same passphrase each side takes the other's
//! frames and pymavlink finds every frame of ours signed with the key;
//! with another key, or unsigned, nothing is taken, on either side, and
//! our STATUS counts why.

mod common;

use common::{estimate, spawn_mavlink, udpout, wait_until, PyPeer};
use lightpose_vehicle::mav::signing::{SigningConfig, SigningKey};
use lightpose_vehicle::{Hub, MavlinkSettings};
use serde_json::Value;
use std::sync::Arc;
use std::time::{Duration, Instant};

const PASSPHRASE: &str = "lightpose signing test";

fn signing(passphrase: &str, allow_unsigned: bool) -> SigningConfig {
    SigningConfig {
        key: SigningKey::from_passphrase(passphrase),
        link_id: 4,
        allow_unsigned,
    }
}

/// Run the pymavlink peer (`mav_peer.py N TIMEOUT [PASSPHRASE]`) against
/// one of our components with `settings` (its endpoint filled in), playing
/// the frame thread until the peer is done. Returns the peer's lines and
/// the hub.
fn run_peer(
    n_pos: u32,
    timeout_s: u32,
    peer_pass: Option<&str>,
    ours: Option<SigningConfig>,
) -> (Vec<Value>, Arc<Hub>) {
    let mut args = vec![n_pos.to_string(), timeout_s.to_string()];
    args.extend(peer_pass.map(str::to_string));
    let peer = PyPeer::spawn(&args, &[("MAV_PEER_COMPONENTS", "1")]);
    let (mut child, rx, reader, port) = (peer.child, peer.lines, peer.reader, peer.port);
    let mut s: MavlinkSettings = udpout(port);
    s.heartbeat_period = Duration::from_millis(100);
    s.signing = ours;
    let hub = Hub::new();
    let task = spawn_mavlink(s, hub.clone());
    let mut lines = Vec::new();
    let start = Instant::now();
    for k in 0u64.. {
        hub.outbox.offer(&estimate(k, 1000.0 + k as f64 * 0.01), 1);
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(10)) {
            let done = v.get("done").is_some();
            lines.push(v);
            if done {
                break;
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(timeout_s as u64 + 30),
            "no end: {lines:?}"
        );
    }
    lines.extend(rx.try_iter());
    reader.join().unwrap();
    assert!(child.wait().unwrap().success());
    drop(task);
    (lines, hub)
}

fn count(lines: &[Value], kind: &str) -> usize {
    lines.iter().filter(|l| l["type"] == kind).count()
}

fn refused(hub: &Hub, reason: &str) -> u64 {
    let st = hub.mavlink.status(Instant::now());
    st.refused
        .iter()
        .find(|(r, _)| *r == reason)
        .map_or(0, |(_, n)| *n)
}

#[test]
fn with_the_same_key_both_sides_take_each_others_signed_frames() {
    let (lines, hub) = run_peer(10, 20, Some(PASSPHRASE), Some(signing(PASSPHRASE, false)));
    let done = lines.last().unwrap();
    assert!(count(&lines, "VISION_POSITION_ESTIMATE") >= 10, "{done}");
    assert_eq!(done["bad_data"], 0, "{done}");
    assert_eq!(done["bad_signatures"], 0, "{done}");
    assert_eq!(done["unsigned"], 0, "{done}");
    let ours: Vec<&Value> = lines.iter().filter(|l| l["comp"] == 197).collect();
    assert!(ours.len() >= 12, "{} frames of ours", ours.len());
    assert_eq!(
        done["good_signatures"].as_u64(),
        Some(ours.len() as u64),
        "{done}"
    );
    for l in &ours {
        assert_eq!(l["signed"], true, "{l}");
        assert_eq!(l["link_id"], 4, "{l}");
    }
    // Our side took the autopilot's readings and refused nothing.
    assert!(wait_until(Duration::from_secs(5), || hub
        .readings
        .attitude(Instant::now(), Duration::from_secs(60))
        .is_some()));
    let st = hub.mavlink.status(Instant::now());
    assert!(st.refused.is_empty(), "{:?}", st.refused);
    let sg = st.signing.expect("signing in STATUS");
    assert_eq!(
        sg.key,
        SigningKey::from_passphrase(PASSPHRASE).fingerprint()
    );
    assert_eq!((sg.link_id, sg.allow_unsigned), (4, false));
}

#[test]
fn another_key_is_refused_on_both_sides() {
    let (lines, hub) = run_peer(1, 3, Some("not the key"), Some(signing(PASSPHRASE, false)));
    let done = lines.last().unwrap();
    // pymavlink drops every frame of ours (bad signature), we drop its.
    assert_eq!(count(&lines, "VISION_POSITION_ESTIMATE"), 0, "{done}");
    assert_eq!(count(&lines, "HEARTBEAT"), 0, "{done}");
    assert!(done["bad_data"].as_u64().unwrap() > 0, "{done}");
    assert!(refused(&hub, "bad_signature") > 0);
    let now = Instant::now();
    assert!(hub
        .readings
        .attitude(now, Duration::from_secs(60))
        .is_none());
    assert!(
        hub.mavlink.status(now).autopilot.is_none(),
        "no autopilot adopted"
    );
}

#[test]
fn unsigned_frames_are_refused_unless_allowed() {
    let (_, hub) = run_peer(1, 3, None, Some(signing(PASSPHRASE, false)));
    assert!(refused(&hub, "unsigned") > 0);
    let now = Instant::now();
    assert!(hub
        .readings
        .attitude(now, Duration::from_secs(60))
        .is_none());
    // Allowed (a change-over): the unsigned autopilot's readings are taken,
    // and what we send is still signed (the peer, keyless, sees the flag).
    let (lines, hub) = run_peer(5, 20, None, Some(signing(PASSPHRASE, true)));
    assert!(count(&lines, "VISION_POSITION_ESTIMATE") >= 5);
    let ours: Vec<&Value> = lines.iter().filter(|l| l["comp"] == 197).collect();
    assert!(!ours.is_empty());
    assert!(ours.iter().all(|l| l["flag_signed"] == true), "{ours:?}");
    assert!(wait_until(Duration::from_secs(5), || hub
        .readings
        .attitude(Instant::now(), Duration::from_secs(60))
        .is_some()));
    assert_eq!(refused(&hub, "unsigned"), 0);
}
