//! Without own sensors the tracker's surge keeps up with a vehicle that
//! slows down: on the shipped docking approach in the tank (0.5 → 0.12
//! m/s over its last 6 s), as a user replays it with the shipped
//! calibration, `auto`'s surge p95 after the first second is within 1.1×
//! of the paper's method on the same frames (issue 13's bar), and it is
//! the paper range's change (`paper_rate`) that gets it there.
//!
//! Why: the tracker's only evidence of surge is the change of range, and
//! it read the paper's range only as a reading of x, whose σ is the law's
//! whole residual; the surge then lagged the slowing vehicle by 0.1–0.2
//! m/s (1.28× the paper's on the median, 3/20 seeds within the bar).

mod common;

use common::{p95, root};
use lightpose_core::Estimator;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Simulator, Trajectory};

/// What one estimator did over the seeds: per seed the p95 of |surge
/// error| after 1 s of `est` and of the paper's method over the frames
/// where both give a surge; over all those frames, how many of `est`'s
/// errors its ±2σ covered.
struct Surge {
    p95s: Vec<(f64, f64)>,
    covered: usize,
    frames: usize,
}

fn surge_over_seeds(cal: &Calibration, est: &mut dyn Estimator, seeds: &[u64]) -> Surge {
    let r = root();
    let scene = Scene::load(&r.join("config/scenes/tank.toml")).expect("tank scene");
    let traj = Trajectory::load(&r.join("config/trajectories/dock.csv")).expect("dock");
    let mut paper = build_estimator("moments", cal).expect("moments");
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let (mut covered, mut frames) = (0, 0);
    let p95s = seeds
        .iter()
        .map(|&seed| {
            let mut sim = Simulator::new(scene.clone(), seed);
            est.reset();
            paper.reset();
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for (j, &t) in times.iter().enumerate() {
                let (p, surge) = traj.sample(t);
                let f = sim.frame(j as u64, t, &p, Some(surge));
                let (ea, eb) = (est.estimate(&f), paper.estimate(&f));
                if let (Some(sa), Some(sb), true) = (ea.surge, eb.surge, t >= 1.0) {
                    a.push((sa - surge).abs());
                    b.push((sb - surge).abs());
                    let sd = ea.std.surge.expect("a surge comes with its σ");
                    covered += usize::from((sa - surge).abs() <= 2.0 * sd);
                    frames += 1;
                }
            }
            assert!(
                a.len() >= 35,
                "seed {seed}: only {} frames with surge",
                a.len()
            );
            (p95(a), p95(b))
        })
        .collect();
    Surge {
        p95s,
        covered,
        frames,
    }
}

fn tank_calibration(paper_rate: bool) -> Calibration {
    let mut cal =
        Calibration::load(&root().join("config/calibration/tank.toml")).expect("tank cal");
    let mut s = cal.estimator.clone().unwrap_or_default();
    s.tracker.paper_rate = paper_rate;
    cal.estimator = Some(s);
    cal
}

#[test]
fn surge_keeps_up_with_a_slowing_vehicle_without_own_sensors() {
    let seeds = [1, 2, 3, 4, 5, 6];
    let cal = tank_calibration(true);
    let mut auto = build_estimator("auto", &cal).expect("auto");
    let with = surge_over_seeds(&cal, auto.as_mut(), &seeds);
    let off = tank_calibration(false);
    let mut without = build_estimator("auto", &off).expect("auto");
    let lagging = surge_over_seeds(&off, without.as_mut(), &seeds);
    let ratios = |v: &Surge| v.p95s.iter().map(|(a, b)| a / b).collect::<Vec<_>>();
    let (on, off) = (ratios(&with), ratios(&lagging));
    eprintln!("surge p95 auto/paper per seed: with the paper's rate {on:.2?}, without {off:.2?}");
    for (seed, r) in seeds.iter().zip(&on) {
        assert!(
            *r <= 1.1,
            "seed {seed}: surge {r:.2}× the paper's ({on:.2?})"
        );
    }
    // Measured without it: 1.29–1.38 on five seeds, 0.97 on the sixth;
    // with it 0.65–1.06 (with `paper_range_sigma_scale` 0.5: 1.14–1.34 and
    // 0.98 without, 0.64–1.06 with).
    let worse = off.iter().zip(&on).filter(|(b, a)| b > a).count();
    assert!(worse >= 5, "without the rate: {off:.2?}, with: {on:.2?}");
}

/// And its σ says how far off it may be while the vehicle slows: the
/// change of range carries the law's bias drift, which successive readings
/// share and so the filter cannot average away; the reported surge σ holds
/// it (`paper_rate_drift_mps`). Measured here: 249 of 252 frames (250 with
/// `paper_range_sigma_scale` 0.5); before,
/// 231 (91.7 %; 91.5 % in a 200-run Monte Carlo of this run, and on the
/// held-out approach 1–4 % of runs at its slowest).
#[test]
fn surge_sigma_covers_a_slowing_vehicle_without_own_sensors() {
    let cal = tank_calibration(true);
    let mut auto = build_estimator("auto", &cal).expect("auto");
    let s = surge_over_seeds(&cal, auto.as_mut(), &[1, 2, 3, 4, 5, 6]);
    let share = s.covered as f64 / s.frames as f64;
    eprintln!("surge ±2σ covers {}/{} frames", s.covered, s.frames);
    assert!(share >= 0.93, "surge ±2σ covers {:.1} %", 100.0 * share);
}
