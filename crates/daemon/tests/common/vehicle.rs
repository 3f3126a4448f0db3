//! The vehicle tests' shared parts: a log with no reading of its own (no
//! attitude, depth, temperature or velocity; truth kept), a daemon config
//! that replays it at its recorded pace as a MAVLink component, free
//! ports, and a stand-in autopilot in Rust (lightpose-vehicle's `standin`)
//! that sends the log's truth in step with the replay and collects what
//! the daemon sends back.

use super::root;
use lightpose_core::{LogHeader, LogWriter, Pose};
use lightpose_sim::{Scene, Simulator, Trajectory};
use lightpose_vehicle::mav::inbound::DepthSource;
use lightpose_vehicle::mav::outbound::{Encoder, VisionPosition};
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::mav::signing::SigningConfig;
use lightpose_vehicle::standin::{
    autopilot_heartbeat, autopilot_messages, decode, ErrorStats, Received, SensorState,
};
use lightpose_vehicle::Site;
use mavlink::MavlinkVersion;
use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::time::{Duration, Instant};

/// The `[site]` of these tests.
pub const HEADING_DEG: f64 = 30.0;
pub const BEACON_DEPTH_M: f64 = 3.0;
/// The water temperature the stand-in reports.
pub const WATER_C: f64 = 18.5;

pub fn site() -> Site {
    Site::new(lightpose_core::Angle::from_deg(HEADING_DEG), BEACON_DEPTH_M)
}

/// A UDP port nobody uses now (the config refuses port 0): bound on
/// loopback, then let go.
pub fn free_port() -> u16 {
    let s = UdpSocket::bind("127.0.0.1:0").expect("bind :0");
    s.local_addr().expect("addr").port()
}

/// Simulate the tank along the zigzag for `seconds` at `rate_hz` and write
/// the frames without any reading of their own; the truth of each frame
/// (t, pose).
pub fn write_bare_log(path: &Path, rate_hz: f64, seconds: f64) -> Vec<(f64, Pose)> {
    let mut scene = Scene::load(&root().join("config/scenes/tank.toml")).expect("scene");
    scene.adc.rate_hz = rate_hz;
    let traj = Trajectory::load(&root().join("config/trajectories/zigzag.csv")).expect("traj");
    let header = LogHeader::new(scene.adc.bits, rate_hz);
    let file = std::fs::File::create(path).expect("create log");
    let mut w = LogWriter::new(std::io::BufWriter::new(file), &header).expect("header");
    let mut sim = Simulator::new(scene, 11);
    let mut truth = Vec::new();
    for (seq, t) in traj.frame_times(rate_hz).enumerate() {
        if t > traj.t0() + seconds {
            break;
        }
        let mut f = sim.frame_moving(seq as u64, t, &traj.kinematics(t));
        (f.temp_c, f.attitude, f.depth, f.velocity) = (None, None, None, None);
        let pose = f.truth.expect("the simulator gives the truth").pose;
        truth.push((t, pose));
        w.write_frame(&f).expect("write frame");
    }
    w.flush().expect("flush");
    truth
}

/// The daemon replaying `log` at its recorded pace, POSE and STATUS to
/// `dest`, a MAVLink component on `connection`, plus `extra` TOML.
pub fn mavlink_config(log: &Path, dest: SocketAddr, connection: &str, extra: &str) -> String {
    format!(
        "rate_hz = 20.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"recorded\"\n[outputs]\ndestinations = [\"{dest}\"]\nstatus_interval_s = 0.2\n[site]\nbeacon_heading_deg = {HEADING_DEG}\nbeacon_depth_m = {BEACON_DEPTH_M}\n[mavlink]\nconnection = \"{connection}\"\n{extra}\n",
        root().join("config/calibration/tank.toml").display(),
        log.display()
    )
}

/// The truth at `t`, linear between the log's frames (clamped at the ends).
pub fn truth_at(truth: &[(f64, Pose)], t: f64) -> Pose {
    let k = truth.partition_point(|(tk, _)| *tk <= t);
    if k == 0 {
        return truth[0].1;
    }
    if k >= truth.len() {
        return truth[truth.len() - 1].1;
    }
    let ((t0, a), (t1, b)) = (truth[k - 1], truth[k]);
    let w = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
    let lerp = |u: f64, v: f64| u + w * (v - u);
    Pose::new(
        lerp(a.x, b.x),
        lerp(a.y, b.y),
        lerp(a.z, b.z),
        lightpose_core::Angle::from_deg(lerp(a.pitch.deg(), b.pitch.deg())),
        lightpose_core::Angle::from_deg(lerp(a.yaw.deg(), b.yaw.deg())),
    )
}

/// What the Rust stand-in saw.
#[derive(Debug, Default)]
pub struct Heard {
    pub positions: Vec<VisionPosition>,
    pub heartbeats: usize,
    /// Frames that were not MAVLink 2, or failed their CRC, or unknown.
    pub not_v2: usize,
    pub bad: usize,
    /// With signing: frames without the key's good signature.
    pub refused_signature: usize,
}

