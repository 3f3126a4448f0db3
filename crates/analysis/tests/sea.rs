//! The trade table's open sea (`lightpose_analysis::sea`), on the shipped
//! files (config/scenes/sea-*.toml, config/trajectories/approach.csv,
//! config/calibration/sea-*.toml) with few runs: every case gives its
//! rows; the blinking beacon by day is within 1.5× of the night's p95 (the
//! demodulator leaves the sun out); the steady beacon by day, with the
//! ambient modelled, gives `ok` poses and says so honestly; a blinking
//! beacon's time per frame includes its demodulation; the table and the
//! plot say what they measured.

use lightpose_analysis::sea::{self, SeaSection, SEA_CASES};
use lightpose_analysis::trade::{self, TradeOptions};
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

fn run_all(runs: usize, estimators: &[&str]) -> Vec<SeaSection> {
    let o = TradeOptions {
        runs,
        seed: 1,
        timing_runs: 1,
        estimators: estimators.iter().map(|s| s.to_string()).collect(),
    };
    SEA_CASES
        .iter()
        .map(|c| {
            let l = trade::load(root(), c).expect("shipped files");
            sea::run_case(&l, &o, &|_| indicatif::ProgressBar::hidden()).expect("case runs")
        })
        .collect()
}

#[test]
fn the_open_sea_rows_blink_through_the_day_and_the_steady_beacon_copes() {
    let secs = run_all(6, &["moments", "tracker"]);
    let kinds: Vec<(bool, bool)> = secs.iter().map(|s| (s.blinking, s.day)).collect();
    assert_eq!(
        kinds,
        [(true, false), (true, true), (false, false), (false, true)],
        "the scenes are the cases they are named for"
    );
    for s in &secs {
        assert_eq!(s.rows.len(), 2, "{}: {:?}", s.case.name, s.skipped);
        assert!(s.skipped.is_empty(), "{:?}", s.skipped);
        for r in &s.rows {
            // 6 runs of the 12 s approach at 10 Hz, after its first second.
            assert!(
                r.judged.frames >= 6 * 100,
                "{}: {:?}",
                s.case.name,
                r.judged
            );
            assert!(r.us_per_frame > 0.0 && r.us_per_frame.is_finite());
        }
        // A blinking case's frames go through the demodulator, which is
        // timed (no comparison of timings: speed is the table's, not a
        // test's); a steady one has none.
        match s.demod_us {
            Some(d) => assert!(s.blinking && d > 0.0, "{}", s.case.name),
            None => assert!(!s.blinking, "{}", s.case.name),
        }
        // The bound at the approach's end: finite and below a metre.
        let b = s.crb_end.expect("a bound");
        assert!(b.iter().all(|v| *v > 0.0 && *v < 1.0), "{b:?}");
    }
    let tracker = |i: usize| {
        secs[i]
            .rows
            .iter()
            .find(|r| r.name == "tracker")
            .map(|r| r.judged.clone())
            .expect("tracker row")
    };
    let (night, day) = (tracker(0), tracker(1));
    // The blinking beacon by day: nearly every frame ok, and within 1.5×
    // of the night's p95 on every axis.
    assert!(day.ok * 10 >= day.frames * 9, "{day:?}");
    for i in 0..5 {
        let (d, n) = (day.p95[i].expect("p95"), night.p95[i].expect("p95"));
        assert!(d <= 1.5 * n, "axis {i}: day {d} night {n}");
    }
    // The steady beacon by day, the ambient modelled: ok poses, and few of
    // them beyond 3σ. Six runs draw six waters (K_D ± 0.015): one far
    // draw moves the share by points (5.6 % here; 0.5 % over the 200 runs
    // of docs/estimators.md), hence 10 % and not the 5 %.
    let steady_day = tracker(3);
    assert!(steady_day.ok * 2 >= steady_day.frames, "{steady_day:?}");
    assert!(
        steady_day.beyond3.expect("ok poses") <= 0.10,
        "{steady_day:?}"
    );
    // The table has a row per case and estimator and says what is timed
    // and which noise the bound has.
    let text = sea::table(&secs);
    for c in &SEA_CASES {
        for e in ["moments", "tracker"] {
            let rows = text
                .lines()
                .filter(|l| {
                    l.starts_with(&format!("| {} |", c.name)) && l.contains(&format!("| {e} |"))
                })
                .count();
            assert_eq!(rows, 1, "{}, {e}: {text}", c.name);
        }
    }
    assert!(text.contains("µs/frame (demod + estimator)"), "{text}");
    assert!(text.contains("white-noise limit"), "{text}");
    // The bounds read the light as the estimators do: a blinking beacon's
    // amplitudes bound the approach's end at or below the steady beacon's
    // counts, and the sun's unknown level widens the steady one's.
    let crb = |i: usize| secs[i].crb_end.expect("a bound");
    for a in 0..3 {
        assert!(crb(1)[a] <= crb(3)[a] * (1.0 + 1e-9), "axis {a}");
        assert!(crb(2)[a] <= crb(3)[a] * (1.0 + 1e-9), "axis {a}");
    }
    // And the plot is a PNG.
    let dir = tempfile::tempdir().expect("tempdir");
    let png = dir.path().join(sea::PLOT_NAME);
    sea::plot_png(&secs, &png).expect("plot");
    let bytes = std::fs::read(&png).expect("png written");
    assert!(
        bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
        "{}",
        bytes.len()
    );
}
