//! Own-sensor readings through the daemon (issue 13): a recorded zigzag
//! with attitude, depth and DVL velocity and five bad readings spliced in
//! (tests/data/fusion-all.jsonl, the pipeline's regression log) replayed
//! with the tracker. Each bad reading is refused with its reason and
//! counted in STATUS `readings`; the light still gives every frame a pose.
//! Then readings that disagree with the light: a biased depth (the reading
//! check) and a DVL set up wrong, backwards or turned 45° (the DVL checks).

mod common;

use common::run::{of_class, run_to_end};
use common::{root, subscriber};
use lightposed::Config;
use std::time::Duration;

#[test]
fn bad_readings_are_refused_by_reason_and_counted_in_status() {
    let r = root();
    let (sub, addr) = subscriber();
    let text = format!(
        "rate_hz = 5.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{addr}\"]\nstatus_interval_s = 0.2\n",
        r.join("config/calibration/tank.toml").display(),
        r.join("tests/data/fusion-all.jsonl").display(),
    );
    let cfg = Config::parse(&text, "readings.toml", None).expect("valid config");
    // The log's end stops the daemon; the time is a backstop.
    let (summary, msgs) = run_to_end(cfg, Duration::from_secs(20), &sub);
    assert_eq!(summary.frames, 41, "{summary:?}");
    assert_eq!(
        of_class(&msgs, "POSE").len(),
        41,
        "every frame has its POSE, bad readings or not"
    );
    let st = *of_class(&msgs, "STATUS").last().expect("a STATUS");
    let rd = &st["readings"];
    let n = |sensor: &str, path: &[&str]| {
        let mut v = &rd[sensor];
        for k in path {
            v = &v[*k];
        }
        v.as_u64()
            .unwrap_or_else(|| panic!("{sensor} {path:?} in {rd}"))
    };
    // The same verdicts as the pipeline's regression test on this log.
    assert_eq!(n("attitude", &["used"]), 40, "{rd}");
    assert_eq!(n("attitude", &["refused", "bad_std"]), 1, "{rd}");
    assert_eq!(n("depth", &["used"]), 38, "{rd}");
    assert_eq!(n("depth", &["refused", "bad_std"]), 1, "{rd}");
    assert_eq!(n("depth", &["refused", "implausible"]), 1, "{rd}");
    assert_eq!(n("depth", &["refused", "gate"]), 1, "{rd}");
    assert_eq!(n("velocity", &["used"]), 40, "{rd}");
    assert_eq!(n("velocity", &["refused", "implausible"]), 1, "{rd}");
    assert_eq!(n("velocity", &["ignored"]), 0, "{rd}");
}

/// The same log with every depth reading 0.2 m deep (a depth sensor zeroed
/// on another day): the reading check calls depth disagreeing with the
/// light in STATUS `readings.check`, where the clean log has it agreeing,
/// and the tracker starts to learn an offset (STATUS `estimator`).
#[test]
fn a_biased_depth_is_called_disagreeing_in_status() {
    let r = root();
    let dir = tempfile::tempdir().expect("tempdir");
    let biased = dir.path().join("biased.jsonl");
    let text = std::fs::read_to_string(r.join("tests/data/fusion-all.jsonl")).expect("log");
    let mut out = String::new();
    for line in text.lines() {
        let mut v: serde_json::Value = serde_json::from_str(line).expect("json line");
        if let Some(z) = v["depth"]["z"].as_f64() {
            v["depth"]["z"] = serde_json::json!(z + 0.2);
        }
        out.push_str(&v.to_string());
        out.push('\n');
    }
    std::fs::write(&biased, out).expect("write");
    for (log, told) in [
        (r.join("tests/data/fusion-all.jsonl"), false),
        (biased, true),
    ] {
        let (sub, addr) = subscriber();
        let text = format!(
            "rate_hz = 5.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{addr}\"]\nstatus_interval_s = 0.2\n",
            r.join("config/calibration/tank.toml").display(),
            log.display(),
        );
        let cfg = Config::parse(&text, "check.toml", None).expect("valid config");
        let (_, msgs) = run_to_end(cfg, Duration::from_secs(20), &sub);
        let st = *of_class(&msgs, "STATUS").last().expect("a STATUS");
        let depth = &st["readings"]["check"]["depth"];
        let frames = depth["frames"].as_u64().expect("frames");
        assert!(depth["mean"].is_f64(), "{depth}");
        if told {
            // Called, and then learned (`which_offset`): the tracker takes
            // the offset in and the call ends, within the 8 s.
            let est = &st["estimator"];
            assert!(frames > 0, "{}: {depth}", log.display());
            assert!(depth["mean"].as_f64() > Some(0.5), "{depth}");
            assert!(
                !est["depth_offset"].is_null() || !est["pitch_offset"].is_null(),
                "learning: {est}"
            );
        } else {
            assert_eq!(frames, 0, "{}: {depth}", log.display());
            assert_eq!(depth["disagreeing"], false, "{depth}");
        }
    }
}

