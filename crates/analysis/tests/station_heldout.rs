//! Issue 41's "done when" on a held-out station calibrated from its own
//! logs: a station the project was not tuned on (four beacons on a 0.6 m
//! ring turned 45°, each tilted 5° outwards, at other frequencies, with
//! other brightness and beam widths, gains ±6 %, K_D 0.15, harbour water by
//! day) is swept, fitted by the station calibration
//! (`calibration::fit_station_sweeps`, against its survey), and the
//! tracker built from that calibration — not from the scene — flies the
//! approach of `station_track.rs` (8 → 1.5 m with roll, pitch, yaw and y/z
//! offsets), simulated sample by sample and demodulated, light alone and
//! with the attitude and depth sensors, each eight runs. p95 and ±2σ coverage per axis over
//! x 5 → 1.5 m against issue 41's goals, printed with `--nocapture`;
//! docs/docking.md has the table and what is not met.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

mod approach;
use approach::{fly, measure, table, NAMES};

use lightpose_core::{Angle, NDET};
use lightpose_pipeline::calibration::{
    fit_station_sweeps, Station, StationFitOptions, StationFitted,
};
use lightpose_pipeline::model::tracker::Tracker;
use lightpose_pipeline::settings::EstimatorSettings;
use lightpose_sim::{Scene, SweepKind, SweepPlan};

/// Runs per sensor set (HELDOUT_RUNS=20 for a longer measure): each has
/// ~70 frames in the window, strongly correlated, and three runs put a
/// coverage of 96 % anywhere in 93–99 %.
const RUNS: u64 = 8;

fn dock_example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|a| a.join("shared/spec/dock-example.toml"))
        .find(|p| p.is_file())
        .expect("shared/spec/dock-example.toml above the checkout")
}

/// The held-out station: dock-example's water, array and sensors with
/// the beacons placed, turned, tuned and lit otherwise, the gains and
/// K_D changed (`station_track.rs`'s held-out ring and
/// `station_calibration.rs`'s held-out light, together).
fn held_out(sensors: bool) -> Scene {
    let mut s = Scene::load(&dock_example()).expect("dock-example.toml");
    let d = 0.6 * std::f64::consts::FRAC_1_SQRT_2;
    let ring = [(d, d), (d, -d), (-d, -d), (-d, d)];
    let light = [(3.0, 15.0), (5.0, 25.0), (4.5, 18.0), (3.5, 22.0)];
    for (((b, (y, z)), hz), (v1, sb)) in s
        .beacons
        .iter_mut()
        .zip(ring)
        .zip([400.0, 500.0, 200.0, 250.0])
        .zip(light)
    {
        b.position_m = [0.0, y, z];
        b.axis_yaw = Angle::from_deg(5f64.copysign(y));
        b.axis_pitch = Angle::from_deg(5f64.copysign(z));
        b.blink.mod_hz = hz;
        b.v1 = v1;
        b.sigma_b = Angle::from_deg(sb);
    }
    for k in 0..NDET {
        s.gain[k] = 1.0 + 0.06 * ((k as f64) * 2.3).sin();
    }
    s.light.k_d = 0.15;
    if !sensors {
        s.attitude = None;
        s.depth = None;
    }
    s
}

/// The survey of `scene`'s station, exact.
fn station_text(scene: &Scene) -> String {
    let mut t = String::from("name = \"held-out\"\n");
    for b in &scene.beacons {
        let c = b.position_m;
        t.push_str(&format!(
            "\n[[beacons]]\nid = \"{}\"\nposition_m = [{}, {}, {}]\naxis_yaw_deg = {}\naxis_pitch_deg = {}\nmod_hz = {}\n",
            b.id,
            c[0],
            c[1],
            c[2],
            b.axis_yaw.deg(),
            b.axis_pitch.deg(),
            b.mod_hz()
        ));
    }
    t
}

