//! The frame loop against test sources: deadlines, failures, inputs and
//! outputs, the stop.

use super::*;
use lightpose_core::{Angle, AttitudeReading, Status, NDET};
use std::sync::Mutex;

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
        Ok(frame(k, k as f64 * self.period.as_secs_f64()))
    }
    fn adc_bits(&self) -> u8 {
        10
    }
    fn describe(&self) -> String {
        "stalling test source".into()
    }
    fn period(&self) -> Option<Duration> {
        Some(self.period)
    }
}

fn frame(seq: u64, t: f64) -> Frame {
    Frame {
        seq,
        t,
        adc_bits: 10,
        counts: [100; NDET],
        temp_c: None,
        truth: None,
        attitude: None,
        depth: None,
        velocity: None,
        amplitudes: None,
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
    let source = Stalling {
        k: 0,
        start: None,
        period,
        stall_at: 10,
        stall: Duration::from_millis(200),
        fail_at: 20,
    };
    // Deadlines at the source's own period.
    let e = Engine::new(Box::new(source), Box::new(Nothing))
        .stats(stats.clone())
        // Generous: a loaded CI machine oversleeps by milliseconds.
        .late_tolerance(2.0)
        .fallback_temp_c(Some(12.0))
        .max_frames(30);
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

/// Numbered frames as fast as asked, `n` of them.
struct Counter(u64, u64);
impl FrameSource for Counter {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        if self.0 == self.1 {
            return Err(SourceError::Ended);
        }
        self.0 += 1;
        Ok(frame(self.0 - 1, (self.0 - 1) as f64 * 0.1))
    }
    fn adc_bits(&self) -> u8 {
        10
    }
    fn describe(&self) -> String {
        "counter".into()
    }
}

/// An input with a reading for even frames only.
struct EvenAttitude;
impl Input for EvenAttitude {
    fn attach(&mut self, f: &mut Frame, _now: Instant) {
        if f.seq.is_multiple_of(2) {
            f.attitude = Some(AttitudeReading {
                pitch: Angle::from_deg(1.0),
                yaw: Angle::ZERO,
                roll: None,
                std: None,
            });
        }
    }
}

/// (seq, has attitude, temperature, estimate's seq) of each frame.
type Kept = Arc<Mutex<Vec<(u64, bool, Option<f64>, u64)>>>;

/// An output that keeps what it was given.
struct Keep(Kept, Arc<AtomicBool>);
impl Output for Keep {
    fn emit(&mut self, a: &Acquired, est: &PoseEstimate) {
        let f = &a.frame;
        if let Ok(mut v) = self.0.lock() {
            v.push((f.seq, f.attitude.is_some(), f.temp_c, est.seq));
        }
    }
    fn finish(&mut self) {
        self.1.store(true, Relaxed);
    }
}
use std::sync::atomic::AtomicBool;

#[test]
fn inputs_attach_and_every_output_gets_each_frame_as_acquired() {
    let stats = Arc::new(Stats::default());
    let (a, b) = (
        Arc::new(Mutex::new(Vec::new())),
        Arc::new(Mutex::new(Vec::new())),
    );
    let (fa, fb) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicBool::new(false)),
    );
    let end = Engine::new(Box::new(Counter(0, 6)), Box::new(Nothing))
        .stats(stats.clone())
        .input(Box::new(EvenAttitude))
        .output(Box::new(Keep(a.clone(), fa.clone())))
        .output(Box::new(Keep(b.clone(), fb.clone())))
        .fallback_temp_c(Some(15.0))
        .run();
    assert_eq!(end, EndReason::SourceEnded);
    let got = a.lock().unwrap().clone();
    assert_eq!(got, *b.lock().unwrap(), "both outputs, same frames");
    let want: Vec<_> = (0..6).map(|s| (s, s % 2 == 0, None, s)).collect();
    // The fallback temperature is the estimator's, not the frame's.
    assert_eq!(got, want);
    assert!(fa.load(Relaxed) && fb.load(Relaxed), "outputs finished");
    assert_eq!(stats.frames_with_attitude.load(Relaxed), 3);
    assert_eq!(stats.frames.load(Relaxed), 6);
    assert_eq!(stats.state(), BackendState::Ended);
}

