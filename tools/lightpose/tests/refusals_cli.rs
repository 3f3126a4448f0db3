//! The `lightpose` binary refusing what it cannot do well, at once and in
//! one line (FORMATS.md, "Command line"): counts that would exhaust the
//! memory or the disk, numbers that would panic, an output that is one of
//! its inputs (left byte for byte as it was), and a replay with nothing to
//! replay; and replay's account of what it dropped, each thing said once.

mod common;

use common::{lightpose, replay, root, s, Run};
use lightpose_testkit::data::dive_with_a_corrupt_seq;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A refusal: exit 1, and stderr is one line holding each of `want`.
fn refused(args: &[&str], want: &[&str]) -> String {
    let r = lightpose(args, Duration::from_secs(20));
    assert_eq!(r.code, Some(1), "{args:?}: {}", r.err);
    assert_eq!(r.err.lines().count(), 1, "{args:?}: {}", r.err);
    assert!(r.err.starts_with("lightpose: "), "{}", r.err);
    for w in want {
        assert!(r.err.contains(w), "{args:?}: {:?} lacks {w:?}", r.err);
    }
    r.err
}

fn scene() -> PathBuf {
    root().join("config/scenes/tank.toml")
}
fn dive() -> PathBuf {
    root().join("config/trajectories/dive.csv")
}
fn cal() -> PathBuf {
    root().join("config/calibration/tank.toml")
}

/// Item 1: a run count that cannot be allocated is refused before any
/// work, with its bound; so is one a long trajectory makes too big.
#[test]
fn monte_carlo_run_counts_are_bounded() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("mc");
    let mc = |runs: &'static str, traj: &Path| {
        vec![
            "montecarlo".to_string(),
            "--scene".into(),
            s(&scene()).into(),
            "--trajectory".into(),
            s(traj).into(),
            "--calibration".into(),
            s(&cal()).into(),
            "--out".into(),
            s(&out).into(),
            "--runs".into(),
            runs.into(),
        ]
    };
    for runs in ["18446744073709551615", "1000000000", "1000001"] {
        let a = mc(runs, &dive());
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        refused(&a, &[&format!("--runs {runs}: at most 1000000")]);
    }
    // 10^5 s at 5 Hz: 500001 frames; 200 runs of them is too many.
    let long = dir.path().join("long.csv");
    std::fs::write(&long, "t,x,y,z,pitch,yaw\n0,8,0,0,0,0\n1e5,4,0,0,0,0\n").expect("write");
    let a = mc("200", &long);
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    refused(&a, &["--runs 200", "long.csv", "500001 frames", "50000000"]);
    assert!(!out.exists(), "nothing written");

    let bench = |flag: &str, n: &str| {
        vec![
            "bench".to_string(),
            "--root".into(),
            s(&root()).into(),
            "--case".into(),
            "dive-tank".into(),
            "--sensors".into(),
            "none".into(),
            format!("--{flag}"),
            n.into(),
        ]
    };
    let a = bench("runs", "18446744073709551615");
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    refused(&a, &["--runs 18446744073709551615: at most 1000000"]);
    let a = bench("timing-runs", "18446744073709551615");
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    refused(&a, &["--timing-runs 18446744073709551615: at most 1000"]);
}

/// Audit: `crb --every 0` was taken as 1 and `bench --timing-runs 0`
/// printed a time per frame measured over no run. 0 asks for nothing:
/// refused in one line, as `--runs 0` is.
#[test]
fn zero_counts_are_refused() {
    let (sc, tr) = (scene(), dive());
    refused(
        &[
            "crb",
            "--scene",
            s(&sc),
            "--trajectory",
            s(&tr),
            "--every",
            "0",
        ],
        &["--every 0: at least 1"],
    );
    let r = s(&root()).to_string();
    refused(
        &[
            "bench",
            "--root",
            &r,
            "--case",
            "dive-tank",
            "--sensors",
            "none",
            "--runs",
            "1",
            "--timing-runs",
            "0",
        ],
        &["--timing-runs 0: at least 1"],
    );
}

/// Item 2: a duration or noise that would panic or mean nothing.
#[test]
fn fake_autopilot_refuses_impossible_numbers() {
    let (sc, tr) = (scene(), dive());
    // A port nobody listens on: the refusal comes before any socket.
    let base = [
        "fake-autopilot",
        "--scene",
        s(&sc),
        "--trajectory",
        s(&tr),
        "--connect",
        "udpout:127.0.0.1:9",
    ];
    for (arg, want) in [
        ("--duration=-1", "--duration -1: must be more than 0"),
        ("--duration=NaN", "--duration NaN"),
        (
            "--duration=1e30",
            "--duration 1000000000000000000000000000000",
        ),
        ("--duration=0", "--duration 0"),
        (
            "--pitch-noise-deg=-1",
            "--pitch-noise-deg -1: a 1σ must be 0 to 180°",
        ),
        ("--yaw-noise-deg=NaN", "--yaw-noise-deg NaN"),
        ("--depth-noise-m=inf", "--depth-noise-m inf"),
    ] {
        let mut a = base.to_vec();
        a.push(arg);
        refused(&a, &[want]);
    }
}

