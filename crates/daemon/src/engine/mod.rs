//! The per-frame path, in one dedicated std thread: acquire → account for
//! seq and losses → attach inputs → estimate → hand to every output (POSE
//! datagram, recording, ...) → deadline accounting. Each step is a method
//! below; inputs ([`crate::inputs::Input`]) and outputs
//! ([`crate::outputs::Output`]) plug in without touching the loop.
//!
//! Why one thread and std sockets rather than a channel into tokio:
//! `FrameSource::next_frame` blocks, so it needs its own thread anyway, and
//! doing the rest of the frame right there removes a hand-off (a channel
//! wake-up and a context switch, tens of µs on a small ARM board) from the
//! frame-to-datagram latency budget (p99 < 1 ms). The async side keeps the
//! slow, periodic work: STATUS, the watchdog, signals, the attitude input.
//!
//! Nothing here allocates per frame once warm: the frame is a Copy value,
//! inputs and outputs are called through a fixed list, the POSE text goes
//! into one reused buffer, the recorder queue's slots are allocated once,
//! counters are atomics. Every wait (the source's pacing, the pause after a
//! dead bus) ends at once when the [`Stop`] is raised.

pub mod demod;
mod failure;
mod health;
mod seq;
mod verdicts;

use crate::inputs::Input;
use crate::outputs::Output;
use crate::stats::{BackendState, Stats, TempSource};
use failure::LastFailure;
use lightpose_core::ratelog::RateLog;
use lightpose_core::{Estimator, Frame, PoseEstimate};
use lightpose_hal::{FrameSource, SourceError, Stop, Take};
use seq::{SeqBooks, Step};
use std::sync::atomic::Ordering::Relaxed;
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
    /// The frame thread panicked (with this message, if it had one): said
    /// by the supervisor, which finds the thread gone without a reason.
    /// A failure: the daemon exits non-zero, and systemd restarts it.
    Panicked(String),
}

impl EndReason {
    /// Whether the run failed (rather than stopped or ran out).
    pub fn is_failure(&self) -> bool {
        matches!(self, EndReason::Panicked(_))
    }
}

/// One frame on its way through the engine.
#[derive(Debug, Clone, Copy)]
pub struct Acquired {
    pub frame: Frame,
    /// When the source gave it: deadlines count from here.
    pub arrival: Instant,
    /// When it was sampled (the middle of a board's read), on the same
    /// clock: readings are attached as of here, and latency counts from
    /// here. The arrival for a source whose `t` is not the monotonic clock
    /// (simulated, recorded: no better is known).
    pub capture: Instant,
    /// The wall clock at the capture (Unix seconds): the POSE's `time`.
    pub wall_unix: f64,
}

/// The longest a frame is taken to have been captured before it arrived:
/// longer is no read of a board, but a `t` gone wrong, and the capture is
/// then put this far back rather than anywhere.
const MAX_CAPTURE_LAG: Duration = Duration::from_secs(1);

/// How long before its arrival a frame with monotonic `t` was captured,
/// from the monotonic clock `mono_s` read at its arrival; within
/// `[0, MAX_CAPTURE_LAG]` (a `t` ahead of the clock, or not finite, is
/// taken as captured on arrival).
fn capture_lag(t: f64, mono_s: f64) -> Duration {
    let lag = mono_s - t;
    if lag.is_finite() && lag > 0.0 {
        Duration::from_secs_f64(lag.min(MAX_CAPTURE_LAG.as_secs_f64()))
    } else {
        Duration::ZERO
    }
}

