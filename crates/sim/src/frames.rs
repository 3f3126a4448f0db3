//! The frames an estimator reads from a simulated run, whatever the scene:
//! a v2 scene's frames of counts as [`Simulator::frame_moving`] makes them
//! (bit for bit), a spec v3 scene of one sample per frame through the
//! samples' path, and a scene that samples faster than its frames
//! (a blinking beacon) as its bursts demodulated by the one demodulator
//! a log of that scene would be read with (`lightpose_demod::demodulator_for`
//! on the scene's log header). The Monte Carlo, the trade table and the
//! tests that run estimators on simulated runs all read frames here, so a
//! simulated run is demodulated exactly as its recording would be.

use lightpose_core::samples::{Burst, Demodulated};
use lightpose_core::Frame;
use lightpose_demod::{demodulator_for, ConfigError, Demodulator};

use crate::{Kinematics, Simulator};

/// A simulator and what turns its samples into estimator frames; every
/// buffer made once, so a frame allocates nothing.
pub struct EstimatorFrames {
    sim: Simulator,
    burst: Burst,
    demod: Option<(Demodulator, Box<Demodulated>)>,
}

impl EstimatorFrames {
    /// Frames of `sim`'s scene; an error when the scene samples fast but
    /// its beacons cannot be demodulated (the scene's own validation
    /// refuses such scenes, so this is a scene built by hand).
    pub fn new(sim: Simulator) -> Result<Self, ConfigError> {
        let demod = demodulator_for(&sim.scene().log_header())?.map(|d| {
            let out = Box::new(d.output());
            (d, out)
        });
        let burst = Burst::new(sim.scene().adc.samples_per_frame());
        Ok(EstimatorFrames { sim, burst, demod })
    }

    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    pub fn simulator_mut(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    /// Frame `seq`, its first sample at `t_first` (a trajectory's
    /// `frame_times`), the vehicle at `at(t)`. A demodulated frame's time is
    /// the middle of its samples (MODEL.md); a frame the demodulator
    /// refuses (it cannot: the simulator writes what the scene says) would
    /// be given as its mean counts, without amplitudes.
    pub fn frame(&mut self, seq: u64, t_first: f64, at: impl Fn(f64) -> Kinematics) -> Frame {
        let Some((demod, out)) = self.demod.as_mut() else {
            return self.sim.frame_at(seq, t_first, at, &mut self.burst);
        };
        self.sim.burst(seq, t_first, at, &mut self.burst);
        match demod.demodulate_burst(&self.burst, out) {
            Ok(()) => out.to_frame(),
            Err(_) => crate::simulator::one_sample_frame(&self.burst),
        }
    }

    /// Forget the demodulator's lock (a new run on the same simulator).
    pub fn reset(&mut self) {
        if let Some((d, _)) = self.demod.as_mut() {
            d.reset();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Scene, Trajectory};

    const TRAJ: &str = "t,x,y,z,pitch,yaw\n0,6,0.2,0.1,0,0\n4,5,0.2,0.1,0,0\n";

    #[test]
    fn a_v2_scene_gives_its_frames_bit_for_bit() {
        let scene = Scene::default();
        let traj = Trajectory::parse(TRAJ, "t.csv").unwrap();
        let mut a = EstimatorFrames::new(Simulator::new(scene.clone(), 3)).unwrap();
        let mut b = Simulator::new(scene, 3);
        for (j, t) in traj.frame_times(5.0).enumerate() {
            let f = a.frame(j as u64, t, |t| traj.kinematics(t));
            assert_eq!(f, b.frame_moving(j as u64, t, &traj.kinematics(t)));
            assert!(f.amplitudes.is_none());
        }
    }

    #[test]
    fn a_blinking_scene_gives_demodulated_frames_at_their_middle() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../tests/data/v3/two-beacons.toml"
        ))
        .unwrap();
        let scene = Scene::parse(&text, "two-beacons.toml").unwrap();
        let n = scene.adc.samples_per_frame();
        assert!(n > 1);
        let traj = Trajectory::parse(TRAJ, "t.csv").unwrap();
        let mut frames = EstimatorFrames::new(Simulator::new(scene.clone(), 3)).unwrap();
        let mid = (n - 1) as f64 / (2.0 * scene.adc.sample_hz);
        for (j, t) in traj.frame_times(scene.adc.rate_hz).take(8).enumerate() {
            let f = frames.frame(j as u64, t, |t| traj.kinematics(t));
            assert!((f.t - (t + mid)).abs() < 1e-12);
            let a = f.amplitudes.expect("amplitudes");
            assert_eq!(a.n_beacons, scene.beacon_infos().len());
            // The truth is at the middle, where the frame's time is.
            let truth = f.truth.expect("truth").pose;
            assert!((truth.x - traj.sample(t + mid).0.x).abs() < 1e-12);
        }
    }
}
