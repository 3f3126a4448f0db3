//! Inputs: readings from other sensors that ride with each frame. An input
//! is fed from outside the frame path (a socket task, a serial reader) and,
//! once per frame, attaches what it holds to the frame if it is fresh — so
//! that the estimator, the POSE and the recording all see the same frame.
//!
//! Today: the vehicle's attitude over UDP JSON ([`attitude`]), and the
//! autopilot's and the DVL's readings through lightpose-vehicle's hub
//! ([`vehicle`]). A new input
//! (another sensor, another protocol) is a file here implementing
//! [`Input`], started in `wiring.rs`, with its counters in STATUS.

pub mod attitude;
#[cfg(feature = "ros2")]
pub mod ros2;
#[cfg(feature = "ros2")]
pub mod ros2_readings;
pub mod vehicle;

use lightpose_core::Frame;
use std::time::Instant;

/// Something that attaches readings to a frame. Called on the frame
/// thread, once per frame: it must neither block nor allocate. What it
/// attaches (and what it leaves off as stale) it counts itself, in atomics
/// that STATUS reads.
pub trait Input: Send {
    /// Attach this input's reading to `frame` if one is fresh at `capture`
    /// (when the frame was sampled: the middle of a board's read, before
    /// it arrived) and the frame has none of its own. A reading taken
    /// after the capture (during the read) is fresh.
    fn attach(&mut self, frame: &mut Frame, capture: Instant);
}