/// The frame loop and what it needs. Built with [`Engine::new`] and the
/// setters below (each has a default), then [`Engine::run`] on its thread.
pub struct Engine {
    source: Box<dyn FrameSource>,
    estimator: Box<dyn Estimator>,
    inputs: Vec<Box<dyn Input>>,
    outputs: Vec<Box<dyn Output>>,
    stats: Arc<Stats>,
    stop: Stop,
    /// New estimators from a calibration reload (SIGHUP).
    reload: Option<Receiver<Box<dyn Estimator>>>,
    /// Expected period, for deadline accounting; `None` when the source
    /// goes as fast as it can.
    period: Option<Duration>,
    /// The source's `t` is the monotonic clock at capture (a board): the
    /// clock is then read at each arrival to place the capture.
    t_is_monotonic: bool,
    late_tolerance: f64,
    fallback_temp_c: Option<f64>,
    max_frames: Option<u64>,
    /// Whether the log was told that the estimator estimates the depth
    /// sensor's offset, and the attitude's pitch offset: once a run (the
    /// hypotheses of which sensor is off may hand the lead back and forth
    /// while they are weighed).
    offsets_said: [bool; 2],
    /// Spec v3: the demodulator of a source that gives bursts.
    demod: Option<Box<demod::Demod>>,
}

/// What the loop keeps from one frame to the next.
struct Books {
    /// (arrival, seq) that due times are counted from.
    anchor: Option<(Instant, u64)>,
    /// Gaps in seq, failures between frames and lone glitches.
    seq: SeqBooks,
    late_log: RateLog,
    fail_log: RateLog,
    lost_log: RateLog,
    glitch_log: RateLog,
    /// Estimators replaced (calibration reloads: at most one a second).
    reload_log: RateLog,
    /// The last failure's kind and place: STATUS's `last_error` is
    /// written when they change, not on every failed frame.
    failure: LastFailure,
    health_at: Instant,
    /// What the log was told of the source's skips.
    health_log: health::HealthLog,
}

/// What one attempt to acquire gave. The frame by value, on the stack:
/// boxing it would allocate per frame.
#[allow(clippy::large_enum_variant)]
enum Got {
    Frame(Acquired),
    /// A failed read, counted: try again.
    Retry,
    End(EndReason),
}

impl Engine {
    /// An engine on `source` with `estimator`, no inputs or outputs yet;
    /// deadlines at the source's own period, late after half a period.
    pub fn new(source: Box<dyn FrameSource>, estimator: Box<dyn Estimator>) -> Engine {
        let period = source.period();
        let t_is_monotonic = source.t_is_monotonic();
        // A source of bursts gets its demodulator here, so that no engine
        // runs one without; one its sampling cannot have (wiring refuses
        // such a config first) fails each frame, said in STATUS.
        let demod = source.sampling().map(|s| {
            let rate = source.rate_hz().unwrap_or(0.0);
            match demod::demodulator(&s, rate) {
                Ok(d) => Ok(Box::new(demod::Demod::new(d))),
                Err(e) => Err(e.to_string()),
            }
        });
        let demod = match demod {
            Some(Ok(d)) => Some(d),
            Some(Err(e)) => {
                tracing::error!("demodulator: {e}: every frame will fail");
                None
            }
            None => None,
        };
        Engine {
            demod,
            source,
            estimator,
            inputs: Vec::new(),
            outputs: Vec::new(),
            stats: Arc::new(Stats::default()),
            stop: Stop::new(),
            reload: None,
            period,
            t_is_monotonic,
            late_tolerance: 0.5,
            fallback_temp_c: None,
            max_frames: None,
            offsets_said: [false; 2],
        }
    }

    /// Counters to report from (shared with STATUS).
    pub fn stats(mut self, stats: Arc<Stats>) -> Self {
        self.stats = stats;
        self
    }
    /// The stop that ends the loop (raised by the supervisor); give the
    /// source the same one so that its waits end too.
    pub fn stop(mut self, stop: Stop) -> Self {
        self.stop = stop;
        self
    }
    pub fn input(mut self, input: Box<dyn Input>) -> Self {
        self.inputs.push(input);
        self
    }
    /// Outputs are handed each frame in the order they are added.
    pub fn output(mut self, output: Box<dyn Output>) -> Self {
        self.outputs.push(output);
        self
    }
    pub fn reload(mut self, rx: Receiver<Box<dyn Estimator>>) -> Self {
        self.reload = Some(rx);
        self
    }
    /// Deadlines at another period than the source's (`None`: none).
    pub fn period(mut self, period: Option<Duration>) -> Self {
        self.period = period;
        self
    }
    pub fn late_tolerance(mut self, fraction: f64) -> Self {
        self.late_tolerance = fraction;
        self
    }
    pub fn fallback_temp_c(mut self, t: Option<f64>) -> Self {
        self.fallback_temp_c = t;
        self
    }
    /// Stop after this many frames (benchmarks).
    pub fn max_frames(mut self, n: u64) -> Self {
        self.max_frames = Some(n);
        self
    }

