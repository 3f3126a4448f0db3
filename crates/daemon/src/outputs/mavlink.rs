//! Each estimate to the autopilot: offered to the hub's outbox, from which
//! the MAVLink task sends `VISION_POSITION_ESTIMATE` (and
//! `VISION_SPEED_ESTIMATE`). The outbox refuses (and counts) a pose that is
//! not `ok` or not complete: the autopilot must never fuse a pose the
//! daemon does not trust. The track epoch, whose low byte becomes
//! `reset_counter`, is derived from the statuses by a [`RestartCounter`]:
//! a track that restarted makes the EKF reset to the new position instead
//! of rejecting it.

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
}
