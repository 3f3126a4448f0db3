//! Board-backed frame sources: a [`Bank`] of ADC boards read together, and
//! [`BoardSource`], which turns one bank read into one frame through the
//! channel map, with its sequence number, time, temperature and pacing.
//! Its frames' `t` is the machine's monotonic clock ([`crate::clock`]).
//!
//! Resolution: a bank is one kind of chip (the config's `kind`), so all
//! boards of a frame share one resolution and the frame's `adc_bits` is the
//! chip's (MCP3008 10, MCP3208 12, ADS7828 12, ADS1115 15 single-ended,
//! serial boards as configured and checked on every line). No rescaling,
//! so counts stay exactly what the ADC gave, as the calibration expects.

use std::time::{Duration, Instant};

use embedded_hal::{delay::DelayNs, i2c::I2c, spi::SpiDevice};
use lightpose_core::{Frame, NDET};

use crate::chanmap::{BoardSpec, ChannelMap, RawBoard, MAX_CH};
use crate::clock::monotonic_s;
use crate::drivers::{ads1115::Ads1115, ads7828::Ads7828, mcp3x08::Mcp3x08, DriverError};
use crate::pace::{Pacer, Stop};
use crate::temp::TempReader;
use crate::text::{Recent, Text};
use crate::{FrameSource, Sampling, SourceError, SourceHealth, Take};
use lightpose_core::samples::Burst;

/// A set of boards read together for each frame.
pub trait Bank: Send {
    /// Names and channel counts, in the order that `raw` is indexed.
    fn boards(&self) -> Vec<BoardSpec>;
    /// Resolution of every value this bank gives.
    fn bits(&self) -> u8;
    fn describe(&self) -> String;
    /// Read every channel whose bit is set in `wanted[board]` into
    /// `raw[board][channel]`. An error names the board and channel.
    fn read(&mut self, wanted: &[u16], raw: &mut [RawBoard]) -> Result<(), SourceError>;
    /// Read one sample of the (board, channel) pairs of `order` into
    /// `raw`, converting them one after another in that order where the
    /// bank can ([`Bank::converts_in_order`]); the others read `wanted`
    /// their own way (an ADS1115 bank's overlapped rounds).
    fn read_in_order(
        &mut self,
        order: &[(usize, u8)],
        wanted: &[u16],
        raw: &mut [RawBoard],
    ) -> Result<(), SourceError> {
        let _ = order;
        self.read(wanted, raw)
    }
    /// Whether [`Bank::read_in_order`] converts in the order given, one
    /// conversion after another: then channel k of a burst is converted
    /// k · channel_skew_s after channel 0, as MODEL.md assumes.
    fn converts_in_order(&self) -> bool {
        false
    }
    /// Add this bank's counters (skipped lines, reopens) to `h`.
    fn health(&self, _h: &mut SourceHealth) {}
    /// When the last read's values were sampled
    /// ([`crate::clock::monotonic_s`]), if the bank knows better than the
    /// middle of its read: a serial board's line was sampled before it was
    /// read, and the read mostly waits for it.
    fn sampled_at(&self) -> Option<f64> {
        None
    }
    /// Whether the boards sample on their own clock and send bursts (a
    /// serial bank in burst mode): a burst is then [`Bank::take_burst`]
    /// and [`Bank::burst_sample`], not reads paced here.
    fn samples_itself(&self) -> bool {
        false
    }
    /// Wait for the boards' next whole frame of samples (the channels of
    /// `wanted`) and take it; returns when its first sample was taken
    /// ([`crate::clock::monotonic_s`]).
    fn take_burst(&mut self, wanted: &[u16]) -> Result<f64, SourceError> {
        let _ = wanted;
        Err(no_board())
    }
    /// Sample `i` of the frame [`Bank::take_burst`] took, into `raw`.
    fn burst_sample(&self, i: usize, raw: &mut [RawBoard]) {
        let _ = (i, raw);
    }
    /// Wait until `until` (the next frame's time), ending early on `stop`.
    /// A bank that can use the time does (a serial bank stamps its boards'
    /// lines as they arrive); the others sleep.
    fn idle(&mut self, until: Instant, stop: &Stop) {
        stop.sleep_until(until);
    }
}