/// A stand-in autopilot on `sock`, talking to `daemon` (its `udpin`
/// address) or, when `None`, to whoever sends to it first (a daemon on
/// `udpout`). Every 20 ms it sends ATTITUDE, GLOBAL_POSITION_INT (the
/// daemon's default depth) and SCALED_PRESSURE2 of the truth at the log
/// time the daemon is capturing, and an autopilot HEARTBEAT every second
/// (before every batch until the daemon answers). The log's time is read off the daemon's own
/// messages: the least (arrival − usec) of its VISION_POSITION_ESTIMATEs
/// (each arrives after its capture, so the least is the closest), before
/// the first of them its first heartbeat (sent as it starts), and before
/// that the log's start. Ends `quiet` after the last message heard, or at
/// `deadline`.
pub fn stand_in(
    sock: &UdpSocket,
    daemon: Option<SocketAddr>,
    truth: &[(f64, Pose)],
    quiet: Duration,
    deadline: Duration,
) -> Heard {
    stand_in_signed(sock, daemon, truth, quiet, deadline, None)
}

/// [`stand_in`] as an autopilot with MAVLink 2 signing: what it sends is
/// signed, and what it gets is checked (refusals counted, not read).
pub fn stand_in_signed(
    sock: &UdpSocket,
    daemon: Option<SocketAddr>,
    truth: &[(f64, Pose)],
    quiet: Duration,
    deadline: Duration,
    signing: Option<SigningConfig>,
) -> Heard {
    sock.set_read_timeout(Some(Duration::from_millis(5)))
        .expect("timeout");
    let site = site();
    let mut scan = Scanner::new(Framing::Datagram);
    let mut enc = Encoder::new(1, 1).signed(signing);
    let (start, mut heard) = (Instant::now(), Heard::default());
    let (mut peer, mut origin, mut last_rx): (
        Option<SocketAddr>,
        Option<Instant>,
        Option<Instant>,
    ) = (daemon, None, None);
    let (mut next_send, mut next_beat) = (Instant::now(), Instant::now());
    let mut buf = [0u8; 4096];
    while start.elapsed() < deadline && last_rx.is_none_or(|l| l.elapsed() < quiet) {
        if let Ok((n, from)) = sock.recv_from(&mut buf) {
            let now = Instant::now();
            (peer, last_rx) = (peer.or(Some(from)), Some(now));
            scan.push(&buf[..n]);
            while let Some(s) = scan.next_frame() {
                let Scanned::Frame(f) = s else {
                    heard.bad += 1;
                    continue;
                };
                if f.version != MavlinkVersion::V2 {
                    heard.not_v2 += 1;
                }
                if enc
                    .signer_mut()
                    .is_some_and(|sg| sg.check(f.bytes).is_err())
                {
                    heard.refused_signature += 1;
                    continue;
                }
                match decode(&f) {
                    Some(Received::Position(p)) => {
                        let o = now - Duration::from_micros(p.usec);
                        origin = Some(origin.map_or(o, |x: Instant| x.min(o)));
                        heard.positions.push(p);
                    }
                    Some(Received::Heartbeat { .. }) => {
                        heard.heartbeats += 1;
                        origin = origin.or(Some(now));
                    }
                    _ => {}
                }
            }
            scan.end_of_datagram();
        }
        let Some(to) = peer else { continue };
        let now = Instant::now();
        if now >= next_send {
            next_send = now + Duration::from_millis(20);
            // A heartbeat every second, and before every batch until the
            // daemon answers: it takes readings only from an autopilot it
            // has heard and answers only then, so a first heartbeat lost
            // to a daemon not yet bound would leave its first second
            // without readings and this clock a second behind the replay.
            if origin.is_none() || now >= next_beat {
                next_beat = now + Duration::from_secs(1);
                let _ = sock.send_to(enc.encode(&autopilot_heartbeat()), to);
            }
            let t = origin.map_or(0.0, |o| now.saturating_duration_since(o).as_secs_f64());
            let state = SensorState::of(&site, &truth_at(truth, t), Some(WATER_C));
            let ms = start.elapsed().as_millis() as u32;
            for m in autopilot_messages(&state, DepthSource::GlobalPositionInt, ms) {
                let _ = sock.send_to(enc.encode(&m), to);
            }
        }
    }
    heard
}

/// Errors of the received poses against the truth of their frames (after
/// `skip_s` of log time), and how many of those frames got one.
pub fn judge(
    heard: &[VisionPosition],
    truth: &[(f64, Pose)],
    skip_s: f64,
) -> (ErrorStats, usize, usize) {
    let site = site();
    let mut stats = ErrorStats::default();
    let frames: Vec<&(f64, Pose)> = truth
        .iter()
        .filter(|(t, _)| *t >= truth[0].0 + skip_s)
        .collect();
    let mut covered = 0;
    for (t, pose) in &frames {
        let usec = (t * 1e6).round() as u64;
        if let Some(p) = heard.iter().find(|p| p.usec.abs_diff(usec) <= 1) {
            covered += 1;
            let est = lightpose_vehicle::NedPose {
                position: p.position,
                roll: p.roll,
                pitch: p.pitch,
                heading: p.heading,
            };
            stats.push(&est, &site.pose_ned(pose));
        }
    }
    (stats, covered, frames.len())
}
