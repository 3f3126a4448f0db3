//! What a serial bank in burst mode (spec v3, LPBST packets) must be to
//! give samples whose times are what the demodulator assumes, checked at
//! validation so that `--check-config` says it: the boards' scan spacing
//! (`channel_skew_s`) known and within a sample period, detector k the
//! k-th channel converted (MODEL.md: k · channel_skew_s after channel 0),
//! each board's line fast enough for its samples (the figure when not),
//! and a timeout longer than a frame.

use super::boards::{Common, SerialConfig};
use super::{err, timing::MAX_BUSY};
use crate::serial::burst::{bytes_per_sample, MAX_BLOCK};
use crate::serial::SerialBoard;
use crate::HalError;
use lightpose_core::bounds::shown;
use lightpose_core::NDET;

/// Bytes a second 8N1 moves at `baud`: 10 bits a byte.
pub fn line_bytes_per_s(baud: u32) -> f64 {
    f64::from(baud) / 10.0
}

/// The highest sample rate `baud` carries for a board of `channels`
/// channels of `bits` bits in packets of `block` samples, at most
/// [`MAX_BUSY`] of the line.
pub fn max_sample_hz(baud: u32, channels: u32, bits: u32, block: u32) -> f64 {
    MAX_BUSY * line_bytes_per_s(baud) / bytes_per_sample(channels, bits, block)
}

/// The burst-mode rules for `c`, and the channels' skew into `common`.
pub(super) fn check(
    c: &SerialConfig,
    boards: &[SerialBoard],
    common: &mut Common,
) -> Result<(), HalError> {
    let Some(hz) = common.sample_hz else {
        return Ok(());
    };
    if !(1..=MAX_BLOCK as u16).contains(&c.block_samples) {
        return Err(err(
            "block_samples",
            format!("{} is not in 1..={MAX_BLOCK}", c.block_samples),
        ));
    }
    let skew = match c.channel_skew_s {
        Some(s) if s.is_finite() && s >= 0.0 => s,
        Some(s) => return Err(err("channel_skew_s", format!("{s} is not a time >= 0 s"))),
        None => {
            return Err(err(
                "channel_skew_s",
                "needed with sample_hz: the time between two channels' conversions in the boards' scan (lpadc.ino SPACING_US; the demodulator places each channel's samples by it)",
            ))
        }
    };
    conversion_order(boards, common)?;
    let slots: u32 = boards.iter().map(|b| u32::from(b.channels)).sum();
    let scan = f64::from(slots) * skew;
    if scan > 1.0 / hz {
        return Err(err(
            "channel_skew_s",
            format!(
                "{} s apart, the boards' {slots} channels take {:.1} µs to scan, longer than a sample period ({:.1} µs at sample_hz = {}): the scans would overlap",
                shown(skew),
                scan * 1e6,
                1e6 / hz,
                shown(hz)
            ),
        ));
    }
    for b in boards {
        carries(b, hz, common.bits, c.block_samples)?;
    }
    if let Some(rate) = common.rate_hz {
        let frame_ms = 1e3 / rate;
        if (c.timeout_ms as f64) <= frame_ms {
            return Err(err(
                "timeout_ms",
                format!(
                    "{} ms is not longer than a frame ({frame_ms:.0} ms at rate_hz = {}): every burst would time out while the boards sample it",
                    c.timeout_ms,
                    shown(rate)
                ),
            ));
        }
    }
    common.channel_skew_s = skew;
    Ok(())
}

/// Detector k must be the k-th channel the boards convert: each board
/// converts its channels 0..C−1 on every sample tick, one board after
/// another in the config's order (lpadc.ino `FIRST_SLOT`), so board b's
/// channel c is slot Σ(channels before b) + c.
fn conversion_order(boards: &[SerialBoard], common: &Common) -> Result<(), HalError> {
    let mut first = Vec::with_capacity(boards.len());
    let mut at = 0usize;
    for b in boards {
        first.push(at);
        at += usize::from(b.channels);
    }
    for k in 0..NDET {
        let (b, ch) = common.map.source_of(k);
        let (Some(&f), Some(board)) = (first.get(b), boards.get(b)) else {
            continue;
        };
        let slot = f + usize::from(ch);
        if slot != k {
            return Err(err(
                "map",
                format!(
                    "bursts need detector k to be the k-th channel converted (MODEL.md: k · channel_skew_s after detector 0); detector {k} (r = {}, c = {}) is board {}'s channel {ch}, converted in slot {slot}: boards convert their channels in order, one board after another as listed (lpadc.ino FIRST_SLOT)",
                    k / 5,
                    k % 5,
                    board.name
                ),
            ));
        }
    }
    Ok(())
}

/// Board `b`'s line carries its samples at `hz`, refused at its baud with
/// the figures.
fn carries(b: &SerialBoard, hz: f64, bits: u8, block: u16) -> Result<(), HalError> {
    let (ch, bits32, block32) = (u32::from(b.channels), u32::from(bits), u32::from(block));
    let need = hz * bytes_per_sample(ch, bits32, block32);
    let have = line_bytes_per_s(b.baud);
    if need <= MAX_BUSY * have {
        return Ok(());
    }
    let most = max_sample_hz(b.baud, ch, bits32, block32);
    let baud_for = (need / MAX_BUSY * 10.0).ceil();
    Err(err(
        format!("boards.{}.baud", b.name),
        format!(
            "{} baud moves {have:.0} bytes/s; {} channels of {bits} bits at sample_hz = {} in packets of {block} samples need {need:.0} bytes/s, over {:.0} % of it: at most {most:.0} Hz fits, or a line of {baud_for:.0} baud or more (a native-USB board: docs/serial-protocol.md)",
            b.baud,
            b.channels,
            shown(hz),
            MAX_BUSY * 100.0
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bandwidth table of docs/serial-protocol.md: 16 channels of 12
    /// bits in packets of 16 samples are 24 + 14/16 bytes a sample.
    #[test]
    fn the_table_figures() {
        assert!((bytes_per_sample(16, 12, 16) - 24.875).abs() < 1e-12);
        let at = |baud| max_sample_hz(baud, 16, 12, 16);
        assert!((at(115_200) - 370.5).abs() < 0.1, "{}", at(115_200));
        assert!((at(921_600) - 2964.0).abs() < 0.1, "{}", at(921_600));
        // 2 kHz of 16 channels needs 460 800 < baud <= 921 600.
        assert!(at(460_800) < 2000.0 && at(921_600) > 2000.0);
    }
}