/// Item 3: every command that writes a file refuses to write it over one
/// of its inputs, however spelled, and leaves that input as it was.
#[test]
fn no_command_writes_over_its_own_input() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| dir.path().join(n);
    let copy = |from: &Path, to: &str| {
        std::fs::copy(from, p(to)).expect("copy");
        p(to)
    };
    let log = copy(&root().join("tests/data/dive.jsonl"), "log.jsonl");
    let cal = copy(&cal(), "cal.toml");
    let scene = copy(&scene(), "scene.toml");
    let traj = copy(&dive(), "traj.csv");
    let sweep = p("sweep.jsonl");
    let dark = p("dark.jsonl");
    for (kind, out) in [("orientation", &sweep), ("dark", &dark)] {
        let r = lightpose(
            &[
                "sweep",
                "--scene",
                s(&scene),
                "--out",
                s(out),
                "--kind",
                kind,
                "--samples",
                "2",
            ],
            Duration::from_secs(60),
        );
        assert_eq!(r.code, Some(0), "{}", r.err);
    }
    // The same file by another spelling, and by a hard link.
    let dotted_scene = dir.path().join(".").join("scene.toml");
    let linked = p("linked.jsonl");
    std::fs::hard_link(&log, &linked).expect("hard link");

    let (cal, log, linked) = (s(&cal), s(&log), s(&linked));
    let (scene_s, traj_s, dotted) = (s(&scene), s(&traj), s(&dotted_scene));
    let (sweep_s, dark_s) = (s(&sweep), s(&dark));
    // Each: the command's words, the input it must leave alone (as a path
    // string), and the pair of flags the refusal names.
    let cases: [(&[&str], &str, &str); 8] = [
        (
            &["replay", "--calibration", cal, "--log", log, "--out", log],
            log,
            "(--log and --out)",
        ),
        (
            &[
                "replay",
                "--calibration",
                cal,
                "--log",
                log,
                "--out",
                linked,
            ],
            log,
            "(--log and --out)",
        ),
        (
            &["replay", "--calibration", cal, "--log", log, "--out", cal],
            cal,
            "(--calibration and --out)",
        ),
        (
            &[
                "simulate",
                "--scene",
                scene_s,
                "--trajectory",
                traj_s,
                "--out",
                dotted,
            ],
            scene_s,
            "(--scene and --out)",
        ),
        (
            &[
                "simulate",
                "--scene",
                scene_s,
                "--trajectory",
                traj_s,
                "--out",
                traj_s,
            ],
            traj_s,
            "(--trajectory and --out)",
        ),
        (
            &["sweep", "--scene", scene_s, "--out", scene_s],
            scene_s,
            "(--scene and --out)",
        ),
        (
            &["calibrate", "--sweep", sweep_s, "--out", sweep_s],
            sweep_s,
            "(--sweep and --out)",
        ),
        (
            &[
                "calibrate",
                "--sweep",
                sweep_s,
                "--dark",
                dark_s,
                "--out",
                dark_s,
            ],
            dark_s,
            "(--dark and --out)",
        ),
    ];
    for (a, input, want) in cases {
        let before = std::fs::read(input).expect("input");
        refused(a, &["input and output are the same file", want]);
        assert_eq!(
            std::fs::read(input).expect("input"),
            before,
            "{a:?} changed it"
        );
    }
}

/// Item 4: a sweep past the frame bound is refused before a byte is
/// written, and the bound is the user's to move, as simulate's is.
#[test]
fn sweep_refuses_a_sample_count_past_the_frame_bound() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("sweep.jsonl");
    let sc = scene();
    let sweep = |extra: &[&str]| {
        let mut a = vec!["sweep", "--scene", s(&sc), "--out", s(&out)];
        a.extend_from_slice(extra);
        lightpose(&a, Duration::from_secs(20))
    };
    let r = sweep(&["--samples", "100000000"]);
    assert_eq!(r.code, Some(1), "{}", r.err);
    assert_eq!(r.err.lines().count(), 1, "{}", r.err);
    assert!(
        r.err.contains("--samples 100000000: the all sweep (")
            && r.err.contains("more than --max-frames 10000000"),
        "{}",
        r.err
    );
    assert!(!out.exists(), "nothing written");
    let r = sweep(&["--kind", "dark", "--samples", "3", "--max-frames", "2"]);
    assert_eq!(r.code, Some(1), "{}", r.err);
    assert!(r.err.contains("the dark sweep is 3 frames"), "{}", r.err);
    assert!(!out.exists(), "nothing written");
    let r = sweep(&["--kind", "dark", "--samples", "3", "--max-frames", "3"]);
    assert_eq!(r.code, Some(0), "{}", r.err);
    assert!(r.err.contains("3 frames (dark sweep)"), "{}", r.err);
}

