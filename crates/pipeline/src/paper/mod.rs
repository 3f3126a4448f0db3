//! The paper's estimator (Eren et al. 2017, Algorithm 1, eqs. 1–14): pose
//! read off the image's moments through linear calibrations.
//!
//! - [`steps`]: the per-frame steps, each a small pure function (volts,
//!   temperature, sub-pixel peak, moments, x from the peak, the bow).
//! - [`moments`]: the `"moments"` estimator that runs them with a
//!   calibration's coefficients and carries y, z and surge between frames.
//!
//! Its coefficients come from `calibration::paper_fit`; a change to how a
//! frame is turned into a pose by the paper's method belongs here.

pub mod moments;
pub mod steps;

pub use moments::MomentsEstimator;
