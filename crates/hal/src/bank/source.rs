//! [`BoardSource`]: one bank read (or burst) per frame, through the channel
//! map, with its sequence number, time, temperature and pacing.

use std::time::Duration;

use lightpose_core::{Frame, NDET};

use super::Bank;
use crate::chanmap::{ChannelMap, RawBoard, MAX_CH};
use crate::clock::monotonic_s;
use crate::pace::{Pacer, Stop};
use crate::temp::TempReader;
use crate::text::Text;
use crate::{FrameSource, Sampling, SourceError, SourceHealth, Take};
use lightpose_core::samples::Burst;

/// A [`FrameSource`] over a [`Bank`]: one bank read per frame.
/// How long before the end of its read a bank's own sampling time may be
/// and still be taken: a serial line older than this is not what the
/// board's stream promises (docs/serial-protocol.md: at least the frame
/// rate), and the middle of the read is used.
const MAX_SAMPLED_BEFORE_S: f64 = 1.0;

pub struct BoardSource<B> {
    bank: B,
    map: ChannelMap,
    wanted: Vec<u16>,
    raw: Vec<RawBoard>,
    temp: TempReader,
    pacer: Pacer,
    seq: u64,
    /// The last frame's `t`, which the next must pass.
    last_t: f64,
    bits: u8,
    describe: String,
    /// Spec v3: N samples of every channel a frame, given as bursts.
    sampling: Option<Sampling>,
    /// The (board, channel) of detectors 0..24 in turn, then a thermistor's
    /// channel the map does not use: a burst's conversion order.
    order: Vec<(usize, u8)>,
}

/// Of a burst's sample period, how late a sample may start and the burst
/// still be taken: later (the thread held up, a bus stalled) and its
/// samples are not at t + i / sample_hz, so the frame is dropped.
pub const MAX_LATE_SHARE: f64 = 0.25;
/// How long before a sample is due the wait stops sleeping and spins: a
/// sleep overshoots by tens of µs (more on a loaded machine), a spin by
/// the clock's read.
pub const SPIN_S: f64 = 2e-3;

/// Wait until `due` ([`monotonic_s`]): sleep while far, spin the last
/// [`SPIN_S`]. False when `stop` was raised.
fn wait_until(due: f64, stop: &Stop) -> bool {
    loop {
        if stop.is_raised() {
            return false;
        }
        let left = due - monotonic_s();
        if left <= 0.0 {
            return true;
        }
        if left > SPIN_S {
            // The stop's sleep: ends on a stop, and beats the heartbeat.
            if !stop.sleep(Duration::from_secs_f64(left - SPIN_S)) {
                return false;
            }
        } else {
            std::hint::spin_loop();
        }
    }
}

impl<B: Bank> BoardSource<B> {
    /// `map` must have been validated against `bank.boards()`.
    pub fn new(bank: B, map: ChannelMap, temp: TempReader, pacer: Pacer) -> Self {
        let n = bank.boards().len();
        let mut wanted = map.wanted(n);
        if let Some((b, ch)) = temp.needs_channel() {
            if let Some(w) = wanted.get_mut(b) {
                *w |= 1 << ch;
            }
        }
        let describe = match pacer.period() {
            Some(p) => format!("{} at {:.2} Hz", bank.describe(), 1.0 / p.as_secs_f64()),
            None => format!("{} free-running", bank.describe()),
        };
        let mut order: Vec<(usize, u8)> = (0..NDET).map(|k| map.source_of(k)).collect();
        if let Some((b, ch)) = temp.needs_channel() {
            if !order.contains(&(b, ch)) {
                order.push((b, ch));
            }
        }
        BoardSource {
            sampling: None,
            order,
            bits: bank.bits(),
            bank,
            map,
            wanted,
            raw: vec![[0; MAX_CH]; n],
            temp,
            pacer,
            seq: 0,
            last_t: f64::NEG_INFINITY,
            describe,
        }
    }

    /// Spec v3: read `s.samples_per_frame` samples of every channel a
    /// frame, `1 / s.sample_hz` apart, given by
    /// [`FrameSource::next_take`] as bursts (N = 1 is frames as before).
    pub fn with_sampling(mut self, s: Option<Sampling>) -> Self {
        self.sampling = s.filter(|s| s.samples_per_frame > 1 && s.sample_hz > 0.0);
        if let Some(s) = &self.sampling {
            self.describe = format!(
                "{}, {} samples a frame at {} Hz",
                self.describe, s.samples_per_frame, s.sample_hz
            );
        }
        self
    }

    pub fn bank(&self) -> &B {
        &self.bank
    }

