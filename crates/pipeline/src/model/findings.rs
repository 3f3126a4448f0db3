//! What a model-based estimator found out about the vehicle's hardware
//! rather than about its track, handed to the estimator that replaces it
//! on a calibration reload (core's `Estimator::findings`).
//!
//! Why: a stuck channel or a DVL set up wrong is still so under a new
//! calibration. Found again from scratch, the stuck channel was read as
//! data for its first repeats (11 frames in the tank) and the DVL fused for
//! the seconds its checks need (2–3 s backwards, 18–26 s turned tens of
//! degrees), then the track restarted a second time. What the estimator
//! learned of the water, the sensors' offsets and their agreement with the
//! light is not handed on: it was learned through the old calibration's
//! light.

use std::any::Any;

use lightpose_core::Findings;

use super::frozen::FrozenWatch;
use super::tracker::DvlChecks;

/// The findings of the tracker (its DVL checks' verdicts) and of the
/// single-frame fit (channels only).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Found {
    /// Each channel's history: a frozen channel stays left out until its
    /// count moves.
    pub channels: FrozenWatch,
    /// The DVL checks' verdicts, with empty windows
    /// ([`DvlChecks::verdicts`]).
    pub dvl: Option<DvlChecks>,
}

impl Found {
    pub fn boxed(self) -> Option<Findings> {
        Some(Box::new(self))
    }

    /// `found` if it is of this kind.
    pub fn of(found: &(dyn Any + Send)) -> Option<&Found> {
        found.downcast_ref::<Found>()
    }
}
