//! The demodulator of blinking beacons (spec v3, MODEL.md "A modulated
//! beacon and the samples of a frame"): each frame's samples into each
//! beacon's per-channel amplitude, its 1σ, the ambient level and the
//! clipped count, FORMATS.md's demodulated frame.
//!
//! It exists because at sea the beacon's light must be told from the sun's:
//! a beacon blinking at a few hundred hertz, sampled fast, stands apart
//! from daylight and its flicker (below ~20 Hz), and several beacons at
//! well-chosen frequencies stand apart from each other. The beacon's clock
//! is not the vehicle's, so its phase and drift are found from the samples
//! themselves, frame after frame. The method and its measured figures are
//! in docs/demodulator.md.
//!
//! ```
//! use lightpose_demod::{BeaconSpec, DemodConfig, Demodulator};
//! let cfg = DemodConfig::new(2000.0, 5.0, vec![BeaconSpec::new("top", 250.0)]);
//! let mut demod = Demodulator::new(cfg.validate().unwrap());
//! let mut out = demod.output();
//! let samples = vec![512u16; 25 * demod.samples_per_channel()];
//! demod.demodulate(&samples, 0.0, 10, &mut out).unwrap();
//! assert!((out.light.ambient[0] - 512.0).abs() < 1e-9);
//! ```

pub mod basis;
pub mod config;
mod demod;
pub mod frames;
mod posterior;
mod runs;
mod scan;
pub mod track;

pub use config::{
    check_frequencies, BeaconSpec, ConfigError, DemodConfig, ValidBeacon, ValidConfig, MAX_BEACONS,
};
pub use demod::{detection_threshold, Demodulator, FrameError, Lock};
pub use frames::{demodulator_for, FramesError, LogFrames};
/// What the demodulator writes: lightpose-core's demodulated frame (one
/// type for the demodulator, the logs and the estimators).
pub use lightpose_core::samples::{BeaconAmplitude, Demodulated};