/// A DVL mounted backwards with its mounting rotation unset (the mock's
/// `faults.dvl_turned_deg = 180`, live frames of the tank zigzag with all
/// three sensors): the light's range closes while the DVL says it opens, so
/// the tracker refuses the DVL (STATUS `readings.velocity.refused.light`,
/// `readings.check.dvl`), and the poses go on from the light. Without the
/// fault the DVL is taken on every frame and the two changes of range
/// agree.
#[test]
fn a_dvl_mounted_backwards_is_refused_by_the_light_in_status() {
    for turned in [0.0, 180.0] {
        let (sub, addr) = subscriber();
        let text = common::run::dvl_mock_config(turned, addr);
        let cfg = Config::parse(&text, "dvl.toml", None).expect("valid config");
        let h = common::run::run_in_process(cfg, Duration::from_secs(5));
        let mut msgs = Vec::new();
        while !h.is_finished() {
            msgs.extend(common::run::collect(&sub, Duration::from_millis(100)));
        }
        msgs.extend(common::run::collect(&sub, Duration::from_millis(300)));
        h.join().expect("daemon");
        let st = *of_class(&msgs, "STATUS").last().expect("a STATUS");
        let (vel, dvl) = (&st["readings"]["velocity"], &st["readings"]["check"]["dvl"]);
        let refused = vel["refused"]["light"].as_u64().expect("refused.light");
        let used = vel["used"].as_u64().expect("used");
        let light = dvl["range_change_m"]["light"]
            .as_f64()
            .expect("a window judged");
        let by_dvl = dvl["range_change_m"]["dvl"]
            .as_f64()
            .expect("a window judged");
        let ok = of_class(&msgs, "POSE")
            .iter()
            .filter(|p| p["status"] == "ok")
            .count();
        if turned == 0.0 {
            assert_eq!(refused, 0, "{st}");
            assert_eq!(dvl["refused"], false, "{dvl}");
            assert!((light / by_dvl - 1.0).abs() < 0.5, "{dvl}");
        } else {
            assert!(refused > used, "{vel}");
            assert_eq!(dvl["refused"], true, "{dvl}");
            assert!(light * by_dvl < 0.0, "{dvl}");
        }
        assert!(ok > 25, "turned {turned}: {ok} ok poses");
    }
}

/// A DVL turned 45° (its mounting rotation set wrong) on a minute of
/// coming and going before the beacon with all three sensors, replayed:
/// its change of range still agrees within the law's wander, but its track
/// turns from the light's, so the tracker's mounting check refuses it and
/// STATUS `readings.check.dvl.turned_deg` says by how much (what to set the
/// DVL's mounting rotation to undo).
#[test]
fn a_dvl_turned_45_degrees_is_refused_and_its_turn_told_in_status() {
    use lightpose_core::{LogHeader, LogWriter};
    use lightpose_sim::{Scene, Simulator, Trajectory};
    let r = root();
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("turned.jsonl");
    let text = std::fs::read_to_string(r.join("config/scenes/tank.toml")).expect("scene");
    let scene = Scene::parse(
        &(text + "\n[attitude]\n\n[depth]\n\n[dvl]\n"),
        "tank+sensors",
    )
    .expect("scene with sensors");
    let traj = Trajectory::load(&r.join("tests/data/to-and-fro.csv")).expect("trajectory");
    let header = LogHeader::new(scene.adc.bits, scene.adc.rate_hz);
    let file = std::fs::File::create(&log).expect("create log");
    let mut w = LogWriter::new(std::io::BufWriter::new(file), &header).expect("header");
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let mut sim = Simulator::new(scene, 5);
    let (s, c) = 45f64.to_radians().sin_cos();
    for (seq, &t) in times.iter().enumerate() {
        let mut f = sim.frame_moving(seq as u64, t, &traj.kinematics(t));
        let v = f.velocity.as_mut().expect("a DVL reading");
        let [fwd, right, down] = v.v.0;
        v.v.0 = [c * fwd - s * right, s * fwd + c * right, down];
        w.write_frame(&f).expect("write frame");
    }
    w.flush().expect("flush");
    drop(w);
    let (sub, addr) = subscriber();
    let text = format!(
        "rate_hz = 5.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{addr}\"]\nstatus_interval_s = 0.2\n",
        r.join("config/calibration/tank.toml").display(),
        log.display(),
    );
    let cfg = Config::parse(&text, "turned.toml", None).expect("valid config");
    let (summary, msgs) = run_to_end(cfg, Duration::from_secs(30), &sub);
    assert_eq!(summary.frames as usize, times.len(), "{summary:?}");
    let st = *of_class(&msgs, "STATUS").last().expect("a STATUS");
    let (vel, dvl) = (&st["readings"]["velocity"], &st["readings"]["check"]["dvl"]);
    let refused = vel["refused"]["light"].as_u64().expect("refused.light");
    let turned = dvl["turned_deg"].as_f64().expect("a turn judged");
    assert_eq!(dvl["refused"], true, "{dvl}");
    assert!(refused > 150, "{vel}");
    assert!((turned - 45.0).abs() < 6.0, "{dvl}");
}

