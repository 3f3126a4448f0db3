//! The vehicle's own readings — the autopilot's attitude, depth and water
//! temperature over MAVLink, the DVL's velocity over TCP — as the I/O
//! tasks left them in the shared [`Hub`]; attached to each frame before it
//! is estimated, so that the estimator, the recording and a later replay
//! all see the same frame. What was attached or stale is counted by the
//! hub (STATUS `vehicle.readings`).

use super::Input;
use lightpose_core::Frame;
use lightpose_vehicle::{Hub, MaxAge};
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
        // (an attitude carried there by its rates). Lock-free, no
        // allocation.
        self.hub.readings.attach(frame, capture, &self.max_age);
    }
}
