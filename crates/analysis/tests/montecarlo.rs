//! The Monte Carlo engine's promises: the result depends on the seed and
//! not on the thread count, the scene's spreads are really drawn, the
//! estimator's own σ is checked against truth, and bad inputs fail with one
//! line. Few runs each, so the tests stay fast in a debug build.

use indicatif::ProgressBar;
use lightpose_analysis::montecarlo::{run, Axis, McConfig, McError, McResult, AXES};
use lightpose_core::{Estimator, Frame, PoseEstimate, Status};
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Trajectory};
use std::path::PathBuf;

fn root(p: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join(p)
}

fn tank_dive(runs: usize) -> (McConfig, Calibration) {
    let cfg = McConfig {
        scene: Scene::load(&root("config/scenes/tank.toml")).unwrap(),
        trajectory: Trajectory::load(&root("config/trajectories/dive.csv")).unwrap(),
        runs,
        seed: 7,
    };
    let cal = Calibration::load(&root("config/calibration/tank.toml")).unwrap();
    (cfg, cal)
}

fn moments(cfg: &McConfig, cal: &Calibration) -> McResult {
    run(
        cfg,
        || build_estimator("moments", cal),
        &ProgressBar::hidden(),
    )
    .unwrap()
}

#[test]
fn same_result_on_one_and_two_threads() {
    let (cfg, cal) = tank_dive(24);
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let one = pool(1).install(|| moments(&cfg, &cal));
    let two = pool(2).install(|| moments(&cfg, &cal));
    assert_eq!(one.threads, 1);
    assert_eq!(two.threads, 2);
    assert!(one.same_numbers(&two));
    // ...and the seed matters: another seed is another ensemble.
    let other = moments(
        &McConfig {
            seed: 8,
            ..cfg.clone()
        },
        &cal,
    );
    assert!(!one.same_numbers(&other));
    assert_eq!(one.steps.len(), 41);
}

#[test]
fn spreads_are_drawn_and_zero_spread_leaves_only_noise() {
    let (mut cfg, cal) = tank_dive(300);
    let spread = moments(&cfg, &cal);
    let n = spread.draws.len() as f64;
    let mean =
        |f: fn(&lightpose_analysis::Draw) -> f64| spread.draws.iter().map(f).sum::<f64>() / n;
    let sd = |f: fn(&lightpose_analysis::Draw) -> f64, m: f64| {
        (spread.draws.iter().map(|d| (f(d) - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    let (tm, km) = (mean(|d| d.temp_c), mean(|d| d.k_d));
    let (ts, ks) = (sd(|d| d.temp_c, tm), sd(|d| d.k_d, km));
    // 300 draws: the sample sd is within ~8 % (1σ ≈ 4 %) of the spread.
    assert!((ts - 3.0).abs() < 0.25, "temperature sd {ts}");
    assert!((ks - 0.015).abs() < 0.0013, "K_D sd {ks}");
    assert!(
        (tm - 20.0).abs() < 0.6 && (km - 0.09).abs() < 0.003,
        "{tm} {km}"
    );

    // σ = 0: every run has the nominal water; the x band (driven mostly
    // by K_D and temperature) shrinks to the electronic noise's.
    cfg.scene.montecarlo.sigma_temp_c = 0.0;
    cfg.scene.montecarlo.sigma_k_d = 0.0;
    let noise_only = moments(&cfg, &cal);
    assert!(noise_only
        .draws
        .iter()
        .all(|d| d.temp_c == 20.0 && d.k_d == 0.09));
    let hw = |r: &McResult| r.steps[0].axes[0].unwrap().half_width();
    assert!(
        hw(&noise_only) < 0.7 * hw(&spread),
        "x half-width {} with noise only, {} with spreads",
        hw(&noise_only),
        hw(&spread)
    );
    assert!(hw(&noise_only) > 0.0);

    // ...and without electronic noise too, every run is the same run.
    cfg.scene.noise = None;
    cfg.runs = 20;
    let still = moments(&cfg, &cal);
    for s in &still.steps {
        for st in s.axes.iter().flatten() {
            assert_eq!(st.p025, st.p975, "t = {}", s.t);
        }
    }
}

/// An estimator that returns the truth shifted by a known multiple of the
/// σ it reports, so that the coverage it earns is known exactly.
struct Shifted;

const SIGMA: f64 = 0.1;
/// Error of frame `seq` in units of σ: 0.05, 0.15, …, 2.95 in turn (never
/// exactly on the ±2σ edge, where rounding would decide).
fn k_sigma(seq: u64) -> f64 {
    (seq % 30) as f64 / 10.0 + 0.05
}

impl Estimator for Shifted {
    fn name(&self) -> &'static str {
        "shifted"
    }
    fn estimate(&mut self, f: &Frame) -> PoseEstimate {
        let mut e = PoseEstimate::empty(f.seq, f.t, Status::Ok, "shifted");
        if let Some(tr) = f.truth {
            e.x = Some(tr.pose.x + k_sigma(f.seq) * SIGMA);
            e.std.x = Some(SIGMA);
            // y has a value but no σ: not part of the coverage.
            e.y = Some(tr.pose.y);
        }
        e
    }
    fn reset(&mut self) {}
}

#[test]
fn coverage_counts_truth_within_two_sigma() {
    let (cfg, _) = tank_dive(5);
    let r = run(
        &cfg,
        || Ok::<Box<dyn Estimator>, String>(Box::new(Shifted)),
        &ProgressBar::hidden(),
    )
    .unwrap();
    let steps = r.times.len() as u64;
    let inside = (0..steps).filter(|&s| k_sigma(s) <= 2.0).count() * cfg.runs;
    let c = r.coverage[Axis::X.index()].unwrap();
    assert_eq!(c.n, cfg.runs * steps as usize);
    assert_eq!(c.inside, inside);
    assert!(r.coverage[Axis::Y.index()].is_none());
    assert_eq!(r.estimator, "shifted");
    // Axes it never estimates have no statistics; the rest do, every step.
    for s in &r.steps {
        assert_eq!(s.ok_fraction, 1.0);
        for a in AXES {
            assert_eq!(s.axes[a.index()].is_some(), matches!(a, Axis::X | Axis::Y));
        }
    }
    assert_eq!(r.sample(2, 3, Axis::Z), None);
    let x = r.sample(2, 3, Axis::X).unwrap();
    assert!((x - (r.truth[3][0] + k_sigma(3) * SIGMA)).abs() < 1e-12);
}

#[test]
fn bad_inputs_fail_with_one_line() {
    let (mut cfg, cal) = tank_dive(0);
    let e = run(
        &cfg,
        || build_estimator("moments", &cal),
        &ProgressBar::hidden(),
    )
    .unwrap_err();
    assert!(matches!(e, McError::NoRuns));
    cfg.runs = 4;
    let e = run(
        &cfg,
        || build_estimator("kalman", &cal),
        &ProgressBar::hidden(),
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with("estimator: unknown estimator \"kalman\""),
        "{msg}"
    );
    assert!(!msg.contains('\n'));
    cfg.scene.montecarlo.sigma_k_d = -1.0;
    let e = run(
        &cfg,
        || build_estimator("moments", &cal),
        &ProgressBar::hidden(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("sigma_k_d = -1"), "{e}");
}