#[test]
fn a_raised_stop_ends_the_loop_and_a_dead_bus_pause() {
    struct Dead;
    impl FrameSource for Dead {
        fn next_frame(&mut self) -> Result<Frame, SourceError> {
            Err(SourceError::Unavailable {
                place: "test".into(),
                msg: "unplugged".into(),
            })
        }
        fn adc_bits(&self) -> u8 {
            10
        }
        fn describe(&self) -> String {
            "dead".into()
        }
    }
    let stop = Stop::new();
    let stats = Arc::new(Stats::default());
    // A long period: each failure pauses 100 ms unless stopped.
    let e = Engine::new(Box::new(Dead), Box::new(Nothing))
        .stats(stats.clone())
        .stop(stop.clone())
        .period(Some(Duration::from_secs(3600)));
    let t = std::thread::spawn(move || e.run());
    while stats.failed.load(Relaxed) < 2 {
        std::thread::sleep(Duration::from_millis(5));
    }
    let t0 = Instant::now();
    stop.raise();
    assert_eq!(t.join().unwrap(), EndReason::Stopped);
    assert!(t0.elapsed() < Duration::from_secs(2), "{:?}", t0.elapsed());
    assert_eq!(stats.state(), BackendState::Stopped);
}

/// Frames with the given seqs, then the end.
struct Seqs(Vec<u64>, usize);
impl FrameSource for Seqs {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        let k = self.1;
        self.1 += 1;
        match self.0.get(k) {
            Some(&s) => Ok(frame(s, k as f64 * 0.1)),
            None => Err(SourceError::Ended),
        }
    }
    fn adc_bits(&self) -> u8 {
        10
    }
    fn describe(&self) -> String {
        "seqs".into()
    }
}

/// Audit: one corrupt seq (500 for 4) counted 496 frames lost, though the
/// log reader takes its gap back as a lone glitch; a real gap still counts.
#[test]
fn a_lone_seq_glitch_loses_nothing_and_a_gap_still_counts() {
    let lost = |seqs: Vec<u64>| {
        let stats = Arc::new(Stats::default());
        let end = Engine::new(Box::new(Seqs(seqs, 0)), Box::new(Nothing))
            .stats(stats.clone())
            .run();
        assert_eq!(end, EndReason::SourceEnded);
        (stats.lost.load(Relaxed), stats.last_seq.load(Relaxed))
    };
    assert_eq!(lost(vec![0, 1, 2, 3, 500, 5, 6, 7]), (0, 7));
    assert_eq!(lost(vec![0, 1, 2, 3, 500, 9, 10]), (4, 10));
    assert_eq!(lost(vec![0, 1, 2, 6, 7]), (3, 7));
}

/// Audit: `lost` was added to unchecked: two claims of nearly 2^64 frames
/// (a seq stepping back, then to u64::MAX again) panicked in debug and
/// wrapped in release. It saturates.
#[test]
fn lost_frames_saturate_at_u64_max() {
    let stats = Arc::new(Stats::default());
    let seqs = vec![0, u64::MAX, 0, u64::MAX];
    let end = Engine::new(Box::new(Seqs(seqs, 0)), Box::new(Nothing))
        .stats(stats.clone())
        .run();
    assert_eq!(end, EndReason::SourceEnded);
    assert_eq!(stats.lost.load(Relaxed), u64::MAX);
    assert_eq!(stats.frames.load(Relaxed), 4);
}