    /// One burst into `burst`: sample i of every channel read at
    /// t + i / sample_hz (spun to), in detector order where the bank
    /// converts in order. A bus error, a stop or a sample started late
    /// drops the frame (its `seq` used up).
    fn read_burst(
        &mut self,
        n: usize,
        sample_hz: f64,
        burst: &mut Burst,
    ) -> Result<(), SourceError> {
        if burst.n() != n {
            burst.resize(n);
        }
        if self.bank.samples_itself() {
            return self.take_own_burst(n, burst);
        }
        if let Some(until) = self.pacer.due() {
            self.bank.idle(until, self.pacer.stop());
        }
        let seq = self.seq;
        self.seq += 1;
        let dt = 1.0 / sample_hz;
        let mut counts = [0u16; NDET];
        let t0 = monotonic_s();
        for i in 0..n {
            let due = t0 + i as f64 * dt;
            if !wait_until(due, self.pacer.stop()) {
                return Err(SourceError::Stopped);
            }
            // A long burst spins: the watchdog still hears the thread.
            self.pacer.stop().beat();
            if monotonic_s() - due > MAX_LATE_SHARE * dt {
                return Err(SourceError::BadData {
                    place: Text::from_static("board bank"),
                    msg: Text::from_static(
                        "a sample of the burst began over a quarter of its period late (the thread or the bus held up): frame dropped",
                    ),
                });
            }
            self.bank
                .read_in_order(&self.order, &self.wanted, &mut self.raw)?;
            self.map.apply(&self.raw, &mut counts);
            let samples = burst.samples_mut();
            for (k, &c) in counts.iter().enumerate() {
                samples[k * n + i] = c;
            }
        }
        self.stamp_burst(seq, t0, burst);
        Ok(())
    }
    /// A burst the boards sampled on their own clock: sample i of every
    /// channel through the map, `t` the first sample's time. The boards
    /// pace the frames: the pacer does not wait.
    fn take_own_burst(&mut self, n: usize, burst: &mut Burst) -> Result<(), SourceError> {
        let seq = self.seq;
        self.seq += 1;
        let t0 = self.bank.take_burst(&self.wanted)?;
        let mut counts = [0u16; NDET];
        for i in 0..n {
            self.bank.burst_sample(i, &mut self.raw);
            self.map.apply(&self.raw, &mut counts);
            let samples = burst.samples_mut();
            for (k, &c) in counts.iter().enumerate() {
                samples[k * n + i] = c;
            }
        }
        self.stamp_burst(seq, t0, burst);
        Ok(())
    }

    /// A burst's header: its `seq`, `t` (never back), ADC and temperature.
    fn stamp_burst(&mut self, seq: u64, t0: f64, burst: &mut Burst) {
        let t = t0.max(self.last_t + 1e-6);
        self.last_t = t;
        burst.seq = seq;
        burst.t = t;
        burst.adc_bits = self.bits;
        burst.temp_c = self.temp.for_frame(&self.raw);
        burst.truth = None;
        burst.attitude = None;
        burst.depth = None;
        burst.velocity = None;
    }

    pub fn into_bank(self) -> B {
        self.bank
    }
}

impl<B: Bank> FrameSource for BoardSource<B> {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        if self.sampling.is_some() {
            return Err(crate::bursts_only("board bank"));
        }
        if let Some(until) = self.pacer.due() {
            self.bank.idle(until, self.pacer.stop());
        }
        // A failed read still uses up its sequence number, so that the log
        // shows the lost frame as a gap.
        let seq = self.seq;
        self.seq += 1;
        // The frame's time is the middle of its read: the channels are
        // sampled one after another (or round by round) between its start
        // and its end, so the middle is the least wrong single time for all
        // of them, off by at most half the read (docs/hardware.md, "A
        // frame's time and its sampling skew"). Stamped before the read, a
        // slow bank (ADS1115 at a low data rate) put every frame up to a
        // whole read early. On the monotonic clock (seconds since boot),
        // not since the source was made: `t` is MAVLink's `usec`, which
        // must not start over when the daemon restarts (crate::clock).
        let begun = monotonic_s();
        self.bank.read(&self.wanted, &mut self.raw)?;
        let ended = monotonic_s();
        let mid = begun + (ended - begun).max(0.0) / 2.0;
        // A serial board's own sampling time where it is one (its line can
        // have waited in the buffer before the read began, not longer than
        // the lines' timeout allows), else the middle of the read; and
        // never back in time: a reader must see `t` increase.
        let t = self
            .bank
            .sampled_at()
            .filter(|s| s.is_finite() && *s <= ended && ended - *s <= MAX_SAMPLED_BEFORE_S)
            .unwrap_or(mid)
            .max(self.last_t + 1e-6);
        self.last_t = t;
        let mut counts = [0u16; NDET];
        self.map.apply(&self.raw, &mut counts);
        Ok(Frame {
            seq,
            t,
            adc_bits: self.bits,
            counts,
            temp_c: self.temp.for_frame(&self.raw),
            truth: None,
            attitude: None,
            depth: None,
            velocity: None,
            amplitudes: None,
        })
    }
    fn adc_bits(&self) -> u8 {
        self.bits
    }
    fn describe(&self) -> String {
        self.describe.clone()
    }
    fn t_is_monotonic(&self) -> bool {
        true
    }
    /// The pace it reads at: the daemon's deadlines (`late`) judge board
    /// frames too. Without it a bus stalled for seconds, or the process
    /// stopped, showed only as a dip in fps.
    fn period(&self) -> Option<Duration> {
        self.pacer.period()
    }
    fn sampling(&self) -> Option<Sampling> {
        self.sampling.clone()
    }
    fn next_take(&mut self, burst: &mut Burst) -> Result<Take, SourceError> {
        let Some((n, hz)) = self
            .sampling
            .as_ref()
            .map(|s| (s.samples_per_frame, s.sample_hz))
        else {
            return self.next_frame().map(Take::Frame);
        };
        self.read_burst(n, hz, burst).map(|()| Take::Burst)
    }
    fn health(&self) -> SourceHealth {
        let mut h = SourceHealth {
            temp: Some(self.temp.health().clone()),
            ..SourceHealth::default()
        };
        self.bank.health(&mut h);
        h
    }
}
