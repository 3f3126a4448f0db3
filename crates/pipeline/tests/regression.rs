//! Regression: the recorded logs of tests/data/ (X.jsonl) replayed with the
//! shipped tank calibration must give the expected POSE lines beside them
//! (X.poses.jsonl), gpsd-style: the paper's method on the older logs, the
//! tracker on the logs with the vehicle's own sensors (fusion-*). Numbers
//! are compared to 1e-9 relative (the tracker's, iterated fits and all, to
//! 1e-6), so a different libm's last bit does not fail the test but any
//! change of the method does. To accept an intended change, rebuild the expected files
//! with `tools/regen-expected.sh` or `LIGHTPOSE_REGEN=1 cargo test -p
//! lightpose-pipeline --test regression`, and review the diff.

use lightpose_core::{LogReader, ReadingUse, Refusal, Status};
use lightpose_pipeline::{build_estimator, replay, Calibration, ReplaySummary};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The estimator a log's expectations were recorded with, and the relative
/// tolerance of its numbers.
fn estimator_of(name: &str) -> (&'static str, f64) {
    if name.starts_with("fusion") {
        ("tracker", 1e-6)
    } else {
        ("moments", 1e-9)
    }
}

fn run(name: &str) -> (Vec<u8>, ReplaySummary) {
    let root = root();
    let cal = Calibration::load(&root.join("config/calibration/tank.toml")).expect("calibration");
    // Each estimator pinned by name: "auto" follows the best estimator the
    // calibration allows, which is not what these expectations record.
    let mut est = build_estimator(estimator_of(name).0, &cal).expect("estimator");
    let mut log = LogReader::open(&root.join(format!("tests/data/{name}.jsonl"))).expect("log");
    let mut out = Vec::new();
    let s = replay(est.as_mut(), &mut log, &mut out, |_| {}).expect("replay");
    (out, s)
}

fn same(a: &Value, b: &Value, path: &str, tol: f64) -> Result<(), String> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (
                x.as_f64().unwrap_or(f64::NAN),
                y.as_f64().unwrap_or(f64::NAN),
            );
            if (x - y).abs() <= tol * (1.0 + x.abs().max(y.abs())) {
                Ok(())
            } else {
                Err(format!("{path}: {x} vs expected {y}"))
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            let keys: std::collections::BTreeSet<_> = x.keys().chain(y.keys()).collect();
            for k in keys {
                same(
                    x.get(k).unwrap_or(&Value::Null),
                    y.get(k).unwrap_or(&Value::Null),
                    &format!("{path}.{k}"),
                    tol,
                )?;
            }
            Ok(())
        }
        _ if a == b => Ok(()),
        _ => Err(format!("{path}: {a} vs expected {b}")),
    }
}

fn check(name: &str) -> ReplaySummary {
    let (got, summary) = run(name);
    let expected_path = root().join(format!("tests/data/{name}.poses.jsonl"));
    if std::env::var_os("LIGHTPOSE_REGEN").is_some() {
        std::fs::write(&expected_path, &got).expect("write expected");
        return summary;
    }
    let want = std::fs::read_to_string(&expected_path).expect("expected poses");
    let got = String::from_utf8(got).expect("utf-8");
    let (g, w): (Vec<&str>, Vec<&str>) = (got.lines().collect(), want.lines().collect());
    assert_eq!(
        g.len(),
        w.len(),
        "{name}: {} POSE lines, expected {}",
        g.len(),
        w.len()
    );
    for (i, (a, b)) in g.iter().zip(&w).enumerate() {
        let a: Value = serde_json::from_str(a).expect("our line is JSON");
        let b: Value = serde_json::from_str(b).expect("expected line is JSON");
        if let Err(e) = same(&a, &b, "", estimator_of(name).1) {
            panic!("{name}.poses.jsonl line {}: {e}", i + 1);
        }
    }
    summary
}

fn count(s: &ReplaySummary, st: Status) -> u64 {
    s.status[Status::ALL.iter().position(|x| *x == st).unwrap()]
}

#[test]
fn dive() {
    let s = check("dive");
    assert_eq!((s.frames, s.bad_lines), (41, 0));
    assert!(s.report.is_some());
}

#[test]
fn zigzag() {
    let s = check("zigzag");
    assert_eq!((s.frames, s.bad_lines), (41, 0));
}

#[test]
fn dive_12bit() {
    let s = check("dive-12bit");
    assert_eq!(s.frames, 41);
    // The same trajectory through a finer ADC estimates the same pose: the
    // counts convert by the frame's own resolution.
    let (a, b) = (s.report.unwrap(), check("dive").report.unwrap());
    let (xa, xb) = (a.axes[0].unwrap(), b.axes[0].unwrap());
    assert!(
        (xa.rmse - xb.rmse).abs() < 0.15,
        "x rmse 12-bit {} vs 10-bit {}",
        xa.rmse,
        xb.rmse
    );
}

#[test]
fn dark_saturated_and_bad_lines() {
    let s = check("hard");
    assert_eq!(s.bad_lines, 1);
    assert_eq!(s.frames, 41);
    assert_eq!(count(&s, Status::NoLight), 4);
    assert!(count(&s, Status::Saturated) > 10);
}

fn readings(s: &ReplaySummary, which: usize, u: ReadingUse) -> u64 {
    s.readings[which][u.index()]
}

/// The zigzag with attitude, depth and DVL, five bad readings spliced in:
/// each refused with its reason, the frame's light still used.
#[test]
fn fusion_all_refuses_bad_readings_by_reason() {
    let s = check("fusion-all");
    assert_eq!((s.frames, s.bad_lines, s.bad_readings), (41, 0, 0));
    assert_eq!(count(&s, Status::Ok) + count(&s, Status::Initialising), 41);
    let (att, depth, vel) = (0, 1, 2);
    let r = |_: usize, f| ReadingUse::Refused(f);
    assert_eq!(readings(&s, att, ReadingUse::Used), 40);
    assert_eq!(readings(&s, att, r(att, Refusal::BadStd)), 1);
    assert_eq!(readings(&s, depth, ReadingUse::Used), 38);
    assert_eq!(readings(&s, depth, r(depth, Refusal::BadStd)), 1);
    assert_eq!(readings(&s, depth, r(depth, Refusal::Implausible)), 1);
    assert_eq!(readings(&s, depth, r(depth, Refusal::Gate)), 1);
    assert_eq!(readings(&s, vel, ReadingUse::Used), 40);
    assert_eq!(readings(&s, vel, r(vel, Refusal::Implausible)), 1);
    let line = s.readings_line().unwrap();
    assert!(line.contains("depth 38 used, 1 refused_bad_std"), "{line}");
    // With all three sensors the run stays within centimetres.
    let z = s.report.unwrap().axes[2].unwrap();
    assert!(z.p95 < 0.05, "{z:?}");
}

/// The dive with depth alone: every depth used.
#[test]
fn fusion_depth() {
    let s = check("fusion-depth");
    assert_eq!(s.frames, 41);
    assert_eq!(readings(&s, 1, ReadingUse::Used), 41);
    assert_eq!(readings(&s, 0, ReadingUse::Absent), 41);
    assert!(s.report.unwrap().axes[2].unwrap().p95 < 0.06);
}