    /// Run until stopped, the source ends, or `max_frames` frames.
    pub fn run(mut self) -> EndReason {
        let mut books = Books {
            anchor: None,
            seq: SeqBooks::default(),
            late_log: RateLog::new(),
            fail_log: RateLog::new(),
            lost_log: RateLog::new(),
            glitch_log: RateLog::new(),
            reload_log: RateLog::new(),
            failure: LastFailure::default(),
            health_at: Instant::now(),
            health_log: health::HealthLog::default(),
        };
        self.stats.set_state(BackendState::Running);
        let reason = loop {
            if let Some(end) = self.between_frames(&mut books) {
                break end;
            }
            let mut acq = match self.acquire(&mut books) {
                Got::Frame(a) => a,
                Got::Retry => continue,
                Got::End(end) => break end,
            };
            self.account_seq(&acq, &mut books);
            self.attach_inputs(&mut acq);
            let est = self.estimate(&acq.frame);
            let burst = self.demod.as_ref().and_then(|d| d.last_burst());
            for o in &mut self.outputs {
                if let Some(b) = burst {
                    o.raw(b);
                }
                o.emit(&acq, &est);
            }
            self.account_done(&acq, &est, Instant::now(), &mut books);
        };
        for o in &mut self.outputs {
            o.finish();
        }
        // The last STATUS shows the source's counters as they ended, and
        // the log is told what it was not yet: the skips, and the frame
        // events after their last line (at stop, whatever the step).
        self.copy_health(&mut books, true);
        self.close_logs(
            &mut books,
            Instant::now(),
            lightpose_core::ratelog::Close::AtStop,
        );
        if reason != EndReason::SourceEnded {
            self.stats.set_state(BackendState::Stopped);
        }
        reason
    }

    /// A sign of life for the watchdog, on the stop (whose waits in the
    /// source beat it too).
    fn beat(&self) {
        self.stop.beat();
    }

    /// Stop, frame budget, calibration reload, heartbeat and (once a
    /// second) the source's health.
    fn between_frames(&mut self, books: &mut Books) -> Option<EndReason> {
        if self.stop.is_raised() {
            return Some(EndReason::Stopped);
        }
        if self
            .max_frames
            .is_some_and(|m| self.stats.frames.load(Relaxed) >= m)
        {
            return Some(EndReason::FrameLimit);
        }
        // The newest of those waiting: one replaced per frame, reloads
        // faster than frames had piled up without bound (a SIGHUP storm,
        // 10 MB → 487 MB) and restarted the track at every frame.
        if let Some(mut e) = self.reload.as_ref().and_then(|rx| rx.try_iter().last()) {
            // A stuck channel or a DVL set up wrong is still so under the
            // new calibration (pipeline's model/findings.rs).
            let found = self.estimator.findings();
            if let Some(f) = &found {
                e.take_findings(f.as_ref());
            }
            if let Some(k) = books.reload_log.tick(Instant::now()) {
                tracing::info!(
                    replaced_since_last_line = k,
                    "calibration reloaded: estimator {} replaced{}",
                    e.name(),
                    if found.is_some() {
                        "; what it found of the hardware (stuck channels, the DVL's checks) kept"
                    } else {
                        ""
                    }
                );
            }
            self.estimator = e;
            // A new track: the autopilot is told (MAVLink reset_counter).
            self.outputs.iter_mut().for_each(|o| o.estimator_replaced());
            self.stats.calibration_reloads.fetch_add(1, Relaxed);
        }
        self.beat();
        if books.health_at.elapsed() >= Duration::from_secs(1) {
            // Once a second, not per frame: the copy allocates.
            books.health_at = Instant::now();
            self.copy_health(books, false);
            self.settle_logs(books, books.health_at);
        }
        None
    }

