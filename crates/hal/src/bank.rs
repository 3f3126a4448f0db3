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

use std::time::Instant;

use crate::chanmap::{BoardSpec, RawBoard, MAX_CH};
use crate::drivers::DriverError;
use crate::pace::Stop;
use crate::text::{Recent, Text};
use crate::{SourceError, SourceHealth};

mod i2c;
mod source;
mod spi;
#[cfg(test)]
mod tests;

pub use i2c::{I2cAdc, I2cBank, I2cSlot, StdDelay};
pub use source::{BoardSource, MAX_LATE_SHARE, SPIN_S};
pub use spi::SpiBank;

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

/// A (board, channel) past the bank's boards: a map the config should have
/// refused.
fn no_board() -> SourceError {
    SourceError::BadData {
        place: Text::from_static("board bank"),
        msg: Text::from_static("the channel order names a board the bank does not have"),
    }
}
