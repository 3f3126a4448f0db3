//! The vehicle's own readings — the autopilot's attitude, depth and water
//! temperature over MAVLink, the DVL's velocity over TCP — as the I/O
//! tasks left them in the shared [`Hub`]; attached to each frame before it
//! is estimated, so that the estimator, the recording and a later replay
//! all see the same frame. What was attached or stale is counted by the
//! hub (STATUS `vehicle.readings`).
//!
//! A reading carried to the capture (an attitude by its rates, a depth by
//! the DVL's climb rate) without a std of its own, as MAVLink's come, goes
//! on the frame with the σ the estimator assumes for it widened by the
//! carry ([`assumed_std`], told to the hub at start and at each reload;
//! docs/vehicle.md, "Time").

use super::Input;
use lightpose_core::{Angle, Frame};
use lightpose_pipeline::model::ModelEstimator;
use lightpose_pipeline::settings::EstimatorSettings;
use lightpose_vehicle::{AssumedStd, Hub, MaxAge};
use std::sync::Arc;
use std::time::Instant;

/// The frame thread's end of the hub's readings.
pub struct VehicleReadings {
    pub hub: Arc<Hub>,
    pub max_age: MaxAge,
}

impl Input for VehicleReadings {
    #[inline]
    fn attach(&mut self, frame: &mut Frame, capture: Instant) {
        // A frame's own readings (a replayed log, the simulator's sensors)
        // win: attach fills only what the frame lacks, as of its capture
        // (an attitude carried there by its rates, a std-less carried one
        // given the assumed σ widened). Lock-free, no allocation.
        self.hub.readings.attach(frame, capture, &self.max_age);
    }
}

/// The σ the estimator named `estimator` (as it names itself) assumes for
/// a reading without a std, from the calibration's `[estimator]` table
/// (`settings`; `None`: the defaults): `[estimator.tracker]`'s
/// `attitude_sigma_pitch_deg`, `attitude_sigma_yaw_deg` and
/// `depth_sigma_m`. The single-frame `model` takes its attitude σ from
/// `[estimator.model]` instead (it reads no depth: the tracker's depth σ
/// stands). Any other estimator (`moments`) reads no readings: the
/// tracker's σ anyway, so that a recording made with it carries what a
/// replay with the tracker would have assumed.
pub fn assumed_std(estimator: &str, settings: Option<&EstimatorSettings>) -> AssumedStd {
    let defaults = EstimatorSettings::default();
    let s = settings.unwrap_or(&defaults);
    let (pitch, yaw) = if estimator == ModelEstimator::NAME {
        (
            s.model.attitude_sigma_pitch_deg,
            s.model.attitude_sigma_yaw_deg,
        )
    } else {
        (
            s.tracker.attitude_sigma_pitch_deg,
            s.tracker.attitude_sigma_yaw_deg,
        )
    };
    AssumedStd {
        pitch: Angle::from_deg(pitch),
        yaw: Angle::from_deg(yaw),
        depth_m: s.tracker.depth_sigma_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_pipeline::model::Tracker;

    #[test]
    fn the_assumed_sigma_is_the_estimator_s_configured_one() {
        let close = |a: AssumedStd, p: f64, y: f64, d: f64| {
            (a.pitch.deg() - p).abs() < 1e-12
                && (a.yaw.deg() - y).abs() < 1e-12
                && (a.depth_m - d).abs() < 1e-15
        };
        // No [estimator] table: the tracker's defaults.
        let a = assumed_std(Tracker::NAME, None);
        assert!(close(a, 0.3, 1.5, 0.02), "{a:?}");
        // The calibration's [estimator.tracker] values.
        let mut s = EstimatorSettings::default();
        s.tracker.attitude_sigma_pitch_deg = 0.5;
        s.tracker.attitude_sigma_yaw_deg = 2.0;
        s.tracker.depth_sigma_m = 0.05;
        s.model.attitude_sigma_pitch_deg = 0.7;
        s.model.attitude_sigma_yaw_deg = 3.0;
        let a = assumed_std(Tracker::NAME, Some(&s));
        assert!(close(a, 0.5, 2.0, 0.05), "{a:?}");
        // The single-frame model: its own attitude σ.
        let a = assumed_std(ModelEstimator::NAME, Some(&s));
        assert!(close(a, 0.7, 3.0, 0.05), "{a:?}");
        // moments reads no readings: the tracker's.
        let a = assumed_std("moments", Some(&s));
        assert!(close(a, 0.5, 2.0, 0.05), "{a:?}");
    }
}