    /// The closing line of each kind of frame event whose condition is
    /// over (core's `RateLog::settle`: none for the step in force), with
    /// the events since its last line, at the level of its lines. Once a
    /// second between frames (with the health copy) is enough: the line
    /// comes at most a second after it is due. No allocation unless a
    /// line is written.
    fn settle_logs(&self, books: &mut Books, now: Instant) {
        self.close_logs(books, now, lightpose_core::ratelog::Close::Over);
    }

    /// The closing lines `when`: of the conditions over (`settle_logs`),
    /// or, at stop, of every kind with events not told yet (core's
    /// `RateLog::flush`), so that the journal's counts add up to the last
    /// STATUS's.
    fn close_logs(&self, books: &mut Books, now: Instant, when: lightpose_core::ratelog::Close) {
        let stats = &self.stats;
        let ago = |log: &RateLog| log.since_last(now).as_secs_f64();
        if let Some(k) = books.late_log.close(now, when) {
            tracing::warn!(
                late_total = stats.late.load(Relaxed),
                since_last_line = k,
                "late frames: {when}: {k} more since the last line, the last {:.1} s ago",
                ago(&books.late_log)
            );
        }
        if let Some(k) = books.fail_log.close(now, when) {
            tracing::warn!(
                failed_total = stats.failed.load(Relaxed),
                since_last_line = k,
                "failed frames: {when}: {k} more since the last line, the last {:.1} s ago",
                ago(&books.fail_log)
            );
        }
        if let Some(k) = books.lost_log.close(now, when) {
            tracing::warn!(
                lost_total = stats.lost.load(Relaxed),
                gaps_since_last_line = k,
                "seq gaps (frames lost at the source): {when}: {k} more since the last line, the last {:.1} s ago",
                ago(&books.lost_log)
            );
        }
        if let Some(k) = books.reload_log.close(now, when) {
            tracing::info!(
                replaced_since_last_line = k,
                "calibration reloaded: {when}: {k} more estimators replaced since the last line"
            );
        }
        if let Some(k) = books.glitch_log.close(now, when) {
            tracing::info!(
                lost_total = stats.lost.load(Relaxed),
                glitches_since_last_line = k,
                "lone seq glitches: {when}: {k} more since the last line, the last {:.1} s ago",
                ago(&books.glitch_log)
            );
        }
    }

    /// The source's health into STATUS, and a line in the log when the
    /// skips it counts (garbage or another board's lines on a serial port,
    /// a replayed log's glitches and malformed readings) grew: see
    /// [`health`]. Lines a board sent faster than frames take them
    /// (superseded) are no fault: said once when first seen, then only
    /// counted.
    fn copy_health(&self, books: &mut Books, at_exit: bool) {
        let new = self.source.health();
        let Ok(mut h) = self.stats.source_health.lock() else {
            return;
        };
        books
            .health_log
            .note(h.as_ref(), &new, Instant::now(), at_exit);
        if h.as_ref().map_or(0, |h| h.superseded_lines) == 0 && new.superseded_lines > 0 {
            tracing::info!(
                superseded_lines = new.superseded_lines,
                "serial board(s) send lines faster than frames take them: each frame takes a board's newest line, the others are counted (backend.health.superseded_lines) and not logged again"
            );
        }
        *h = Some(new);
        drop(h);
        if let (Some(d), Ok(mut g)) = (&self.demod, self.stats.demod.lock()) {
            d.report(&mut g);
        }
    }