fn channels_of(mask: u16) -> impl Iterator<Item = u8> {
    (0..MAX_CH as u8).filter(move |c| mask & (1 << c) != 0)
}

/// The error of a chip's failure at `place`. Allocates nothing while the
/// failure repeats: the place is a clone, a bus error's words are built by
/// `recent` only when they change (formatting the bus's own error may
/// still allocate: an `io::Error`'s Debug builds its OS message).
fn bus_error<E: core::fmt::Debug>(
    place: &Text,
    e: DriverError<E>,
    recent: &mut Recent,
) -> SourceError {
    let place = place.clone();
    match e {
        DriverError::NotReady { .. } => SourceError::Timeout { place },
        // A channel the chip lacks is a wrong map, not a bus fault: a retry
        // cannot help.
        e @ DriverError::NoChannel { .. } => SourceError::BadData {
            place,
            msg: Text::format(format_args!("{e}")),
        },
        e @ DriverError::Bus(_) => SourceError::Bus {
            place,
            msg: recent.text(format_args!("{e}")),
        },
    }
}

/// Where each channel of a chip is, for its errors: "`chip` channel n",
/// built once when the bank is made, so that a failure clones one.
struct ChipPlaces {
    chip: Text,
    channels: Vec<Text>,
}

impl ChipPlaces {
    fn new(chip: String, channels: u8) -> Self {
        ChipPlaces {
            channels: (0..channels)
                .map(|ch| Text::from(format!("{chip} channel {ch}")))
                .collect(),
            chip: Text::from(chip),
        }
    }

    /// The place of channel `ch`; one the chip lacks (a map the config
    /// should have refused) is formatted on the spot.
    fn channel(&self, ch: u8) -> Text {
        match self.channels.get(ch as usize) {
            Some(p) => p.clone(),
            None => Text::format(format_args!("{} channel {ch}", self.chip)),
        }
    }
}

/// MCP3008/MCP3208 chips, each on its own chip select.
pub struct SpiBank<S> {
    chips: Vec<(String, Mcp3x08<S>)>,
    places: Vec<ChipPlaces>,
    recent: Recent,
}

impl<S: SpiDevice + Send> SpiBank<S> {
    pub fn new(chips: Vec<(String, Mcp3x08<S>)>) -> Self {
        let places = chips
            .iter()
            .map(|(name, c)| ChipPlaces::new(format!("board {name} ({})", c.kind().name()), 8))
            .collect();
        SpiBank {
            chips,
            places,
            recent: Recent::default(),
        }
    }
    /// Give the chips back (tests check their mocks).
    pub fn into_chips(self) -> Vec<(String, Mcp3x08<S>)> {
        self.chips
    }
}

impl<S: SpiDevice + Send> Bank for SpiBank<S> {
    fn boards(&self) -> Vec<BoardSpec> {
        self.chips
            .iter()
            .map(|(n, _)| BoardSpec {
                name: n.clone(),
                channels: 8,
            })
            .collect()
    }
    fn bits(&self) -> u8 {
        self.chips.first().map_or(10, |(_, c)| c.kind().bits())
    }
    fn describe(&self) -> String {
        let kind = self
            .chips
            .first()
            .map_or("MCP3x08", |(_, c)| c.kind().name());
        format!("{} x{} on SPI", kind, self.chips.len())
    }
    fn read(&mut self, wanted: &[u16], raw: &mut [RawBoard]) -> Result<(), SourceError> {
        for (b, ((_, chip), places)) in self.chips.iter_mut().zip(&self.places).enumerate() {
            let mask = wanted.get(b).copied().unwrap_or(0);
            for ch in channels_of(mask) {
                raw[b][ch as usize] = chip
                    .read_channel(ch)
                    .map_err(|e| bus_error(&places.channel(ch), e, &mut self.recent))?;
            }
        }
        Ok(())
    }
    /// Every MCP3x08 conversion is its own transfer, so any order costs
    /// the same bus time: a burst converts in detector order.
    fn read_in_order(
        &mut self,
        order: &[(usize, u8)],
        _: &[u16],
        raw: &mut [RawBoard],
    ) -> Result<(), SourceError> {
        for &(b, ch) in order {
            let (Some((_, chip)), Some(places), Some(out)) =
                (self.chips.get_mut(b), self.places.get(b), raw.get_mut(b))
            else {
                return Err(no_board());
            };
            out[ch as usize % MAX_CH] = chip
                .read_channel(ch)
                .map_err(|e| bus_error(&places.channel(ch), e, &mut self.recent))?;
        }
        Ok(())
    }
    fn converts_in_order(&self) -> bool {
        true
    }
}

