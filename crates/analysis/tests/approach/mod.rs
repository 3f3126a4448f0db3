//! The docking approach of issue 41 and its measures, shared by the
//! tests that fly it (`station_track.rs` on a scene's own model,
//! `station_heldout.rs` on a calibration fitted from the station's logs),
//! so that both mean one approach and one p95.

// Each test file uses its own part of it.
#![allow(dead_code)]

use lightpose_core::{Estimator, PoseEstimate, Status, Truth};
use lightpose_pipeline::model::tracker::Tracker;
use lightpose_sim::{EstimatorFrames, Scene, Simulator, Trajectory};

/// The approach: 0.5 m/s from x 8 m to 1.4 m, heading for the mouth from
/// y 0.35 m, z −0.25 m off its axis (yaw and pitch along the path, with a
/// crab of ±2° and a pitch wobble of ±1.5° on top), rolling 2° ± 6°.
pub fn approach() -> Trajectory {
    let mut csv = String::from("t,x,y,z,pitch,yaw,roll\n");
    let (u, t_end): (f64, f64) = (0.5, 13.2);
    let mut t = 0.0f64;
    while t <= t_end + 1e-9 {
        let x = 8.0 - u * t;
        let (y, vy) = (0.35 * (-t / 5.0).exp(), -0.07 * (-t / 5.0).exp());
        let (z, vz) = (-0.25 * (-t / 6.0).exp(), 0.25 / 6.0 * (-t / 6.0).exp());
        let yaw = (vy / u).atan().to_degrees() + 2.0 * (0.5 * t).sin();
        let pitch = (vz / u.hypot(vy)).atan().to_degrees() + 1.5 * (0.4 * t + 1.0).sin();
        let roll = 2.0 + 6.0 * (0.35 * t).sin();
        csv += &format!("{t:.2},{x:.4},{y:.5},{z:.5},{pitch:.4},{yaw:.4},{roll:.4}\n");
        t += 0.25;
    }
    Trajectory::parse(&csv, "approach.csv").expect("the approach")
}

/// Each frame's estimate and truth along the approach, `tr` reading the
/// frames of `scene` simulated sample by sample and demodulated.
pub fn fly(scene: &Scene, seed: u64, mut tr: Tracker) -> Vec<(PoseEstimate, Truth)> {
    let traj = approach();
    let mut frames = EstimatorFrames::new(Simulator::new(scene.clone(), seed)).expect("frames");
    let n = traj.burst_count(
        scene.adc.rate_hz,
        scene.adc.samples_per_frame(),
        scene.adc.sample_hz,
    );
    let times: Vec<f64> = traj
        .frame_times(scene.adc.rate_hz)
        .take(n as usize)
        .collect();
    times
        .iter()
        .enumerate()
        .map(|(j, &t)| {
            let f = frames.frame(j as u64, t, |t| traj.kinematics(t));
            let e = tr.estimate(&f);
            (e, f.truth.expect("truth"))
        })
        .collect()
}

pub const NAMES: [&str; 6] = ["x", "y", "z", "roll", "pitch", "yaw"];

/// Error and 1σ of every axis (m, °), None where the estimate has none.
pub fn errors(e: &PoseEstimate, t: &Truth) -> [Option<(f64, f64)>; 6] {
    let p = &t.pose;
    let wrap = |d: f64| (d + 180.0).rem_euclid(360.0) - 180.0;
    let pair = |v: Option<f64>, sd: Option<f64>, truth: f64, angle: bool| {
        let d = v? - truth;
        Some((if angle { wrap(d) } else { d }, sd?))
    };
    [
        pair(e.x, e.std.x, p.x, false),
        pair(e.y, e.std.y, p.y, false),
        pair(e.z, e.std.z, p.z, false),
        pair(e.roll_deg, e.std.roll, p.roll.deg(), true),
        pair(e.pitch_deg, e.std.pitch, p.pitch.deg(), true),
        pair(e.yaw_deg, e.std.yaw, p.yaw.deg(), true),
    ]
}

/// Over the `ok` frames with the truth's x in [1.5, 5] m of every run: per
/// axis the p95 of |error| and the share within ±2σ; and the `ok` share.
pub fn measure(runs: &[Vec<(PoseEstimate, Truth)>]) -> ([f64; 6], [f64; 6], f64) {
    let mut err: [Vec<f64>; 6] = Default::default();
    let mut inside = [0usize; 6];
    let (mut ok, mut all) = (0usize, 0usize);
    for (e, t) in runs.iter().flatten() {
        if !(1.5..=5.0).contains(&t.pose.x) {
            continue;
        }
        all += 1;
        if e.status != Status::Ok {
            continue;
        }
        ok += 1;
        for (i, v) in errors(e, t).iter().enumerate() {
            let (d, sd) = v.expect("an ok pose has every axis and its σ");
            err[i].push(d.abs());
            inside[i] += usize::from(d.abs() <= 2.0 * sd);
        }
    }
    let p95 = err.clone().map(|mut v| {
        v.sort_by(f64::total_cmp);
        v[((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len()) - 1]
    });
    let cover = std::array::from_fn(|i| inside[i] as f64 / err[i].len().max(1) as f64);
    (p95, cover, ok as f64 / all.max(1) as f64)
}

pub fn table(what: &str, p95: &[f64; 6], cover: &[f64; 6], goals: &[f64; 6], ok: f64) {
    println!("\n{what} ({:.0} % ok over x 5 → 1.5 m)", 100.0 * ok);
    println!("| axis | p95 | goal | within ±2σ |\n|---|---|---|---|");
    for i in 0..6 {
        let unit = if i < 3 { "m" } else { "°" };
        println!(
            "| {} | {:.3} {unit} | {} {unit} | {:.1} % |",
            NAMES[i],
            p95[i],
            goals[i],
            100.0 * cover[i]
        );
    }
}
