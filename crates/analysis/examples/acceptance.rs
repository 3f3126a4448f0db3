//! The acceptance table of issue 13 for one run: p95 of |error| per axis
//! after the first second, from a simulated log (its truth) and the POSE
//! lines `lightpose replay` wrote for it, against the targets for
//! the run's set of own sensors; without sensors, against the paper's
//! method on the same log. Used by tools/heldout-check.sh.
//!
//!   cargo run --release -p lightpose-analysis --example acceptance -- \
//!       RUN SET LOG AUTO_POSES [MOMENTS_POSES]
//!
//! SET: all (attitude + depth + DVL), depth or none. Prints one Markdown
//! row per estimator and, for `none`, the ratios auto/moments: over each
//! estimator's own frames after 1 s, and over the frames where both give
//! the axis (the paper's method gives surge only once its window is full).

// Axis loops index several per-axis arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::LogReader;
use std::collections::HashMap;
use std::path::Path;

const AXES: [&str; 6] = ["x", "y", "z", "pitch", "yaw", "surge"];

/// Per frame after the first second: |error| per axis where given.
type Errors = Vec<[Option<f64>; 6]>;

/// Per frame with truth: seq, t and the true value of each axis.
type Truths = Vec<(u64, f64, [f64; 6])>;

fn truths(log: &Path) -> Result<(Truths, f64), Box<dyn std::error::Error>> {
    let mut out = Vec::new();
    let mut t0 = f64::NAN;
    for f in LogReader::open(log)? {
        let f = f?;
        if t0.is_nan() {
            t0 = f.t;
        }
        if let Some(tr) = f.truth {
            out.push((
                f.seq,
                f.t,
                tr.pose.values_with_surge(tr.surge.unwrap_or(f64::NAN)),
            ));
        }
    }
    Ok((out, t0))
}

fn errors(log: &Path, poses: &Path) -> Result<Errors, Box<dyn std::error::Error>> {
    let (truth, t0) = truths(log)?;
    let mut by_seq: HashMap<u64, [Option<f64>; 6]> = HashMap::new();
    for line in std::fs::read_to_string(poses)?.lines() {
        let v: serde_json::Value = serde_json::from_str(line)?;
        let Some(seq) = v["seq"].as_u64() else {
            continue;
        };
        by_seq.insert(seq, AXES.map(|a| v[a].as_f64()));
    }
    let mut out = Vec::new();
    for (seq, t, tr) in truth {
        if t < t0 + 1.0 - 1e-9 {
            continue;
        }
        let got = by_seq.get(&seq).copied().unwrap_or([None; 6]);
        let mut row = [None; 6];
        for a in 0..6 {
            row[a] = got[a].map(|g| {
                let mut d = g - tr[a];
                if a == 4 {
                    d = (d + 180.0).rem_euclid(360.0) - 180.0;
                }
                d.abs()
            });
        }
        out.push(row);
    }
    Ok(out)
}

/// Nearest-rank 95th percentile of axis `a` over the frames `keep` allows.
fn p95(e: &Errors, a: usize, keep: impl Fn(usize) -> bool) -> Option<f64> {
    let mut v: Vec<f64> = (0..e.len())
        .filter(|&j| keep(j))
        .filter_map(|j| e[j][a])
        .collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let rank = ((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len());
    Some(v[rank - 1])
}

fn cell(v: Option<f64>, target: Option<f64>) -> String {
    match (v, target) {
        (Some(v), Some(t)) => format!("{v:.3} {} {t}", if v <= t { "≤" } else { "**>**" }),
        (Some(v), None) => format!("{v:.3}"),
        (None, _) => "—".into(),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 5 {
        return Err("usage: acceptance RUN SET LOG AUTO_POSES [MOMENTS_POSES]".into());
    }
    let (run, set) = (&a[1], a[2].as_str());
    let auto = errors(Path::new(&a[3]), Path::new(&a[4]))?;
    let targets: [Option<f64>; 6] = match set {
        "all" => [
            Some(0.1),
            Some(0.1),
            Some(0.05),
            Some(1.0),
            Some(3.0),
            Some(0.05),
        ],
        "depth" => [Some(0.5), None, Some(0.06), Some(3.0), None, Some(0.25)],
        _ => [None; 6],
    };
    let row: Vec<String> = (0..6)
        .map(|i| cell(p95(&auto, i, |_| true), targets[i]))
        .collect();
    println!("| {run} | {set} | auto | {} |", row.join(" | "));
    if let Some(m) = a.get(5) {
        let mom = errors(Path::new(&a[3]), Path::new(m))?;
        let row: Vec<String> = (0..6).map(|i| cell(p95(&mom, i, |_| true), None)).collect();
        println!("| {run} | {set} | moments | {} |", row.join(" | "));
        // The bar: x, surge within 1.1× of moments, y, z no worse.
        let bar = [1.1, 1.0, 1.0, f64::NAN, f64::NAN, 1.1];
        let ratio = |keep: &dyn Fn(usize) -> bool, i: usize| match (
            p95(&auto, i, keep),
            p95(&mom, i, keep),
        ) {
            (Some(x), Some(y)) if y > 0.0 => {
                let r = x / y;
                if bar[i].is_nan() {
                    format!("{r:.2}")
                } else {
                    format!(
                        "{r:.2} {} {}",
                        if r <= bar[i] { "≤" } else { "**>**" },
                        bar[i]
                    )
                }
            }
            _ => "—".into(),
        };
        let own: Vec<String> = (0..6).map(|i| ratio(&|_| true, i)).collect();
        println!("| {run} | {set} | auto/moments | {} |", own.join(" | "));
        let common: Vec<String> = (0..6)
            .map(|i| ratio(&|j| auto[j][i].is_some() && mom[j][i].is_some(), i))
            .collect();
        println!(
            "| {run} | {set} | auto/moments, same frames | {} |",
            common.join(" | ")
        );
    }
    Ok(())
}
