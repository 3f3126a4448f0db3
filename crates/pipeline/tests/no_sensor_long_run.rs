//! Without own sensors the tracker keeps the vehicle for a whole minute of
//! coming and going between 5 and 8 m in the tank, reversing sharply every
//! 10 s (tests/data/to-and-fro-far.csv): no frame `diverged`, and x within
//! 1.1× of the paper's method, y and z no worse (issue 13's bar), p95
//! after the first second on the frames where both give a value.
//!
//! Why: near the beam axis the light says nothing, to first order, of how
//! a spot off the dome's centre splits between yaw and y (or pitch and
//! z). With the angles' rates a random walk, their σ grew by about 0.8°/s,
//! past 40° within the minute; the counts' update then ran off along the
//! ridge (yaw 48° off) and the track was lost near 50 s on every
//! minute-long run without sensors, one-way or not. On this path it was
//! 1.0–2.8× the paper's in x. `unmeasured_attitude_sigma_deg` bounds
//! their σ (15°).

mod common;

use common::{p95, root};
use lightpose_core::Status;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Simulator, Trajectory};

/// One run: how many frames `auto` called `diverged`, and per axis (x, y,
/// z) the p95 of |error| of `auto` and of the paper's method.
struct Run {
    diverged: usize,
    p95s: [(f64, f64); 3],
}

fn run(cal: &Calibration, seed: u64) -> Run {
    let r = root();
    let scene = Scene::load(&r.join("config/scenes/tank.toml")).expect("tank scene");
    let traj = Trajectory::load(&r.join("tests/data/to-and-fro-far.csv")).expect("trajectory");
    let mut auto = build_estimator("auto", cal).expect("auto");
    let mut paper = build_estimator("moments", cal).expect("moments");
    let mut sim = Simulator::new(scene.clone(), seed);
    let mut diverged = 0;
    let mut errs: [(Vec<f64>, Vec<f64>); 3] = Default::default();
    for (j, t) in traj.frame_times(scene.adc.rate_hz).enumerate() {
        let (p, surge) = traj.sample(t);
        let f = sim.frame(j as u64, t, &p, Some(surge));
        let (a, b) = (auto.estimate(&f), paper.estimate(&f));
        diverged += usize::from(a.status == Status::Diverged);
        let truth = [p.x, p.y, p.z];
        for (i, (ea, eb)) in [(a.x, b.x), (a.y, b.y), (a.z, b.z)].into_iter().enumerate() {
            if let (Some(va), Some(vb), true) = (ea, eb, t >= 1.0) {
                errs[i].0.push((va - truth[i]).abs());
                errs[i].1.push((vb - truth[i]).abs());
            }
        }
    }
    Run {
        diverged,
        p95s: errs.map(|(a, b)| (p95(a), p95(b))),
    }
}

fn tank_calibration() -> Calibration {
    Calibration::load(&root().join("config/calibration/tank.toml")).expect("tank calibration")
}

#[test]
fn a_minute_of_coming_and_going_without_sensors_keeps_the_track() {
    let cal = tank_calibration();
    for seed in 1..=3 {
        let r = run(&cal, seed);
        let [(xa, xb), (ya, yb), (za, zb)] = r.p95s;
        eprintln!(
            "seed {seed}: diverged {}, x {xa:.3}/{xb:.3}, y {ya:.3}/{yb:.3}, z {za:.3}/{zb:.3}",
            r.diverged
        );
        assert_eq!(r.diverged, 0, "seed {seed}: the track was lost");
        assert!(xa <= 1.1 * xb, "seed {seed}: x {xa:.3} against {xb:.3}");
        assert!(
            ya <= yb && za <= zb,
            "seed {seed}: y {ya:.3}/{yb:.3}, z {za:.3}/{zb:.3}"
        );
    }
}

/// The same minute without the bound (the setting at 0): the track is
/// lost on at least one of the seeds above, so the test above sees what
/// it guards against.
#[test]
fn without_the_hold_the_same_minute_loses_the_track() {
    let mut cal = tank_calibration();
    let mut settings = cal.estimator.clone().unwrap_or_default();
    settings.tracker.unmeasured_attitude_sigma_deg = 0.0;
    cal.estimator = Some(settings);
    let lost = (1..=3).filter(|&seed| run(&cal, seed).diverged > 0).count();
    assert!(lost >= 1, "no seed lost the track without the hold");
}
