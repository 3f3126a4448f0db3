//! The ROS 2 node heard by another DDS (issue 42's done-when): in a network
//! namespace of its own (`unshare -n`; loopback up with multicast and a
//! 224.0.0.0/4 route, so that discovery never leaves it), a participant of
//! Eclipse Cyclone DDS (PyPI `cyclonedds`, pinned in
//! tests/python/requirements.txt) with ROS 2's type and topic names listens
//! to the daemon's default simulation for 10 s: pose, odom and tf at ≥ 80 %
//! of the frame rate, each pose the POSE datagram of its frame, every
//! covariance diagonal finite and positive.
//!
//! The test re-runs itself inside the namespace. Without `unshare` (or
//! without the right to make a namespace: not root) it fails with one line.

mod common;

use common::run::{signal, spawn_daemon_to, wait_exit};
use common::{root, subscriber};
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Set inside the namespace: the test's body runs.
const INSIDE: &str = "LIGHTPOSE_TEST_IN_NETNS";

/// The default simulation's frame rate (config/lightposed.toml).
const RATE_HZ: f64 = 5.0;
const LISTEN_S: f64 = 10.0;

fn run(cmd: &str, args: &[&str]) {
    let out = Command::new(cmd).args(args).output();
    match out {
        Ok(o) if o.status.success() => {}
        Ok(o) => panic!(
            "ros2 test: {cmd} {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => panic!(
            "ros2 test: cannot run {cmd} ({e}): iproute2 is needed for the namespace's loopback"
        ),
    }
}

/// True inside the namespace (loopback set up); outside, re-runs `test`
/// under `unshare -n` and judges its result.
fn in_own_network(test: &str) -> bool {
    if std::env::var_os(INSIDE).is_some() {
        run("ip", &["link", "set", "lo", "up"]);
        run("ip", &["link", "set", "lo", "multicast", "on"]);
        run("ip", &["route", "add", "224.0.0.0/4", "dev", "lo"]);
        return true;
    }
    // The venv made out here: inside there is no network for pip.
    lightpose_testkit::python::python();
    let exe = std::env::current_exe().expect("the test binary's path");
    let out = Command::new("unshare")
        .arg("-n")
        .arg(&exe)
        .args([test, "--exact", "--nocapture", "--test-threads=1"])
        .env(INSIDE, "1")
        .stdin(Stdio::null())
        .output();
    let out = match out {
        Ok(o) => o,
        Err(e) => panic!("ros2 test: cannot run unshare ({e}): util-linux's unshare -n makes the test's private network"),
    };
    let (so, se) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    if se.contains("unshare failed") || se.contains("Operation not permitted") {
        panic!(
            "ros2 test: unshare -n refused (root, or CAP_SYS_ADMIN, is needed): {}",
            se.trim()
        );
    }
    assert!(
        out.status.success() && so.contains("test result: ok. 1 passed"),
        "ros2 test inside the namespace failed:\n{so}\n{se}"
    );
    // What was measured inside, said outside.
    for l in so.lines().filter_map(|l| l.find("ros2: ").map(|i| &l[i..])) {
        println!("{l}");
    }
    false
}

fn config(dest: std::net::SocketAddr) -> String {
    let text = std::fs::read_to_string(root().join("config/lightposed.toml")).expect("config");
    assert!(text.contains("127.0.0.1:17150"), "the default destination");
    assert!(
        text.contains(&format!("rate_hz = {RATE_HZ:.1}")),
        "the default rate"
    );
    let text = text.replace("127.0.0.1:17150", &dest.to_string());
    format!("{text}\n[ros2]\nnetworks = [\"127.0.0.1\"]\n")
}

