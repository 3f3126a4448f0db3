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
//! - [`station`], [`station_fit`] (spec v3): a docking station's survey
//!   file, its `[station]` table, and the fit of each beacon's light and
//!   the array's gains from the station's sweeps, the survey checked.
//!
//! The estimators' settings (the `[estimator]` table) are in
//! [`crate::settings`], so that the estimators need nothing from here but
//! the numbers.

mod dark;
mod feature;
pub mod file;

/// How far apart two truth values may be and still be the same pose of a
/// sweep, and how near zero a value is zero: a tank carriage's read-back
/// precision, 1 mm and 0.05°. A sweep recorded elsewhere carries its
/// truth as measured; compared to 1e-9 (as a simulated sweep's exact
/// values allow), noise of 1e-6 on it refused the whole sweep as "mixed
/// pose" and a pose's frames fell into groups of one.
pub(crate) const TRUTH_TOL_M: f64 = 1e-3;
pub(crate) const TRUTH_TOL_DEG: f64 = 0.05;

/// Whether two truth poses are the same pose of a sweep (`TRUTH_TOL_M`,
/// `TRUTH_TOL_DEG`); roll too (spec v3: a station's sweep turns it, and
/// every v1/v2 pose's roll is 0).
pub(crate) fn same_pose(a: &lightpose_core::Pose, b: &lightpose_core::Pose) -> bool {
    [a.x - b.x, a.y - b.y, a.z - b.z]
        .iter()
        .all(|d| d.abs() <= TRUTH_TOL_M)
        && [
            a.pitch.deg() - b.pitch.deg(),
            a.yaw.deg() - b.yaw.deg(),
            a.roll.deg() - b.roll.deg(),
        ]
        .iter()
        .all(|d| d.abs() <= TRUTH_TOL_DEG)
}
/// How far from the beacon a sweep's truth may put the array: past 500 m
/// no beacon's light reaches a photodiode even in the clearest water (a
/// K_D of 0.02 m⁻¹ and the inverse square leave 1e-8 of the light at 4
/// m), so such a truth is a typing error (mm for m), not a pose.
pub(crate) const MAX_TRUTH_M: f64 = 500.0;

/// Why a lit sweep frame is fit by neither the paper's fits nor the light
/// model, or `None` when it can be: the frame's water temperature and its
/// truth pose must be possible. One absurd truth (x = 1e9 m) had widened
/// the calibration's coverage to 1e9 m and, in the light model, given `ok`
/// poses with σx 2e7 m; a temperature of 500 °C reached the light model's
/// temperature gain while the paper's fits skipped the frame.
pub(crate) fn sweep_frame_fault(f: &lightpose_core::Frame) -> Option<&'static str> {
    use lightpose_core::light::WATER_TEMP_C;
    let truth = f.truth?.pose;
    if f.temp_c.is_some_and(|t| !WATER_TEMP_C.contains(&t)) {
        return Some("temperature not water's (-10 to 60 °C)");
    }
    let within = |v: f64, lim: f64| v.abs() <= lim;
    let plausible = truth.x > 0.0
        && [truth.x, truth.y, truth.z]
            .iter()
            .all(|v| within(*v, MAX_TRUTH_M))
        && within(truth.pitch.deg(), 90.0)
        && within(truth.yaw.deg(), 180.0);
    (!plausible).then_some(
        "truth beyond any lit pose (x in (0, 500] m, |y| and |z| up to 500 m, |pitch| up to 90°, |yaw| up to 180°)",
    )
}

pub mod least_squares;
mod lm;
pub mod paper_fit;
pub mod physical_fit;
pub mod station;
pub mod station_fit;
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
pub use station::{
    CalibratedBeacon, Station, StationCalibration, StationError, SurveyCheck, SurveyedBeacon,
};
pub use station_fit::{
    fit_station_sweeps, StationFitError, StationFitOptions, StationFitted, StationFitter,
};
