//! A sweep recorded in a real tank carries its truth as the carriage
//! measured it, not to the last digit: it calibrates as the exact one
//! does. Before, truth was compared to 1e-9 (a pose's frames "the same",
//! a value "zero"): noise of 1e-6 on y, z and the angles refused the whole
//! sweep as "mixed pose", and 1e-12 broke every pose into groups of one
//! frame, so the light model was left out with "sweep has no frames with
//! a truth pose".

mod common;

use common::{root, Lcg};
use lightpose_pipeline::calibration::{calibrate, calibrate_full, CalibrateOptions};
use lightpose_sim::{Scene, SweepKind, SweepPlan};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::Path;

/// `from` with every frame's truth moved by up to ±`m` metres and ±`deg`
/// degrees, as a carriage reads it back.
fn measured(from: &Path, to: &Path, m: f64, deg: f64) {
    let mut rng = Lcg(7);
    let mut out = BufWriter::new(File::create(to).expect("create"));
    for line in BufReader::new(File::open(from).expect("open")).lines() {
        let mut v: serde_json::Value = serde_json::from_str(&line.expect("line")).expect("json");
        if let Some(t) = v.get_mut("truth").and_then(|t| t.as_object_mut()) {
            for (k, s) in [("x", m), ("y", m), ("z", m), ("pitch", deg), ("yaw", deg)] {
                if let Some(x) = t.get(k).and_then(|x| x.as_f64()) {
                    t.insert(k.into(), (x + s * (2.0 * rng.uniform() - 1.0)).into());
                }
            }
        }
        writeln!(out, "{v}").expect("write");
    }
}

#[test]
fn a_sweep_with_measured_truth_calibrates_as_the_exact_one() {
    let scene = Scene::load(&root().join("config/scenes/tank.toml")).expect("tank scene");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (exact, noisy, dark) = (
        d.join("exact.jsonl"),
        d.join("noisy.jsonl"),
        d.join("dark.jsonl"),
    );
    for (kind, samples, seed, path) in [
        (SweepKind::All, 10, 21, &exact),
        (SweepKind::Dark, 200, 22, &dark),
    ] {
        let out = BufWriter::new(File::create(path).expect("create sweep"));
        SweepPlan::new(kind, samples)
            .write(&scene, seed, out)
            .expect("write sweep");
    }
    measured(&exact, &noisy, 5e-4, 0.02);
    let cal = |sweep: &Path| {
        let mut opts = CalibrateOptions::new(vec![sweep.to_path_buf()]);
        opts.dark = Some(dark.clone());
        calibrate(&opts, |e| panic!("bad line: {e}")).expect("calibrates")
    };
    let (a, b) = (cal(&exact), cal(&noisy));
    assert_eq!(a.meta.frames, b.meta.frames);
    let (pa, pb) = (
        a.physical.as_ref().expect("the exact sweep's light model"),
        b.physical
            .as_ref()
            .expect("the measured sweep's light model"),
    );
    let rel = |x: f64, y: f64| ((x - y) / x).abs();
    assert!(
        rel(pa.k_d.value, pb.k_d.value) < 0.01,
        "K_D {:?} {:?}",
        pa.k_d,
        pb.k_d
    );
    assert!(
        rel(pa.v1.value, pb.v1.value) < 0.01,
        "V1 {:?} {:?}",
        pa.v1,
        pb.v1
    );
    assert!(
        rel(a.fits.x.b1, b.fits.x.b1) < 0.01,
        "x law {} {}",
        a.fits.x.b1,
        b.fits.x.b1
    );
}

/// A sweep of one frame per pose has no noise to read at any pose: the
/// light model is left out saying so (it said "sweep has no frames with a
/// truth pose", of a sweep whose every frame had one).
#[test]
fn a_sweep_of_one_frame_per_pose_says_why_the_light_model_is_left_out() {
    let scene = Scene::load(&root().join("config/scenes/tank.toml")).expect("tank scene");
    let dir = tempfile::tempdir().unwrap();
    let sweep = dir.path().join("sweep.jsonl");
    let out = BufWriter::new(File::create(&sweep).expect("create sweep"));
    SweepPlan::new(SweepKind::All, 1)
        .write(&scene, 23, out)
        .expect("write sweep");
    let c = calibrate_full(&CalibrateOptions::new(vec![sweep]), |e| {
        panic!("bad line: {e}")
    })
    .expect("the paper's fits");
    let why = c.physical_skipped.expect("no light model").to_string();
    assert!(why.contains("frames in a row"), "{why}");
    assert!(!why.contains("no frames with a truth pose"), "{why}");
}
