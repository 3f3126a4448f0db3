//! Issue 40's harbour approach by day (spec v3), held out: the scenes of
//! tests/data/v3/harbour-*.toml are not the default one and were not tuned
//! on; each is calibrated here from its own sweeps (`SweepPlan`, written
//! and read back as a log, BURSTs demodulated on the way by the
//! calibration's reader), and the approach is simulated sample by sample
//! and demodulated as its log would be (`lightpose_sim::EstimatorFrames`).
//!
//! - A beacon blinking at 250 Hz, sampled at 2 kHz, through 5 V of
//!   daylight at 4 m with flicker 0.3, AHRS with roll: the tracker's p95
//!   meets the paper's requirements and is within 1.5× of the same run at
//!   night.
//! - The same run with the paper's steady beacon, calibrated at night,
//!   with the ambient modelled (`[estimator.tracker.daylight]`): at least
//!   half the frames `ok` after the first second, and no more than 5 % of
//!   those beyond 3σ on x, y or z.
//!
//! Each test prints the table it measures (`--nocapture`); the figures are
//! in docs/estimators.md, "By day".

// Coordinate loops index several parallel per-coordinate arrays at once.
#![allow(clippy::needless_range_loop)]

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use lightpose_core::{Estimator, Status};
use lightpose_pipeline::calibration::{calibrate_full, CalibrateOptions};
use lightpose_pipeline::settings::DaylightConfig;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{EstimatorFrames, Scene, Simulator, SweepKind, SweepPlan, Trajectory};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/v3")
        .join(name)
}

fn scene(name: &str) -> Scene {
    Scene::load(&data(name)).expect("harbour scene")
}

/// `scene` calibrated from its own sweeps (`per_pose` frames at each pose
/// of MODEL.md's grids), written to `dir` as a log and read back.
fn calibrate(scene: &Scene, per_pose: u32, dir: &Path, tag: &str) -> Calibration {
    let path = dir.join(format!("{tag}-sweep.jsonl"));
    let out = BufWriter::new(File::create(&path).expect("sweep file"));
    SweepPlan::new(SweepKind::All, per_pose)
        .write(scene, 17, out)
        .expect("sweep written");
    let opts = CalibrateOptions::new(vec![path]);
    let c = calibrate_full(&opts, |e| panic!("bad sweep line: {e}")).expect("calibrated");
    assert!(
        c.physical_skipped.is_none(),
        "{tag}: no light model: {:?}",
        c.physical_skipped
    );
    c.cal
}

/// What a run of the tracker gave after its first second.
#[derive(Debug, Default)]
struct Run {
    frames: usize,
    ok: usize,
    /// Per coordinate (x, y, z, pitch, yaw) of the `ok` poses: |error|,
    /// and |error| / σ.
    err: [Vec<f64>; 5],
    z: [Vec<f64>; 5],
    by_status: Vec<(Status, usize)>,
}