/// The mock flying a minute of coming and going in the tank with all three
/// sensors as fast as it goes, with `fault` (a `faults` table's keys),
/// the tracker on calibration `cal`, sending to `dest`.
fn biased_minute_config(cal: &std::path::Path, fault: &str, dest: &str) -> String {
    let r = root();
    format!(
        "rate_hz = 5.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"mock\"\nscene = \"{}\"\ntrajectory = \"{}\"\nrate_hz = 0\nloop = false\nseed = 11\nfaults = {{ {fault} }}\n[outputs]\ndestinations = [\"{dest}\"]\nstatus_interval_s = 0.2\n",
        cal.display(),
        r.join("tests/data/tank-sensors.toml").display(),
        r.join("tests/data/to-and-fro.csv").display(),
    )
}

/// A depth sensor 0.1 m off, or an AHRS pitched 2° up, under the gate
/// (mock `faults.depth_bias_m`, `faults.pitch_bias_deg`; a minute of
/// coming and going in the tank with all three sensors, as fast as it
/// goes): the reading check calls it, and the tracker learns the offset of
/// the sensor that is off, the other's not reported (STATUS
/// `estimator.depth_offset`, `pitch_offset`). Before, the bias went into
/// every pose and only the check said so, as it still does with the
/// calls unanswered (`called_*_sigma` 0: neither offset reported).
#[test]
fn a_biased_sensor_s_offset_is_learned_and_told_in_status() {
    let r = root();
    let dir = tempfile::tempdir().expect("tempdir");
    // The same calibration with the check's calls not answered (the
    // behaviour before): the bias is believed, nothing learned.
    let believed = dir.path().join("believed.toml");
    let cal = std::fs::read_to_string(r.join("config/calibration/tank.toml")).expect("cal");
    std::fs::write(
        &believed,
        cal + "\n[estimator.tracker]\ncalled_depth_offset_sigma_m = 0.0\ncalled_pitch_offset_sigma_deg = 0.0\n",
    )
    .expect("write");
    for (fault, depth_bias, pitch_bias, cal) in [
        (
            "depth_bias_m = 0.1",
            0.1,
            0.0,
            r.join("config/calibration/tank.toml"),
        ),
        (
            "pitch_bias_deg = 2.0",
            0.0,
            2.0,
            r.join("config/calibration/tank.toml"),
        ),
        ("depth_bias_m = 0.1", 0.0, 0.0, believed),
    ] {
        let (sub, addr) = subscriber();
        let text = biased_minute_config(&cal, fault, &addr.to_string());
        let cfg = Config::parse(&text, "biased.toml", None).expect("valid config");
        let (summary, msgs) = run_to_end(cfg, Duration::from_secs(60), &sub);
        assert!(summary.frames > 290, "{fault}: {summary:?}");
        let st = *of_class(&msgs, "STATUS").last().expect("a STATUS");
        let est = &st["estimator"];
        let check = &st["readings"]["check"];
        let called = |c: &str| check[c]["frames"].as_u64().unwrap_or(0);
        assert!(
            called("depth") + called("pitch") > 0,
            "{fault}: never called: {check}"
        );
        if depth_bias == 0.0 && pitch_bias == 0.0 {
            assert!(
                est["depth_offset"].is_null() && est["pitch_offset"].is_null(),
                "believed: {est}"
            );
            continue;
        }
        let (learned, other, want) = if depth_bias != 0.0 {
            (&est["depth_offset"], &est["pitch_offset"], depth_bias)
        } else {
            (&est["pitch_offset"], &est["depth_offset"], pitch_bias)
        };
        let m = learned["m"].as_f64().or(learned["deg"].as_f64());
        let sd = learned["std"].as_f64();
        let (Some(m), Some(sd)) = (m, sd) else {
            panic!("{fault}: no offset learned: {est}");
        };
        assert!((m - want).abs() <= 3.0 * sd, "{fault}: {m} ± {sd}: {est}");
        assert!(other.is_null(), "{fault}: the other sensor blamed: {est}");
    }
}

/// The real binary's log on a sensor off by a constant: the reading
/// check's WARN, then one line (not one per change of lead while the
/// hypotheses are weighed) saying which offset the estimator now
/// estimates.
#[test]
fn the_log_says_once_which_offset_is_estimated() {
    let r = root();
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = dir.path().join("biased.toml");
    std::fs::write(
        &cfg,
        biased_minute_config(
            &r.join("config/calibration/tank.toml"),
            "depth_bias_m = 0.1",
            "127.0.0.1:9",
        ),
    )
    .expect("config");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lightposed"))
        .arg("--config")
        .arg(&cfg)
        .env_remove("RUST_LOG")
        .output()
        .expect("run lightposed");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("disagree with the light"), "{err}");
    let said = err
        .lines()
        .filter(|l| l.contains("the estimator estimates the depth sensor's offset"))
        .count();
    assert_eq!(said, 1, "{err}");
}