/// Audit: the due time `anchor + period × slots` and its tolerance were
/// unchecked, and panicked ("overflow when adding duration to instant")
/// with a huge period or seq gap. Such frames are not judged late.
#[test]
fn a_due_time_beyond_the_clock_is_not_judged() {
    for (period, seqs) in [
        (Duration::from_secs(u64::MAX / 4), vec![0, 1, 2, 3]),
        (Duration::MAX, vec![0, 1]),
        (Duration::from_secs(3600), vec![0, 1 << 40, (1 << 40) + 1]),
    ] {
        let stats = Arc::new(Stats::default());
        let end = Engine::new(Box::new(Seqs(seqs.clone(), 0)), Box::new(Nothing))
            .stats(stats.clone())
            .period(Some(period))
            .run();
        assert_eq!(end, EndReason::SourceEnded, "{period:?}");
        assert_eq!(stats.frames.load(Relaxed), seqs.len() as u64);
        assert_eq!(stats.late.load(Relaxed), 0, "{period:?} {seqs:?}");
    }
    let now = Instant::now();
    let p = Duration::from_millis(20);
    assert_eq!(
        deadline(now, 3, p, 0.5),
        Some((now + 3 * p, now + 3 * p + p / 2))
    );
    assert_eq!(deadline(now, u64::from(u32::MAX) + 1, p, 0.5), None);
    assert_eq!(deadline(now, 1, p, f64::INFINITY), None);
}

/// Fails every frame, the same way.
struct Silent(u64);
impl FrameSource for Silent {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        if self.0 == 0 {
            return Err(SourceError::Ended);
        }
        self.0 -= 1;
        Err(if self.0 % 100 == 50 {
            SourceError::BadData {
                place: "board b".into(),
                msg: "odd".into(),
            }
        } else {
            SourceError::Timeout {
                place: "board a".into(),
            }
        })
    }
    fn adc_bits(&self) -> u8 {
        10
    }
    fn describe(&self) -> String {
        "silent".into()
    }
}

/// Audit: STATUS's `last_error` was formatted anew on every failed frame.
/// It is written when the failure changes in kind or place, and says the
/// latest one.
#[test]
fn the_last_error_is_written_when_it_changes() {
    let stats = Arc::new(Stats::default());
    let end = Engine::new(Box::new(Silent(120)), Box::new(Nothing))
        .stats(stats.clone())
        .run();
    assert_eq!(end, EndReason::SourceEnded);
    assert_eq!(stats.failed.load(Relaxed), 120);
    let last = stats.last_error.lock().unwrap().clone();
    // Frame 70 (of 120, counting down to 50) was the odd one out; the
    // timeouts after it are said again.
    assert_eq!(last.as_deref(), Some("board a: timed out waiting for data"));
}

/// An output that counts estimator replacements, noting the frames it had
/// seen when each came.
struct Replaced(Arc<Mutex<Vec<u64>>>, u64);
impl Output for Replaced {
    fn emit(&mut self, _: &Acquired, _: &PoseEstimate) {
        self.1 += 1;
    }
    fn estimator_replaced(&mut self) {
        if let Ok(mut v) = self.0.lock() {
            v.push(self.1);
        }
    }
}

#[test]
fn a_reload_tells_every_output_once_between_frames() {
    let (tx, rx) = std::sync::mpsc::channel::<Box<dyn Estimator>>();
    tx.send(Box::new(Nothing)).unwrap();
    let (a, b) = (
        Arc::new(Mutex::new(Vec::new())),
        Arc::new(Mutex::new(Vec::new())),
    );
    let stats = Arc::new(Stats::default());
    let end = Engine::new(Box::new(Counter(0, 4)), Box::new(Nothing))
        .stats(stats.clone())
        .reload(rx)
        .output(Box::new(Replaced(a.clone(), 0)))
        .output(Box::new(Replaced(b.clone(), 0)))
        .run();
    assert_eq!(end, EndReason::SourceEnded);
    assert_eq!(stats.calibration_reloads.load(Relaxed), 1);
    let (a, b) = (a.lock().unwrap().clone(), b.lock().unwrap().clone());
    assert_eq!(a.len(), 1, "{a:?}");
    assert_eq!(a, b, "both outputs, at the same frame");
}

/// One frame whose `t` is on the monotonic clock and `lag` behind it as it
/// is handed over (captured `lag` before its arrival); as it does, it
/// stores an attitude taken `age` before that into `hub` with a yaw rate
/// of 30 °/s, yaw −179°.
struct Lagging {
    hub: Arc<lightpose_vehicle::Hub>,
    lag: f64,
    age: Duration,
    done: bool,
}

