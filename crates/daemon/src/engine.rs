//! The per-frame path: acquire → attitude → estimate → serialize → send →
//! record, all in one dedicated std thread.
//!
//! Why one thread and std sockets rather than a channel into tokio:
//! `FrameSource::next_frame` blocks, so it needs its own thread anyway, and
//! doing the rest of the frame right there removes a hand-off (a channel
//! wake-up and a context switch, tens of µs on a small ARM board) from the
//! frame-to-datagram latency budget (p99 < 1 ms). The async side keeps the
//! slow, periodic work: STATUS, the watchdog, signals, the attitude input.
//!
//! Nothing here allocates per frame once warm: the frame is a Copy value,
//! the POSE text goes into one reused buffer, the recorder queue's slots are
//! allocated once, counters are atomics.

use crate::attitude::AttitudeCell;
use crate::publish::Publisher;
use crate::recorder::Recorder;
use crate::stats::{BackendState, Stats, TempSource};
use lightpose_core::Estimator;
use lightpose_hal::{FrameSource, SourceError};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

/// Why the loop ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EndReason {
    /// Asked to stop (SIGTERM, shutdown future).
    Stopped,
    /// The source has no more frames.
    SourceEnded,
    /// The frame budget of a benchmark was spent.
    FrameLimit,
}

pub struct Engine {
    pub source: Box<dyn FrameSource>,
    pub estimator: Box<dyn Estimator>,
    pub publisher: Arc<Publisher>,
    pub stats: Arc<Stats>,
    pub recorder: Option<Recorder>,
    pub attitude: Option<(Arc<AttitudeCell>, Duration)>,
    pub stop: Arc<AtomicBool>,
    /// New estimators from a calibration reload (SIGHUP).
    pub reload: Option<Receiver<Box<dyn Estimator>>>,
    /// Expected period, for deadline accounting; `None` when the source
    /// goes as fast as it can.
    pub period: Option<Duration>,
    pub late_tolerance: f64,
    pub fallback_temp_c: Option<f64>,
    pub max_frames: Option<u64>,
    /// Base for the heartbeat the watchdog looks at.
    pub epoch: Instant,
}

/// Logs the first event of a kind, then at most one line a second with the
/// count since: visible, not flooding.
struct RateLog {
    last: Option<Instant>,
    suppressed: u64,
}

impl RateLog {
    fn new() -> Self {
        RateLog {
            last: None,
            suppressed: 0,
        }
    }
    /// `Some(n)` when a line should be written now, n = events folded in.
    fn tick(&mut self, now: Instant) -> Option<u64> {
        match self.last {
            Some(t) if now.duration_since(t) < Duration::from_secs(1) => {
                self.suppressed += 1;
                None
            }
            _ => {
                self.last = Some(now);
                let n = self.suppressed + 1;
                self.suppressed = 0;
                Some(n)
            }
        }
    }
}

