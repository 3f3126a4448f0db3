//! Calibration: the file every estimator runs on, and the fits that write
//! it from truth-labelled sweeps.
//!
//! - [`mod@file`]: the calibration file format (the paper's coefficients, their
//!   quality and validity range, `[physical]`, `[estimator]`), typed and
//!   checked on load.
//! - [`paper_fit`]: `lightpose calibrate`'s fit of the paper's coefficients
//!   (paper section 2.2.1), streamed over the sweeps; it also feeds the
//!   physical fit.
//! - [`physical_fit`]: the fit of MODEL.md's light equation and each
//!   channel's gain and offset, the `[physical]` table the model-based
//!   estimators run on.
//! - [`least_squares`]: the streaming straight-line fit the paper's fit
//!   uses.
//!
//! The estimators' settings (the `[estimator]` table) are in
//! [`crate::settings`], so that the estimators need nothing from here but
//! the numbers.

pub mod file;
pub mod least_squares;
pub mod paper_fit;
pub mod physical_fit;
mod sweep_logs;

pub use file::{
    CalError, Calibration, Coverage, Dark, Feature, Fits, Limits, LinearFit, Meta, Moment, Origin,
    RangeBasis, RangeFit, Refusal, SceneFacts, FORMAT, MAX_SURGE_WINDOW, VERSION,
};
pub use paper_fit::{calibrate, calibrate_full, CalibrateError, CalibrateOptions, Calibrated};
pub use physical_fit::{
    fit_physical, CalibError, FitOptions, ParamEstimate, PhysicalCalibration, PhysicalFitter,
    ScatterFit,
};