    /// The next frame from the source; a failure is counted and logged,
    /// and after a dead bus (which fails at once) the loop pauses rather
    /// than spin a core on it.
    fn acquire(&mut self, books: &mut Books) -> Got {
        let got = self.take();
        let arrival = Instant::now();
        let mono_s = self.t_is_monotonic.then(lightpose_hal::clock::monotonic_s);
        let wall_unix = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        self.beat();
        let stats = &self.stats;
        match got {
            Ok(frame) => {
                if stats.state() != BackendState::Running {
                    stats.set_state(BackendState::Running);
                }
                // A board's `t` is the middle of its read: the readings and
                // the latency belong to that instant, not to the end of
                // the read (up to half a slow read later).
                let lag = mono_s.map_or(Duration::ZERO, |m| capture_lag(frame.t, m));
                Got::Frame(Acquired {
                    frame,
                    arrival,
                    capture: arrival.checked_sub(lag).unwrap_or(arrival),
                    wall_unix: wall_unix - lag.as_secs_f64(),
                })
            }
            // A wait the supervisor's stop ended: not a failure.
            Err(SourceError::Stopped) => Got::End(EndReason::Stopped),
            Err(SourceError::Ended) => {
                stats.set_state(BackendState::Ended);
                tracing::info!("source ended after {} frames", stats.frames.load(Relaxed));
                Got::End(EndReason::SourceEnded)
            }
            Err(e) => {
                let n = stats.failed.fetch_add(1, Relaxed) + 1;
                books.seq.failed();
                stats.set_state(BackendState::Failing);
                let new = books.failure.changed(&e);
                if let Some(k) = books.fail_log.tick(arrival) {
                    tracing::warn!(
                        failed_total = n,
                        since_last_line = k,
                        same_error = books.failure.count,
                        "frame failed: {e}"
                    );
                }
                if new {
                    if let Ok(mut g) = stats.last_error.lock() {
                        *g = Some(e.to_string());
                    }
                }
                if matches!(e, SourceError::Unavailable { .. }) {
                    let pause = self
                        .period
                        .unwrap_or(Duration::from_millis(10))
                        .min(Duration::from_millis(100));
                    self.stop.sleep(pause);
                }
                Got::Retry
            }
        }
    }

    /// The source's next frame: a burst demodulated when it gives bursts.
    fn take(&mut self) -> Result<Frame, SourceError> {
        let Some(d) = self.demod.as_mut() else {
            return self.source.next_frame();
        };
        d.taking();
        match self.source.next_take(&mut d.burst)? {
            Take::Frame(f) => Ok(f),
            Take::Burst => d.frame(),
        }
    }

    /// Frames the source skipped (a gap in seq, failures not counted
    /// again), and taken back when the frame claiming them was a lone
    /// glitch (see [`seq`]), as the log reader does.
    fn account_seq(&self, acq: &Acquired, books: &mut Books) {
        let seq = acq.frame.seq;
        let lost = &self.stats.lost;
        match books.seq.admit(seq) {
            Step::InLine => {}
            Step::Gap { from, lost: gap } => {
                // Only this thread writes `lost`; saturating, as a seq
                // near u64::MAX can claim nearly 2^64 frames.
                let n = lost.load(Relaxed).saturating_add(gap);
                lost.store(n, Relaxed);
                if let Some(k) = books.lost_log.tick(acq.arrival) {
                    tracing::warn!(
                        lost_total = n,
                        gaps_since_last_line = k,
                        "seq jumped {from} → {seq}: frames lost at the source"
                    );
                }
            }
            Step::Glitch {
                glitch,
                taken_back,
                lost: gap,
            } => {
                // Only this thread writes `lost`: what is taken back was
                // added by the frame before.
                let n = lost
                    .load(Relaxed)
                    .saturating_sub(taken_back)
                    .saturating_add(gap);
                lost.store(n, Relaxed);
                if let Some(k) = books.glitch_log.tick(acq.arrival) {
                    tracing::info!(
                        lost_total = n,
                        glitches_since_last_line = k,
                        "seq {glitch} was a lone glitch (seq {seq} is in line with the frame before it): the {taken_back} frames its jump counted lost are taken back"
                    );
                }
            }
        }
        self.stats.last_seq.store(seq, Relaxed);
    }

    /// Every input's reading that is fresh at the frame's capture onto it.
    fn attach_inputs(&mut self, acq: &mut Acquired) {
        for i in &mut self.inputs {
            i.attach(&mut acq.frame, acq.capture);
        }
        // What the recording will read back as, so that a replay of it
        // gives these poses bit for bit.
        lightpose_core::log::as_logged(&mut acq.frame);
        if acq.frame.attitude.is_some() {
            self.stats.frames_with_attitude.fetch_add(1, Relaxed);
        }
    }

