//! The paper's pose pipeline (Eren et al. 2017, eqs. 1–14) as a library:
//! the per-frame steps, the moments estimator built from them, the fit of
//! its coefficients from truth-labelled sweeps, and offline replay.
//!
//! It is a library, not part of the CLI, so that the daemon, the Monte Carlo
//! and the tests run exactly the code that `lightpose replay` runs.

pub mod calibrate;
pub mod calibration;
pub mod crb;
pub mod estimators;
pub mod fit;
pub mod model;
pub mod moments;
pub mod replay;
pub mod steps;
pub mod tracker;

pub use calibration::{CalError, Calibration};
pub use estimators::{build_estimator, BuildError};
pub use moments::MomentsEstimator;
pub use replay::{replay, ErrorReport, ReplayError, ReplaySummary};
