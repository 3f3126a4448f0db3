//! Against an independent MAVLink implementation (pymavlink 2.4.50 from
//! tools/pyenv.sh), over real UDP on loopback: what we send must decode in
//! pymavlink as MAVLink 2 with valid CRCs and the values FORMATS.md says;
//! what pymavlink encodes must give us the readings it stands for.

mod common;

use common::{estimate, spawn_mavlink, wait_until, PyPeer};
use lightpose_core::Angle;
use lightpose_vehicle::mav::inbound::DepthSource;
use lightpose_vehicle::{Hub, MavlinkSettings, NedVec, Site};
use serde_json::Value;
use std::time::{Duration, Instant};

const H_DEG: f64 = 30.0;
const BEACON_NED: [f64; 3] = [10.0, -5.0, 1.0];
/// Spec v3: the estimates sent carry a roll and its σ (common::estimate
/// has none, a v2 estimate's roll 0 and configured σ are the unit tests').
const ROLL_DEG: f64 = -6.0;
const ROLL_STD_DEG: f64 = 0.7;

fn site() -> Site {
    let mut s = Site::new(Angle::from_deg(H_DEG), 3.0);
    s.beacon_ned = NedVec(BEACON_NED);
    s
}

fn close(got: &Value, want: f64, tol: f64, what: &str) {
    let g = got
        .as_f64()
        .unwrap_or_else(|| panic!("{what}: {got} is not a number"));
    assert!((g - want).abs() <= tol, "{what}: got {g}, want {want}");
}

/// The test pose (common::estimate) in NED, worked out by hand from
/// FORMATS.md: N = x cos h + y sin h, E = x sin h − y cos h, D = −z, plus
/// the beacon's position; heading h + 180° + yaw.
fn expected_position() -> ([f64; 3], f64) {
    let (s, c) = H_DEG.to_radians().sin_cos();
    let (x, y, z) = (5.0, 1.0, 0.5);
    let n = [
        BEACON_NED[0] + x * c + y * s,
        BEACON_NED[1] + x * s - y * c,
        BEACON_NED[2] - z,
    ];
    (n, (H_DEG + 180.0 - 20.0 - 360.0).to_radians())
}

/// The 21-element upper triangle, by hand: the horizontal block turned by
/// h, the rest on the diagonal (roll: the estimate's σ, [`ROLL_STD_DEG`]).
fn expected_covariance() -> [f64; 21] {
    let (s, c) = H_DEG.to_radians().sin_cos();
    let (vx, vy) = (0.2f64.powi(2), 0.05f64.powi(2));
    let mut u = [0.0; 21];
    u[0] = c * c * vx + s * s * vy; // NN
    u[1] = c * s * (vx - vy); // NE
    u[6] = s * s * vx + c * c * vy; // EE
    u[11] = 0.03f64.powi(2); // DD
    u[15] = ROLL_STD_DEG.to_radians().powi(2); // roll
    u[18] = 1f64.to_radians().powi(2); // pitch
    u[20] = 2f64.to_radians().powi(2); // yaw
    u
}

#[test]
fn pymavlink_reads_what_we_send_and_we_read_what_it_sends() {
    let peer = PyPeer::spawn(&["20".into(), "20".into()], &[]);
    let (mut child, rx, reader, port) = (peer.child, peer.lines, peer.reader, peer.port);
    let endpoint = format!("udpout:127.0.0.1:{port}").parse().unwrap();

    // Two components on the same autopilot: depth from GLOBAL_POSITION_INT
    // (197, the default) and from VFR_HUD (198).
    let hub_a = Hub::new();
    let mut sa = MavlinkSettings::new(endpoint, site());
    sa.heartbeat_period = Duration::from_millis(100);
    let mut sb = sa.clone();
    sb.component_id = 198;
    sb.input.depth = DepthSource::VfrHud;
    let hub_b = Hub::new();
    let _a = spawn_mavlink(sa, hub_a.clone());
    let _b = spawn_mavlink(sb, hub_b.clone());

    // Play the frame thread: an ok pose every 10 ms, epoch 3.
    let mut lines = Vec::new();
    let t0 = 1000.0;
    let start = Instant::now();
    for k in 0u64.. {
        let mut e = estimate(k, t0 + k as f64 * 0.01);
        (e.roll_deg, e.std.roll) = (Some(ROLL_DEG), Some(ROLL_STD_DEG));
        hub_a.outbox.offer(&e, 3);
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(10)) {
            let done = v.get("done").is_some();
            lines.push(v);
            if done {
                break;
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no end: {lines:?}"
        );
    }
    lines.extend(rx.try_iter());
    reader.join().unwrap();
    assert!(child.wait().unwrap().success());

    let done = lines.last().unwrap();
    assert_eq!(done["bad_data"], 0, "{done}");
    assert_eq!(done["receive_errors"], 0, "{done}");
    check_positions(&lines, t0);
    check_speeds(&lines);
    check_heartbeats_and_sequence(&lines);
    check_readings(&hub_a, &hub_b);
}

