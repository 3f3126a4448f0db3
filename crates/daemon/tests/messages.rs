//! What the real binary says to the person who runs it: log lines without
//! colour codes when they go to a file, a pipe or the journal, and the
//! refusals that are found only when a file is used (a calibration that is
//! not there, an estimator this build does not know) named at the config's
//! file and line like every other refused key.

mod common;
use common::run::{replay_config, wait_exit};
use common::{root, shipped};

use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const ESC: u8 = 0x1b;

/// The binary with none of the caller's environment that changes its
/// logging (a test run from a systemd unit or with NO_COLOR set).
fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lightposed"));
    c.env_remove("NO_COLOR")
        .env_remove("JOURNAL_STREAM")
        .env_remove("RUST_LOG")
        .stdout(Stdio::null());
    c
}

/// A replay of the shipped dive (42 frames) as fast as it goes: a whole
/// run, its log lines included, in well under a second.
fn short_run(dir: &Path) -> std::path::PathBuf {
    // Nobody needs to listen: a refused send is counted, not fatal.
    let dest = "127.0.0.1:9".parse().expect("address");
    let p = dir.join("replay.toml");
    let text = replay_config(&root().join("tests/data/dive.jsonl"), dest);
    std::fs::write(&p, text).expect("config");
    p
}

#[test]
fn log_lines_to_a_pipe_have_no_colour_codes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = bin()
        .arg("--config")
        .arg(short_run(dir.path()))
        .stderr(Stdio::piped())
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("publishing to"), "the log is there: {err}");
    assert!(
        !out.stderr.contains(&ESC),
        "no escape codes in a pipe: {err:?}"
    );
}

/// Run the short replay with stderr on a terminal (a pty); what it wrote.
fn at_a_terminal(env: &[(&str, &str)]) -> Vec<u8> {
    let dir = tempfile::tempdir().expect("tempdir");
    let pty = nix::pty::openpty(None, None).expect("openpty");
    let mut child = {
        let mut c = bin();
        c.arg("--config")
            .arg(short_run(dir.path()))
            .envs(env.iter().copied())
            .stderr(Stdio::from(pty.slave));
        c.spawn().expect("spawn")
        // `c` dropped: the child holds the only end of the terminal, so the
        // reader below sees its end when the child exits.
    };
    let mut master = std::fs::File::from(pty.master);
    let reader = std::thread::spawn(move || {
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        // Linux says EIO once no one holds the terminal's other end.
        while let Ok(n) = master.read(&mut buf) {
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
        got
    });
    let st = wait_exit(&mut child, Duration::from_secs(20));
    let got = reader.join().expect("reader");
    assert_eq!(st.code(), Some(0), "{}", String::from_utf8_lossy(&got));
    assert!(
        String::from_utf8_lossy(&got).contains("publishing to"),
        "the log is there: {}",
        String::from_utf8_lossy(&got)
    );
    got
}

#[test]
fn log_lines_at_a_terminal_are_coloured_unless_no_color_or_journald() {
    assert!(at_a_terminal(&[]).contains(&ESC), "a person at a terminal");
    for env in [("NO_COLOR", "1"), ("JOURNAL_STREAM", "8:1234")] {
        let got = at_a_terminal(&[env]);
        assert!(
            !got.contains(&ESC),
            "{env:?}: {:?}",
            String::from_utf8_lossy(&got)
        );
    }
}

/// `--check-config` and a start both refuse with exit 2 and one line that
/// begins with `want`.
fn refused_at(cfg: &Path, want: &str, then: &str) {
    let out = bin().arg("--check-config").arg(cfg).output().expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let line = err.trim_end();
    assert!(line.starts_with(want), "want {want:?}: {line}");
    assert!(line.contains(then), "want {then:?}: {line}");
    let out = bin().arg("--config").arg(cfg).output().expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "start: {err}");
    assert!(err.trim_end().starts_with(want), "start: {want:?}: {err}");
}

