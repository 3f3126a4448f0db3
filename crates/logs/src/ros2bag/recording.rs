//! A ROS 2 bag as a recording (lightposed's `[recording] format = "ros2"`):
//! the recorder's [`LogSink`] over a [`Ros2Bag`], so that the bag is
//! rotated, flushed, synced, cut back and pruned as any MCAP recording.
//!
//! What it keeps is what the ROS 2 node publishes: each `ok` estimate as
//! pose, odometry and `/tf` at its capture (wall clock), and each STATUS as
//! `/diagnostics`. The frames themselves are not in it (a ROS 2 reader has
//! no type for them): a recording to replay or calibrate from is `mcap`
//! or `jsonl`; frames are counted, so the recorder's accounting holds.

use super::Ros2Bag;
use crate::ros2msg::{diagnostics, solve, LastEstimate, Time};
use crate::sink::LogSink;
use crate::write::WriteError;
use lightpose_core::{Burst, Demodulated, Frame, PoseEstimate};
use std::collections::BTreeMap;
use std::io::Write;

/// The recorder's sink of a ROS 2 bag.
pub struct Ros2Recording<W: Write> {
    bag: Ros2Bag<W>,
    frames: u64,
    last: LastEstimate,
    /// The latest estimate's log time `t` and its wall-clock capture: a
    /// STATUS (at a log time) is stamped on the same wall clock.
    clock: Option<(f64, f64)>,
}

impl<W: Write> Ros2Recording<W> {
    pub fn new(bag: Ros2Bag<W>) -> Self {
        Ros2Recording {
            bag,
            frames: 0,
            last: LastEstimate::default(),
            clock: None,
        }
    }

    fn frame(&mut self) -> Result<(), WriteError> {
        self.frames += 1;
        Ok(())
    }
}

/// Nanoseconds since 1970 of a wall-clock time in seconds (0 before it).
fn wall_nanos(wall: f64) -> u64 {
    super::nanos(&Time::from_unix(wall))
}

impl<W: Write> LogSink for Ros2Recording<W> {
    fn write_frame(&mut self, _: &Frame) -> Result<(), WriteError> {
        self.frame()
    }
    fn write_burst(&mut self, _: &Burst) -> Result<(), WriteError> {
        self.frame()
    }
    fn write_demodulated(&mut self, _: &Demodulated) -> Result<(), WriteError> {
        self.frame()
    }
    fn write_pose(&mut self, p: &PoseEstimate, wall_unix: Option<f64>) -> Result<(), WriteError> {
        self.last.observe(p);
        // A bag's stamps are the wall clock: an estimate without one has
        // no place in it (the recorder always gives it).
        let Some(wall) = wall_unix.filter(|w| w.is_finite() && *w > 0.0) else {
            return Ok(());
        };
        self.clock = Some((p.t, wall));
        match solve(p, wall) {
            Some(s) => self.bag.write_estimate(&s, wall_nanos(wall)),
            None => Ok(()),
        }
    }
    fn write_status(&mut self, t: f64, json: &[u8]) -> Result<(), WriteError> {
        // Before any estimate there is no wall clock to put it on.
        let Some((t0, wall0)) = self.clock else {
            return Ok(());
        };
        let wall = wall0 + (t - t0);
        let d = diagnostics(json, &self.last, Time::from_unix(wall));
        self.bag.write_diagnostics(&d, wall_nanos(wall))
    }
    fn write_metadata(
        &mut self,
        name: &str,
        pairs: BTreeMap<String, String>,
    ) -> Result<(), WriteError> {
        self.bag.write_metadata(name, pairs)
    }
    fn keeps_poses(&self) -> bool {
        true
    }
    fn flush(&mut self) -> Result<(), WriteError> {
        self.bag.flush()
    }
    fn frames_written(&self) -> u64 {
        self.frames
    }
    fn finish(self: Box<Self>) -> Result<(), WriteError> {
        self.bag.finish().map(drop)
    }
}
