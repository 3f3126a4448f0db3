//! `lightpose convert` end to end: a log through MCAP and back unchanged
//! with its POSE lines, a recording cut short recovered with what was
//! dropped named, and bad input refused in one line.

mod common;

use common::{root, run, s, sweep};
use std::path::Path;

/// `lightpose convert args`: (success, stderr).
fn lightpose(args: &[&Path]) -> (bool, String) {
    let (ok, _, err) = run(&[&[Path::new("convert")], args].concat());
    (ok, err)
}

#[test]
fn a_log_goes_through_mcap_and_back_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let log = root().join("tests/data/zigzag.jsonl");
    let poses = root().join("tests/data/zigzag.poses.jsonl");
    let (mcap, back, back_poses) = (
        dir.path().join("z.mcap"),
        dir.path().join("z.jsonl"),
        dir.path().join("z.poses.jsonl"),
    );
    let a = |s: &'static str| Path::new(s);
    let (ok, err) = lightpose(&[a("--in"), &log, a("--out"), &mcap, a("--poses"), &poses]);
    assert!(ok, "{err}");
    assert!(err.starts_with("41 frames, 41 poses: "), "{err}");
    let (ok, err) = lightpose(&[
        a("--in"),
        &mcap,
        a("--out"),
        &back,
        a("--poses"),
        &back_poses,
    ]);
    assert!(ok, "{err}");
    assert_eq!(std::fs::read(&log).unwrap(), std::fs::read(&back).unwrap());
    assert_eq!(
        std::fs::read(&poses).unwrap(),
        std::fs::read(&back_poses).unwrap()
    );

    // Cut as a power loss would: every frame of the complete chunks comes
    // back, and the dropped bytes are named.
    let (small, cut) = (dir.path().join("small.mcap"), dir.path().join("cut.mcap"));
    let (ok, err) = lightpose(&[
        a("--in"),
        &log,
        a("--out"),
        &small,
        a("--chunk-kib"),
        a("2"),
    ]);
    assert!(ok, "{err}");
    let bytes = std::fs::read(&small).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let rec = dir.path().join("rec.jsonl");
    let (ok, err) = lightpose(&[a("--in"), &cut, a("--out"), &rec]);
    assert!(ok, "{err}");
    let frames = std::fs::read_to_string(&rec).unwrap().lines().count() - 1;
    assert!(frames > 5 && frames < 41, "{frames}: {err}");
    assert!(
        err.starts_with(&format!("{frames} frames, 0 poses: ")),
        "{err}"
    );
    let line = err.lines().nth(1).unwrap_or_default();
    assert!(
        line.starts_with(&format!("lightpose: {}: byte ", cut.display()))
            && line.contains("recording never finished")
            && line.contains("bytes after it (an incomplete record) dropped"),
        "{err}"
    );
}

#[test]
fn bad_input_is_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("fake.mcap");
    std::fs::copy(root().join("tests/data/dive.jsonl"), &fake).unwrap();
    let a = |s: &'static str| Path::new(s);
    let (ok, err) = lightpose(&[a("--in"), &fake, a("--out"), &dir.path().join("o.jsonl")]);
    assert!(!ok);
    assert_eq!(
        err,
        format!(
            "lightpose: {}: byte 0: not an MCAP file (no MCAP magic), though named .mcap\n",
            fake.display()
        )
    );
    let (ok, err) = lightpose(&[
        a("--in"),
        &root().join("tests/data/dive.jsonl"),
        a("--out"),
        &dir.path().join("o.txt"),
    ]);
    assert!(!ok);
    assert!(
        err.ends_with("o.txt: the output must be named .jsonl or .mcap\n")
            && err.lines().count() == 1,
        "{err}"
    );
}