#[test]
fn a_missing_calibration_and_an_unknown_estimator_name_the_config_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (scene, traj, cal) = shipped();
    let config = |name: &str, estimator: &str, calibration: &str| {
        let p = dir.path().join(name);
        let text = format!(
            "# lightposed\nrate_hz = 50.0\n\nestimator = \"{estimator}\"\ncalibration = \"{calibration}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n",
            scene.display(),
            traj.display()
        );
        std::fs::write(&p, text).expect("config");
        p
    };
    let cal = cal.display().to_string();

    let p = config("nocal.toml", "auto", "cfg/nope.toml");
    refused_at(
        &p,
        &format!("lightposed: {}:5: calibration: ", p.display()),
        "cfg/nope.toml: No such file or directory",
    );
    let p = config("noest.toml", "trackr", &cal);
    refused_at(
        &p,
        &format!("lightposed: {}:4: estimator: ", p.display()),
        "unknown estimator \"trackr\" (known: ",
    );
    // Audit: a calibration that is read but wrong was said at its own
    // line only, without the config's place that named it.
    let bad = dir.path().join("badcal.toml");
    let good = std::fs::read_to_string(&cal).expect("calibration");
    std::fs::write(&bad, format!("foo = 1\n{good}")).expect("calibration");
    let p = config("badcalcfg.toml", "auto", &bad.display().to_string());
    refused_at(
        &p,
        &format!(
            "lightposed: {}:5: calibration: {}:1: ",
            p.display(),
            bad.display()
        ),
        "foo",
    );
    // Not TOML at all (a log named as the calibration): said to be a log.
    let log = root().join("tests/data/dive.jsonl");
    let p = config("logcal.toml", "auto", &log.display().to_string());
    refused_at(
        &p,
        &format!(
            "lightposed: {}:5: calibration: {}: an intensity log (JSON Lines)",
            p.display(),
            log.display()
        ),
        "not a calibration",
    );
}

/// A replayed log of a 12-bit board against the 10-bit tank calibration:
/// the tracker would call every frame `bad_frame` without saying why
/// (bad-input audit: 41 of 41, STATUS `last_error` null, exit 0); the start
/// refuses it in one line, exit 2, and so does `--check-config` (audit: it
/// said ok), both at the config's `calibration` line. The paper's method
/// reads any ADC.
#[test]
fn a_log_of_another_adc_than_the_light_models_is_refused_at_start() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (_, _, cal) = shipped();
    let log = common::root().join("tests/data/dive-12bit.jsonl");
    let config = |estimator: &str| {
        let p = dir.path().join(format!("{estimator}.toml"));
        let text = format!(
            "rate_hz = 5.0\nestimator = \"{estimator}\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n",
            cal.display(),
            log.display()
        );
        std::fs::write(&p, text).expect("config");
        p
    };
    let p = config("tracker");
    refused_at(
        &p,
        &format!(
            "lightposed: {}:3: calibration {}: backend replay: ",
            p.display(),
            cal.display()
        ),
        "frames of a 12-bit ADC, and the calibration's light model is of a 10-bit one",
    );
    let out = bin()
        .arg("--check-config")
        .arg(config("moments"))
        .output()
        .expect("run");
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = bin()
        .arg("--config")
        .arg(config("moments"))
        .output()
        .expect("run");
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A replayed log with one corrupt seq and one malformed reading: the
/// frames after them go on, STATUS counts both and names the reading's
/// line, and the log says what was skipped (it was counted, not logged).
#[test]
fn skips_a_source_counts_are_logged_and_in_status() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(root().join("tests/data/dive.jsonl")).expect("log");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    lines[5] = lines[5].replacen("\"seq\":4,", "\"seq\":500,", 1);
    lines[9] = lines[9].replacen("\"counts\"", "\"depth\":{\"zz\":1},\"counts\"", 1);
    let log = dir.path().join("skips.jsonl");
    std::fs::write(&log, lines.join("\n") + "\n").expect("write");
    let (sub, dest) = {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
        let a = s.local_addr().expect("addr");
        (s, a)
    };
    sub.set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let cfg = dir.path().join("replay.toml");
    let text = replay_config(&log, dest).replace("[outputs]", "[outputs]\nstatus_interval_s = 0.2");
    std::fs::write(&cfg, text).expect("config");
    let out = bin().arg("--config").arg(&cfg).output().expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        err.contains("source skipped") && err.contains("1 glitches in seq or t"),
        "{err}"
    );
    assert!(err.contains("1 malformed readings"), "{err}");
    let mut last = None;
    let mut buf = vec![0u8; 65536];
    while let Ok(n) = sub.recv(&mut buf) {
        let v: serde_json::Value = serde_json::from_slice(&buf[..n]).expect("json");
        if v["class"] == "STATUS" {
            last = Some(v);
        }
    }
    let st = last.expect("a STATUS");
    let h = &st["backend"]["health"];
    assert_eq!(
        (h["glitches"].as_u64(), h["bad_readings"].as_u64()),
        (Some(1), Some(1)),
        "{st}"
    );
    assert!(
        h["last_bad_reading"]
            .as_str()
            .is_some_and(|m| m.contains("skips.jsonl:10")),
        "{st}"
    );
    assert_eq!(st["frames"].as_u64(), Some(lines.len() as u64 - 1), "{st}");
}
