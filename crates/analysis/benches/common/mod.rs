//! What the station benches share: dock-example.toml's four beacons, or
//! five at 4.8 kHz (MODEL.md: five beacons need N = 480), and demodulated
//! frames of a vehicle held still 3 m out.

use lightpose_core::light::temperature_gain;
use lightpose_core::{Angle, BeamVec, Frame, Pose};
use lightpose_pipeline::model::station_fit::Pose6;
use lightpose_sim::{EstimatorFrames, Kinematics, Scene, Simulator};
use std::path::Path;

pub fn scene(five: bool) -> Scene {
    let p = dock_example();
    let mut s = Scene::load(&p).expect("dock-example.toml");
    if five {
        // 4 800 / 2m with m = 3, 2, 4, 8, 16: no two in an odd : odd ratio.
        s.adc.sample_hz = 4800.0;
        let mut extra = s.beacons[0].clone();
        extra.id = "centre".into();
        extra.position_m = [0.0, 0.35, 0.35];
        s.beacons.push(extra);
        for (b, hz) in s
            .beacons
            .iter_mut()
            .zip([800.0, 1200.0, 600.0, 300.0, 150.0])
        {
            b.blink.mod_hz = hz;
        }
    }
    s
}

/// 20 demodulated frames of `s` at 3 m, their temperature gain and the
/// true pose.
pub fn frames(s: &Scene) -> (Vec<Frame>, f64, Pose6) {
    let truth = Pose::new(
        3.0,
        0.12,
        -0.08,
        Angle::from_deg(3.0),
        Angle::from_deg(-4.0),
    )
    .with_roll(Angle::from_deg(6.0));
    let mut f = EstimatorFrames::new(Simulator::new(s.clone(), 5)).expect("frames");
    let still = Kinematics {
        pose: truth,
        velocity: BeamVec::default(),
    };
    let mut gt = 1.0;
    let frames = (0..20)
        .map(|i| {
            let fr = f.frame(i, i as f64 / s.adc.rate_hz, |_| still);
            gt = temperature_gain(fr.temp_c.unwrap_or(s.temp_c));
            assert!(fr.amplitudes.is_some(), "demodulated");
            fr
        })
        .collect();
    let q = Pose6::new(
        truth.x,
        truth.y,
        truth.z,
        truth.pitch.rad(),
        truth.yaw.rad(),
        truth.roll.rad(),
    );
    (frames, gt, q)
}

/// `shared/spec/dock-example.toml` beside the checkout (the first ancestor
/// of this crate that has it: a worktree sits deeper than main).
pub fn dock_example() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|a| a.join("shared/spec/dock-example.toml"))
        .find(|p| p.is_file())
        .expect("shared/spec/dock-example.toml above the checkout")
}