/// Item 5: a replay that could replay nothing fails, naming the log and
/// why.
#[test]
fn a_replay_of_nothing_fails() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(root().join("tests/data/dive.jsonl")).expect("dive log");
    let lines: Vec<&str> = text.lines().collect();
    let out = dir.path().join("poses.jsonl");
    let last = |r: &Run| r.err.lines().last().unwrap_or_default().to_string();

    let header = dir.path().join("header.jsonl");
    std::fs::write(&header, format!("{}\n", lines[0])).expect("write");
    let r = replay(&header, &out, &[]);
    assert_eq!(r.code, Some(1), "{}", r.err);
    assert_eq!(
        last(&r),
        format!(
            "lightpose: {}: no frame could be replayed: the log has no frames",
            header.display()
        )
    );

    let bad = dir.path().join("bad.jsonl");
    std::fs::write(
        &bad,
        format!("{}\ngarbage\n{{\"class\":\"FRAME\"}}\n", lines[0]),
    )
    .expect("write");
    let r = replay(&bad, &out, &[]);
    assert_eq!(r.code, Some(1), "{}", r.err);
    let l = last(&r);
    assert!(
        l.starts_with(&format!(
            "lightpose: {}: no frame could be replayed: 2 bad lines (first: {}:2: not valid JSON",
            bad.display(),
            bad.display()
        )),
        "{l}"
    );
    assert!(!r.err.contains("0 poses"), "{}", r.err);

    // Every t absurd: each frame refused by its line.
    let absurd = dir.path().join("absurd.jsonl");
    let frames: Vec<String> = lines[1..4]
        .iter()
        .map(|l| l.replacen("\"t\":", "\"t\":1e300,\"was\":", 1))
        .collect();
    std::fs::write(&absurd, format!("{}\n{}\n", lines[0], frames.join("\n"))).expect("write");
    let r = replay(&absurd, &out, &[]);
    assert_eq!(r.code, Some(1), "{}", r.err);
    assert!(
        last(&r).contains("no frame could be replayed: 3 bad lines (first: ")
            && last(&r).contains("absurd.jsonl:2:"),
        "{}",
        r.err
    );
}

/// Item 5 (a, b): the readings line is said once (stdout with --report,
/// else stderr), and malformed readings are named by their first line.
#[test]
fn replay_says_each_thing_once_and_names_the_first_bad_reading() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text =
        std::fs::read_to_string(root().join("tests/data/fusion-all.jsonl")).expect("fusion log");
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    for i in [3, 6] {
        assert!(
            lines[i].contains("\"attitude\":{\"pitch\":"),
            "{}",
            lines[i]
        );
        lines[i] = lines[i].replacen(
            "\"attitude\":{\"pitch\":",
            "\"attitude\":{\"pitch\":\"x\",\"was\":",
            1,
        );
    }
    let log = dir.path().join("readings.jsonl");
    std::fs::write(&log, lines.join("\n") + "\n").expect("write");
    let out = dir.path().join("poses.jsonl");

    let r = replay(&log, &out, &["--report"]);
    assert_eq!(r.code, Some(0), "{}", r.err);
    assert_eq!(r.out.matches("readings: ").count(), 1, "{}", r.out);
    assert!(!r.err.contains("readings: "), "{}", r.err);
    let dropped = format!(
        "lightpose: {}: 2 malformed sensor readings dropped (frames kept; first: {}:4: ",
        log.display(),
        log.display()
    );
    assert!(r.err.contains(&dropped), "{}", r.err);

    let r = replay(&log, &out, &[]);
    assert_eq!(r.code, Some(0), "{}", r.err);
    assert_eq!(r.err.matches("readings: ").count(), 1, "{}", r.err);
    assert!(!r.out.contains("readings: "), "{}", r.out);
}

/// One corrupt `seq` in a recorded log (found by a bad-input audit: seq 500
/// in frame 5 of 41 cost the 36 frames after it and claimed 494 lost) costs
/// nothing after it: every frame is replayed, the glitch is said, and only
/// the one frame its seq claimed to skip is counted lost.
#[test]
fn one_corrupt_seq_costs_no_frame_after_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (log, frames) = dive_with_a_corrupt_seq(dir.path());
    let out = dir.path().join("poses.jsonl");
    let r = replay(&log, &out, &[]);
    assert_eq!(r.code, Some(0), "{}", r.err);
    let poses = std::fs::read_to_string(&out)
        .expect("poses")
        .lines()
        .count();
    assert_eq!(poses, frames, "{}", r.err);
    assert!(r.err.contains("1 lone frame(s) out of line"), "{}", r.err);
    // The corrupt frame's own seq (4) is missing from the line: one lost.
    assert!(r.err.contains("1 gaps in seq, 1 frames lost"), "{}", r.err);
}