fn wait_child(c: &mut std::process::Child, within: Duration) -> std::process::ExitStatus {
    let t0 = Instant::now();
    loop {
        if let Some(s) = c.try_wait().expect("wait") {
            return s;
        }
        if t0.elapsed() > within {
            let _ = c.kill();
            panic!("the cyclonedds listener did not end within {within:?} of its window");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn finite_positive_diag(cov: &Value) -> bool {
    let c = cov.as_array().expect("36 floats");
    c.len() == 36 && (0..6).all(|i| c[i * 7].as_f64().is_some_and(|v| v.is_finite() && v > 0.0))
}

#[test]
fn cyclone_dds_hears_pose_odom_tf_and_diagnostics() {
    if !in_own_network("cyclone_dds_hears_pose_odom_tf_and_diagnostics") {
        return;
    }
    let py = lightpose_testkit::python::python();
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, dest) = subscriber();
    let (mut daemon, mut got) = spawn_daemon_to(dir.path(), &config(dest), &sub, Stdio::inherit());
    let mut listener = Command::new(py)
        .arg(root().join("tests/python/ros2_listener.py"))
        .arg(LISTEN_S.to_string())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start the cyclonedds listener");
    // Its output read as it comes (a full pipe would stall it).
    let mut stdout = listener.stdout.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut stdout, &mut s).map(|_| s)
    });
    let t0 = Instant::now();
    let mut buf = [0u8; 65536];
    // Until the listener ends (its window opens at the first pose it hears).
    while t0.elapsed() < Duration::from_secs_f64(LISTEN_S + 25.0) && !reader.is_finished() {
        if let Ok(n) = sub.recv(&mut buf) {
            got.push(buf[..n].to_vec());
        }
    }
    let status = wait_child(&mut listener, Duration::from_secs(5));
    let text = reader.join().expect("reader").expect("listener's output");
    signal(&daemon, nix::sys::signal::Signal::SIGTERM);
    assert!(wait_exit(&mut daemon, Duration::from_secs(10)).success());
    assert!(status.success(), "listener failed: {status}");

    let poses: Vec<Value> = got
        .iter()
        .filter_map(|b| serde_json::from_slice::<Value>(b).ok())
        .filter(|v| v["class"] == "POSE")
        .collect();
    let lines: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object a line"))
        .collect();
    let last = lines.last().expect("a last line");
    assert_eq!(last["done"], true, "{last}");
    let counts = &last["counts"];
    let want = (0.8 * RATE_HZ * LISTEN_S) as u64;
    for topic in ["pose", "odom", "tf"] {
        let n = counts[topic].as_u64().expect("count");
        assert!(
            n >= want,
            "{topic}: {n} samples in {LISTEN_S} s, want >= {want} (80 % of {RATE_HZ} Hz)"
        );
    }
    assert!(counts["diagnostics"].as_u64() >= Some(5), "{counts}");
    // The graph (`ros2 node list`): our node in ros_discovery_info, as a
    // Jazzy peer decodes it (16-byte GIDs; the default build's distro).
    let graph: Vec<&Value> = lines.iter().filter(|l| l["topic"] == "graph").collect();
    assert!(
        graph.iter().any(|g| g["gid_len"] == 16
            && g["nodes"]
                .as_array()
                .is_some_and(|n| n.iter().any(|n| n[1] == "lightposed"))),
        "no lightposed node in ros_discovery_info: {graph:?}"
    );
    let mut matched = 0;
    for l in lines
        .iter()
        .filter(|l| l["topic"] == "pose" || l["topic"] == "odom")
    {
        let stamp = l["stamp"].as_f64().expect("stamp");
        let p = poses
            .iter()
            .find(|p| p["time"].as_f64().is_some_and(|t| (t - stamp).abs() < 1e-6))
            .unwrap_or_else(|| panic!("no POSE datagram at {stamp}: {l}"));
        assert_eq!(p["status"], "ok", "only ok poses go to ROS 2: {p}");
        let xyz = [&p["x"], &p["y"], &p["z"]].map(|v| v.as_f64().expect("x y z"));
        let got: Vec<f64> = l["xyz"]
            .as_array()
            .expect("xyz")
            .iter()
            .map(|v| v.as_f64().expect("f64"))
            .collect();
        assert_eq!(got, xyz.to_vec(), "the pose of frame {}", p["seq"]);
        assert_eq!(l["frame_id"], "lightpose_beacon");
        assert!(finite_positive_diag(&l["cov"]), "{l}");
        if l["topic"] == "odom" {
            assert_eq!(l["child"], "base_link");
            assert!(finite_positive_diag(&l["twist_cov"]), "{l}");
        }
        matched += 1;
    }
    assert!(matched as u64 >= 2 * want, "{matched}");
    let tf = lines.iter().find(|l| l["topic"] == "tf").expect("a tf");
    assert_eq!(
        (&tf["frame_id"], &tf["child"]),
        (&Value::from("lightpose_beacon"), &Value::from("base_link"))
    );
    let ok: Vec<f64> = poses
        .iter()
        .filter(|p| p["status"] == "ok")
        .filter_map(|p| p["time"].as_f64())
        .collect();
    let stamps: Vec<f64> = lines
        .iter()
        .filter(|l| l["topic"] == "pose")
        .filter_map(|l| l["stamp"].as_f64())
        .collect();
    let (first, last) = (stamps[0], stamps[stamps.len() - 1]);
    let between = ok.iter().filter(|t| (first..=last).contains(*t)).count();
    println!(
        "ros2: counts {counts}, {} POSE datagrams ({} ok), {between} ok between the first and last pose heard, {matched} pose/odom matched",
        poses.len(),
        ok.len()
    );
    assert_eq!(stamps.len(), between, "once heard, every ok pose arrives");
}