impl Engine {
    /// Run until stopped, the source ends, or `max_frames` frames.
    pub fn run(mut self) -> EndReason {
        let mut buf: Vec<u8> = Vec::with_capacity(1024);
        let mut anchor: Option<(Instant, u64)> = None;
        let mut last_seq: Option<u64> = None;
        // Failures since the last good frame: a board's seq runs on through
        // them, and they are already counted as failed, not as lost.
        let mut failed_since_ok = 0u64;
        let (mut late_log, mut fail_log, mut lost_log) =
            (RateLog::new(), RateLog::new(), RateLog::new());
        let stats = self.stats.clone();
        stats.set_state(BackendState::Running);
        let mut health_at = Instant::now();
        let reason = loop {
            if self.stop.load(Relaxed) {
                break EndReason::Stopped;
            }
            if self
                .max_frames
                .is_some_and(|m| stats.frames.load(Relaxed) >= m)
            {
                break EndReason::FrameLimit;
            }
            if let Some(rx) = &self.reload {
                if let Ok(e) = rx.try_recv() {
                    tracing::info!("calibration reloaded: estimator {} replaced", e.name());
                    self.estimator = e;
                    stats.calibration_reloads.fetch_add(1, Relaxed);
                }
            }
            stats
                .heartbeat_ns
                .store(self.epoch.elapsed().as_nanos() as u64, Relaxed);
            if health_at.elapsed() >= Duration::from_secs(1) {
                // Once a second, not per frame: the copy allocates.
                health_at = Instant::now();
                if let Ok(mut h) = stats.source_health.lock() {
                    *h = Some(self.source.health());
                }
            }
            let got = self.source.next_frame();
            let arrival = Instant::now();
            let wall = SystemTime::now()
                .duration_since(SystemTime::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64());
            stats
                .heartbeat_ns
                .store(self.epoch.elapsed().as_nanos() as u64, Relaxed);
            let mut frame = match got {
                Ok(f) => f,
                Err(SourceError::Ended) => {
                    stats.set_state(BackendState::Ended);
                    tracing::info!("source ended after {} frames", stats.frames.load(Relaxed));
                    break EndReason::SourceEnded;
                }
                Err(e) => {
                    let n = stats.failed.fetch_add(1, Relaxed) + 1;
                    failed_since_ok += 1;
                    stats.set_state(BackendState::Failing);
                    if let Some(k) = fail_log.tick(arrival) {
                        tracing::warn!(failed_total = n, since_last_line = k, "frame failed: {e}");
                    }
                    if let Ok(mut g) = stats.last_error.lock() {
                        *g = Some(e.to_string());
                    }
                    // A dead bus fails at once: do not spin a core on it.
                    let pause = self
                        .period
                        .unwrap_or(Duration::from_millis(10))
                        .min(Duration::from_millis(100));
                    if matches!(e, SourceError::Unavailable { .. }) {
                        std::thread::sleep(pause);
                    }
                    continue;
                }
            };
            if stats.state() != BackendState::Running {
                stats.set_state(BackendState::Running);
            }

            if let Some(prev) = last_seq {
                let gap = frame
                    .seq
                    .saturating_sub(prev + 1)
                    .saturating_sub(failed_since_ok);
                if gap > 0 {
                    let n = stats.lost.fetch_add(gap, Relaxed) + gap;
                    if let Some(k) = lost_log.tick(arrival) {
                        tracing::warn!(
                            lost_total = n,
                            gaps_since_last_line = k,
                            "seq jumped {prev} → {}: frames lost at the source",
                            frame.seq
                        );
                    }
                }
            }
            last_seq = Some(frame.seq);
            failed_since_ok = 0;
            stats.last_seq.store(frame.seq, Relaxed);

            if frame.attitude.is_none() {
                if let Some((cell, max_age)) = &self.attitude {
                    frame.attitude = cell.fresh(arrival, *max_age);
                }
            }
            if frame.attitude.is_some() {
                stats.frames_with_attitude.fetch_add(1, Relaxed);
            }
            // The frame as acquired (with its attitude) is what gets
            // recorded; the fallback temperature is the daemon's, not the
            // board's, and a replay applies it again.
            if let Some(r) = &self.recorder {
                r.record(&frame);
            }
            let mut est_frame = frame;
            match (frame.temp_c, self.fallback_temp_c) {
                (Some(t), _) => stats.set_temp(Some(t), TempSource::Frame),
                (None, Some(fb)) => {
                    est_frame.temp_c = Some(fb);
                    stats.set_temp(Some(fb), TempSource::Fallback);
                }
                (None, None) => stats.set_temp(None, TempSource::Missing),
            }

            let est = self.estimator.estimate(&est_frame);
            est.write_json(Some(wall), &mut buf);
            self.publisher.send(&buf);
            let done = Instant::now();
            stats.latency.record(done - arrival);

            let si = est.status.index();
            stats.by_status[si].fetch_add(1, Relaxed);
            stats.last_status.store(si as u8, Relaxed);
            stats.frames.fetch_add(1, Relaxed);

            if let Some(p) = self.period {
                // Due time from the seq, so that the frame after a dropped
                // or failed one is judged by its own slot.
                let (a_at, a_seq) = *anchor.get_or_insert((arrival, frame.seq));
                let slots = frame.seq.saturating_sub(a_seq).min(u32::MAX as u64) as u32;
                let d = a_at + p * slots;
                let tol = p.mul_f64(self.late_tolerance);
                if done > d + tol {
                    let n = stats.late.fetch_add(1, Relaxed) + 1;
                    if let Some(k) = late_log.tick(done) {
                        tracing::warn!(
                            late_total = n,
                            since_last_line = k,
                            "frame {} late by {:.1} ms (period {:.1} ms)",
                            frame.seq,
                            (done - d).as_secs_f64() * 1e3,
                            p.as_secs_f64() * 1e3
                        );
                    }
                    // Re-anchor on this frame: one stall counts once, not
                    // every frame after it.
                    anchor = Some((arrival, frame.seq));
                }
            }
        };
        if let Some(mut r) = self.recorder.take() {
            r.finish();
        }
        if reason != EndReason::SourceEnded {
            stats.set_state(BackendState::Stopped);
        }
        reason
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Outputs;
    use lightpose_core::{Frame, PoseEstimate, Status, NDET};

    /// Frames every `period`, except that one frame comes `stall` late.
    struct Stalling {
        k: u64,
        start: Option<Instant>,
        period: Duration,
        stall_at: u64,
        stall: Duration,
        fail_at: u64,
    }

    impl FrameSource for Stalling {
        fn next_frame(&mut self) -> Result<Frame, SourceError> {
            let k = self.k;
            self.k += 1;
            let start = *self.start.get_or_insert_with(Instant::now);
            let mut due = start + self.period * k as u32;
            if k >= self.stall_at {
                due += self.stall;
            }
            if let Some(w) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(w);
            }
            if k == self.fail_at {
                return Err(SourceError::Timeout {
                    place: "test".into(),
                });
            }
            Ok(Frame {
                seq: k,
                t: k as f64 * self.period.as_secs_f64(),
                adc_bits: 10,
                counts: [100; NDET],
                temp_c: None,
                truth: None,
                attitude: None,
                depth: None,
                velocity: None,
            })
        }
        fn adc_bits(&self) -> u8 {
            10
        }
        fn describe(&self) -> String {
            "stalling test source".into()
        }
    }