impl FrameSource for Lagging {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        if std::mem::replace(&mut self.done, true) {
            return Err(SourceError::Ended);
        }
        let taken = Instant::now() - self.age;
        let t = lightpose_hal::clock::monotonic_s() - self.lag;
        self.hub.readings.store_attitude_with_rates(
            taken,
            &AttitudeReading::new(Angle::ZERO, Angle::from_deg(-179.0)),
            Some(lightpose_vehicle::AttitudeRates {
                pitch: 0.0,
                yaw: 30f64.to_radians(),
            }),
        );
        Ok(frame(0, t))
    }
    fn adc_bits(&self) -> u8 {
        10
    }
    fn describe(&self) -> String {
        "lagging".into()
    }
    fn t_is_monotonic(&self) -> bool {
        true
    }
}

/// (attitude's yaw in degrees, arrival − capture in seconds) per frame.
type Seen = Arc<Mutex<Vec<(Option<f64>, f64)>>>;
struct Watch(Seen);
impl Output for Watch {
    fn emit(&mut self, a: &Acquired, _: &PoseEstimate) {
        let yaw = a.frame.attitude.map(|r| r.yaw.deg());
        if let Ok(mut v) = self.0.lock() {
            v.push((yaw, (a.arrival - a.capture).as_secs_f64()));
        }
    }
}

/// What a `Lagging` source's frame was given.
fn lagging(lag: f64, age: Duration) -> (Option<f64>, f64) {
    let hub = lightpose_vehicle::Hub::new();
    let seen: Seen = Arc::default();
    let src = Lagging {
        hub: hub.clone(),
        lag,
        age,
        done: false,
    };
    let input = crate::inputs::vehicle::VehicleReadings {
        hub,
        max_age: lightpose_vehicle::MaxAge::default(),
    };
    let end = Engine::new(Box::new(src), Box::new(Nothing))
        .input(Box::new(input))
        .output(Box::new(Watch(seen.clone())))
        .run();
    assert_eq!(end, EndReason::SourceEnded);
    let v = seen.lock().unwrap().clone();
    assert_eq!(v.len(), 1);
    v[0]
}

/// Audit: readings were attached at the frame's arrival, though the frame
/// was captured up to half a slow read before, and ATTITUDE's rates were
/// dropped. A frame captured 150 ms before it arrived gets the attitude
/// as of its capture: one taken 100 ms before the arrival (50 ms after
/// the capture) carried back 50 ms at 30 °/s, across −180°.
#[test]
fn readings_are_attached_as_of_the_frame_capture() {
    let (yaw, lag) = lagging(0.150, Duration::from_millis(100));
    // At least 150 ms; more if the thread was preempted between the
    // frame's stamp and its arrival (a loaded CI machine).
    assert!(
        (0.150..0.250).contains(&lag),
        "captured {lag} s before arrival"
    );
    // −179° − 1.5° = −180.5° ≡ 179.5° (±0.3°: 10 ms of preemption at
    // 30 °/s)
    let yaw = yaw.expect("an attitude");
    assert!((yaw - 179.5).abs() < 0.3, "yaw {yaw}");
    // Taken 350 ms before the arrival: 200 ms before the capture, within
    // the 250 ms limit there (stale at the arrival), carried forward 0.2 s.
    let (yaw, _) = lagging(0.150, Duration::from_millis(350));
    let yaw = yaw.expect("fresh at the capture");
    assert!((yaw - (-173.0)).abs() < 0.3, "yaw {yaw}");
    // 300 ms before the capture: stale, rates or not.
    assert_eq!(lagging(0.150, Duration::from_millis(450)).0, None);
}

/// (carried yaw in degrees, attitude std) per frame, as the outputs see
/// it (the recording's frame).
type SeenStd = Arc<Mutex<Vec<(f64, Option<lightpose_core::AttitudeStd>)>>>;
struct WatchStd(SeenStd);
impl Output for WatchStd {
    fn emit(&mut self, a: &Acquired, _: &PoseEstimate) {
        if let (Some(r), Ok(mut v)) = (a.frame.attitude, self.0.lock()) {
            v.push((r.yaw.deg(), r.std));
        }
    }
}

