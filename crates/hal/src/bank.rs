//! Board-backed frame sources: a [`Bank`] of ADC boards read together, and
//! [`BoardSource`], which turns one bank read into one frame through the
//! channel map, with its sequence number, time, temperature and pacing.
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
use crate::drivers::{ads1115::Ads1115, ads7828::Ads7828, mcp3x08::Mcp3x08, DriverError};
use crate::pace::Pacer;
use crate::temp::TempReader;
use crate::{FrameSource, SourceError, SourceHealth};

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
    /// Add this bank's counters (skipped lines, reopens) to `h`.
    fn health(&self, _h: &mut SourceHealth) {}
}

fn channels_of(mask: u16) -> impl Iterator<Item = u8> {
    (0..MAX_CH as u8).filter(move |c| mask & (1 << c) != 0)
}

fn bus_error<E: core::fmt::Debug>(
    place: impl FnOnce() -> String,
    e: DriverError<E>,
) -> SourceError {
    match e {
        DriverError::NotReady { .. } => SourceError::Timeout { place: place() },
        e => SourceError::Bus {
            place: place(),
            msg: e.to_string(),
        },
    }
}

/// MCP3008/MCP3208 chips, each on its own chip select.
pub struct SpiBank<S> {
    chips: Vec<(String, Mcp3x08<S>)>,
}

impl<S: SpiDevice + Send> SpiBank<S> {
    pub fn new(chips: Vec<(String, Mcp3x08<S>)>) -> Self {
        SpiBank { chips }
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
        for (b, (name, chip)) in self.chips.iter_mut().enumerate() {
            let mask = wanted.get(b).copied().unwrap_or(0);
            for ch in channels_of(mask) {
                raw[b][ch as usize] = chip.read_channel(ch).map_err(|e| {
                    bus_error(
                        || format!("board {name} ({}) channel {ch}", chip.kind().name()),
                        e,
                    )
                })?;
            }
        }
        Ok(())
    }
}

/// An ADC chip on a shared I²C bus.
pub trait I2cAdc: Send {
    const CHANNELS: u8;
    const BITS: u8;
    const NAME: &'static str;
    fn address(&self) -> u8;
    fn read<I: I2c, D: DelayNs>(
        &self,
        bus: &mut I,
        delay: &mut D,
        ch: u8,
    ) -> Result<u16, DriverError<I::Error>>;
}

impl I2cAdc for Ads7828 {
    const CHANNELS: u8 = crate::drivers::ads7828::CHANNELS;
    const BITS: u8 = 12;
    const NAME: &'static str = "ADS7828";
    fn address(&self) -> u8 {
        Ads7828::address(self)
    }
    fn read<I: I2c, D: DelayNs>(
        &self,
        bus: &mut I,
        _: &mut D,
        ch: u8,
    ) -> Result<u16, DriverError<I::Error>> {
        self.read_channel(bus, ch)
    }
}

impl I2cAdc for Ads1115 {
    const CHANNELS: u8 = crate::drivers::ads1115::CHANNELS;
    const BITS: u8 = crate::drivers::ads1115::BITS;
    const NAME: &'static str = "ADS1115";
    fn address(&self) -> u8 {
        Ads1115::address(self)
    }
    fn read<I: I2c, D: DelayNs>(
        &self,
        bus: &mut I,
        delay: &mut D,
        ch: u8,
    ) -> Result<u16, DriverError<I::Error>> {
        self.read_channel(bus, delay, ch)
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
pub struct I2cBank<I, C, D> {
    buses: Vec<(String, I)>,
    chips: Vec<I2cSlot<C>>,
    delay: D,
}

impl<I: I2c + Send, C: I2cAdc, D: DelayNs + Send> I2cBank<I, C, D> {
    /// `chips[i].bus` indexes `buses`; an index out of range is refused.
    pub fn new(buses: Vec<(String, I)>, chips: Vec<I2cSlot<C>>, delay: D) -> Result<Self, String> {
        if let Some(s) = chips.iter().find(|s| s.bus >= buses.len()) {
            return Err(format!("board {}: no bus {}", s.name, s.bus));
        }
        Ok(I2cBank {
            buses,
            chips,
            delay,
        })
    }
    pub fn into_buses(self) -> Vec<(String, I)> {
        self.buses
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
        for (b, slot) in self.chips.iter().enumerate() {
            let mask = wanted.get(b).copied().unwrap_or(0);
            let (bus_name, bus) = &mut self.buses[slot.bus];
            for ch in channels_of(mask) {
                raw[b][ch as usize] = slot.chip.read(bus, &mut self.delay, ch).map_err(|e| {
                    bus_error(
                        || {
                            format!(
                                "board {} ({} 0x{:02X} on {bus_name}) channel {ch}",
                                slot.name,
                                C::NAME,
                                slot.chip.address()
                            )
                        },
                        e,
                    )
                })?;
            }
        }
        Ok(())
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
pub struct BoardSource<B> {
    bank: B,
    map: ChannelMap,
    wanted: Vec<u16>,
    raw: Vec<RawBoard>,
    temp: TempReader,
    pacer: Pacer,
    start: Instant,
    seq: u64,
    bits: u8,
    describe: String,
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
        BoardSource {
            bits: bank.bits(),
            bank,
            map,
            wanted,
            raw: vec![[0; MAX_CH]; n],
            temp,
            pacer,
            start: Instant::now(),
            seq: 0,
            describe,
        }
    }

    pub fn bank(&self) -> &B {
        &self.bank
    }
    pub fn into_bank(self) -> B {
        self.bank
    }
}

impl<B: Bank> FrameSource for BoardSource<B> {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        self.pacer.wait();
        let t = self.start.elapsed().as_secs_f64();
        // A failed read still uses up its sequence number, so that the log
        // shows the lost frame as a gap.
        let seq = self.seq;
        self.seq += 1;
        self.bank.read(&self.wanted, &mut self.raw)?;
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
        })
    }
    fn adc_bits(&self) -> u8 {
        self.bits
    }
    fn describe(&self) -> String {
        self.describe.clone()
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