/// A (board, channel) past the bank's boards: a map the config should have
/// refused.
fn no_board() -> SourceError {
    SourceError::BadData {
        place: Text::from_static("board bank"),
        msg: Text::from_static("the channel order names a board the bank does not have"),
    }
}

/// An ADC chip on a shared I²C bus, read in two steps so that chips which
/// convert on their own once started (ADS1115) overlap their conversions:
/// the bank starts the same slot (the n-th wanted channel) on every chip,
/// waits once, then collects them all.
pub trait I2cAdc: Send {
    const CHANNELS: u8;
    const BITS: u8;
    const NAME: &'static str;
    fn address(&self) -> u8;
    /// Start converting `ch`. A chip that converts while it is read
    /// (ADS7828) does the whole conversion here: `Some(counts)`. A chip
    /// that converts on its own (ADS1115) returns `None` at once, and its
    /// counts come from [`I2cAdc::collect`] after [`I2cAdc::conversion_ns`].
    fn start<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        delay: &mut D,
        ch: u8,
    ) -> Result<Option<u16>, DriverError<I::Error>>;
    /// How long a conversion `start` left running takes.
    fn conversion_ns(&self) -> u32 {
        0
    }
    /// The counts of the conversion `start` left running. Only called after
    /// a `start` that returned `None`.
    fn collect<I: I2c, D: DelayNs>(
        &mut self,
        _bus: &mut I,
        _delay: &mut D,
    ) -> Result<u16, DriverError<I::Error>> {
        Err(DriverError::NotReady { polls: 0 })
    }
    /// Set the chip up before its first frame; returns how long it then
    /// needs to settle (the bank waits once, for the slowest chip).
    fn warm_up<I: I2c>(&mut self, _bus: &mut I) -> Result<u32, DriverError<I::Error>> {
        Ok(0)
    }
}

impl I2cAdc for Ads7828 {
    const CHANNELS: u8 = crate::drivers::ads7828::CHANNELS;
    const BITS: u8 = 12;
    const NAME: &'static str = "ADS7828";
    fn address(&self) -> u8 {
        Ads7828::address(self)
    }
    fn start<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        _: &mut D,
        ch: u8,
    ) -> Result<Option<u16>, DriverError<I::Error>> {
        self.read_channel(bus, ch).map(Some)
    }
    /// The internal reference is off at power-up: turn it on and let it
    /// settle before the first frame.
    fn warm_up<I: I2c>(&mut self, bus: &mut I) -> Result<u32, DriverError<I::Error>> {
        self.power_up_reference(bus)
    }
}

impl I2cAdc for Ads1115 {
    const CHANNELS: u8 = crate::drivers::ads1115::CHANNELS;
    const BITS: u8 = crate::drivers::ads1115::BITS;
    const NAME: &'static str = "ADS1115";
    fn address(&self) -> u8 {
        Ads1115::address(self)
    }
    fn start<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        delay: &mut D,
        ch: u8,
    ) -> Result<Option<u16>, DriverError<I::Error>> {
        Ads1115::start(self, bus, delay, ch).map(|()| None)
    }
    fn conversion_ns(&self) -> u32 {
        self.data_rate().conversion_ns()
    }
    fn collect<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        delay: &mut D,
    ) -> Result<u16, DriverError<I::Error>> {
        self.finish(bus, delay)
    }
}