/// Audit: MAVLink's ATTITUDE brings no std, so an attitude carried to the
/// capture went on with none and the estimator took its configured σ as
/// if the reading were taken then. With the hub told the estimator's σ
/// (as wiring does at start), the frame the outputs and the recording see
/// carries that σ widened by the carry: 0.2 s at 30 °/s here.
#[test]
fn a_carried_mavlink_attitude_goes_on_the_frame_with_the_assumed_sigma_widened() {
    let hub = lightpose_vehicle::Hub::new();
    hub.readings
        .assume_std(Some(crate::inputs::vehicle::assumed_std("tracker", None)));
    let seen: SeenStd = Arc::default();
    let src = Lagging {
        hub: hub.clone(),
        lag: 0.150,
        age: Duration::from_millis(350),
        done: false,
    };
    let input = crate::inputs::vehicle::VehicleReadings {
        hub,
        max_age: lightpose_vehicle::MaxAge::default(),
    };
    let end = Engine::new(Box::new(src), Box::new(Nothing))
        .input(Box::new(input))
        .output(Box::new(WatchStd(seen.clone())))
        .run();
    assert_eq!(end, EndReason::SourceEnded);
    let v = seen.lock().unwrap().clone();
    assert_eq!(v.len(), 1);
    let (yaw, std) = v[0];
    // How far it was carried, from the carried yaw (−179° at 30 °/s):
    // 0.2 s, more if the thread was preempted.
    let span = (yaw + 179.0) / 30.0;
    assert!((0.199..0.25).contains(&span), "carried {span} s");
    // σ² + q·Δ³/3 + (σ_ω·Δ)² (q = 20 (°/s²)²/Hz, σ_ω = 0.5 °/s) on the
    // tracker's 0.3° / 1.5°: at 0.2 s, 0.392° / 1.520°.
    let model = |s: f64| (s * s + 20.0 * span.powi(3) / 3.0 + (0.5 * span).powi(2)).sqrt();
    let std = std.expect("the assumed σ, widened");
    assert!((std.pitch.deg() - model(0.3)).abs() < 1e-6, "{std:?}");
    assert!((std.yaw.deg() - model(1.5)).abs() < 1e-6, "{std:?}");
    assert!(std.pitch.deg() > 0.39, "{std:?}");
}

#[test]
fn a_capture_lag_out_of_reason_is_bounded() {
    assert_eq!(capture_lag(99.85, 100.0), Duration::from_secs_f64(0.15));
    // t ahead of the clock, or not a number: captured on arrival.
    assert_eq!(capture_lag(100.5, 100.0), Duration::ZERO);
    assert_eq!(capture_lag(f64::NAN, 100.0), Duration::ZERO);
    // A t of another epoch (0 at start) read as monotonic: a second back.
    assert_eq!(capture_lag(0.0, 1e5), MAX_CAPTURE_LAG);
    assert_eq!(capture_lag(f64::NEG_INFINITY, 1e5), Duration::ZERO);
}

/// A bank whose read sleeps `read`.
struct SlowBank(Duration);
impl lightpose_hal::Bank for SlowBank {
    fn boards(&self) -> Vec<lightpose_hal::chanmap::BoardSpec> {
        vec![lightpose_hal::chanmap::BoardSpec {
            name: "slow".into(),
            channels: 16,
        }]
    }
    fn bits(&self) -> u8 {
        12
    }
    fn describe(&self) -> String {
        "slow".into()
    }
    fn read(
        &mut self,
        _: &[u16],
        _: &mut [lightpose_hal::chanmap::RawBoard],
    ) -> Result<(), SourceError> {
        std::thread::sleep(self.0);
        Ok(())
    }
}

