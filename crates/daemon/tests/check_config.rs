//! What `--check-config` passed and a start then failed on or did wrong
//! (config audit): an empty or doubled destination list, a recording
//! directory that is a file or under one, a listen address that cannot be
//! bound (not this machine's, in use, two inputs on one port), a missing
//! scene, trajectory or log, a multicast interface that is not this
//! machine's. Each is refused at `--check-config` and at a start, in one
//! line naming the config's FILE:LINE. Real binary, real files in a temp
//! dir, real sockets.

mod common;
use common::shipped;

use lightposed::{Config, Publisher};
use std::net::{TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_lightposed"))
}

/// A sim config with the shipped files, `outputs` as the body of
/// `[outputs]` and `extra` tables after it.
fn sim_text(outputs: &str, extra: &str) -> String {
    let (scene, traj, cal) = shipped();
    format!(
        "rate_hz = 20.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\n[outputs]\n{outputs}\n{extra}",
        cal.display(),
        scene.display(),
        traj.display()
    )
}

const OUT: &str = "destinations = [\"127.0.0.1:9\"]";

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write config");
    p
}

/// The line (1-based) of the first line of `text` that holds `needle`.
fn line_of(text: &str, needle: &str) -> usize {
    let i = text.lines().position(|l| l.contains(needle));
    i.map(|i| i + 1)
        .unwrap_or_else(|| panic!("{needle:?} in {text}"))
}

/// Run the binary with `flag` and the config; its exit code and stderr.
fn run(flag: &str, cfg: &Path) -> (Option<i32>, String) {
    let out = bin().arg(flag).arg(cfg).output().expect("run lightposed");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `--check-config` and a start both refuse `cfg` with exit `code` and
/// one line holding `FILE:LINE: ` (the config's) and each of `want`.
fn refused(cfg: &Path, code: i32, line: usize, want: &[&str]) -> String {
    let place = format!("{}:{line}: ", cfg.display());
    let mut first = String::new();
    for flag in ["--check-config", "--config"] {
        let (got, err) = run(flag, cfg);
        assert_eq!(got, Some(code), "{flag}: {err}");
        assert_eq!(err.lines().count(), 1, "{flag}: one line: {err}");
        let lead = format!("lightposed: {place}");
        assert!(err.starts_with(&lead), "{flag}: want {lead:?} first: {err}");
        for w in want {
            assert!(err.contains(w), "{flag}: want {w:?}: {err}");
        }
        if first.is_empty() {
            first = err;
        }
    }
    first
}

#[test]
fn an_empty_or_doubled_destination_list_is_refused_at_its_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let text = sim_text("status_interval_s = 1.0\ndestinations = []", "");
    let p = write(d, "empty.toml", &text);
    let err = refused(&p, 2, line_of(&text, "destinations"), &[]);
    assert!(
        err.contains(
            ": outputs.destinations: empty: POSE, STATUS and VERSION would be sent nowhere"
        ),
        "{err}"
    );
    // With a multicast group the datagrams do go somewhere.
    let text = sim_text(
        "destinations = []\n[outputs.multicast]\ngroup = \"239.255.71.50:17150\"",
        "",
    );
    let p = write(d, "mcast.toml", &text);
    let (code, err) = run("--check-config", &p);
    assert_eq!(code, Some(0), "{err}");
    let text = sim_text(
        "destinations = [\n  \"127.0.0.1:9\",\n  \"127.0.0.1:10\",\n  \"127.0.0.1:9\",\n]",
        "",
    );
    let p = write(d, "twice.toml", &text);
    let line = line_of(&text, "destinations") + 3;
    refused(
        &p,
        2,
        line,
        &["outputs.destinations: 127.0.0.1:9 is given twice (items 1 and 3)"],
    );
    // An IPv4 address and its IPv4-mapped IPv6 form are one place.
    let text = sim_text(
        "destinations = [\"127.0.0.1:9\", \"[::ffff:127.0.0.1]:9\"]",
        "",
    );
    let p = write(d, "mapped.toml", &text);
    refused(&p, 2, line_of(&text, "destinations"), &["given twice"]);
    let text = sim_text(
        "destinations = [\"239.255.71.50:17150\"]\n[outputs.multicast]\ngroup = \"239.255.71.50:17150\"",
        "",
    );
    let p = write(d, "group.toml", &text);
    refused(
        &p,
        2,
        line_of(&text, "destinations"),
        &["is also outputs.multicast.group"],
    );
}