/// One chip of an [`I2cBank`]: its name and which bus it is on.
pub struct I2cSlot<C> {
    pub name: String,
    pub bus: usize,
    pub chip: C,
}

/// I²C ADCs of one kind on one or more buses (four ADS1115 per bus is 16
/// channels, so 25 detectors need two buses).
///
/// A frame is read in rounds: round n starts the n-th wanted channel of
/// every chip, waits once for the longest conversion left running, then
/// collects. Seven ADS1115 with 25 channels take 4 conversion times, not
/// 25; chips that convert while read (ADS7828) simply go slot by slot.
pub struct I2cBank<I, C, D> {
    buses: Vec<(String, I)>,
    chips: Vec<I2cSlot<C>>,
    delay: D,
    /// Per chip, the channel this round left converting, to collect (kept
    /// here so that a frame allocates nothing).
    pending: Vec<Option<u8>>,
    /// Per chip, where its errors happen (a failing frame allocates
    /// nothing either).
    places: Vec<ChipPlaces>,
    recent: Recent,
}

/// The `n`-th channel set in `mask`.
fn nth_channel(mask: u16, n: usize) -> Option<u8> {
    channels_of(mask).nth(n)
}

fn i2c_chip<C: I2cAdc>(slot: &I2cSlot<C>, bus_name: &str) -> String {
    format!(
        "board {} ({} 0x{:02X} on {bus_name})",
        slot.name,
        C::NAME,
        slot.chip.address()
    )
}

impl<I: I2c + Send, C: I2cAdc, D: DelayNs + Send> I2cBank<I, C, D> {
    /// `chips[i].bus` indexes `buses`; an index out of range is refused.
    pub fn new(buses: Vec<(String, I)>, chips: Vec<I2cSlot<C>>, delay: D) -> Result<Self, String> {
        if let Some(s) = chips.iter().find(|s| s.bus >= buses.len()) {
            return Err(format!("board {}: no bus {}", s.name, s.bus));
        }
        let places = chips
            .iter()
            .map(|s| ChipPlaces::new(i2c_chip(s, &buses[s.bus].0), C::CHANNELS))
            .collect();
        Ok(I2cBank {
            buses,
            pending: vec![None; chips.len()],
            chips,
            delay,
            places,
            recent: Recent::default(),
        })
    }
    pub fn into_buses(self) -> Vec<(String, I)> {
        self.buses
    }

    /// Set every chip up before the first frame (the ADS7828's internal
    /// reference is turned on) and wait once for the slowest to settle.
    pub fn warm_up(&mut self) -> Result<(), SourceError> {
        let mut settle = 0;
        for (slot, places) in self.chips.iter_mut().zip(&self.places) {
            let (_, bus) = &mut self.buses[slot.bus];
            // Once, at open: the place is built only if it fails.
            let ns = slot.chip.warm_up(bus).map_err(|e| {
                let place = Text::format(format_args!("{} warm-up", places.chip));
                bus_error(&place, e, &mut self.recent)
            })?;
            settle = settle.max(ns);
        }
        if settle > 0 {
            self.delay.delay_ns(settle);
        }
        Ok(())
    }