/// Audit: STATUS latency counted from the frame's arrival and left out
/// half the read, though README sizes ArduSub's VISO_DELAY_MS from it. A
/// board frame read in 100 ms is captured in its middle: its latency is
/// at least 50 ms.
#[test]
fn latency_counts_from_the_capture_and_includes_half_the_read() {
    use lightpose_hal::{pace::Pacer, temp::TempKind, temp::TempReader};
    let read = Duration::from_millis(100);
    let src = lightpose_hal::BoardSource::new(
        SlowBank(read),
        lightpose_hal::ChannelMap::sequential(16),
        TempReader::new(TempKind::None, 0.0),
        Pacer::new(None),
    );
    let stats = Arc::new(Stats::default());
    let seen: Seen = Arc::default();
    let end = Engine::new(Box::new(src), Box::new(Nothing))
        .stats(stats.clone())
        .output(Box::new(Watch(seen.clone())))
        .max_frames(3)
        .run();
    assert_eq!(end, EndReason::FrameLimit);
    let p50 = stats.latency.quantile(0.5).expect("latency");
    // Half the read, not more than that and a loaded machine's delays.
    assert!((0.050..0.5).contains(&p50), "latency p50 {p50} s");
    for (_, lag) in seen.lock().unwrap().iter() {
        assert!(
            (0.050..0.5).contains(lag),
            "captured {lag} s before arrival"
        );
    }
}

/// Fails `fails` times at once, then a frame every 10 ms.
struct FailsFirst {
    fails: u64,
    seq: u64,
}
impl FrameSource for FailsFirst {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        if self.fails > 0 {
            self.fails -= 1;
            return Err(SourceError::Timeout {
                place: "board a".into(),
            });
        }
        std::thread::sleep(Duration::from_millis(10));
        self.seq += 1;
        Ok(frame(self.seq, self.seq as f64 * 0.01))
    }
    fn adc_bits(&self) -> u8 {
        10
    }
    fn describe(&self) -> String {
        "fails first".into()
    }
}

/// The journal of a run whose first 30 frames fail, ended after
/// `frames` frames (30 failures counted).
fn burst_of_30_failures(frames: u64) -> String {
    let stats = Arc::new(Stats::default());
    let text = lightpose_testkit::logs::logged(|| {
        let end = Engine::new(
            Box::new(FailsFirst { fails: 30, seq: 0 }),
            Box::new(Nothing),
        )
        .stats(stats.clone())
        .max_frames(frames)
        .run();
        assert_eq!(end, EndReason::FrameLimit);
    });
    assert_eq!(stats.failed.load(Relaxed), 30);
    text
}

/// A burst of 30 failures: the first is said at once; the 29 after it
/// were never told (the journal's count stopped at 1 while STATUS said
/// 30). Once none came for the step in force (1 s), the closing line
/// tells them, at the failures' level, within a second more.
#[test]
fn the_end_of_a_burst_of_failures_is_told() {
    let text = burst_of_30_failures(260);
    let failed: Vec<&str> = text.lines().filter(|l| l.contains("failed")).collect();
    assert_eq!(failed.len(), 2, "{text}");
    assert!(failed[0].contains("since_last_line=1"), "{text}");
    assert!(
        failed[1].contains("WARN")
            && failed[1].contains("failed_total=30")
            && failed[1]
                .contains("failed frames: the condition is over: 29 more since the last line"),
        "{text}"
    );
}

/// A burst of 30 failures whose end the stop cuts (the source ends 50 ms
/// later, before the 1 s step): the 29 after the first line were never
/// told. At stop they are, in one line at the failures' level, and the
/// journal's counts add up to STATUS's.
#[test]
fn a_burst_cut_by_the_stop_is_told_at_stop() {
    let text = burst_of_30_failures(5);
    let failed: Vec<&str> = text.lines().filter(|l| l.contains("failed")).collect();
    assert_eq!(failed.len(), 2, "{text}");
    assert!(failed[0].contains("since_last_line=1"), "{text}");
    assert!(
        failed[1].contains("WARN")
            && failed[1].contains("failed_total=30")
            && failed[1].contains("since_last_line=29")
            && failed[1].contains("failed frames: at stop: 29 more since the last line"),
        "{text}"
    );
    assert!(!text.contains("the condition is over"), "{text}");
}