    struct Nothing;
    impl Estimator for Nothing {
        fn name(&self) -> &'static str {
            "nothing"
        }
        fn estimate(&mut self, f: &Frame) -> PoseEstimate {
            PoseEstimate::empty(f.seq, f.t, Status::NoLight, "nothing")
        }
        fn reset(&mut self) {}
    }

    #[test]
    fn a_stall_counts_once_as_late_and_a_failure_as_failed() {
        let period = Duration::from_millis(20);
        let stats = Arc::new(Stats::default());
        let e = Engine {
            source: Box::new(Stalling {
                k: 0,
                start: None,
                period,
                stall_at: 10,
                stall: Duration::from_millis(200),
                fail_at: 20,
            }),
            estimator: Box::new(Nothing),
            publisher: Arc::new(
                Publisher::open(&Outputs {
                    destinations: vec![],
                    multicast: None,
                    status_interval: Duration::from_secs(1),
                })
                .unwrap(),
            ),
            stats: stats.clone(),
            recorder: None,
            attitude: None,
            stop: Arc::new(AtomicBool::new(false)),
            reload: None,
            period: Some(period),
            // Generous: a loaded CI machine oversleeps by milliseconds.
            late_tolerance: 2.0,
            fallback_temp_c: Some(12.0),
            max_frames: Some(30),
            epoch: Instant::now(),
        };
        assert_eq!(e.run(), EndReason::FrameLimit);
        assert_eq!(stats.frames.load(Relaxed), 30);
        assert_eq!(stats.late.load(Relaxed), 1, "the stalled frame, once");
        assert_eq!(stats.failed.load(Relaxed), 1);
        assert_eq!(
            stats.lost.load(Relaxed),
            0,
            "the failed frame is not counted again"
        );
        assert_eq!(stats.temp(), (Some(12.0), TempSource::Fallback));
        assert_eq!(stats.by_status[1].load(Relaxed), 30);
    }
}
