//! The one interface every pose estimator implements, so that replay, the
//! daemon and the Monte Carlo can run any of them.

use std::any::Any;

use crate::{Frame, PoseEstimate};

/// What an estimator found out about the vehicle's hardware rather than
/// about its track (a channel stuck, a DVL set up wrong), handed to the
/// estimator that replaces it; each estimator knows its own kind.
pub type Findings = Box<dyn Any + Send>;

/// A per-frame pose estimator that keeps its own state between frames.
///
/// `estimate` must never panic and never return NaN: a frame that cannot
/// give a pose gives a status word (see [`crate::Status`]).
pub trait Estimator: Send {
    /// Short name, as it appears in POSE messages and tables.
    fn name(&self) -> &'static str;
    /// Estimate the pose for the next frame (frames arrive in time order).
    fn estimate(&mut self, frame: &Frame) -> PoseEstimate;
    /// Forget all state (a new run, or a jump in time).
    fn reset(&mut self);
    /// Whether every `ok` pose it gives carries a std of each of its five
    /// fields (x, y, z, pitch, yaw). What the autopilot is sent needs one
    /// (`[mavlink] missing_std = "skip"` sends nothing without), so
    /// `--check-config` refuses a MAVLink configuration whose estimator
    /// never gives them. False by default: an estimator says so itself.
    fn std_with_every_ok_pose(&self) -> bool {
        false
    }
    /// The water's K_D (m⁻¹) as the estimator has learned it from the
    /// frames so far, if it learns it; None when it takes the
    /// calibration's (the default). What STATUS and the replay summary
    /// report as `water_k_d`: water the calibration did not see, found.
    fn water_k_d(&self) -> Option<f64> {
        None
    }

    /// The depth sensor's offset and its 1σ (m), if the estimator
    /// estimates it (the tracker's `depth_offset_sigma_m`); None otherwise
    /// (the default). What STATUS and the replay summary report as
    /// `depth_offset`.
    fn depth_offset(&self) -> Option<(f64, f64)> {
        None
    }

    /// The attitude sensor's pitch offset and its 1σ (degrees), if the
    /// estimator estimates it (the tracker's `pitch_offset_sigma_deg`).
    fn pitch_offset_deg(&self) -> Option<(f64, f64)> {
        None
    }

    /// What this estimator found out about the hardware, for the one
    /// that replaces it on a calibration reload (SIGHUP): a stuck channel
    /// or a DVL set up wrong is still so under the new calibration, and
    /// would otherwise be read as data until found again. None (the
    /// default) when it finds nothing such.
    fn findings(&self) -> Option<Findings> {
        None
    }

    /// Take over `found`, the findings of the estimator this one replaces;
    /// findings of a kind it does not know are ignored (the default).
    fn take_findings(&mut self, found: &(dyn Any + Send)) {
        let _ = found;
    }
}