/// A log whose corner channel reads full scale throughout (a stuck
/// photodiode) replays with poses, and the summary names the channel.
#[test]
fn a_stuck_channel_is_named_and_poses_come() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(root().join("tests/data/dive.jsonl")).expect("log");
    let stuck: Vec<String> = text
        .lines()
        .map(|l| match l.find("\"counts\":[") {
            Some(i) => {
                let at = i + "\"counts\":[".len();
                let end = at + l[at..].find(',').expect("25 counts");
                format!("{}1023{}", &l[..at], &l[end..])
            }
            None => l.to_string(),
        })
        .collect();
    let log = dir.path().join("stuck.jsonl");
    std::fs::write(&log, stuck.join("\n") + "\n").expect("write");
    let out = dir.path().join("poses.jsonl");
    let r = replay(&log, &out, &[]);
    assert_eq!(r.code, Some(0), "{}", r.err);
    assert!(r.err.contains("left out as stuck"), "{}", r.err);
    assert!(
        r.err
            .contains(&format!("(0,0) on {} frames", stuck.len() - 1)),
        "{}",
        r.err
    );
    let ok = std::fs::read_to_string(&out)
        .expect("poses")
        .lines()
        .filter(|l| l.contains("\"status\":\"ok\""))
        .count();
    assert!(ok >= 30, "{ok} ok poses: {}", r.err);
}

/// A 12-bit log against the 10-bit tank calibration: the model-based
/// estimators are refused at once, naming both; the paper's method runs.
#[test]
fn a_log_of_another_adc_is_refused_for_the_light_model() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("poses.jsonl");
    let log = root().join("tests/data/dive-12bit.jsonl");
    let cal = cal();
    let replay_with = |est: &str| {
        let (c, l, o) = (s(&cal), s(&log), s(&out));
        let args = [
            "replay",
            "--calibration",
            c,
            "--log",
            l,
            "--out",
            o,
            "--estimator",
            est,
        ];
        lightpose(&args, Duration::from_secs(20))
    };
    for est in ["auto", "tracker", "model"] {
        let r = replay_with(est);
        assert_eq!(r.code, Some(1), "{est}: {}", r.err);
        let last = r.err.lines().last().unwrap_or_default();
        assert!(
            last.contains("12-bit ADC") && last.contains("10-bit"),
            "{est}: {}",
            r.err
        );
    }
    assert_eq!(replay_with("moments").code, Some(0));
}

/// calibrate names its own options when they are no ADC's or no water's
/// (a v_ref of 1e30 wrote a calibration with it, 0 said "no light"), and a
/// sweep with no frames says so instead of an empty list.
#[test]
fn calibrate_names_its_options_and_an_empty_sweep() {
    let dir = tempfile::tempdir().expect("tempdir");
    let sweep = dir.path().join("header-only.jsonl");
    let header = "{\"class\":\"HEADER\",\"format\":\"lightpose-intensity\",\"version\":1,\"rows\":5,\"cols\":5,\"adc_bits\":10,\"rate_hz\":5}\n";
    std::fs::write(&sweep, header).expect("write");
    let out = dir.path().join("cal.toml");
    let (sw, o) = (s(&sweep), s(&out));
    refused(
        &["calibrate", "--sweep", sw, "--out", o, "--v-ref", "1e30"],
        &["--v-ref 1e30"],
    );
    refused(
        &["calibrate", "--sweep", sw, "--out", o, "--v-ref", "0"],
        &["--v-ref 0"],
    );
    refused(
        &[
            "calibrate",
            "--sweep",
            sw,
            "--out",
            o,
            "--default-temp",
            "NaN",
        ],
        &["--default-temp NaN", "water"],
    );
    refused(
        &["calibrate", "--sweep", sw, "--out", o],
        &["the sweep has no frames"],
    );
    assert!(!out.exists());
}

/// A log given where the calibration goes is said to be a log, with what
/// to do with it (an audit got only TOML's `invalid key`).
#[test]
fn a_log_given_as_the_calibration_is_named_a_log() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = root().join("tests/data/dive.jsonl");
    let out = dir.path().join("poses.jsonl");
    let err = refused(
        &[
            "replay",
            "--calibration",
            s(&log),
            "--log",
            s(&log),
            "--out",
            s(&out),
        ],
        &[
            "dive.jsonl: an intensity log (JSON Lines)",
            "lightpose calibrate --sweep",
            "not a calibration",
        ],
    );
    assert!(!err.contains("invalid key"), "{err}");
    assert!(!out.exists(), "nothing written");
}
