//! ADC chips on one shared I²C bus (ADS7828, ADS1115): the bank starts the
//! same slot on every chip, waits once, then collects, so that chips which
//! convert on their own overlap their conversions.

use std::time::Duration;

use embedded_hal::{delay::DelayNs, i2c::I2c};

use super::{bus_error, channels_of, no_board, Bank, ChipPlaces};
use crate::chanmap::{BoardSpec, RawBoard, MAX_CH};
use crate::drivers::{ads1115::Ads1115, ads7828::Ads7828, DriverError};
use crate::text::{Recent, Text};
use crate::SourceError;

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
