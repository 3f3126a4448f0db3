//! `replay` keeps running statistics of the error against truth, not every
//! frame's error (issue 16: 58 MB at a million frames): the heap it holds
//! while replaying a long log with truth is bounded, measured here with a
//! global allocator that tracks the bytes live, and its report is the one
//! of the short log it repeats.

use lightpose_core::LogReader;
use lightpose_pipeline::replay::AxisError;
use lightpose_pipeline::{build_estimator, replay, Calibration};
use lightpose_testkit::alloc::Counting;
use std::io::{BufReader, Read, Write};
use std::path::Path;

#[global_allocator]
static A: Counting = Counting::new();

/// The frames of a short log repeated `times` times with seq and t running
/// on: a long log made on the fly, never held in memory.
struct Repeat {
    header: String,
    /// Each frame's line after its `t` value.
    frames: Vec<String>,
    k: usize,
    total: usize,
    pending: Vec<u8>,
    at: usize,
}

impl Read for Repeat {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        if self.at == self.pending.len() {
            self.pending.clear();
            self.at = 0;
            if !self.header.is_empty() {
                self.pending
                    .extend_from_slice(std::mem::take(&mut self.header).as_bytes());
            } else if self.k < self.total {
                let rest = &self.frames[self.k % self.frames.len()];
                let t = self.k as f64 * 0.2;
                let line = format!("{{\"class\":\"FRAME\",\"seq\":{},\"t\":{t}{rest}\n", self.k);
                self.pending.extend_from_slice(line.as_bytes());
                self.k += 1;
            } else {
                return Ok(0);
            }
        }
        let n = out.len().min(self.pending.len() - self.at);
        out[..n].copy_from_slice(&self.pending[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

#[test]
fn a_long_replay_with_truth_holds_a_bounded_heap_and_reports_alike() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cal = Calibration::load(&root.join("config/calibration/tank.toml")).expect("calibration");
    let text = std::fs::read_to_string(root.join("tests/data/dive.jsonl")).expect("log");
    let mut lines = text.lines();
    let header = format!("{}\n", lines.next().expect("header"));
    // Lines start {"class":"FRAME","seq":S,"t":T, ...: keep what follows T.
    let frames: Vec<String> = lines
        .map(|l| {
            let after_t = &l[l.find(",\"t\":").expect("t") + 5..];
            after_t[after_t.find(',').expect("more")..].to_string()
        })
        .collect();
    let truths: Vec<serde_json::Value> = text
        .lines()
        .skip(1)
        .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("frame")["truth"].clone())
        .collect();
    let n = frames.len();
    let times = 500;
    let total = n * times;

    let replay_into = |mut out: &mut dyn Write| {
        let src = Repeat {
            header: header.clone(),
            frames: frames.clone(),
            k: 0,
            total,
            pending: Vec::new(),
            at: 0,
        };
        let mut log = LogReader::new(BufReader::new(src), "repeat.jsonl").expect("header");
        let mut est = build_estimator("moments", &cal).expect("estimator");
        A.peak_of(|| {
            replay(est.as_mut(), &mut log, &mut out, |e| {
                panic!("no bad line: {e}")
            })
            .expect("replay")
        })
    };
    let (long, held) = replay_into(&mut std::io::sink());
    assert_eq!(long.frames, total as u64);
    // 20,500 frames with truth on six axes: every error kept would be
    // 1 MB at least, 1.6 MB as the vectors grow.
    assert!(held < 800_000, "{held} bytes held while replaying");

    // The same replay with its POSE lines kept: the exact statistics from
    // them and the truth agree with the running ones.
    let mut poses = Vec::new();
    replay_into(&mut poses);
    let mut errs: [Vec<f64>; 6] = Default::default();
    let keys = ["x", "y", "z", "pitch", "yaw", "surge"];
    for (k, line) in String::from_utf8(poses).expect("utf-8").lines().enumerate() {
        let p: serde_json::Value = serde_json::from_str(line).expect("POSE");
        let t = &truths[k % n];
        for (i, key) in keys.iter().enumerate() {
            if let (Some(e), Some(tv)) = (p[key].as_f64(), t[key].as_f64()) {
                let d = e - tv;
                let d = if i == 3 || i == 4 {
                    (d + 180.0).rem_euclid(360.0) - 180.0
                } else {
                    d
                };
                errs[i].push(d);
            }
        }
    }
    let report = long.report.expect("truth");
    for (i, got) in report.axes.iter().enumerate() {
        let want = AxisError::of(&errs[i]);
        let (Some(x), Some(y)) = (want, got) else {
            assert_eq!(want.is_some(), got.is_some(), "{}", keys[i]);
            continue;
        };
        assert_eq!(y.n, x.n, "{}", keys[i]);
        assert!(x.n > 2048, "past the exact buffer");
        let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol * (1.0 + a.abs());
        assert!(
            close(x.mean, y.mean, 1e-9) && close(x.rmse, y.rmse, 1e-9),
            "{x:?} {y:?}"
        );
        assert!(
            (x.p95 - y.p95).abs() <= 1e-3 * x.p95 + 4.8e-7,
            "{x:?} {y:?}"
        );
        assert!(close(x.last, y.last, 1e-9), "{x:?} {y:?}");
    }
}
