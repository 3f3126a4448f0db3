//! Outputs: where each frame and its estimate go once estimated. The frame
//! thread hands every output the frame as acquired (with its inputs'
//! readings, without the daemon's fallback temperature) and the estimate,
//! in order, and measures latency to the last of them.
//!
//! Today: POSE datagrams over UDP ([`udp`]), the recording of frames (and,
//! in MCAP, estimates and STATUS: [`recorder`], [`recfile`]) and the live
//! view for Foxglove ([`live`]), the web page's feed ([`web`]), the pose to the autopilot over MAVLink
//! ([`mavlink`]). A new output (another protocol, another recording
//! format, a live viewer) is a file here implementing [`Output`], added to
//! the engine in `wiring.rs`.

pub mod live;
pub mod mavlink;
pub mod recfile;
pub mod recorder;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod spsc;
pub mod udp;
pub mod web;

use crate::engine::Acquired;
use lightpose_core::PoseEstimate;

/// Something that receives each (frame, estimate). Called on the frame
/// thread: it must not block (hand slow work to a thread of its own behind
/// a bounded queue, as the recorder does) nor allocate per frame.
pub trait Output: Send {
    fn emit(&mut self, frame: &Acquired, est: &PoseEstimate);
    /// Spec v3: the raw samples the frame about to be emitted was
    /// demodulated from, just before its [`Output::emit`] (a recorder of
    /// BURST lines keeps them). Not called for frames of one sample.
    fn raw(&mut self, burst: &lightpose_core::samples::Burst) {
        let _ = burst;
    }
    /// The engine replaced its estimator (a calibration reload): the
    /// estimates that follow are a new track. Called on the frame thread,
    /// between two frames.
    fn estimator_replaced(&mut self) {}
    /// The engine stops: flush what is queued. Called once, on the frame
    /// thread, before the engine returns.
    fn finish(&mut self) {}
}

/// Something that also takes each STATUS the daemon publishes (the MCAP
/// recording, the live view). Called on the async side, once a second:
/// it may allocate, but must not block.
pub trait StatusTap: Send + Sync {
    fn status(&self, json: &[u8]);
    /// The daemon stops (after the last STATUS): tell what the log was
    /// not told yet (core's `RateLog::flush`).
    fn stop(&self) {}
}
