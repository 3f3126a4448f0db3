//! A sweep frame whose truth or temperature no lit frame can have (a
//! truth typed in millimetres, a thermometer's fault) is left out of both
//! fits, counted by reason. Before, one truth of x = 1e9 m widened the
//! calibration's coverage to 1e9 m (and, in an audit, gave `ok` poses with
//! σx 2e7 m), and a temperature of 500 °C, skipped by the paper's fits as
//! a bare `bad_frame`, reached the light model's temperature gain.

mod common;

use common::root;
use lightpose_pipeline::calibration::{calibrate_full, CalibrateOptions, Calibrated};
use lightpose_sim::{Scene, SweepKind, SweepPlan};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::Path;

/// `from` with the truth x of lit frame `at_x` and the temperature of lit
/// frame `at_t` made impossible.
fn spoiled(from: &Path, to: &Path, at_x: usize, at_t: usize) {
    let mut out = BufWriter::new(File::create(to).expect("create"));
    for (i, line) in BufReader::new(File::open(from).expect("open"))
        .lines()
        .enumerate()
    {
        let mut v: serde_json::Value = serde_json::from_str(&line.expect("line")).expect("json");
        if i == at_x {
            v["truth"]["x"] = 1e9.into();
        }
        if i == at_t {
            v["temp_c"] = 500.0.into();
        }
        writeln!(out, "{v}").expect("write");
    }
}

#[test]
fn impossible_truth_and_temperature_are_left_out_of_both_fits() {
    let scene = Scene::load(&root().join("config/scenes/tank.toml")).expect("tank scene");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (clean, bad, dark) = (
        d.join("clean.jsonl"),
        d.join("bad.jsonl"),
        d.join("dark.jsonl"),
    );
    for (kind, samples, seed, path) in [
        (SweepKind::All, 10, 31, &clean),
        (SweepKind::Dark, 200, 32, &dark),
    ] {
        let out = BufWriter::new(File::create(path).expect("create sweep"));
        SweepPlan::new(kind, samples)
            .write(&scene, seed, out)
            .expect("write sweep");
    }
    // Mid-pose frames of a translation pose and of an orientation pose.
    spoiled(&clean, &bad, 45, 2005);
    let cal = |sweep: &Path| -> Calibrated {
        let mut opts = CalibrateOptions::new(vec![sweep.to_path_buf()]);
        opts.dark = Some(dark.clone());
        calibrate_full(&opts, |e| panic!("bad line: {e}")).expect("calibrates")
    };
    let (a, b) = (cal(&clean), cal(&bad));
    assert_eq!(b.cal.meta.frames + 2, a.cal.meta.frames);
    assert_eq!(b.cal.coverage.x_m, a.cal.coverage.x_m);
    let notes = b.notes.join("\n");
    assert!(notes.contains("1 truth beyond any lit pose"), "{notes}");
    assert!(notes.contains("1 temperature not water's"), "{notes}");
    assert!(!notes.contains("bad_frame"), "{notes}");
    let (pa, pb) = (
        a.cal.physical.as_ref().expect("clean light model"),
        b.cal
            .physical
            .as_ref()
            .expect("spoiled sweep's light model"),
    );
    // Two frames of 3000 less: the same model to well within its doubt.
    for (what, x, y, sd) in [
        ("K_D", pa.k_d.value, pb.k_d.value, pa.k_d.std),
        ("V1", pa.v1.value, pb.v1.value, pa.v1.std),
    ] {
        assert!((x - y).abs() < sd, "{what}: {x} against {y} (σ {sd})");
    }
    assert!(
        (pb.chi2_per_dof - pa.chi2_per_dof).abs() < 0.05,
        "χ²/dof {} against {}",
        pb.chi2_per_dof,
        pa.chi2_per_dof
    );
}