/// The station's sweep (3 frames a pose, BURST lines) and its fit.
fn calibrate(scene: &Scene, seed: u64) -> StationFitted {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("sweep.jsonl");
    let out = BufWriter::new(File::create(&path).expect("sweep file"));
    SweepPlan::for_scene(SweepKind::All, 3, scene)
        .write(scene, seed, out)
        .expect("sweep written");
    let text = station_text(scene);
    let st = Station::parse(&text, "held-out.toml").expect("station file");
    let o = StationFitOptions {
        v_ref: scene.adc.v_ref,
        ..StationFitOptions::default()
    };
    let (f, bad) = fit_station_sweeps(&[path], &st, &text, "held-out.toml", &o).expect("fitted");
    assert_eq!(bad, 0);
    f
}

/// The tracker as `build_estimator` makes it from a station's
/// calibration: the fitted array and water, the survey's placements with
/// the fitted V1 and σ_b.
fn tracker_of(f: &StationFitted) -> Tracker {
    // The settings `calibrate --station` writes (the sweeps' span).
    assert!(
        f.x_span[0] < 1.5 && f.x_span[1] > 8.0,
        "the sweeps cover the approach: {:?}",
        f.x_span
    );
    let cfg = f.estimator_settings(EstimatorSettings::default()).tracker;
    Tracker::new(f.physical.sensor_model(), cfg)
        .expect("tracker")
        .with_station(f.station.beacon_lights())
}

#[test]
fn a_held_out_station_calibrated_from_its_logs_docks_on_that_calibration() {
    let sweep_scene = held_out(true);
    let f = calibrate(&sweep_scene, 21);
    println!(
        "held-out station calibrated: chi2/dof {:.3}, {} poses, K_D {:.4} ± {:.4} (truth 0.15)",
        f.station.chi2_per_dof, f.station.poses, f.physical.k_d.value, f.physical.k_d.std
    );
    for (b, t) in f.station.beacons.iter().zip(&sweep_scene.beacons) {
        println!(
            "  {}: V1 {:.4} ± {:.4} (truth {:.4} before the gains' mean), σ_b {:.3}° ± {:.3}° (truth {}), model error {:.2} %",
            b.id,
            b.v1.value,
            b.v1.std,
            t.v1,
            b.sigma_b_deg.value,
            b.sigma_b_deg.std,
            t.sigma_b.deg(),
            100.0 * b.model_rel
        );
    }
    // The simulator's light is the model's: what the fit finds wrong is
    // the noise's chance and what it does not know, well under the fixed
    // 2 % it replaces.
    for b in &f.station.beacons {
        assert!(
            b.model_rel > 0.0 && b.model_rel < 0.012,
            "{}: {}",
            b.id,
            b.model_rel
        );
    }
    assert!(
        f.station.chi2_per_dof < 1.2,
        "chi2/dof {}",
        f.station.chi2_per_dof
    );

    let cases = [
        ("light alone", false, [0.1, 0.05, 0.05, 2.0, 2.0, 2.0], 600),
        (
            "attitude + depth",
            true,
            [0.05, 0.03, 0.02, 1.0, 1.0, 1.0],
            700,
        ),
    ];
    for (what, sensors, goals, seed) in cases {
        let s = held_out(sensors);
        let nruns: u64 = std::env::var("HELDOUT_RUNS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(RUNS);
        let runs: Vec<_> = (0..nruns)
            .map(|k| fly(&s, seed + k, tracker_of(&f)))
            .collect();
        let (p95, cover, ok) = measure(&runs);
        table(
            &format!("held-out station on its calibration, {what}"),
            &p95,
            &cover,
            &goals,
            ok,
        );
        assert!(ok > 0.9, "{what}: ok {ok}");
        for i in 0..6 {
            assert!(p95[i] <= goals[i], "{what} {}: p95 {}", NAMES[i], p95[i]);
            // The goal's 90–98 %, now every axis is observed: the σ
            // rests on each beacon's model error as its calibration
            // measured it (with the fixed 2 % it was 98.5–99.1 % over 20
            // runs on five axes: docs/docking.md).
            assert!(
                (0.9..=0.98).contains(&cover[i]),
                "{what} {}: ±2σ {}",
                NAMES[i],
                cover[i]
            );
        }
    }
}