#[test]
fn a_recording_dir_that_is_a_file_or_under_one_is_refused_and_nothing_is_made() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let file = d.join("not-a-dir");
    std::fs::write(&file, b"x").expect("write");
    let text = sim_text(OUT, &format!("[recording]\ndir = \"{}\"\n", file.display()));
    let p = write(d, "file.toml", &text);
    let err = refused(&p, 2, line_of(&text, "dir ="), &["recording.dir: "]);
    assert!(
        err.trim_end()
            .ends_with("not-a-dir: exists and is not a directory"),
        "{err}"
    );
    let under = file.join("rec/today");
    let text = sim_text(
        OUT,
        &format!("[recording]\ndir = \"{}\"\n", under.display()),
    );
    let p = write(d, "under.toml", &text);
    refused(
        &p,
        2,
        line_of(&text, "dir ="),
        &[
            "recording.dir: ",
            "rec/today cannot be created: ",
            "not-a-dir: exists and is not a directory",
        ],
    );
    // A directory that is not there yet passes, and is not made by the
    // check.
    let new = d.join("new/rec");
    let text = sim_text(OUT, &format!("[recording]\ndir = \"{}\"\n", new.display()));
    let p = write(d, "new.toml", &text);
    let (code, err) = run("--check-config", &p);
    assert_eq!(code, Some(0), "{err}");
    assert!(!d.join("new").exists(), "--check-config creates nothing");
}

#[test]
fn a_missing_scene_trajectory_or_log_is_refused_at_its_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let (scene, traj, cal) = shipped();
    for (key, shipped_file) in [("scene", &scene), ("trajectory", &traj)] {
        for kind in ["sim", "mock"] {
            let text = sim_text(OUT, "")
                .replace(&shipped_file.display().to_string(), "missing/nothing.txt")
                .replace("kind = \"sim\"", &format!("kind = \"{kind}\""));
            let p = write(d, &format!("{kind}-{key}.toml"), &text);
            let want = format!("backend.{key}: {}", d.join("missing/nothing.txt").display());
            refused(
                &p,
                2,
                line_of(&text, &format!("{key} =")),
                &[&want, "No such file"],
            );
        }
    }
    let text = format!(
        "rate_hz = 5.0\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\npace = \"fast\"\nlog = \"gone.jsonl\"\n[outputs]\n{OUT}\n",
        cal.display()
    );
    let p = write(d, "replay.toml", &text);
    refused(&p, 2, 6, &["backend.log: ", "gone.jsonl", "No such file"]);
}

const ATT: &str =
    "[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 1.0\n[attitude]\nenabled = true\n";

