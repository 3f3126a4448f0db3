//! A dark log the user gave that cannot give dark levels is refused in one
//! line naming it (audit): one with no frames had been replaced by
//! MODEL.md's nominal levels without a word, and one whose every channel
//! read the same count on every frame (a stuck ADC) set the no-light level
//! at two LSB, so that beacon-off frames read as `out_of_range`.

mod common;

use common::root;
use lightpose_pipeline::calibration::{calibrate, CalibrateError, CalibrateOptions};
use lightpose_sim::{Scene, SweepKind, SweepPlan};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::Path;

fn write_sweep(kind: SweepKind, samples: u32, seed: u64, path: &Path) {
    let scene = Scene::load(&root().join("config/scenes/tank.toml")).expect("tank scene");
    let out = BufWriter::new(File::create(path).expect("create sweep"));
    SweepPlan::new(kind, samples)
        .write(&scene, seed, out)
        .expect("write sweep");
}

/// `from` rewritten line by line by `edit` (the header passes as it is).
fn rewrite(from: &Path, to: &Path, edit: impl Fn(&mut serde_json::Value) -> bool) {
    let mut out = BufWriter::new(File::create(to).expect("create"));
    for line in BufReader::new(File::open(from).expect("open")).lines() {
        let mut v: serde_json::Value = serde_json::from_str(&line.expect("line")).expect("json");
        if v["class"] == "HEADER" || edit(&mut v) {
            writeln!(out, "{v}").expect("write");
        }
    }
}

fn refusal(sweep: &Path, dark: &Path) -> String {
    let mut opts = CalibrateOptions::new(vec![sweep.to_path_buf()]);
    opts.dark = Some(dark.to_path_buf());
    match calibrate(&opts, |e| panic!("bad line: {e}")) {
        Err(e @ CalibrateError::Refused(_)) => e.to_string(),
        other => panic!("not refused: {other:?}"),
    }
}

#[test]
fn a_dark_log_without_frames_or_noise_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (sweep, dark) = (d.join("sweep.jsonl"), d.join("dark.jsonl"));
    write_sweep(SweepKind::All, 3, 31, &sweep);
    write_sweep(SweepKind::Dark, 50, 32, &dark);
    let empty = d.join("empty-dark.jsonl");
    rewrite(&dark, &empty, |_| false);
    let e = refusal(&sweep, &empty);
    assert!(e.contains("empty-dark.jsonl has no frames"), "{e}");
    let stuck = d.join("stuck-dark.jsonl");
    rewrite(&dark, &stuck, |v| {
        v["counts"] = serde_json::json!(vec![31; 25]);
        true
    });
    let e = refusal(&sweep, &stuck);
    assert!(
        e.contains("stuck-dark.jsonl") && e.contains("same count on all 50 frames"),
        "{e}"
    );
    // The dark log as recorded calibrates.
    let mut opts = CalibrateOptions::new(vec![sweep]);
    opts.dark = Some(dark);
    calibrate(&opts, |e| panic!("bad line: {e}")).expect("calibrates");
}
