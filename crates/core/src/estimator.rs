//! The one interface every pose estimator implements, so that replay, the
//! daemon and the Monte Carlo can run any of them.

use crate::{Frame, PoseEstimate};

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
}