/// An IMU driver's `sensor_msgs/msg/Imu` (Cyclone DDS, tests/python/ros2_imu.py)
/// reaches the attitude input: STATUS shows readings attached to frames,
/// and a NaN and a non-unit quaternion counted and refused while frames go
/// on; `[site]` brings `/tf_static`.
#[test]
fn an_imu_from_cyclone_dds_is_the_attitude_input() {
    if !in_own_network("an_imu_from_cyclone_dds_is_the_attitude_input") {
        return;
    }
    let py = lightpose_testkit::python::python();
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, dest) = subscriber();
    // The scene without its own attitude sensor: the IMU's is the frames'.
    let text = config(dest).replace("embedded:tank-ahrs-scene", "embedded:tank-scene")
        + "imu_topic = \"/imu/data\"\nimu_max_age_s = 0.5\n[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n";
    let (mut daemon, _) = spawn_daemon_to(dir.path(), &text, &sub, Stdio::inherit());
    let out = Command::new(py)
        .arg(root().join("tests/python/ros2_imu.py"))
        .args(["4", "4"])
        .stderr(Stdio::inherit())
        .output()
        .expect("run the cyclonedds IMU");
    assert!(out.status.success(), "IMU publisher failed");
    // The STATUS after the last reading.
    let mut last = None;
    let mut poses = 0;
    let mut buf = [0u8; 65536];
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(2) {
        if let Ok(n) = sub.recv(&mut buf) {
            if let Ok(v) = serde_json::from_slice::<Value>(&buf[..n]) {
                match v["class"].as_str() {
                    Some("STATUS") => last = Some(v),
                    Some("POSE") => poses += 1,
                    _ => {}
                }
            }
        }
    }
    signal(&daemon, nix::sys::signal::Signal::SIGTERM);
    assert!(wait_exit(&mut daemon, Duration::from_secs(10)).success());
    let status = last.expect("a STATUS");
    let a = &status["attitude"];
    println!(
        "ros2: imu: {} | attitude {a}",
        String::from_utf8_lossy(&out.stdout).trim()
    );
    assert_eq!(a["input"], true, "{a}");
    assert!(a["received"].as_u64() >= Some(40), "{a}");
    assert!(
        a["attached"].as_u64() >= Some(10),
        "the IMU's reading rode with frames: {a}"
    );
    assert_eq!(
        a["rejected_by"]["angle"], 4,
        "2 NaN and 2 non-unit quaternions: {a}"
    );
    assert!(poses >= 5, "frames went on: {poses} POSE in 2 s");
}

/// The POSE and STATUS datagrams that came while `child` ran (and `after`
/// more): POSEs as they came, the last STATUS.
fn collect_while(
    sub: &std::net::UdpSocket,
    child: &mut std::process::Child,
    after: Duration,
) -> (Vec<Value>, Option<Value>) {
    let (mut poses, mut last) = (Vec::new(), None);
    let mut buf = [0u8; 65536];
    let mut ended: Option<Instant> = None;
    let t0 = Instant::now();
    while ended.is_none_or(|e| e.elapsed() < after) {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the publisher did not end"
        );
        if ended.is_none() && child.try_wait().expect("wait").is_some() {
            ended = Some(Instant::now());
        }
        if let Ok(n) = sub.recv(&mut buf) {
            if let Ok(v) = serde_json::from_slice::<Value>(&buf[..n]) {
                match v["class"].as_str() {
                    Some("STATUS") => last = Some(v),
                    Some("POSE") => poses.push(v),
                    _ => {}
                }
            }
        }
    }
    (poses, last)
}

