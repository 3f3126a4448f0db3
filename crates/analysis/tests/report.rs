//! What a Monte Carlo run writes: the CSV's columns and rows, the summary's
//! table beside the paper's figures, and plots that render to PNG and SVG
//! from the bundled font alone (plotters' ab_glyph backend never looks at
//! system fonts, so an unregistered font would fail here).

use indicatif::ProgressBar;
use lightpose_analysis::montecarlo::{run, McConfig, McResult, AXES};
use lightpose_analysis::plot::{render_png, render_svg};
use lightpose_analysis::report::{self, csv_header, RunInfo};
use lightpose_analysis::PaperCase;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Trajectory};
use std::path::PathBuf;

fn root(p: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join(p)
}

fn small_zigzag() -> McResult {
    let cfg = McConfig {
        scene: Scene::load(&root("config/scenes/tank.toml")).unwrap(),
        trajectory: Trajectory::load(&root("config/trajectories/zigzag.csv")).unwrap(),
        runs: 12,
        seed: 5,
    };
    let cal = Calibration::load(&root("config/calibration/tank.toml")).unwrap();
    run(
        &cfg,
        || build_estimator("moments", &cal),
        &ProgressBar::hidden(),
    )
    .unwrap()
}

#[test]
fn csv_and_summary_have_the_right_columns() {
    let r = small_zigzag();
    let dir = tempfile::tempdir().unwrap();
    let info = RunInfo {
        scene: "config/scenes/tank.toml".into(),
        trajectory: "config/trajectories/zigzag.csv".into(),
        calibration: "config/calibration/tank.toml".into(),
        case: Some(PaperCase::ZigzagClear),
    };
    report::write_all(&r, &info, dir.path()).unwrap();

    let csv = std::fs::read_to_string(dir.path().join(report::CSV_NAME)).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.join(","), csv_header(&r.axes()));
    // One beacon gives no roll: the columns are the six they always were.
    assert_eq!(r.axes(), &AXES[..6]);
    assert!(!header.iter().any(|h| h.starts_with("roll_")));
    assert_eq!(&header[..2], ["t", "ok_fraction"]);
    for a in r.axes() {
        for col in ["truth", "mean", "p025", "p975", "hw95", "std", "n"] {
            let name = format!("{}_{col}", a.name());
            assert!(header.contains(&name.as_str()), "no column {name}");
        }
    }
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 41);
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for (j, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), header.len(), "row {j}");
        assert!(!row.iter().any(|f| f.contains("NaN")), "row {j}: {row:?}");
        let t: f64 = row[0].parse().unwrap();
        assert!((t - j as f64 / 5.0).abs() < 1e-9);
        let ok: f64 = row[col("ok_fraction")].parse().unwrap();
        assert!((0.0..=1.0).contains(&ok));
        // x is estimated at every step by most runs: its half-width is half the percentile span.
        let (lo, hi, hw): (f64, f64, f64) = (
            row[col("x_p025")].parse().unwrap(),
            row[col("x_p975")].parse().unwrap(),
            row[col("x_hw95")].parse().unwrap(),
        );
        assert!((hw - 0.5 * (hi - lo)).abs() < 1e-12 && hw > 0.0);
        // n counts the runs that gave an x (a frame may give none).
        let n: usize = row[col("x_n")].parse().unwrap();
        assert!((2..=12).contains(&n), "row {j}: x_n = {n}");
    }
    // At t = 0 the truth is the trajectory's first knot.
    assert_eq!(rows[0][col("x_truth")], "8.5");
    assert_eq!(rows[0][col("y_truth")], "0.2");

    let md = std::fs::read_to_string(dir.path().join(report::SUMMARY_NAME)).unwrap();
    assert!(md.starts_with("# Case II: zigzag, clear water"), "{md}");
    assert!(md.contains(
        "| axis | final nominal error | paper | 95 % HW start | paper | 95 % HW end | paper |"
    ));
    // Each axis row carries our figure and the paper's (x: 0.13, 0.83, 0.46).
    let xrow = md.lines().find(|l| l.starts_with("| x (m) |")).unwrap();
    assert!(
        xrow.contains("| 0.13 |") && xrow.contains("| 0.83 |") && xrow.contains("| 0.46 |"),
        "{xrow}"
    );
    for a in r.axes() {
        assert!(
            md.lines()
                .any(|l| l.starts_with(&format!("| {} (", a.name()))),
            "no row for {}",
            a.name()
        );
    }
    assert!(!md.contains("| roll"), "{md}");
    assert!(md.contains("## Coverage of the estimator's own σ"));
    assert!(md.contains("Differences from the paper larger than a factor of two"));
}

#[test]
fn plots_render_to_png_and_svg_with_the_bundled_font() {
    let r = small_zigzag();
    let dir = tempfile::tempdir().unwrap();
    let (png, svg) = (dir.path().join("p.png"), dir.path().join("p.svg"));
    render_png(&r, "test plot", &png).unwrap();
    render_svg(&r, "test plot", &svg).unwrap();
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert!(
        bytes.len() > 20_000,
        "a {} byte PNG has no plot in it",
        bytes.len()
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg"));
    // Title, panel captions and legend are there as text.
    for want in [
        "test plot",
        "(b) top view",
        "(c) x (m)",
        "(h) surge (m/s)",
        "95 % band",
        "truth",
    ] {
        assert!(text.contains(want), "SVG lacks {want:?}");
    }
    // Each panel its own letter, once (an audit found two "(a)").
    for letter in 'a'..='h' {
        let label = format!("({letter}) ");
        let n = text.matches(&label).count();
        assert_eq!(n, 1, "panel ({letter}) labelled {n} times");
    }
    // A directory that does not exist is an error naming the path, not a panic.
    let bad = dir.path().join("no/such/dir/p.png");
    let e = render_png(&r, "x", &bad).unwrap_err().to_string();
    assert!(e.contains("no/such/dir"), "{e}");
}
