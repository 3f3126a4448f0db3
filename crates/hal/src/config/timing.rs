//! What a board bank can give: the time one sample of every wanted channel
//! takes, from the chips' clocks and the size of their transfers, and so
//! the highest sample rate it keeps up with and the spacing of its
//! channels' conversions (MODEL.md's `channel_skew_s`). A rate the bus
//! cannot give is refused at validation (`--check-config`), naming the
//! time and the rate that fits, rather than paced into frames whose `t`
//! and sample instants would be a lie.

use super::boards::Common;
use super::err;
use crate::drivers::ads1115::{self, DataRate};
use crate::HalError;
use lightpose_core::samples::MAX_SAMPLES_PER_FRAME;

/// The kernel's cost of one SPI transfer (a spidev ioctl) beyond its
/// clocks: tens of µs on a Raspberry Pi (docs/hardware.md); the lower end,
/// so that a bank the bus could serve is not refused.
pub const SPI_TRANSFER_OVERHEAD_S: f64 = 10e-6;
/// One MCP3x08 conversion: a 3-byte full-duplex transfer.
pub const MCP_CLOCKS_PER_CHANNEL: f64 = 24.0;
/// The kernel's cost of one I²C message beyond its clocks (two per
/// ADS7828 conversion: the command written, the result read).
pub const I2C_MESSAGE_OVERHEAD_S: f64 = 20e-6;
/// One ADS7828 conversion on the bus: start, address and command byte
/// (19 clocks), repeated start, address and two result bytes (29), stop.
pub const ADS7828_CLOCKS_PER_CHANNEL: f64 = 49.0;
/// The I²C clock assumed when a table does not give its `i2c_clock_hz`.
pub const DEFAULT_I2C_HZ: u32 = 100_000;
/// Share of a sample period the bank's read may take: above it the pacer
/// slips behind (the ADS1115's frame rule, now every board's).
pub const MAX_BUSY: f64 = 0.8;

/// One sample of every wanted channel, as the bank reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleTiming {
    /// From the first channel's conversion to the end of the read, s.
    pub read_s: f64,
    /// Between consecutive channels' conversions, s (MODEL.md
    /// `channel_skew_s`): the bank converts its channels one after another.
    pub channel_skew_s: f64,
}

impl SampleTiming {
    /// The highest sample rate this read keeps up with.
    pub fn max_sample_hz(&self) -> f64 {
        MAX_BUSY / self.read_s
    }
}

/// MCP3008/MCP3208 chips read one after another, each its wanted channels
/// in turn, one 24-clock transfer a channel at the chip's SCLK.
/// `chips` is (SCLK in Hz, wanted channels) per chip.
pub fn spi(chips: &[(u32, u32)]) -> Option<SampleTiming> {
    let per = |hz: u32| MCP_CLOCKS_PER_CHANNEL / f64::from(hz.max(1)) + SPI_TRANSFER_OVERHEAD_S;
    let read_s: f64 = chips.iter().map(|&(hz, n)| f64::from(n) * per(hz)).sum();
    in_turn(read_s, chips.iter().map(|c| c.1).sum())
}

/// ADS7828 chips, each channel a command written and a result read.
pub fn ads7828(channels: u32, scl_hz: u32) -> Option<SampleTiming> {
    let per = ADS7828_CLOCKS_PER_CHANNEL / f64::from(scl_hz.max(1)) + 2.0 * I2C_MESSAGE_OVERHEAD_S;
    in_turn(f64::from(channels) * per, channels)
}

/// ADS1115 chips: `rounds` conversions of 1.1/DR one after another (one
/// slot of every chip at once), every channel's transfers at `scl_hz`.
/// Its channels are not evenly spaced (a round's are converted together):
/// the skew given is the mean spacing.
pub fn ads1115(rounds: u32, channels: u32, dr: DataRate, scl_hz: u32) -> Option<SampleTiming> {
    let read_s = ads1115::frame_read_ns(rounds, channels, dr, scl_hz) as f64 * 1e-9;
    in_turn(read_s, channels)
}

fn in_turn(read_s: f64, channels: u32) -> Option<SampleTiming> {
    (channels > 0 && read_s > 0.0).then(|| SampleTiming {
        read_s,
        channel_skew_s: read_s / f64::from(channels),
    })
}