#[test]
fn a_listen_address_not_of_this_machine_is_refused_at_its_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let text = sim_text(
        OUT,
        &format!("{ATT}listen = \"203.0.113.5:14550\"\nallow_from = [\"203.0.113.9\"]\n"),
    );
    let p = write(d, "att.toml", &text);
    let err = refused(
        &p,
        1,
        line_of(&text, "listen ="),
        &["203.0.113.5 is not an address of this machine"],
    );
    // The place first, as every refusal: FILE:LINE: key address: why.
    let place = format!(
        "lightposed: {}:{}: ",
        p.display(),
        line_of(&text, "listen =")
    );
    assert!(
        err.starts_with(&format!("{place}attitude.listen 203.0.113.5:14550: ")),
        "{err}"
    );
    let text = sim_text(
        OUT,
        "[foxglove]\nlisten = \"203.0.113.5:8765\"\nallow_remote = true\n",
    );
    let p = write(d, "fox.toml", &text);
    refused(
        &p,
        1,
        line_of(&text, "listen ="),
        &[
            "foxglove.listen 203.0.113.5:8765: ",
            "not an address of this machine",
        ],
    );
    let text = sim_text(OUT, "[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 1.0\n[mavlink]\nconnection = \"udpin:203.0.113.5:14550\"\nallow_remote = true\n");
    let p = write(d, "mav.toml", &text);
    refused(
        &p,
        1,
        line_of(&text, "connection ="),
        &[
            "mavlink: udpin:203.0.113.5:14550: ",
            "not an address of this machine",
        ],
    );
    let text = sim_text(
        OUT,
        "[outputs.multicast]\ngroup = \"239.255.71.50:17150\"\ninterface = \"203.0.113.5\"\n",
    );
    let p = write(d, "mif.toml", &text);
    refused(
        &p,
        1,
        line_of(&text, "interface ="),
        &[
            "outputs.multicast: cannot set interface: ",
            "203.0.113.5 is not an address of this machine",
        ],
    );
}

/// Audit: an attitude input beyond loopback names who may send or says
/// allow_remote; refused at the listen line otherwise, before any bind.
#[test]
fn a_remote_attitude_listen_without_allow_from_or_allow_remote_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    for (i, more) in ["", "allow_remote = false\n"].into_iter().enumerate() {
        let text = sim_text(OUT, &format!("{ATT}listen = \"0.0.0.0:17151\"\n{more}"));
        let p = write(d, &format!("open{i}.toml"), &text);
        refused(
            &p,
            2,
            line_of(&text, "listen ="),
            &[
                "attitude.listen: 0.0.0.0:17151 is not a loopback address",
                "allow_from",
                "allow_remote = true",
            ],
        );
    }
    let text = sim_text(
        OUT,
        &format!("{ATT}listen = \"0.0.0.0:17151\"\nallow_from = [\n\"10.0.0.5\",\n\"nope\"]\n"),
    );
    let p = write(d, "bad_from.toml", &text);
    refused(
        &p,
        2,
        line_of(&text, "\"nope\""),
        &["attitude.allow_from: \"nope\" is not an address"],
    );
}

#[test]
fn a_port_in_use_is_said_at_its_line_and_asks_if_lightposed_runs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let udp = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let port = udp.local_addr().expect("addr").port();
    let tcp = TcpListener::bind("127.0.0.1:0").expect("listen");
    let tcp_port = tcp.local_addr().expect("addr").port();
    let in_use = "in use (is lightposed already running?): ";
    let text = sim_text(OUT, &format!("{ATT}listen = \"127.0.0.1:{port}\"\n"));
    let p = write(d, "att.toml", &text);
    let want = format!("attitude.listen 127.0.0.1:{port}: ");
    refused(&p, 1, line_of(&text, "listen ="), &[&want, in_use]);
    let text = sim_text(
        OUT,
        &format!("[foxglove]\nlisten = \"127.0.0.1:{tcp_port}\"\n"),
    );
    let p = write(d, "fox.toml", &text);
    let want = format!("foxglove.listen 127.0.0.1:{tcp_port}: ");
    refused(&p, 1, line_of(&text, "listen ="), &[&want, in_use]);
    let text = sim_text(OUT, &format!("[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 1.0\n[mavlink]\nconnection = \"udpin:127.0.0.1:{port}\"\n"));
    let p = write(d, "mav.toml", &text);
    let want = format!("mavlink: udpin:127.0.0.1:{port}: ");
    refused(&p, 1, line_of(&text, "connection ="), &[&want, in_use]);
    drop((udp, tcp));
}