    /// Round `n`: start the `n`-th wanted channel of every chip, wait once,
    /// collect what is left running.
    fn round(&mut self, n: usize, wanted: &[u16], raw: &mut [RawBoard]) -> Result<(), SourceError> {
        let mut wait_ns = 0;
        for (b, slot) in self.chips.iter_mut().enumerate() {
            self.pending[b] = None;
            let Some(ch) = nth_channel(wanted.get(b).copied().unwrap_or(0), n) else {
                continue;
            };
            let (_, bus) = &mut self.buses[slot.bus];
            let started = slot
                .chip
                .start(bus, &mut self.delay, ch)
                .map_err(|e| bus_error(&self.places[b].channel(ch), e, &mut self.recent))?;
            match started {
                Some(v) => raw[b][ch as usize] = v,
                None => {
                    self.pending[b] = Some(ch);
                    wait_ns = wait_ns.max(slot.chip.conversion_ns());
                }
            }
        }
        if wait_ns > 0 {
            self.delay.delay_ns(wait_ns);
        }
        for (b, slot) in self.chips.iter_mut().enumerate() {
            let Some(ch) = self.pending[b] else {
                continue;
            };
            let (_, bus) = &mut self.buses[slot.bus];
            raw[b][ch as usize] = slot
                .chip
                .collect(bus, &mut self.delay)
                .map_err(|e| bus_error(&self.places[b].channel(ch), e, &mut self.recent))?;
        }
        Ok(())
    }
}

impl<I: I2c + Send, C: I2cAdc, D: DelayNs + Send> Bank for I2cBank<I, C, D> {
    fn boards(&self) -> Vec<BoardSpec> {
        self.chips
            .iter()
            .map(|s| BoardSpec {
                name: s.name.clone(),
                channels: C::CHANNELS,
            })
            .collect()
    }
    fn bits(&self) -> u8 {
        C::BITS
    }
    fn describe(&self) -> String {
        format!(
            "{} x{} on {} I2C bus(es)",
            C::NAME,
            self.chips.len(),
            self.buses.len()
        )
    }
    fn read(&mut self, wanted: &[u16], raw: &mut [RawBoard]) -> Result<(), SourceError> {
        let rounds = wanted
            .iter()
            .take(self.chips.len())
            .map(|m| m.count_ones() as usize)
            .max()
            .unwrap_or(0);
        for n in 0..rounds {
            self.round(n, wanted, raw)?;
        }
        Ok(())
    }
    /// Chips that convert while read (ADS7828) go in the order given, one
    /// conversion after another; chips that convert on their own (ADS1115)
    /// keep their overlapped rounds, whose channels are not evenly spaced.
    fn read_in_order(
        &mut self,
        order: &[(usize, u8)],
        wanted: &[u16],
        raw: &mut [RawBoard],
    ) -> Result<(), SourceError> {
        if !self.converts_in_order() {
            return self.read(wanted, raw);
        }
        for &(b, ch) in order {
            let (Some(slot), Some(places), Some(out)) =
                (self.chips.get_mut(b), self.places.get(b), raw.get_mut(b))
            else {
                return Err(no_board());
            };
            let (_, bus) = &mut self.buses[slot.bus];
            let v = slot
                .chip
                .start(bus, &mut self.delay, ch)
                .map_err(|e| bus_error(&places.channel(ch), e, &mut self.recent))?;
            // A chip that converts while read gives its counts at once.
            out[ch as usize % MAX_CH] = v.ok_or_else(|| {
                bus_error::<I::Error>(
                    &places.channel(ch),
                    DriverError::NotReady { polls: 0 },
                    &mut self.recent,
                )
            })?;
        }
        Ok(())
    }
    fn converts_in_order(&self) -> bool {
        self.chips.iter().all(|s| s.chip.conversion_ns() == 0)
    }
}

/// A [`DelayNs`] that sleeps the thread (std, any platform).
#[derive(Debug, Default, Clone, Copy)]
pub struct StdDelay;

