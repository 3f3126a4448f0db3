//! Each estimate to the autopilot: offered to the hub's outbox, from which
//! the MAVLink task sends `VISION_POSITION_ESTIMATE` (and
//! `VISION_SPEED_ESTIMATE`). The outbox refuses (and counts) a pose that is
//! not `ok` or not complete: the autopilot must never fuse a pose the
//! daemon does not trust. The track epoch, whose low byte becomes
//! `reset_counter`, is derived from the statuses by a [`RestartCounter`]:
//! a track that restarted makes the EKF reset to the new position instead
//! of rejecting it. It starts from the wall clock (a restarted daemon is a
//! reset too) and steps at the first `ok` pose after a calibration reload
//! ([`Output::estimator_replaced`]).

use super::Output;
use crate::engine::Acquired;
use lightpose_core::PoseEstimate;
use lightpose_vehicle::{Hub, RestartCounter};
use std::sync::Arc;

/// The frame thread's end of the hub's outbox.
pub struct ToAutopilot {
    hub: Arc<Hub>,
    restarts: RestartCounter,
}

impl ToAutopilot {
    pub fn new(hub: Arc<Hub>) -> Self {
        ToAutopilot {
            hub,
            restarts: RestartCounter::default(),
        }
    }
}

impl Output for ToAutopilot {
    #[inline]
    fn emit(&mut self, _frame: &Acquired, est: &PoseEstimate) {
        let epoch = self.restarts.observe(est);
        // Queued, or counted by the outbox as not ok / incomplete.
        let _ = self.hub.outbox.offer(est, epoch);
    }

    fn estimator_replaced(&mut self) {
        self.restarts.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{Frame, Status, StdDev, NDET};
    use std::time::Instant;

    fn ok(seq: u64) -> PoseEstimate {
        let mut e = PoseEstimate::empty(seq, seq as f64 * 0.1, Status::Ok, "test");
        (e.x, e.y, e.z, e.pitch_deg, e.yaw_deg) =
            (Some(5.0), Some(0.0), Some(0.0), Some(0.0), Some(0.0));
        e.std = StdDev {
            x: Some(0.1),
            y: Some(0.1),
            z: Some(0.1),
            pitch: Some(1.0),
            yaw: Some(1.0),
            surge: None,
            roll: None,
        };
        e
    }

    /// A calibration reload makes the next `ok` pose a reset for the
    /// autopilot, even from an estimator that is `ok` from its first frame.
    #[test]
    fn a_replaced_estimator_steps_the_reset_counter() {
        let hub = Hub::new();
        let mut out = ToAutopilot::new(hub.clone());
        let acq = Acquired {
            frame: Frame::new(0, 0.0, 12, [0; NDET]),
            arrival: Instant::now(),
            capture: Instant::now(),
            wall_unix: 0.0,
        };
        let mut seen = 0;
        let mut epoch = |out: &mut ToAutopilot, seq| {
            out.emit(&acq, &ok(seq));
            hub.outbox.take_new(&mut seen).expect("queued").epoch
        };
        let first = epoch(&mut out, 1);
        assert_eq!(epoch(&mut out, 2), first);
        out.estimator_replaced();
        assert_eq!(epoch(&mut out, 3), first.wrapping_add(1));
        assert_eq!(epoch(&mut out, 4), first.wrapping_add(1));
    }
}