/// The library's start (no check before it, as a test or an embedder
/// runs it) names the line too.
#[test]
fn a_start_without_the_check_names_the_line_of_the_address_it_cannot_bind() {
    let dir = tempfile::tempdir().expect("tempdir");
    let taken = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let port = taken.local_addr().expect("addr").port();
    let text = sim_text(OUT, &format!("{ATT}listen = \"127.0.0.1:{port}\"\n"));
    let p = write(dir.path(), "att.toml", &text);
    let cfg = Config::load(&p).expect("valid");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let got = rt.block_on(async {
        let publisher = Publisher::open(&cfg.outputs).expect("publisher");
        let run = lightposed::run(cfg, publisher, std::future::pending());
        tokio::time::timeout(Duration::from_secs(10), run).await
    });
    let e = got.expect("fails at once").expect_err("the port is taken");
    let line = lightposed::error::report(&e);
    let place = format!(
        "{}:{}: attitude.listen 127.0.0.1:{port}: in use",
        p.display(),
        line_of(&text, "listen =")
    );
    assert!(line.contains(&place), "{line}");
    assert_eq!(e.exit_code(), 1, "{line}");
    drop(taken);
}

/// A port free now, below the kernel's ephemeral range (32768 and up):
/// the tests that bind port 0 meanwhile cannot be handed it between this
/// test's binds. From the ephemeral range, one was (CI, once: "the
/// attitude port is free again: Address already in use").
fn quiet_port(free: impl Fn(u16) -> bool) -> u16 {
    let start = 20000 + (std::process::id() % 5000) as u16;
    (start..30000)
        .chain(20000..start)
        .find(|&p| free(p))
        .expect("a free port in 20000-29999")
}

#[test]
fn the_check_lets_go_of_what_it_binds() {
    let dir = tempfile::tempdir().expect("tempdir");
    let port = quiet_port(|p| UdpSocket::bind(("127.0.0.1", p)).is_ok());
    let tcp_port = quiet_port(|p| p != port && TcpListener::bind(("127.0.0.1", p)).is_ok());
    let text = sim_text(
        OUT,
        &format!(
            "{ATT}listen = \"127.0.0.1:{port}\"\n[foxglove]\nlisten = \"127.0.0.1:{tcp_port}\"\n"
        ),
    );
    let p = write(dir.path(), "ok.toml", &text);
    let cfg = Config::load(&p).expect("valid");
    lightposed::wiring::check(&cfg).expect("passes");
    UdpSocket::bind(("127.0.0.1", port)).expect("the attitude port is free again");
    TcpListener::bind(("127.0.0.1", tcp_port)).expect("the live view's port is free again");
}

#[test]
fn two_inputs_on_one_port_and_poses_sent_to_an_input_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let text = sim_text(
        OUT,
        "[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 1.0\n[attitude]\nenabled = true\nlisten = \"127.0.0.1:17199\"\n[mavlink]\nconnection = \"udpin:0.0.0.0:17199\"\nallow_remote = true\n",
    );
    let p = write(d, "both.toml", &text);
    let err = refused(
        &p,
        2,
        line_of(&text, "connection ="),
        &["mavlink.connection: udpin:0.0.0.0:17199 is the UDP port of attitude.listen 127.0.0.1:17199"],
    );
    let att = format!("{}:{}", p.display(), line_of(&text, "listen ="));
    assert!(err.contains(&att), "names the other's line too: {err}");
    let text = sim_text(
        "destinations = [\"127.0.0.1:9\", \"127.0.0.1:17198\"]",
        &format!("{ATT}listen = \"127.0.0.1:17198\"\n"),
    );
    let p = write(d, "loop.toml", &text);
    refused(
        &p,
        2,
        line_of(&text, "destinations"),
        &["outputs.destinations: 127.0.0.1:17198 is the daemon's own input attitude.listen"],
    );
}

#[test]
fn an_interface_for_an_ipv6_group_is_refused_where_it_would_be_ignored() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = sim_text(
        &format!(
            "{OUT}\n[outputs.multicast]\ngroup = \"[ff02::1]:17150\"\ninterface = \"127.0.0.1\""
        ),
        "",
    );
    let p = write(dir.path(), "v6.toml", &text);
    refused(
        &p,
        2,
        line_of(&text, "interface ="),
        &["outputs.multicast.interface: 127.0.0.1 would be ignored"],
    );
}