/// Issue 42's bad input: Cyclone DDS feeds the IMU, a depth
/// (FluidPressure) and a DVL (TwistWithCovarianceStamped) good readings
/// and bad ones (tests/python/ros2_bad_inputs.py): a NaN and a non-unit
/// quaternion, a shorter type under the Imu's type name (DDS matches, the
/// sample cannot be read), a 1 MB frame id, another type on the Imu's
/// topic name (no match), a NaN, negative-variance and too deep pressure,
/// a NaN and too fast twist. Each is counted in STATUS by its reason, the
/// good ones ride with frames, and POSE datagrams kept coming at the rate.
#[test]
fn bad_ros2_inputs_are_counted_and_frames_go_on() {
    if !in_own_network("bad_ros2_inputs_are_counted_and_frames_go_on") {
        return;
    }
    let py = lightpose_testkit::python::python();
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, dest) = subscriber();
    sub.set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    let text = config(dest).replace("embedded:tank-ahrs-scene", "embedded:tank-scene")
        + "imu_topic = \"/imu/data\"\ndepth_topic = \"/depth/pressure\"\ndvl_topic = \"/dvl/twist\"\n[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n";
    let (mut daemon, _) = spawn_daemon_to(dir.path(), &text, &sub, Stdio::inherit());
    let mut child = Command::new(py)
        .arg(root().join("tests/python/ros2_bad_inputs.py"))
        .arg("4")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("run the cyclonedds publisher");
    let (poses, last) = collect_while(&sub, &mut child, Duration::from_millis(1500));
    let mut out = String::new();
    std::io::Read::read_to_string(&mut child.stdout.take().expect("piped"), &mut out)
        .expect("its output");
    assert!(child.wait().expect("wait").success(), "publisher failed");
    signal(&daemon, nix::sys::signal::Signal::SIGTERM);
    assert!(wait_exit(&mut daemon, Duration::from_secs(10)).success());
    let sent: Value = serde_json::from_str(out.trim()).expect("the publisher's line");
    let status = last.expect("a STATUS");
    let (a, inputs) = (&status["attitude"], &status["ros2"]["inputs"]);
    println!("ros2: bad inputs: sent {sent} | attitude {a} | inputs {inputs}");

    let good = sent["good"].as_u64().expect("good");
    assert!(a["received"].as_u64() >= Some(good * 8 / 10), "{a}");
    assert!(a["attached"].as_u64() >= Some(10), "{a}");
    assert_eq!(a["rejected_by"]["angle"], 4, "2 NaN, 2 non-unit: {a}");
    // 3 unreadable samples, and the 1 MB one refused if DDS delivered it;
    // the String samples would add 3 more had they matched.
    let malformed = a["rejected_by"]["malformed"].as_u64().expect("malformed");
    assert!((3..=4).contains(&malformed), "{a}");
    // The String writer is never matched (Cyclone compares type names),
    // but discovery names it.
    let other = &status["ros2"]["other_type_writers"];
    assert_eq!(
        other,
        &serde_json::json!(["rt/imu/data: std_msgs::msg::dds_::String_"]),
        "{other}"
    );
    for (name, want) in [
        ("depth", &sent["sent"]["depth"]),
        ("dvl", &sent["sent"]["dvl"]),
    ] {
        let i = &inputs[name];
        for (reason, n) in i["rejected_by"].as_object().expect("reasons") {
            assert_eq!(
                n,
                want.get(reason).unwrap_or(&Value::from(0)),
                "{name} {reason}: {i}"
            );
        }
        assert!(i["stored"].as_u64() >= Some(good * 8 / 10), "{name}: {i}");
        assert!(
            i["attached"].as_u64() >= Some(10),
            "{name} rode with frames: {i}"
        );
    }
    // The frame loop went on through the bad readings: POSEs at the rate,
    // no gap longer than three periods.
    let times: Vec<f64> = poses.iter().filter_map(|p| p["time"].as_f64()).collect();
    let (from, to) = (
        sent["bad_from"].as_f64().expect("from") - 1.0,
        sent["bad_to"].as_f64().expect("to") + 1.0,
    );
    let within: Vec<f64> = times
        .iter()
        .copied()
        .filter(|t| (from..=to).contains(t))
        .collect();
    let want = (0.8 * RATE_HZ * (to - from)) as usize;
    assert!(
        within.len() >= want,
        "{} POSE in {:.1} s, want >= {want}",
        within.len(),
        to - from
    );
    let gap = within.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!(gap < 3.0 / RATE_HZ, "a {gap:.2} s gap between POSEs");
    println!(
        "ros2: bad inputs: {} POSE in the {:.1} s around the bad readings, longest gap {gap:.2} s, malformed {malformed}",
        within.len(),
        to - from
    );
}