/// N = `sample_hz` / `rate_hz`, a whole number by MODEL.md's rule
/// (lightpose-core's, within 1e-9 relative), at most core's
/// `MAX_SAMPLES_PER_FRAME`; 1 without `sample_hz`. Needs a paced rate.
pub fn samples_per_frame(sample_hz: Option<f64>, rate_hz: Option<f64>) -> Result<u32, HalError> {
    let Some(hz) = sample_hz else { return Ok(1) };
    let Some(rate) = rate_hz else {
        return Err(err(
            "sample_hz",
            "needs a frame rate (rate_hz = 0 reads as fast as possible)",
        ));
    };
    let n = lightpose_core::modulation::samples_per_frame(hz, rate).map_err(|_| {
        err(
            "sample_hz",
            format!(
                "{} is not a whole multiple of rate_hz = {rate} (each frame holds the same number of samples of every channel)",
                lightpose_core::bounds::shown(hz)
            ),
        )
    })?;
    let most = MAX_SAMPLES_PER_FRAME as u64;
    if n > most {
        return Err(err(
            "sample_hz",
            format!("{hz} Hz is {n} samples a frame at {rate} Hz, over {most}"),
        ));
    }
    Ok(n as u32)
}

/// The bank keeps up with its sample rate (`sample_hz`, else `rate_hz`:
/// a frame of one sample); the channels' spacing is then known.
pub fn keeps_up(
    common: &mut Common,
    sample_hz: Option<f64>,
    t: Option<SampleTiming>,
    what: &str,
) -> Result<(), HalError> {
    let Some(t) = t else { return Ok(()) };
    common.channel_skew_s = t.channel_skew_s;
    let Some(rate) = common.rate_hz else {
        return Ok(());
    };
    let Some(hz) = sample_hz else {
        return fits("rate_hz", rate, &t, what);
    };
    fits("sample_hz", hz, &t, what)
}

/// Refuse a sample rate the bank's read cannot keep up with, at `key`
/// (`sample_hz`, or `rate_hz` when a frame is one sample), saying what
/// the read is made of (`what`) and the rate that fits.
pub fn fits(key: &str, hz: f64, t: &SampleTiming, what: &str) -> Result<(), HalError> {
    if hz * t.read_s <= MAX_BUSY {
        return Ok(());
    }
    Err(err(
        key,
        format!(
            "{hz} Hz: one sample of every channel takes {} ({what}), over {:.0} % of the {} period; at most {:.1} Hz fits",
            duration(t.read_s),
            MAX_BUSY * 100.0,
            duration(1.0 / hz),
            t.max_sample_hz()
        ),
    ))
}

/// A time in the unit that shows it best.
fn duration(s: f64) -> String {
    if s >= 0.1 {
        format!("{s:.2} s")
    } else if s >= 1e-3 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{:.1} µs", s * 1e6)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The example bank (docs/hardware.md): 25 channels on four MCP3008
    /// at 3.6 MHz: 25 × (6.7 µs of clocks + 10 µs) = 0.42 ms, so about
    /// 1.9 kHz of samples; at 1.35 MHz 25 × 27.8 µs = 0.69 ms, 1.15 kHz.
    #[test]
    fn the_example_spi_bank() {
        let t = spi(&[
            (3_600_000, 8),
            (3_600_000, 8),
            (3_600_000, 8),
            (3_600_000, 1),
        ])
        .unwrap();
        assert!((t.read_s - 25.0 * (24.0 / 3.6e6 + 10e-6)).abs() < 1e-12);
        assert!((t.channel_skew_s - t.read_s / 25.0).abs() < 1e-15);
        assert!(
            (1900.0..1930.0).contains(&t.max_sample_hz()),
            "{}",
            t.max_sample_hz()
        );
        let slow = spi(&[(1_350_000, 25)]).unwrap();
        assert!((1140.0..1160.0).contains(&slow.max_sample_hz()));
        assert!(fits("sample_hz", 1000.0, &slow, "x").is_ok());
        let e = fits("sample_hz", 2000.0, &slow, "25 transfers")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sample_hz")
                && e.contains("2000 Hz")
                && e.contains("694.4 µs")
                && e.contains("at most 1152.0 Hz"),
            "{e}"
        );
    }

    /// An I²C bank is far slower: 25 ADS7828 conversions at 400 kHz take
    /// 25 × (122.5 + 40) µs = 4.1 ms, under 200 samples a second.
    #[test]
    fn i2c_banks_cannot_sample_a_blinking_beacon() {
        let t = ads7828(25, 400_000).unwrap();
        assert!((t.read_s - 25.0 * (49.0 / 4e5 + 40e-6)).abs() < 1e-12);
        assert!(t.max_sample_hz() < 200.0);
        let dr = DataRate::from_sps(860).unwrap();
        let t = ads1115(4, 25, dr, 400_000).unwrap();
        assert!(t.max_sample_hz() < 100.0, "{}", t.max_sample_hz());
        assert!(spi(&[]).is_none() && ads7828(0, 100_000).is_none());
    }
}