/// `autopilot_system_id` and `autopilot_component_id` are MAVLink ids,
/// 1..=255 (0 is the broadcast id): refused at their line otherwise.
#[test]
fn the_autopilot_ids_are_refused_at_their_line_outside_1_to_255() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let site = "[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 1.0\n";
    for (key, v, want) in [
        ("autopilot_component_id", "0", "0 is the broadcast id"),
        ("autopilot_system_id", "0", "0 is the broadcast id"),
        ("autopilot_component_id", "256", ""),
    ] {
        let text = sim_text(
            OUT,
            &format!("{site}[mavlink]\nconnection = \"udpout:127.0.0.1:14550\"\n{key} = {v}\n"),
        );
        let p = write(d, "ids.toml", &text);
        let what = format!("mavlink.{key}: ");
        refused(&p, 2, line_of(&text, key), &[&what, want]);
    }
    let text = sim_text(
        OUT,
        &format!("{site}[mavlink]\nconnection = \"udpout:127.0.0.1:14550\"\nautopilot_system_id = 2\nautopilot_component_id = 255\n"),
    );
    let p = write(d, "ok.toml", &text);
    let (code, err) = run("--check-config", &p);
    assert_eq!(code, Some(0), "{err}");
}

/// Spec v3: a board sampling a blinking beacon (config/examples/
/// mcp3008-beacon.toml: `sample_hz` and `beacons` in `[backend]`) passes
/// `--check-config` (its chips are not opened: they may appear later), and
/// a `mod_hz` its samples cannot resolve is refused at the `beacons` line,
/// naming the beacon.
#[test]
fn a_board_sampling_a_beacon_is_checked_and_a_bad_mod_hz_refused_at_its_line() {
    let (_, _, cal) = shipped();
    let example =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/mcp3008-beacon.toml");
    let text = std::fs::read_to_string(example)
        .expect("read the example")
        .replace(
            "\"/etc/lightpose/calibration.toml\"",
            &format!("\"{}\"", cal.display()),
        );
    assert!(text.contains("sample_hz = 1000.0") && text.contains("mod_hz = 250.0"));
    let dir = tempfile::tempdir().expect("tempdir");
    let ok = write(dir.path(), "beacon.toml", &text);
    let (code, err) = run("--check-config", &ok);
    assert_eq!(code, Some(0), "{err}");
    // 1000 / 300 samples a period is no whole number.
    let bad_text = text.replace("mod_hz = 250.0", "mod_hz = 300.0");
    let bad = write(dir.path(), "bad.toml", &bad_text);
    refused(
        &bad,
        2,
        line_of(&bad_text, "beacons = ["),
        &["backend.beacons", "beacon \"beacon\"", "mod_hz = 300"],
    );
}

/// The serial example sampling a beacon (config/examples/
/// serial-beacon.toml: LPBST bursts at 500 Hz on two boards at 1 000 000
/// baud) passes `--check-config`, demodulator included; on lines of
/// 115 200 baud it is refused, with the figure.
#[test]
fn a_serial_board_sampling_a_beacon_is_checked_with_its_baud() {
    let (_, _, cal) = shipped();
    let example =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/serial-beacon.toml");
    let text = std::fs::read_to_string(example)
        .expect("read the example")
        .replace(
            "\"/etc/lightpose/calibration.toml\"",
            &format!("\"{}\"", cal.display()),
        );
    let dir = tempfile::tempdir().expect("tempdir");
    let ok = write(dir.path(), "serial.toml", &text);
    let (code, err) = run("--check-config", &ok);
    assert_eq!(code, Some(0), "{err}");
    let slow = write(
        dir.path(),
        "slow.toml",
        &text.replace("baud = 1000000", "baud = 115200"),
    );
    let (code, err) = run("--check-config", &slow);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("boards.m0.baud") && err.contains("at most 441 Hz fits"),
        "{err}"
    );
}