    /// The estimate, with the fallback temperature when the frame has none.
    fn estimate(&mut self, frame: &Frame) -> PoseEstimate {
        let mut f = *frame;
        match (frame.temp_c, self.fallback_temp_c) {
            (Some(t), _) => self.stats.set_temp(Some(t), TempSource::Frame),
            (None, Some(fb)) => {
                f.temp_c = Some(fb);
                self.stats.set_temp(Some(fb), TempSource::Fallback);
            }
            (None, None) => self.stats.set_temp(None, TempSource::Missing),
        }
        let est = self.estimator.estimate(&f);
        let water = self.estimator.water_k_d();
        if let (Some(k), None) = (water, self.stats.water_k_d()) {
            // A bank told the doubt, or the tracker's water check finding
            // counts unlike the calibration's water (with a DVL).
            tracing::warn!(
                t = frame.t,
                "the estimator is learning the water (K_D {k:.3} m⁻¹ so far): STATUS water_k_d"
            );
        }
        self.stats.set_water_k_d(water);
        let depth = self.estimator.depth_offset();
        let pitch = self.estimator.pitch_offset_deg();
        let [d_said, p_said] = &mut self.offsets_said;
        for (said, now, what) in [
            (
                d_said,
                depth.map(|d| (d.0, "m")),
                "the depth sensor's offset",
            ),
            (
                p_said,
                pitch.map(|p| (p.0, "°")),
                "the attitude's pitch offset",
            ),
        ] {
            if let (Some((v, unit)), false) = (now, *said) {
                // Told in the calibration, or learned once the reading
                // check called a reading disagreeing.
                *said = true;
                tracing::info!(
                    t = frame.t,
                    "the estimator estimates {what} ({v:+.3} {unit} so far): STATUS estimator.depth_offset, pitch_offset"
                );
            }
        }
        self.stats.set_depth_offset(depth);
        self.stats.set_pitch_offset_deg(pitch);
        est
    }

    /// Latency (capture to done: what the autopilot's `VISO_DELAY_MS`
    /// must cover, less the link), counts, and the deadline: with a
    /// period, frame `seq` is due at `anchor + (seq − anchor_seq) ×
    /// period`, so that the frame after a dropped or failed one is judged
    /// by its own slot.
    fn account_done(&self, acq: &Acquired, est: &PoseEstimate, done: Instant, books: &mut Books) {
        let stats = &self.stats;
        stats
            .latency
            .record(done.saturating_duration_since(acq.capture));
        let si = est.status.index();
        stats.by_status[si].fetch_add(1, Relaxed);
        stats.last_status.store(si as u8, Relaxed);
        stats.frames.fetch_add(1, Relaxed);
        verdicts::count(stats, est, &acq.frame);

        let Some(p) = self.period else { return };
        let seq = acq.frame.seq;
        let (a_at, a_seq) = *books.anchor.get_or_insert((acq.arrival, seq));
        let Some((due, late_after)) =
            deadline(a_at, seq.saturating_sub(a_seq), p, self.late_tolerance)
        else {
            // A due time beyond the clock (a huge period or seq gap): not
            // judged; the frames after are judged from this one.
            books.anchor = Some((acq.arrival, seq));
            return;
        };
        if done > late_after {
            let n = stats.late.fetch_add(1, Relaxed) + 1;
            if let Some(k) = books.late_log.tick(done) {
                tracing::warn!(
                    late_total = n,
                    since_last_line = k,
                    "frame {seq} late by {:.1} ms (period {:.1} ms)",
                    (done - due).as_secs_f64() * 1e3,
                    p.as_secs_f64() * 1e3
                );
            }
            // Re-anchor on this frame: one stall counts once, not every
            // frame after it.
            books.anchor = Some((acq.arrival, seq));
        }
    }
}

/// When the frame `slots` periods `p` after `anchor` is due, and when it
/// is late; `None` when either is beyond the clock's range.
fn deadline(
    anchor: Instant,
    slots: u64,
    p: Duration,
    tolerance: f64,
) -> Option<(Instant, Instant)> {
    let due = anchor.checked_add(p.checked_mul(u32::try_from(slots).ok()?)?)?;
    let slack = Duration::try_from_secs_f64(p.as_secs_f64() * tolerance).ok()?;
    Some((due, due.checked_add(slack)?))
}

#[cfg(test)]
mod tests;
