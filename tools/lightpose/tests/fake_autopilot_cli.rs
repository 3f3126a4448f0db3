//! `lightpose fake-autopilot` end to end on loopback, with the test in the
//! daemon's place: what the stand-in sends must read (through the vehicle
//! crate's reader) as the trajectory's attitude, depth and temperature, and
//! the errors it prints for the estimates it gets back must be those of the
//! estimates: zero for the truth, 1 m north for ones moved 1 m north. And
//! its numbers out of range are refused, not a panic.

mod common;

use common::{lightpose, root};
use lightpose_core::Angle;
use lightpose_sim::Trajectory;
use lightpose_vehicle::mav::inbound::{interpret, Input, InputConfig};
use lightpose_vehicle::mav::outbound::{vision_position, Encoder, Outgoing, OutputConfig};
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::Site;
use mavlink::dialects::ardupilotmega::{GLOBAL_POSITION_INT_DATA, VFR_HUD_DATA};
use mavlink::MessageData;
use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

#[test]
fn the_stand_in_autopilot_sends_the_truth_and_judges_what_comes_back() {
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let port = sock.local_addr().unwrap().port();
    let (scene, traj) = (
        root().join("config/scenes/tank.toml"),
        root().join("config/trajectories/dive.csv"),
    );
    let child = Command::new(env!("CARGO_BIN_EXE_lightpose"))
        .args(["fake-autopilot", "--scene"])
        .arg(&scene)
        .arg("--trajectory")
        .arg(&traj)
        .args(["--connect", &format!("udpout:127.0.0.1:{port}")])
        .args(["--duration", "2.5", "--clock", "own", "--rate", "20"])
        .args([
            "--pitch-noise-deg",
            "0",
            "--yaw-noise-deg",
            "0",
            "--depth-noise-m",
            "0",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .expect("lightpose runs");

    // What it sends: the dive (yaw 0, pitch 10° → 8.7°, z 0 → 0.22 m) in
    // water at the scene's 20 °C, read as the daemon would. The depth goes
    // as the daemon's default takes it: GLOBAL_POSITION_INT.relative_alt,
    // mm, negative below the surface (2.78 to 3 m under a beacon 3 m
    // deep), and no VFR_HUD.
    let site = Site::new(Angle::from_deg(30.0), 3.0);
    let mut sc = Scanner::new(Framing::Datagram);
    let mut buf = [0u8; 2048];
    let (mut seen, mut tool) = ([false; 3], None);
    let start = Instant::now();
    while !seen.iter().all(|s| *s) && start.elapsed() < Duration::from_secs(10) {
        let (n, from) = sock.recv_from(&mut buf).expect("the stand-in sends");
        tool = Some(from);
        sc.push(&buf[..n]);
        while let Some(Scanned::Frame(f)) = sc.next_frame() {
            assert_ne!(f.msg_id, VFR_HUD_DATA::ID, "VFR_HUD by default");
            if f.msg_id == GLOBAL_POSITION_INT_DATA::ID {
                let m = GLOBAL_POSITION_INT_DATA::deser(f.version, f.payload).unwrap();
                assert!(
                    (-3000..=-2780).contains(&m.relative_alt),
                    "relative_alt {} mm",
                    m.relative_alt
                );
            }
            match interpret(&f, &InputConfig::default(), &site).unwrap() {
                Input::Attitude(a, _) => {
                    assert!(a.yaw.deg().abs() < 1e-4, "yaw in B {}", a.yaw.deg());
                    assert!(
                        (8.6..=10.01).contains(&a.pitch.deg()),
                        "pitch {}",
                        a.pitch.deg()
                    );
                    seen[0] = true;
                }
                Input::Depth(d) => {
                    assert!((-0.01..=0.25).contains(&d.z), "z {}", d.z);
                    seen[1] = true;
                }
                Input::Temperature(t) => {
                    assert_eq!(t, 20.0);
                    seen[2] = true;
                }
                _ => {}
            }
        }
        sc.end_of_datagram();
    }
    assert!(seen.iter().all(|s| *s), "{seen:?}");

    // What it gets back: 20 estimates at the truth, 2 of them 1 m north,
    // and one at a time the 8 s dive never reaches (not judged).
    let traj = Trajectory::load(&traj).unwrap();
    let mut enc = Encoder::new(1, 197);
    for k in 0..21u64 {
        let t = if k == 20 { 50.0 } else { 0.5 + 0.1 * k as f64 };
        let pose = traj.kinematics(t).pose;
        let o = Outgoing {
            seq: k,
            t,
            pose,
            surge: None,
            std: [Some(0.1); 6],
            roll_std: None,
            epoch: 0,
        };
        let mut v = vision_position(&o, &site, &OutputConfig::default()).unwrap();
        if k % 10 == 3 {
            v.position.0[0] += 1.0;
        }
        sock.send_to(enc.encode(&v.message().unwrap()), tool.unwrap())
            .unwrap();
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let summary = stdout.lines().last().unwrap_or_default();
    assert!(
        summary.contains("received 21 VISION_POSITION_ESTIMATE (1 off"),
        "{stdout}"
    );
    assert!(
        summary.contains(
            "p95 over 20: north 1.000 m, east 0.000 m, down 0.000 m, pitch 0.00°, heading 0.00°"
        ),
        "{summary}"
    );
}

/// Listening (`udpin`) with no daemon to answer, it sends nothing and says
/// so (it said "sent 11 sets" that went nowhere).
#[test]
fn with_no_peer_nothing_is_counted_as_sent() {
    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let out = Command::new(env!("CARGO_BIN_EXE_lightpose"))
        .args(["fake-autopilot", "--scene"])
        .arg(root().join("config/scenes/tank.toml"))
        .arg("--trajectory")
        .arg(root().join("config/trajectories/dive.csv"))
        .args(["--connect", &format!("udpin:127.0.0.1:{port}")])
        .args(["--duration", "1"])
        .output()
        .expect("runs");
    let said = String::from_utf8_lossy(&out.stdout) + String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("sent 0 sets of sensor messages"), "{said}");
}

/// Audit: `--rate 1e-20` passed the `rate > 0` check and panicked making
/// its period (exit 101). Every number of fake-autopilot is refused out of
/// its range at once, in one line naming the option and the bound (exit 1,
/// as its other number checks), before any file is read or socket opened;
/// the bounds themselves are taken.
#[test]
fn numbers_out_of_range_are_refused_with_their_bound() {
    let (scene, traj) = (
        root().join("config/scenes/tank.toml"),
        root().join("config/trajectories/dive.csv"),
    );
    let base = [
        "fake-autopilot",
        "--scene",
        scene.to_str().expect("utf-8 path"),
        "--trajectory",
        traj.to_str().expect("utf-8 path"),
        "--connect",
        "udpout:127.0.0.1:9",
    ];
    let rate = "--rate {}: must be 0.01 to 1000 Hz";
    for (arg, want) in [
        ("--rate=1e-20", rate.replace("{}", "0.00000000000000000001")),
        ("--rate=0.001", rate.replace("{}", "0.001")),
        ("--rate=1000.5", rate.replace("{}", "1000.5")),
        ("--rate=0", rate.replace("{}", "0")),
        ("--rate=-5", rate.replace("{}", "-5")),
        ("--rate=NaN", rate.replace("{}", "NaN")),
        ("--rate=inf", rate.replace("{}", "inf")),
        (
            "--beacon-depth-m=-1",
            "--beacon-depth-m: -1 is not within 0..11000".into(),
        ),
        (
            "--beacon-heading-deg=inf",
            "--beacon-heading-deg: inf is not within -360..360".into(),
        ),
    ] {
        let mut a = base.to_vec();
        a.push(arg);
        let r = lightpose(&a, Duration::from_secs(20));
        assert_eq!(r.code, Some(1), "{arg}: {}", r.err);
        assert_eq!(r.err.lines().count(), 1, "{arg}: {}", r.err);
        assert!(r.err.starts_with("lightpose: "), "{arg}: {}", r.err);
        assert!(r.err.contains(&want), "{arg}: {:?} lacks {want:?}", r.err);
    }
    for arg in ["--rate=0.01", "--rate=1000"] {
        let mut a = base.to_vec();
        a.extend([arg, "--duration", "0.2"]);
        let r = lightpose(&a, Duration::from_secs(20));
        assert_eq!(r.code, Some(0), "{arg}: {}", r.err);
    }
    // Without --rate: 10 Hz, the ATTITUDE stream the README asks of an
    // autopilot, not the tank scene's 5 Hz frame rate (an audit).
    let mut a = base.to_vec();
    a.extend(["--duration", "0.2"]);
    let r = lightpose(&a, Duration::from_secs(20));
    assert_eq!(r.code, Some(0), "{}", r.err);
    assert!(r.err.contains(", 10 Hz,"), "{}", r.err);
}

/// With `--signing-passphrase-file` every frame it sends carries a good
/// signature of that passphrase's key (what a signed autopilot sends); a
/// key file that is not there is one line naming the option.
#[test]
fn a_signing_stand_in_signs_what_it_sends() {
    use lightpose_vehicle::mav::signing::{SigningConfig, SigningKey};
    let dir = tempfile::tempdir().unwrap();
    let pass = dir.path().join("mav.pass");
    std::fs::write(&pass, "desk check\n").unwrap();
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let port = sock.local_addr().unwrap().port();
    let mut child = Command::new(env!("CARGO_BIN_EXE_lightpose"))
        .args(["fake-autopilot", "--scene"])
        .arg(root().join("config/scenes/tank.toml"))
        .arg("--trajectory")
        .arg(root().join("config/trajectories/dive.csv"))
        .args(["--connect", &format!("udpout:127.0.0.1:{port}")])
        .args(["--duration", "3", "--rate", "20"])
        .arg("--signing-passphrase-file")
        .arg(&pass)
        .stdout(Stdio::null())
        .spawn()
        .expect("lightpose runs");
    let mut signer = lightpose_vehicle::mav::signing::Signer::new(SigningConfig {
        key: SigningKey::from_passphrase("desk check"),
        link_id: 0,
        allow_unsigned: false,
    });
    let (mut sc, mut buf, mut good) = (Scanner::new(Framing::Datagram), [0u8; 2048], 0);
    while good < 20 {
        let (n, _) = sock.recv_from(&mut buf).expect("the stand-in sends");
        sc.push(&buf[..n]);
        while let Some(ev) = sc.next_frame() {
            let Scanned::Frame(f) = ev else {
                panic!("a bad frame: {ev:?}")
            };
            assert_eq!(signer.check(f.bytes), Ok(()), "message {}", f.msg_id);
            good += 1;
        }
        sc.end_of_datagram();
    }
    assert!(child.wait().unwrap().success());
    let out = Command::new(env!("CARGO_BIN_EXE_lightpose"))
        .args(["fake-autopilot", "--scene"])
        .arg(root().join("config/scenes/tank.toml"))
        .arg("--trajectory")
        .arg(root().join("config/trajectories/dive.csv"))
        .arg("--signing-key-file")
        .arg(dir.path().join("absent.key"))
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("--signing-key-file:") && err.contains("absent.key"),
        "{err}"
    );
}
