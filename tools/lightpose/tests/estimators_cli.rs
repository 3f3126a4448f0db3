//! End-to-end checks of the estimator integration through the `lightpose`
//! binary: calibrate writes (or warns about) the light model, replay names
//! the estimator "auto" chose, and `bench` produces its trade table.

mod common;

use common::{root, run as lightpose, s, sweep};
use std::path::Path;

/// `lightpose simulate` of `scene` along `traj` with `seed` into `out`.
fn simulate(scene: &Path, traj: &Path, seed: &str, out: &Path) {
    let (ok, _, err) = lightpose(&[
        "simulate",
        "--scene",
        s(scene),
        "--trajectory",
        s(traj),
        "--seed",
        seed,
        "--out",
        s(out),
    ]);
    assert!(ok, "{err}");
}

/// `lightpose calibrate` on a (sweep, dark) pair into `out`, plus `extra`
/// arguments; as [`lightpose`] returns.
fn calibrate(sw: &Path, dk: &Path, out: &Path, extra: &[&str]) -> (bool, String, String) {
    let mut args = vec![
        "calibrate",
        "--sweep",
        s(sw),
        "--dark",
        s(dk),
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    lightpose(&args)
}

#[test]
fn calibrate_fits_the_light_model_and_auto_replay_uses_the_tracker() {
    let dir = tempfile::tempdir().unwrap();
    let (sw, dk) = sweep(dir.path(), &root().join("config/scenes/tank.toml"));
    let cal = dir.path().join("cal.toml");
    let (ok, _, err) = calibrate(&sw, &dk, &cal, &[]);
    assert!(ok, "{err}");
    // Each light-model parameter is printed with its standard error.
    for p in [
        "V1      =",
        "sigma_b =",
        "sigma_R =",
        "K_D     =",
        "omega   =",
        "sigma_h =",
    ] {
        let line = err
            .lines()
            .find(|l| l.contains(p))
            .unwrap_or_else(|| panic!("{p} in {err}"));
        assert!(line.contains(" ± "), "{line}");
    }
    let text = std::fs::read_to_string(&cal).unwrap();
    assert!(text.contains("[physical.k_d]"), "{text}");

    // Replay a short simulated log with "auto": the tracker is chosen and
    // named on stderr and in every POSE line.
    let log = dir.path().join("dive.jsonl");
    simulate(
        &root().join("config/scenes/tank.toml"),
        &root().join("config/trajectories/dive.csv"),
        "3",
        &log,
    );
    let poses = dir.path().join("poses.jsonl");
    let (ok, _, err) = lightpose(&[
        "replay",
        "--calibration",
        s(&cal),
        "--log",
        s(&log),
        "--out",
        s(&poses),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("estimator tracker (auto)"), "{err}");
    let out = std::fs::read_to_string(&poses).unwrap();
    assert!(out.lines().count() > 10, "{out}");
    assert!(
        out.lines().all(|l| l.contains("\"estimator\":\"tracker\"")),
        "{out}"
    );
}

#[test]
fn a_light_model_the_sweep_cannot_determine_is_left_out_with_one_warning() {
    // Clear water with no scattering, yet the fit is told to model it: the
    // sweep cannot determine the halo, so [physical] is left out, the moments part
    // still calibrates, and "auto" falls back to moments.
    let dir = tempfile::tempdir().unwrap();
    let scene_text = std::fs::read_to_string(root().join("config/scenes/tank.toml")).unwrap();
    let no_scatter = scene_text.replace("[scattering]\nomega = 0.5\nsigma_h_deg = 20.0\n", "");
    assert_ne!(
        no_scatter, scene_text,
        "the tank scene's scattering table moved"
    );
    let scene = dir.path().join("clear.toml");
    std::fs::write(&scene, no_scatter).unwrap();
    let (sw, dk) = sweep(dir.path(), &scene);
    let cal = dir.path().join("cal.toml");
    let (ok, _, err) = calibrate(&sw, &dk, &cal, &["--scattering", "on"]);
    assert!(ok, "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    // It names the parameter: with ω → 0 the halo's shape and K_D are
    // confounded, so the weakest direction may be named by any of them.
    assert!(warnings[0].contains("cannot determine"), "{err}");
    assert!(
        ["omega", "sigma_h", "k_d", "v1", "sigma_b", "sigma_r"]
            .iter()
            .any(|p| warnings[0].contains(&format!("determine {p}:"))),
        "{err}"
    );
    let text = std::fs::read_to_string(&cal).unwrap();
    assert!(!text.contains("[physical"), "{text}");
    assert!(text.contains("[fits.x]"), "{text}");
}

#[test]
fn bench_runs_every_estimator_on_one_case() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench.md");
    let (ok, stdout, err) = lightpose(&[
        "bench",
        "--runs",
        "2",
        "--timing-runs",
        "1",
        "--case",
        "dive-tank",
        "--sensors",
        "attitude,all",
        "--root",
        s(&root()),
        "--out",
        s(&out),
    ]);
    assert!(ok, "{err}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), stdout);
    assert!(stdout.contains("dive-tank — attitude (2 runs)"), "{stdout}");
    assert!(
        stdout.contains("dive-tank — attitude + depth + DVL (2 runs)"),
        "{stdout}"
    );
    for est in ["moments", "model", "tracker"] {
        // Six axes per estimator and sensor set, each row with a finite
        // time per frame.
        let rows: Vec<&str> = stdout
            .lines()
            .filter(|l| l.starts_with(&format!("| {est} |")))
            .collect();
        assert_eq!(rows.len(), 12, "{stdout}");
        let us: f64 = rows[0].split('|').nth(2).unwrap().trim().parse().unwrap();
        assert!(us > 0.0 && us.is_finite(), "{}", rows[0]);
    }
    // The bound stands beside x: finite at both ends.
    let x = stdout
        .lines()
        .find(|l| l.starts_with("| tracker |") && l.contains("| x (m) |"))
        .unwrap();
    let cells: Vec<&str> = x.split('|').map(str::trim).collect();
    let crb_end: f64 = cells[10].parse().unwrap();
    assert!(crb_end > 0.0 && crb_end < 2.0, "{x}");
    // And the bound for a tracker, which pools the frames: below one
    // frame's bound by the end of the run.
    let track_end: f64 = cells[11].parse().unwrap();
    assert!(track_end > 0.0 && track_end < crb_end, "{x}");
    // The summary names every section and estimator.
    assert!(stdout.contains("| dive-tank | all | tracker |"), "{stdout}");
    let (ok, _, err) = lightpose(&["bench", "--case", "spiral", "--runs", "2"]);
    assert!(!ok);
    assert!(err.contains("unknown case \"spiral\""), "{err}");
    let (ok, _, err) = lightpose(&["bench", "--sensors", "gps", "--runs", "2"]);
    assert!(!ok);
    assert!(err.contains("--sensors gps"), "{err}");
}

/// A case, set or estimator named twice is run once (an alias beside its
/// name, `all` beside `attitude+depth+dvl`: each had run, and been
/// tabled, twice); cases take a comma list like the other flags; and an
/// --out that cannot be written fails before the runs, not after them.
#[test]
fn bench_runs_each_thing_named_once_and_checks_its_out_first() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench.md");
    let args = |out: &str| {
        vec![
            "bench".to_string(),
            "--runs=2".into(),
            "--timing-runs=1".into(),
            "--case=dive-tank,dive-clear".into(),
            "--sensors=all,attitude+depth+dvl".into(),
            "--estimators=moments,moments".into(),
            format!("--root={}", s(&root())),
            format!("--out={out}"),
        ]
    };
    let a = args(s(&out));
    let (ok, stdout, err) = lightpose(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    assert_eq!(
        stdout.matches("| dive-tank | all | moments |").count(),
        1,
        "{stdout}"
    );
    assert_eq!(stdout.matches("### dive-tank").count(), 1, "{stdout}");
    let a = args(s(dir.path()));
    let (ok, stdout, err) = lightpose(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!ok && err.contains("cannot be written"), "{err}");
    assert!(
        !err.contains("bench: dive-tank"),
        "ran before failing: {err}"
    );
    assert!(stdout.is_empty(), "{stdout}");
}

/// `lightpose crb` prints the bound at every frame of the trajectory: the
/// y/yaw ridge without the attitude sensor, pinned with it (MODEL.md);
/// depth pins z.
#[test]
fn crb_prints_the_bound_along_the_trajectory() {
    let scene = root().join("config/scenes/tank.toml");
    let traj = root().join("config/trajectories/dive.csv");
    let rows = |extra: &[&str]| -> Vec<Vec<f64>> {
        let mut args = vec!["crb", "--scene", s(&scene), "--trajectory", s(&traj)];
        args.extend_from_slice(extra);
        let (ok, out, err) = lightpose(&args);
        assert!(ok, "{err}");
        out.lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| t "))
            .map(|l| {
                l.trim_matches('|')
                    .split('|')
                    .map(|c| c.trim().replace('∞', "inf").parse::<f64>().expect("number"))
                    .collect()
            })
            .collect()
    };
    let free = rows(&[]);
    let pinned = rows(&["--sensors", "attitude"]);
    let depth = rows(&["--sensors", "depth"]);
    // z's bound (column 8) is at most the depth sensor's 0.02 m.
    assert!(depth.iter().all(|r| r[8] <= 0.02 + 1e-9), "{depth:?}");
    assert!(free.iter().all(|r| r[8] > 0.02), "{free:?}");
    // 8 s at 5 Hz: 41 frames, t in column 0, bound y in column 7.
    assert_eq!(free.len(), 41);
    assert_eq!(pinned.len(), 41);
    assert_eq!(free[40][0], 8.0);
    assert!(free.iter().all(|r| r[7] > 1.0), "{free:?}");
    assert!(pinned.iter().all(|r| r[7] < 0.3), "{pinned:?}");
    // The bound for a tracker: six more columns, surge last; with the DVL
    // surge's bound is the DVL's own noise or below.
    let track = rows(&["--sensors", "all", "--track"]);
    assert_eq!(track[40].len(), 17);
    assert!(track.iter().all(|r| r[16] <= 0.02 + 1e-9), "{track:?}");
    assert!(track[40][12] < track[0][12], "{track:?}");
    let every = rows(&["--every", "10", "--half-width"]);
    assert_eq!(every.len(), 5);
    assert!((every[4][6] / free[40][6] - 1.959964).abs() < 0.01);

    let (ok, _, err) = lightpose(&[
        "crb",
        "--scene",
        "no/such/scene.toml",
        "--trajectory",
        s(&traj),
    ]);
    assert!(!ok);
    assert!(err.contains("no/such/scene.toml"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// Spec v3 scenes: the bound reads a blinking beacon's amplitudes (and
/// says so), which bound the harbour approach at or below the steady
/// beacon's counts by day at every frame; a v2 scene prints as before.
#[test]
fn crb_reads_a_blinking_beacon_s_amplitudes_and_a_steady_one_s_sun() {
    let traj = root().join("tests/data/v3/harbour-approach.csv");
    let run = |scene: &str| -> (String, Vec<Vec<f64>>) {
        let scene = root().join(scene);
        let (ok, out, err) = lightpose(&["crb", "--scene", s(&scene), "--trajectory", s(&traj)]);
        assert!(ok, "{err}");
        let rows = out
            .lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| t "))
            .map(|l| {
                l.trim_matches('|')
                    .split('|')
                    .map(|c| c.trim().parse::<f64>().expect("number"))
                    .collect()
            })
            .collect();
        (out, rows)
    };
    let (blink_out, blink) = run("tests/data/v3/harbour-day.toml");
    let (steady_out, steady) = run("tests/data/v3/harbour-steady.toml");
    assert!(
        blink_out.contains("a blinking beacon's amplitudes, 200 samples"),
        "{blink_out}"
    );
    assert!(
        steady_out.contains("its level unknown each frame"),
        "{steady_out}"
    );
    assert_eq!(blink.len(), steady.len());
    assert!(!blink.is_empty());
    // These scenes' AHRS reads roll: the trajectory's roll and its bound
    // are columns too, and bound x, y, z are columns 7, 8, 9.
    assert!(blink_out.contains("| roll (°) |") && blink_out.contains("| bound roll (°) |"));
    for (b, st) in blink.iter().zip(&steady) {
        for c in 7..10 {
            assert!(b[c] <= st[c] + 1e-9, "column {c}: {b:?} {st:?}");
        }
    }
    let tank = root().join("config/scenes/tank.toml");
    let dive = root().join("config/trajectories/dive.csv");
    let (ok, out, _) = lightpose(&["crb", "--scene", s(&tank), "--trajectory", s(&dive)]);
    assert!(ok && !out.contains("light:"), "{out}");
}

/// A docking station (spec v3, `dock-example.toml`): the bound of light
/// alone sees roll, and four beacons bound y, z and yaw where one beacon
/// cannot (issue 41's scale: 1.96σ at 5 m y .14, z .17 m, roll 6.9°).
#[test]
fn crb_of_a_docking_station_bounds_roll_and_the_ridges() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("dock.csv");
    std::fs::write(
        &traj,
        "t,x,y,z,pitch,yaw,roll\n0,5,0,0,0,0,0\n2,1.5,0.1,0,0,0,5\n",
    )
    .expect("write");
    let scene = root().join("../shared/spec/dock-example.toml");
    let (ok, out, err) = lightpose(&[
        "crb",
        "--scene",
        s(&scene),
        "--trajectory",
        s(&traj),
        "--sensors",
        "none",
        "--half-width",
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("station: 4 beacon(s)") && out.contains("roll from the light alone"),
        "{out}"
    );
    let rows: Vec<Vec<f64>> = out
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| t "))
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .map(|c| c.trim().parse().expect("number"))
                .collect()
        })
        .collect();
    assert_eq!(rows.len(), 21, "{out}");
    // Columns: t, x, y, z, pitch, yaw, roll, then the bound's x … roll.
    let first = &rows[0];
    assert!(
        first[8] > 0.1 && first[8] < 0.2 && first[9] > 0.12 && first[9] < 0.25,
        "{first:?}"
    );
    assert!(first[12] > 5.0 && first[12] < 9.0, "roll {first:?}");
    let last = &rows[20];
    assert!(last[8] < 0.01 && last[12] < 0.5, "{last:?}");
}

/// Told that the water may be far from the calibration's (`k_d_sigma =
/// 0.3`, a bank of waters), the tracker learns the water of a log flown in
/// murkier water than the tank's (K_D 0.19 against 0.09, a minute of
/// coming and going at 4–6 m with the attitude sensor) and `replay` says
/// so; told nothing, it says nothing about the water, unless the log has
/// a DVL, with which the tracker's water check finds it untold.
#[test]
fn replay_reports_the_water_the_tracker_learned_when_told_to_doubt_it() {
    let dir = tempfile::tempdir().unwrap();
    let scene = root().join("tests/data/tank-murky.toml");
    let traj = root().join("tests/data/to-and-fro.csv");
    let log = dir.path().join("murky.jsonl");
    simulate(&scene, &traj, "7", &log);
    let shipped = root().join("config/calibration/tank.toml");
    let told = dir.path().join("told.toml");
    let mut cal = std::fs::read_to_string(&shipped).unwrap();
    cal += "\n[estimator.tracker]\nk_d_sigma = 0.3\n";
    std::fs::write(&told, cal).unwrap();
    let replay = |cal: &Path| {
        let poses = dir.path().join("poses.jsonl");
        let (ok, _, err) = lightpose(&[
            "replay",
            "--calibration",
            s(cal),
            "--estimator",
            "tracker",
            "--log",
            s(&log),
            "--out",
            s(&poses),
        ]);
        assert!(ok, "{err}");
        err
    };
    let learned = |err: &str| -> f64 {
        err.lines()
            .find_map(|l| l.strip_prefix("water: K_D "))
            .and_then(|l| l.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no water line in {err}"))
    };
    let err = replay(&told);
    let k = learned(&err);
    assert!((0.15..=0.24).contains(&k), "learned K_D {k}: {err}");
    let err = replay(&shipped);
    assert!(!err.contains("water:"), "{err}");
    let with_dvl = dir.path().join("murky-dvl.toml");
    let mut text = std::fs::read_to_string(&scene).unwrap();
    text += "\n[depth]\n\n[dvl]\n";
    std::fs::write(&with_dvl, text).unwrap();
    simulate(&with_dvl, &traj, "7", &log);
    let err = replay(&shipped);
    let k = learned(&err);
    assert!((0.15..=0.24).contains(&k), "found untold, K_D {k}: {err}");
}

/// What calibrate used to take without a word (an audit): a sweep header's
/// `v_ref` no ADC has (1e300 was written into the calibration; −5 was
/// replaced by 5 V) is refused naming the log; a sweep cut short, and
/// frames the paper's fits cannot use (truth neither level nor centred),
/// are told as notes, where it said "calibrated from N frames" alone.
#[test]
fn calibrate_refuses_an_impossible_header_v_ref_and_tells_what_it_left() {
    let dir = tempfile::tempdir().unwrap();
    let (sw, dk) = sweep(dir.path(), &root().join("config/scenes/tank.toml"));
    let text = std::fs::read_to_string(&sw).unwrap();
    let (head, frames) = text.split_once('\n').unwrap();
    let mut h: serde_json::Value = serde_json::from_str(head).unwrap();
    for bad in [
        serde_json::json!(1e300),
        serde_json::json!(-5.0),
        serde_json::json!("x"),
    ] {
        h["v_ref"] = bad.clone();
        let path = dir.path().join("bad-vref.jsonl");
        std::fs::write(&path, format!("{h}\n{frames}")).unwrap();
        let (ok, _, err) = calibrate(&path, &dk, &dir.path().join("c.toml"), &[]);
        assert!(!ok, "v_ref {bad}: {err}");
        assert!(
            err.contains(&format!("{}: header v_ref: ", path.display())),
            "{err}"
        );
    }
    // Ten frames moved off both the level and the centred poses, and the
    // last line cut in half.
    let mut lines: Vec<String> = frames.lines().map(String::from).collect();
    for l in lines.iter_mut().skip(100).step_by(50).take(10) {
        let mut f: serde_json::Value = serde_json::from_str(l).unwrap();
        f["truth"]["pitch"] = serde_json::json!(5.0);
        f["truth"]["y"] = serde_json::json!(0.5);
        *l = f.to_string();
    }
    let last = lines.pop().unwrap();
    lines.push(last[..last.len() / 2].to_string());
    let cut = dir.path().join("cut.jsonl");
    std::fs::write(&cut, format!("{head}\n{}", lines.join("\n"))).unwrap();
    let (ok, _, err) = calibrate(&cut, &dk, &dir.path().join("c.toml"), &[]);
    assert!(ok, "{err}");
    let n = lines.len() + 1;
    assert!(
        err.contains(&format!(
            "note: {}: line {n}: last line cut short",
            cut.display()
        )),
        "{err}"
    );
    assert!(
        err.contains("note: frames the paper's fits did not use: 10 mixed pose"),
        "{err}"
    );
}