fn of_type<'a>(lines: &'a [Value], t: &str) -> Vec<&'a Value> {
    lines.iter().filter(|l| l["type"] == t).collect()
}

fn check_positions(lines: &[Value], t0: f64) {
    let pos = of_type(lines, "VISION_POSITION_ESTIMATE");
    assert!(pos.len() >= 20, "{} positions", pos.len());
    let (ned, heading) = expected_position();
    let cov = expected_covariance();
    for m in pos {
        assert_eq!(
            (m["sys"].as_u64(), m["comp"].as_u64()),
            (Some(1), Some(197))
        );
        assert_eq!(m["v2"], true);
        let f = &m["fields"];
        // usec is the capture time t = t0 + k·0.01 s in µs.
        let us = f["usec"].as_u64().unwrap();
        let k = ((us as f64 * 1e-6 - t0) / 0.01).round();
        assert_eq!(us, ((t0 + k * 0.01) * 1e6).round() as u64);
        for (key, want) in ["x", "y", "z"].iter().zip(ned) {
            close(&f[*key], want, 1e-5, key);
        }
        close(&f["roll"], ROLL_DEG.to_radians(), 1e-6, "roll");
        close(&f["pitch"], 10f64.to_radians(), 1e-6, "pitch");
        close(&f["yaw"], heading, 1e-6, "yaw");
        let c = f["covariance"].as_array().unwrap();
        assert_eq!(c.len(), 21);
        for (i, (g, w)) in c.iter().zip(cov).enumerate() {
            close(g, w, 1e-6 * w.abs().max(1e-3), &format!("covariance[{i}]"));
        }
        assert_eq!(f["reset_counter"], 3);
    }
}

