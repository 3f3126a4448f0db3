//! Spec v3 in the simulator: the samples' path agrees with the v2 frame
//! where they meet (one sample, steady beacon, no daylight), a blinking
//! beacon's samples swing between its dark and lit levels, and a roll
//! column is read by the attitude sensor.

use lightpose_core::Burst;
use lightpose_sim::{Scene, Simulator, Trajectory};

const DIVE: &str = "t,x,y,z,pitch,yaw\n0,8.5,0,0,10,0\n2.6,7.22,0,0.22,8.7,0\n5.2,5.93,0,0.38,5.2,0\n8,4.53,0,0.45,0,0\n";

/// One sample per frame of a v2 scene through `burst` is the v2 frame:
/// the same noise draws in the same order, the same counts and readings.
#[test]
fn one_sample_of_a_v2_scene_is_its_v2_frame() {
    let text = "[noise]\n\n[attitude]\n\n[depth]\n\n[dvl]\n\n[scattering]\n";
    let scene = Scene::parse(text, "v2.toml").unwrap();
    assert!(scene.is_v2());
    let tr = Trajectory::parse(DIVE, "dive.csv").unwrap();
    let (mut a, mut b) = (Simulator::new(scene.clone(), 7), Simulator::new(scene, 7));
    let mut burst = Burst::new(1);
    for (seq, t) in tr.frame_times(5.0).enumerate() {
        let f = a.frame_moving(seq as u64, t, &tr.kinematics(t));
        b.burst(seq as u64, t, |t| tr.kinematics(t), &mut burst);
        let g = lightpose_sim::simulator::one_sample_frame(&burst);
        assert_eq!(f, g, "frame {seq}");
    }
}

/// A beacon blinking at 50 Hz sampled at 1 kHz: each channel's samples sit
/// at the dark offset or at the steady beacon's level, half the time each.
#[test]
fn a_blinking_beacon_swings_between_dark_and_lit() {
    let steady = Scene::parse("[adc]\nbits = 12\n", "s.toml").unwrap();
    let blink = Scene::parse(
        "[adc]\nbits = 12\nrate_hz = 5\nsample_hz = 1000\n\n[beacon]\nmod_hz = 50\nphase_deg = 9\n",
        "b.toml",
    )
    .unwrap();
    let tr = Trajectory::parse(DIVE, "dive.csv").unwrap();
    let k = tr.kinematics(4.0);
    let lit = Simulator::new(steady, 1)
        .frame(0, 4.0, &k.pose, None)
        .counts;
    let mut sim = Simulator::new(blink, 1);
    let mut b = Burst::new(200);
    sim.burst(0, 4.0, |_| k, &mut b);
    let dark = lightpose_core::frame::volts_to_counts(0.15, 5.0, 12);
    for (ch, &lit) in lit.iter().enumerate() {
        let s = b.channel(ch);
        let on = s.iter().filter(|&&c| c == lit).count();
        let off = s.iter().filter(|&&c| c == dark).count();
        assert_eq!((on, off), (100, 100), "channel {ch}: {s:?}");
    }
    assert_eq!(
        b.truth.unwrap().pose,
        k.pose,
        "still: the truth at the middle"
    );
}

/// A trajectory with a roll column: the truth rolls and the attitude
/// sensor reports roll (MODEL.md: with sigma_roll_deg 0.3 by default).
#[test]
fn a_rolling_trajectory_is_read_with_its_roll() {
    let scene = Scene::parse("[attitude]\nsigma_roll_deg = 0\n", "r.toml").unwrap();
    let tr = Trajectory::parse(
        "t,x,y,z,pitch,yaw,roll\n0,6,0,0,0,0,10\n2,5,0,0,0,0,20\n",
        "r.csv",
    )
    .unwrap();
    let mut sim = Simulator::new(scene, 3);
    sim.set_report_roll(tr.has_roll());
    let f = sim.frame_moving(0, 1.0, &tr.kinematics(1.0));
    let truth = f.truth.unwrap().pose.roll.deg();
    let read = f.attitude.unwrap().roll.unwrap().deg();
    assert!(
        (truth - 15.0).abs() < 0.5 && (read - truth).abs() < 1e-9,
        "{truth} {read}"
    );
    let plain = Simulator::new(Scene::parse("[attitude]\n", "p.toml").unwrap(), 3).frame_moving(
        0,
        1.0,
        &tr.kinematics(1.0),
    );
    assert!(plain.attitude.unwrap().roll.is_none());
}
