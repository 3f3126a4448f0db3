//! Pose estimation from one photodiode frame at a time, as a library: the
//! paper's estimator (Eren et al. 2017, eqs. 1–14), the model-based
//! estimators that invert MODEL.md's light equation, the calibration they
//! run on and the fits that write it, and offline replay.
//!
//! It is a library, not part of the CLI, so that the daemon, the Monte Carlo
//! and the tests run exactly the code that `lightpose replay` runs.
//!
//! - [`paper`]: the paper's `"moments"` estimator and its per-frame steps.
//! - [`model`]: the model-based `"model"` and `"tracker"` estimators, the
//!   light equation, the solver and the Cramér–Rao bound.
//! - [`calibration`]: the calibration file, the paper's fit and the
//!   physical fit.
//! - [`settings`]: the estimators' settings (a calibration's `[estimator]`
//!   table), apart from both so that neither imports the other.
//! - [`estimators`]: one estimator by name; [`mod@replay`]: a log through one.

pub mod calibration;
pub mod estimators;
pub mod model;
pub mod paper;
pub mod replay;
pub mod settings;

pub use calibration::{CalError, Calibration};
pub use estimators::{build_estimator, reads_frames_of, BuildError};
pub use paper::MomentsEstimator;
pub use replay::{replay, ErrorReport, ReplayError, ReplaySummary};