fn check_speeds(lines: &[Value]) {
    let sp = of_type(lines, "VISION_SPEED_ESTIMATE");
    assert!(!sp.is_empty());
    // Heading 190°, pitch 10°: the bow is (cosθ cos H, cosθ sin H, −sinθ).
    let (st, ct) = 10f64.to_radians().sin_cos();
    let (sh, chh) = 190f64.to_radians().sin_cos();
    let v = [0.4 * ct * chh, 0.4 * ct * sh, -0.4 * st];
    for m in sp {
        let f = &m["fields"];
        for (key, want) in ["x", "y", "z"].iter().zip(v) {
            close(&f[*key], want, 1e-6, key);
        }
        let c: Vec<f64> = f["covariance"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(c.len(), 9);
        for i in 0..3 {
            assert!(c[4 * i] > 0.0);
            for j in 0..3 {
                assert!((c[3 * i + j] - c[3 * j + i]).abs() < 1e-9);
            }
        }
        assert_eq!(f["reset_counter"], 3);
    }
}

fn check_heartbeats_and_sequence(lines: &[Value]) {
    let hb: Vec<_> = of_type(lines, "HEARTBEAT")
        .into_iter()
        .filter(|m| m["comp"] == 197)
        .collect();
    assert!(hb.len() >= 2);
    for m in &hb {
        let f = &m["fields"];
        assert_eq!(f["type"], 18, "MAV_TYPE_ONBOARD_CONTROLLER");
        assert_eq!(f["autopilot"], 8, "MAV_AUTOPILOT_INVALID");
        assert_eq!(f["mavlink_version"], 3);
    }
    assert!(
        hb.iter().any(|m| m["fields"]["system_status"] == 4),
        "ACTIVE while poses flow"
    );
    // One sequence per component, +1 per message. UDP on a loaded machine
    // drops datagrams before the Python reader gets them: a forward gap,
    // of any size (CI saw runs of 100-150 lost, so a gap mod 256 can look
    // like a step back); loopback may also swap two (a sender whose thread
    // moves to another core between two sends). The 8-bit number cannot
    // tell a long gap from a step back, so what is checked is what it can
    // tell: no number sent twice in a row, and most steps +1.
    let seqs: Vec<u64> = lines
        .iter()
        .filter(|l| l["comp"] == 197)
        .map(|l| l["seq"].as_u64().unwrap())
        .collect();
    let steps = sequence_steps(&seqs);
    assert!(
        steps.iter().all(|&s| s != 0),
        "a sequence number repeated: {seqs:?}"
    );
    let ones = steps.iter().filter(|&&s| s == 1).count();
    assert!(
        ones * 10 >= steps.len() * 9,
        "{ones} of {} steps are +1: {seqs:?}",
        steps.len()
    );
}

/// Each step of the 8-bit sequence, mod 256 (0: a repeat).
fn sequence_steps(seqs: &[u64]) -> Vec<u64> {
    seqs.windows(2).map(|w| (w[1] + 256 - w[0]) % 256).collect()
}

#[test]
fn a_sequence_step_counts_across_255_and_a_repeat_is_0() {
    assert_eq!(sequence_steps(&[254, 255, 1, 1, 0]), vec![1, 2, 0, 255]);
}

fn check_readings(hub_a: &Hub, hub_b: &Hub) {
    let ok = wait_until(Duration::from_secs(5), || {
        hub_b
            .readings
            .depth(Instant::now(), Duration::from_secs(60))
            .is_some()
    });
    assert!(ok);
    let (now, age) = (Instant::now(), Duration::from_secs(60));
    for hub in [hub_a, hub_b] {
        let a = hub.readings.attitude(now, age).expect("attitude");
        assert!((a.pitch.rad() - 0.1).abs() < 1e-7);
        // −160° − 30° − 180° = −370° ≡ −10° in B.
        assert!((a.yaw.deg() + 10.0).abs() < 1e-5, "{}", a.yaw.deg());
        // Spec v3: ATTITUDE's roll (0.05 rad) reaches the reading.
        let roll = a.roll.expect("roll").rad();
        assert!((roll - 0.05).abs() < 1e-7, "{roll}");
        let t = hub.readings.temperature(now, age).expect("temperature");
        assert!((t - 12.34).abs() < 1e-9);
        let st = hub.mavlink.status(now);
        assert!(st.refused.is_empty(), "{:?}", st.refused);
        assert!(st.autopilot_heartbeat_age_s.is_some());
        assert_eq!(st.garbage_bytes, 0);
    }
    // 2.6 m deep (GLOBAL_POSITION_INT, mm) and 2.5 m deep (VFR_HUD) under
    // a beacon 3 m deep: z = 0.4 and 0.5 m.
    let za = hub_a.readings.depth(now, age).unwrap().z;
    let zb = hub_b.readings.depth(now, age).unwrap().z;
    assert!((za - 0.4).abs() < 1e-9, "{za}");
    assert!((zb - 0.5).abs() < 1e-6, "{zb}");
}

/// Issue 44: the daemon did not answer TIMESYNC, so PX4 could not map
/// `usec` to its clock. pymavlink, as the autopilot, asks every 50 ms
/// (tc1 = 0, ts1 = its CLOCK_MONOTONIC in ns); each answer echoes a ts1
/// it sent, and its tc1 (our time in ns) lies between the request and the
/// answer on the same clock, the one live frames are stamped on.
#[test]
fn timesync_requests_are_answered_with_our_time_in_ns() {
    let peer = PyPeer::spawn_script("timesync_peer.py", &["5".into(), "20".into()], &[]);
    let (mut child, rx, reader, port) = (peer.child, peer.lines, peer.reader, peer.port);
    let mut s = MavlinkSettings::new(format!("udpout:127.0.0.1:{port}").parse().unwrap(), site());
    s.heartbeat_period = Duration::from_millis(100);
    let hub = Hub::new();
    let task = spawn_mavlink(s, hub.clone());
    let done = rx
        .recv_timeout(Duration::from_secs(40))
        .expect("the peer's summary");
    drop(task);
    assert!(child.wait().expect("python ends").success());
    reader.join().expect("reader");
    let answers = done["answers"].as_array().expect("answers");
    assert!(answers.len() >= 5, "{done}");
    assert_eq!(done["unmatched"], 0, "{done}");
    assert_eq!(done["outside"], 0, "{done}");
    assert_eq!(done["receive_errors"], 0, "{done}");
    for a in answers {
        assert_eq!(a["comp"], 197, "{a}");
        assert!(a["tc1"].as_i64().is_some_and(|t| t > 0), "{a}");
    }
    let st = hub.mavlink.status(Instant::now());
    let n = |v: &[(&str, u64)], k: &str| v.iter().find(|(name, _)| *name == k).map_or(0, |x| x.1);
    assert!(n(&st.sent, "timesync") >= 5, "{st:?}");
    assert!(n(&st.used, "timesync_request") >= 5, "{st:?}");
}
