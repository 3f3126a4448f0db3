//! The simulator backend: lightpose-sim flown along a trajectory, looping,
//! as a FrameSource. It lives in the daemon because the default config runs
//! from scene and trajectory text embedded in the binary, and because the
//! benchmark needs a source whose only cost is the simulator itself.

use crate::config::{Pace, SimBackend};
use lightpose_core::Frame;
use lightpose_hal::{FrameSource, SourceError};
use lightpose_sim::{Scene, Simulator, Trajectory};
use std::time::{Duration, Instant};

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("{0}: {1}")]
    Read(String, std::io::Error),
    #[error("{0}")]
    Scene(#[from] lightpose_sim::SceneError),
    #[error("{0}")]
    Trajectory(#[from] lightpose_sim::TrajectoryError),
}

pub struct SimSource {
    sim: Simulator,
    traj: Trajectory,
    rate_hz: f64,
    /// Frames in one pass of the trajectory.
    per_pass: u64,
    looping: bool,
    pace: Pace,
    k: u64,
    anchor: Option<Instant>,
    what: String,
}

impl SimSource {
    pub fn open(cfg: &SimBackend, rate_hz: f64) -> Result<SimSource, SimError> {
        let scene_text = cfg
            .scene
            .read()
            .map_err(|e| SimError::Read(cfg.scene.describe(), e))?;
        let traj_text = cfg
            .trajectory
            .read()
            .map_err(|e| SimError::Read(cfg.trajectory.describe(), e))?;
        let scene = Scene::parse(&scene_text, &cfg.scene.describe())?;
        let traj = Trajectory::parse(&traj_text, &cfg.trajectory.describe())?;
        let per_pass = traj.frame_times(rate_hz).count().max(1) as u64;
        Ok(SimSource {
            sim: Simulator::new(scene, cfg.seed),
            per_pass,
            rate_hz,
            looping: cfg.looping,
            pace: cfg.pace,
            k: 0,
            anchor: None,
            what: format!(
                "simulator: {} along {} at {rate_hz} Hz{}{}",
                cfg.scene.describe(),
                cfg.trajectory.describe(),
                if cfg.looping { ", looping" } else { "" },
                if cfg.pace == Pace::Fast {
                    ", as fast as possible"
                } else {
                    ""
                }
            ),
            traj,
        })
    }
}

impl FrameSource for SimSource {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        let k = self.k;
        if !self.looping && k >= self.per_pass {
            return Err(SourceError::Ended);
        }
        if self.pace == Pace::Realtime {
            // Keep to the schedule from the first frame: a frame that is
            // late is not waited for, so the source catches up.
            let a = *self.anchor.get_or_insert_with(Instant::now);
            let due = a + Duration::from_secs_f64(k as f64 / self.rate_hz);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        let t_traj = self.traj.t0() + (k % self.per_pass) as f64 / self.rate_hz;
        let (pose, surge) = self.traj.sample(t_traj);
        self.k += 1;
        Ok(self
            .sim
            .frame(k, k as f64 / self.rate_hz, &pose, Some(surge)))
    }

    fn adc_bits(&self) -> u8 {
        self.sim.scene().adc.bits
    }

    fn describe(&self) -> String {
        self.what.clone()
    }
}