/// Replay and calibration read MCAP as they read JSONL: the same POSE
/// lines byte for byte, the same calibration.
#[test]
fn replay_and_calibrate_read_mcap_alike() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).display().to_string();
    let cal = root()
        .join("config/calibration/tank.toml")
        .display()
        .to_string();
    for name in ["dive", "hard", "zigzag"] {
        let log = root()
            .join(format!("tests/data/{name}.jsonl"))
            .display()
            .to_string();
        let mcap = d(&format!("{name}.mcap"));
        let (ok, _, err) = run(&["convert", "--in", &log, "--out", &mcap, "--chunk-kib", "4"]);
        assert!(ok, "{err}");
        let mut outs = Vec::new();
        for (input, out) in [
            (&log, d(&format!("{name}.j.poses"))),
            (&mcap, d(&format!("{name}.m.poses"))),
        ] {
            let (ok, _, err) = run(&[
                "replay",
                "--calibration",
                &cal,
                "--log",
                input,
                "--out",
                &out,
            ]);
            assert!(ok, "{err}");
            outs.push(std::fs::read(&out).unwrap());
        }
        assert!(!outs[0].is_empty());
        assert_eq!(outs[0], outs[1], "{name}: replay from MCAP differs");
    }
    let (sweep, dark) = sweep(dir.path(), &root().join("config/scenes/tank.toml"));
    let (sweep, dark) = (s(&sweep).to_string(), s(&dark).to_string());
    let mut cals = Vec::new();
    for ext in ["jsonl", "mcap"] {
        let (sw, dk) = (d(&format!("s.{ext}")), d(&format!("k.{ext}")));
        for (from, to) in [(&sweep, &sw), (&dark, &dk)] {
            let (ok, _, err) = run(&["convert", "--in", from, "--out", to]);
            assert!(ok, "{err}");
        }
        let out = d(&format!("cal.{ext}.toml"));
        let (ok, _, err) = run(&[
            "calibrate",
            "--sweep",
            &sw,
            "--dark",
            &dk,
            "--out",
            &out,
            "--no-physical",
        ]);
        assert!(ok, "{err}");
        // The file names the sources, which differ by their extension.
        let text = std::fs::read_to_string(&out).unwrap();
        cals.push(text.replace(&format!(".{ext}"), ".LOG"));
    }
    assert_eq!(cals[0], cals[1]);
}

/// `lightpose recover`: a recording cut mid-chunk, which the reference
/// Python library's default reader cannot open, comes back as a file it
/// opens, with every frame of the complete chunks and one line saying
/// what was kept and lost; bad input is one line.
#[test]
fn recover_finishes_a_cut_recording_for_every_reader() {
    let py = lightpose_testkit::python::python();
    let script = root().join("crates/logs/tests/mcap_check.py");
    let dir = tempfile::tempdir().unwrap();
    let log = root().join("tests/data/zigzag.jsonl");
    let small = dir.path().join("small.mcap");
    let (ok, _, err) = run(&[
        "convert",
        "--in",
        s(&log),
        "--out",
        s(&small),
        "--chunk-kib",
        "2",
    ]);
    assert!(ok, "{err}");
    let bytes = std::fs::read(&small).unwrap();
    let (cut, fixed) = (dir.path().join("cut.mcap"), dir.path().join("fixed.mcap"));
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let check = |mode: &str, f: &Path| {
        lightpose_testkit::python::run_python(&py, &script, &[Path::new(mode), f])
    };
    assert!(check("default", &cut).starts_with("error="));
    let (ok, _, err) = run(&["recover", "--in", s(&cut), "--out", s(&fixed)]);
    assert!(ok, "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let kept: u64 = err
        .strip_prefix(&format!("{} -> {}: kept ", cut.display(), fixed.display()))
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{err}"));
    assert!(
        err.contains("; lost ") && err.contains("(first: byte "),
        "{err}"
    );
    let line = check("default", &fixed);
    assert!(line.starts_with(&format!("messages={kept} ")), "{line}");
    // Every frame our reader finds in the cut file, and the recovered one
    // is finished.
    let (a, b) = (dir.path().join("a.jsonl"), dir.path().join("b.jsonl"));
    let (ok, _, err) = run(&["convert", "--in", s(&cut), "--out", s(&a)]);
    assert!(ok && err.contains("recording never finished"), "{err}");
    let (ok, _, err) = run(&["convert", "--in", s(&fixed), "--out", s(&b)]);
    assert!(ok && !err.contains("never finished"), "{err}");
    let frames = |p: &Path| std::fs::read_to_string(p).unwrap().lines().count() - 1;
    assert!(
        frames(&b) >= frames(&a) && frames(&a) > 5,
        "{} {}",
        frames(&a),
        frames(&b)
    );
    assert!(line.contains(&format!(" frame={} ", frames(&b))), "{line}");

    for (args, want) in [
        (
            vec!["recover", "--in", s(&cut), "--out", s(&cut)],
            "input and output are the same file".to_string(),
        ),
        (
            vec!["recover", "--in", s(&cut), "--out", "x.jsonl"],
            "x.jsonl: the output must be named .mcap".to_string(),
        ),
        (
            vec!["recover", "--in", s(&log), "--out", s(&fixed)],
            format!(
                "{}: byte 0: not an MCAP file (no MCAP magic): nothing to recover",
                log.display()
            ),
        ),
    ] {
        let (ok, _, err) = run(&args);
        assert!(!ok, "{args:?}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.trim_end().ends_with(&want), "{err}");
    }
}
