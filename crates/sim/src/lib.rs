//! The simulator of the beacon, the water and the detector array: exactly
//! the physics of `MODEL.md`, so that what it writes calibrates and replays
//! like a tank recording, and so that tests, the Monte Carlo and the daemon's
//! mock backend can see the system work without hardware.
//!
//! - [`scene`]: the scene file (TOML) parsed and validated into a [`Scene`];
//! - [`trajectory`]: knots, natural cubic splines and sampling;
//! - [`simulator`]: light to counts, with gains, offsets, noise and the ADC;
//! - [`sweep`]: the calibration sweeps of MODEL.md;
//! - [`frames`]: the frames an estimator reads from a simulated run (a
//!   blinking beacon's bursts demodulated).

pub mod frames;
pub mod scene;
pub mod simulator;
pub mod spline;
pub mod sweep;
pub mod trajectory;

pub use frames::EstimatorFrames;
pub use scene::{
    Adc, AttitudeNoise, Beacon, Blink, Daylight, DepthNoise, DvlNoise, Flicker, McSpread, Noise,
    Scene, SceneError,
};
pub use simulator::Simulator;
pub use sweep::{SweepKind, SweepPlan};
pub use trajectory::{Kinematics, Trajectory, TrajectoryError};