impl DelayNs for StdDelay {
    fn delay_ns(&mut self, ns: u32) {
        std::thread::sleep(Duration::from_nanos(ns as u64));
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chanmap::ChannelMap;
    use crate::temp::TempKind;

    /// One board whose read takes `read` (a sleep).
    struct SlowBank {
        read: Duration,
    }

    impl Bank for SlowBank {
        fn boards(&self) -> Vec<BoardSpec> {
            vec![BoardSpec {
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
        fn read(&mut self, _: &[u16], _: &mut [RawBoard]) -> Result<(), SourceError> {
            std::thread::sleep(self.read);
            Ok(())
        }
    }

    /// CLOCK_MONOTONIC read here, not through the code under test.
    fn since_boot() -> f64 {
        let ts = nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC).unwrap();
        ts.tv_sec() as f64 + ts.tv_nsec() as f64 * 1e-9
    }

    fn slow_source(read: Duration) -> BoardSource<SlowBank> {
        BoardSource::new(
            SlowBank { read },
            ChannelMap::sequential(16),
            TempReader::new(TempKind::None, 0.0),
            Pacer::new(None),
        )
    }

    /// Audit: board frames had no period, so the daemon never judged them
    /// late (a 5 s stop showed only as fps). The pace read at is theirs.
    #[test]
    fn a_paced_board_source_has_its_period() {
        assert_eq!(slow_source(Duration::ZERO).period(), None);
        let paced = BoardSource::new(
            SlowBank {
                read: Duration::ZERO,
            },
            ChannelMap::sequential(16),
            TempReader::new(TempKind::None, 0.0),
            Pacer::from_rate(Some(20.0)),
        );
        assert_eq!(paced.period(), Some(Duration::from_millis(50)));
        assert_eq!(paced.rate_hz(), Some(20.0));
    }

    /// The middle of the read, on CLOCK_MONOTONIC (seconds since boot).
    #[test]
    fn a_frame_is_stamped_at_the_middle_of_its_read() {
        let read = Duration::from_millis(60);
        let mut src = slow_source(read);
        assert!(src.t_is_monotonic());
        let called = since_boot();
        let f = src.next_frame().unwrap();
        let returned = since_boot();
        // The read starts after `called` and ends before `returned`, and
        // lasts at least `read`: its middle is at least read / 2 after
        // `called` and read / 2 before `returned`.
        let half = read.as_secs_f64() / 2.0;
        let (lo, hi) = (called + half, returned - half);
        assert!(
            f.t >= lo - 1e-6 && f.t <= hi + 1e-6,
            "{lo} <= {} <= {hi}",
            f.t
        );
    }

    /// Audit: `t` counted from when the source was made, so every daemon
    /// restart started MAVLink's `usec` at 0 again. Two sources made 50 ms
    /// apart now stamp one timeline.
    #[test]
    fn sources_made_apart_stamp_one_timeline() {
        let read = Duration::from_millis(5);
        let mut a = slow_source(read);
        let fa = a.next_frame().unwrap();
        std::thread::sleep(Duration::from_millis(50));
        let mut b = slow_source(read);
        let fb = b.next_frame().unwrap();
        let now = since_boot();
        assert!(fb.t - fa.t >= 0.050, "{} then {}", fa.t, fb.t);
        assert!(fb.t <= now && now - fb.t < 10.0, "{} at {now}", fb.t);
        // And the first source goes on on the same timeline.
        let fa2 = a.next_frame().unwrap();
        assert!(fa2.t > fb.t, "{} after {}", fa2.t, fb.t);
    }

    #[test]
    fn a_channel_the_chip_lacks_is_bad_data_not_a_bus_error() {
        let r = &mut Recent::default();
        let e = bus_error(
            &"board u0 channel 9".into(),
            DriverError::<embedded_hal::i2c::ErrorKind>::NoChannel { ch: 9, max: 8 },
            r,
        );
        assert!(
            matches!(&e, SourceError::BadData { place, msg } if place == "board u0 channel 9" && msg.contains("no channel 9")),
            "{e:?}"
        );
        let e = bus_error(
            &"x".into(),
            DriverError::Bus(embedded_hal::i2c::ErrorKind::Other),
            r,
        );
        assert!(matches!(e, SourceError::Bus { .. }), "{e:?}");
        let e = bus_error(
            &"x".into(),
            DriverError::<embedded_hal::i2c::ErrorKind>::NotReady { polls: 3 },
            r,
        );
        assert!(matches!(e, SourceError::Timeout { .. }), "{e:?}");
    }
}
