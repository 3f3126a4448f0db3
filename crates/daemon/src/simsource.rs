//! The simulator backend of the daemon: hal's simulator-driven source (the
//! same one that injects faults for the robustness tests, here with none),
//! opened from the scene and trajectory that the config names or that the
//! binary embeds, so the default config runs from anywhere.

use crate::config::{Pace, SimBackend};
use lightpose_hal::mock::{Faults, MockSource};
use lightpose_sim::{Scene, Simulator, Trajectory};

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("{0}: {1}")]
    Read(String, std::io::Error),
    #[error("{0}")]
    Scene(#[from] lightpose_sim::SceneError),
    #[error("{0}")]
    Trajectory(#[from] lightpose_sim::TrajectoryError),
}

/// Open the simulator along the trajectory at `rate_hz`, looping or not.
pub fn open(cfg: &SimBackend, rate_hz: f64) -> Result<MockSource, SimError> {
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
    let src = MockSource::new(
        Simulator::new(scene, cfg.seed),
        traj,
        Some(rate_hz),
        cfg.looping,
        Faults::default(),
    );
    Ok(match cfg.pace {
        Pace::Realtime => src,
        Pace::Fast => src.free_running(),
    })
}
