//! `lightpose simulate` against an independent implementation of MODEL.md
//! spec v3 (tests/python/model_v3.py, written from the spec alone): the
//! raw samples of a scene of two blinking beacons (phase, drift, a dark
//! spell), channel skew, daylight with listed flicker, on a rolling
//! trajectory, compared sample by sample. Equal counts everywhere except
//! where the model says the exact value sits within 1e-6 counts of a
//! rounding boundary or the instant on a square wave's edge (there a
//! difference of 1 count, or of the edge, is allowed, and such samples must
//! be rare). Python is the pinned venv of tools/pyenv.sh: never a skip.

mod common;

use common::{root, run, s};
use lightpose_core::{LogReader, Record, NDET};
use lightpose_testkit::python::{python, run_python};

#[test]
fn bursts_match_the_independent_model_sample_by_sample() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let scene = root().join("tests/data/v3/two-beacons.toml");
    let traj = root().join("tests/data/v3/rolling.csv");
    let log = dir.path().join("v3.jsonl");
    let (ok, _, err) = run(&[
        "simulate",
        "--scene",
        s(&scene),
        "--trajectory",
        s(&traj),
        "--out",
        s(&log),
    ]);
    assert!(ok, "{err}");
    let want = dir.path().join("model.json");
    let script = root().join("tests/python/model_v3.py");
    run_python(&py, &script, &[&scene, &traj, &want]);
    let want: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&want).unwrap()).unwrap();
    let frames = want["frames"].as_array().unwrap();
    let n = want["n"].as_u64().unwrap() as usize;
    assert_eq!(n, 200);
    let mut r = LogReader::open(&log).unwrap();
    assert_eq!(r.header().samples_per_frame(), n);
    let (mut compared, mut doubtful, mut lit_and_dark) = (0usize, 0usize, [false; 2]);
    let mut j = 0;
    while let Some(rec) = r.next_record() {
        let Record::Burst(b) = rec.unwrap() else {
            panic!("frame {j} is not a BURST");
        };
        let w = &frames[j];
        assert!(
            (b.t - w["t"].as_f64().unwrap()).abs() < 1e-12,
            "frame {j} t"
        );
        let doubt: Vec<(usize, usize)> = w["doubt"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| {
                (
                    d[0].as_u64().unwrap() as usize,
                    d[1].as_u64().unwrap() as usize,
                )
            })
            .collect();
        for k in 0..NDET {
            let ws = w["samples"][k].as_array().unwrap();
            for (i, (&got, want)) in b.channel(k).iter().zip(ws).enumerate() {
                let want = want.as_u64().unwrap() as u16;
                if doubt.contains(&(k, i)) {
                    doubtful += 1;
                    continue;
                }
                assert_eq!(got, want, "frame {j} channel {k} sample {i}");
                compared += 1;
            }
            // The blinking shows: a channel's samples are not all one level.
            let (lo, hi) = (
                ws.iter().min_by_key(|v| v.as_u64()),
                ws.iter().max_by_key(|v| v.as_u64()),
            );
            lit_and_dark[usize::from(lo != hi)] = true;
        }
        j += 1;
    }
    assert_eq!(j, frames.len(), "frames");
    assert_eq!(j, 15, "frames while the middle ≤ t_end");
    assert!(lit_and_dark[1], "the beacons blink in the samples");
    assert!(
        doubtful * 1000 < compared,
        "{doubtful} doubtful of {compared}"
    );
}