impl Run {
    fn p95(&self, i: usize) -> f64 {
        let mut v = self.err[i].clone();
        if v.is_empty() {
            return f64::INFINITY;
        }
        v.sort_by(f64::total_cmp);
        v[((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len()) - 1]
    }

    /// Share of `ok` poses within 2σ on coordinate i.
    fn cover2(&self, i: usize) -> f64 {
        let n = self.z[i].len().max(1) as f64;
        self.z[i].iter().filter(|z| **z <= 2.0).count() as f64 / n
    }

    /// Share of `ok` poses beyond 3σ on x, y or z.
    fn beyond3_xyz(&self) -> f64 {
        let n = self.z[0].len();
        let bad = (0..n)
            .filter(|&j| (0..3).any(|i| self.z[i][j] > 3.0))
            .count();
        bad as f64 / n.max(1) as f64
    }

    fn row(&self, name: &str) -> String {
        format!(
            "| {name} | {}/{} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} | {:.0}/{:.0}/{:.0} % | {:.1} % | {:?} |",
            self.ok,
            self.frames,
            self.p95(0),
            self.p95(1),
            self.p95(2),
            self.p95(3),
            self.p95(4),
            100.0 * self.cover2(0),
            100.0 * self.cover2(1),
            100.0 * self.cover2(2),
            100.0 * self.beyond3_xyz(),
            self.by_status
        )
    }
}

const HEAD: &str = "| run | ok after 1 s | p95 x m | y m | z m | pitch ° | yaw ° | ±2σ x/y/z | ok beyond 3σ (x, y or z) | statuses |\n|---|---|---|---|---|---|---|---|---|---|";

/// The approach through `scene` with the tracker of `cal`, over `seeds`.
fn run(scene: &Scene, cal: &Calibration, seeds: &[u64]) -> Run {
    let traj = Trajectory::load(&data("harbour-approach.csv")).expect("trajectory");
    let mut out = Run::default();
    let mut statuses = std::collections::BTreeMap::<&'static str, (Status, usize)>::new();
    for &seed in seeds {
        let mut est: Box<dyn Estimator> = build_estimator("tracker", cal).expect("tracker");
        let mut sim = Simulator::new(scene.clone(), seed);
        sim.set_report_roll(traj.has_roll());
        let mut frames = EstimatorFrames::new(sim).expect("demodulator");
        let at = |t: f64| traj.kinematics(t);
        for (seq, t) in traj.frame_times(scene.adc.rate_hz).enumerate() {
            let frame = frames.frame(seq as u64, t, at);
            if scene.adc.samples_per_frame() > 1 {
                assert!(frame.amplitudes.is_some(), "frame {seq} not demodulated");
            }
            let e = est.estimate(&frame);
            if frame.t - traj.t0() < 1.0 {
                continue;
            }
            out.frames += 1;
            statuses.entry(e.status.as_str()).or_insert((e.status, 0)).1 += 1;
            if e.status != Status::Ok {
                continue;
            }
            out.ok += 1;
            let truth = frame.truth.expect("truth").pose;
            let want = [
                truth.x,
                truth.y,
                truth.z,
                truth.pitch.deg(),
                truth.yaw.deg(),
            ];
            let got = [e.x, e.y, e.z, e.pitch_deg, e.yaw_deg];
            let sd = [e.std.x, e.std.y, e.std.z, e.std.pitch, e.std.yaw];
            for i in 0..5 {
                let g = got[i].expect("an ok pose has every field");
                let s = sd[i].expect("an ok pose has every std");
                let d = (g - want[i]).abs();
                out.err[i].push(d);
                out.z[i].push(d / s);
            }
        }
    }
    out.by_status = statuses.into_values().collect();
    out
}

const SEEDS: [u64; 4] = [1, 2, 3, 4];
/// The paper's requirements: x 0.5, y 0.2, z 0.2 m, pitch and yaw 5°.
const PAPER: [f64; 5] = [0.5, 0.2, 0.2, 5.0, 5.0];

#[test]
fn a_blinking_beacon_by_day_meets_the_paper_and_stays_within_1_5x_of_night() {
    let dir = tempfile::tempdir().expect("tempdir");
    let night_scene = scene("harbour-night.toml");
    let day_scene = scene("harbour-day.toml");
    assert!(day_scene.daylight.is_some() && night_scene.daylight.is_none());
    let night = run(
        &night_scene,
        &calibrate(&night_scene, 3, dir.path(), "night"),
        &SEEDS,
    );
    let day_cal = calibrate(&day_scene, 3, dir.path(), "day");
    // The BURST sweep by day, demodulated on the way: no dark offsets
    // (held at 0), the scene's gains (mean 1: V1 takes the scale).
    let phys = day_cal.physical.as_ref().expect("light model");
    let mean = day_scene.gain.iter().sum::<f64>() / day_scene.gain.len() as f64;
    let gain_err = (0..day_scene.gain.len())
        .map(|k| (phys.gain[k].value - day_scene.gain[k] / mean).abs())
        .fold(0.0, f64::max);
    let offset_max = phys
        .offset_v
        .iter()
        .map(|o| o.value.abs())
        .fold(0.0, f64::max);
    println!("day BURST sweep's light model: gains within {gain_err:.4} of the scene's, offsets ≤ {offset_max:.1e} V, K_D {:.4} ± {:.4}", phys.k_d.value, phys.k_d.std);
    assert!(
        gain_err < 0.01 && offset_max < 1e-4,
        "{gain_err} {offset_max}"
    );
    let day = run(&day_scene, &day_cal, &SEEDS);
    println!(
        "\nharbour approach, beacon blinking at 250 Hz, tracker, {} seeds\n{HEAD}",
        SEEDS.len()
    );
    println!("{}", night.row("night"));
    println!("{}", day.row("day, 5 V, flicker 0.3"));
    for i in 0..5 {
        assert!(
            day.p95(i) <= PAPER[i],
            "day p95[{i}] {} > {}",
            day.p95(i),
            PAPER[i]
        );
        assert!(
            day.p95(i) <= 1.5 * night.p95(i),
            "day p95[{i}] {} beyond 1.5× night's {}",
            day.p95(i),
            night.p95(i)
        );
    }
    assert!(
        day.ok * 10 >= day.frames * 9,
        "{} of {} ok",
        day.ok,
        day.frames
    );
}

#[test]
fn a_steady_beacon_by_day_is_ok_half_the_time_and_honest() {
    let dir = tempfile::tempdir().expect("tempdir");
    let day_scene = scene("harbour-steady.toml");
    // Calibrated at night: the same beacon and water, without the sun.
    let mut night_scene = day_scene.clone();
    night_scene.daylight = None;
    let mut cal = calibrate(&night_scene, 20, dir.path(), "steady-night");
    let unmodelled = run(&day_scene, &cal, &SEEDS);
    let night = run(&night_scene, &cal, &SEEDS);
    cal.estimator
        .get_or_insert_with(Default::default)
        .tracker
        .daylight = Some(DaylightConfig::default());
    let day = run(&day_scene, &cal, &SEEDS);
    let night_modelled = run(&night_scene, &cal, &SEEDS);
    println!(
        "\nharbour approach, steady beacon calibrated at night, tracker, {} seeds\n{HEAD}",
        SEEDS.len()
    );
    println!("{}", night.row("night"));
    println!("{}", unmodelled.row("day, ambient not modelled"));
    println!("{}", day.row("day, ambient modelled"));
    println!("{}", night_modelled.row("night, ambient modelled"));
    assert!(day.ok * 2 >= day.frames, "{} of {} ok", day.ok, day.frames);
    assert!(
        day.beyond3_xyz() <= 0.05,
        "{:.3} beyond 3σ",
        day.beyond3_xyz()
    );
}
