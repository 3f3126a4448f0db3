//! MCP3008 (10-bit) and MCP3208 (12-bit), 8-channel SAR ADCs on SPI.
//!
//! One [`SpiDevice`] per chip: the chip select belongs to the device, so
//! several chips on one bus are several devices (spidev0.0, spidev0.1, ...).
//! Each conversion is one 3-byte full-duplex transfer, aligned so that the
//! result ends at the last bit of the last byte (datasheets, section 6.1
//! "Using the MCP3008/MCP3208 with microcontroller SPI ports").

use embedded_hal::spi::SpiDevice;

use super::DriverError;

/// Which of the two pin-compatible chips this is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum McpKind {
    Mcp3008,
    Mcp3208,
}

impl McpKind {
    pub const fn bits(self) -> u8 {
        match self {
            McpKind::Mcp3008 => 10,
            McpKind::Mcp3208 => 12,
        }
    }
    /// Largest SCLK the datasheet allows at VDD = 5 V (MCP3008: 3.6 MHz,
    /// MCP3208: 2 MHz); at 2.7 V both are lower ([`McpKind::low_supply_clock_hz`]).
    pub const fn max_clock_hz(self) -> u32 {
        match self {
            McpKind::Mcp3008 => 3_600_000,
            McpKind::Mcp3208 => 2_000_000,
        }
    }
    /// Largest SCLK at VDD = 2.7 V, the lowest supply (MCP3008: 1.35 MHz,
    /// MCP3208: 1 MHz): safe at any supply.
    pub const fn low_supply_clock_hz(self) -> u32 {
        match self {
            McpKind::Mcp3008 => 1_350_000,
            McpKind::Mcp3208 => 1_000_000,
        }
    }
    /// Largest SCLK at supply `vdd_v`. The datasheets give the limit at
    /// 2.7 V and at 5 V only; between them it is taken on the straight line
    /// through those two figures (an interpolation of ours, not a datasheet
    /// figure), at and above 5 V the 5 V figure. Without a known supply:
    /// the 2.7 V figure, right at any supply.
    pub fn clock_limit_hz(self, vdd_v: Option<f64>) -> u32 {
        let (lo, hi) = (self.low_supply_clock_hz(), self.max_clock_hz());
        let Some(v) = vdd_v.filter(|v| v.is_finite()) else {
            return lo;
        };
        let x = ((v - 2.7) / (5.0 - 2.7)).clamp(0.0, 1.0);
        (lo as f64 + x * (hi - lo) as f64).floor() as u32
    }
    pub const fn name(self) -> &'static str {
        match self {
            McpKind::Mcp3008 => "MCP3008",
            McpKind::Mcp3208 => "MCP3208",
        }
    }

    /// The 3 bytes that start a single-ended conversion of `ch` (0..8).
    ///
    /// MCP3008: start bit alone in byte 0, then SGL/DIFF=1, D2..D0 in the top
    /// nibble of byte 1. MCP3208: two more result bits, so the command is
    /// shifted left by 2: byte 0 = 0b0000_0 1 1 D2 (start, SGL, D2), byte 1 =
    /// D1 D0 in its top two bits.
    #[inline]
    pub const fn command(self, ch: u8) -> [u8; 3] {
        match self {
            McpKind::Mcp3008 => [0x01, 0x80 | (ch << 4), 0x00],
            McpKind::Mcp3208 => [0x06 | (ch >> 2), (ch & 0x03) << 6, 0x00],
        }
    }

    /// The result in the bytes clocked back during [`McpKind::command`]: the
    /// null bit and the top result bits at the bottom of byte 1, the rest in
    /// byte 2. Bits above them are undefined on the wire and are masked.
    #[inline]
    pub const fn decode(self, rx: [u8; 3]) -> u16 {
        match self {
            McpKind::Mcp3008 => (((rx[1] & 0x03) as u16) << 8) | rx[2] as u16,
            McpKind::Mcp3208 => (((rx[1] & 0x0F) as u16) << 8) | rx[2] as u16,
        }
    }
}

/// One MCP3008/MCP3208 on its own chip select.
#[derive(Debug)]
pub struct Mcp3x08<SPI> {
    spi: SPI,
    kind: McpKind,
}

impl<SPI: SpiDevice> Mcp3x08<SPI> {
    pub const CHANNELS: u8 = 8;

    pub fn new(spi: SPI, kind: McpKind) -> Self {
        Mcp3x08 { spi, kind }
    }
    pub fn kind(&self) -> McpKind {
        self.kind
    }
    /// Give the bus back (tests call `.done()` on their mock).
    pub fn release(self) -> SPI {
        self.spi
    }

    /// One single-ended conversion of channel `ch`.
    pub fn read_channel(&mut self, ch: u8) -> Result<u16, DriverError<SPI::Error>> {
        if ch >= Self::CHANNELS {
            return Err(DriverError::NoChannel {
                ch,
                max: Self::CHANNELS,
            });
        }
        let mut buf = self.kind.command(ch);
        self.spi
            .transfer_in_place(&mut buf)
            .map_err(DriverError::Bus)?;
        Ok(self.kind.decode(buf))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};

    fn xfer(tx: [u8; 3], rx: [u8; 3]) -> Vec<T<u8>> {
        vec![
            T::transaction_start(),
            T::transfer_in_place(tx.to_vec(), rx.to_vec()),
            T::transaction_end(),
        ]
    }

    #[test]
    fn mcp3008_command_bytes_for_every_channel() {
        // SGL=1 then D2 D1 D0: channel 5 = 0b1101 in the top nibble.
        assert_eq!(McpKind::Mcp3008.command(0), [0x01, 0x80, 0x00]);
        assert_eq!(McpKind::Mcp3008.command(5), [0x01, 0xD0, 0x00]);
        assert_eq!(McpKind::Mcp3008.command(7), [0x01, 0xF0, 0x00]);
    }

    #[test]
    fn mcp3208_command_bytes_for_every_channel() {
        // start, SGL, D2 | D1 D0 at the top of byte 1.
        assert_eq!(McpKind::Mcp3208.command(0), [0x06, 0x00, 0x00]);
        assert_eq!(McpKind::Mcp3208.command(3), [0x06, 0xC0, 0x00]);
        assert_eq!(McpKind::Mcp3208.command(4), [0x07, 0x00, 0x00]);
        assert_eq!(McpKind::Mcp3208.command(6), [0x07, 0x80, 0x00]);
    }

    #[test]
    fn mcp3008_reads_ten_bits_and_masks_the_undefined_ones() {
        let mut ex = xfer([0x01, 0x80, 0x00], [0xFF, 0xFE, 0x34]); // junk high bits
        ex.extend(xfer([0x01, 0xB0, 0x00], [0x00, 0x03, 0xFF]));
        ex.extend(xfer([0x01, 0xF0, 0x00], [0x00, 0x00, 0x00]));
        let mut adc = Mcp3x08::new(Mock::new(&ex), McpKind::Mcp3008);
        assert_eq!(adc.read_channel(0).unwrap(), 0x234);
        assert_eq!(adc.read_channel(3).unwrap(), 1023);
        assert_eq!(adc.read_channel(7).unwrap(), 0);
        adc.release().done();
    }

    #[test]
    fn mcp3208_reads_twelve_bits() {
        let mut ex = xfer([0x06, 0x40, 0x00], [0xFF, 0xFA, 0xBC]);
        ex.extend(xfer([0x07, 0xC0, 0x00], [0x00, 0x0F, 0xFF]));
        let mut adc = Mcp3x08::new(Mock::new(&ex), McpKind::Mcp3208);
        assert_eq!(adc.read_channel(1).unwrap(), 0xABC);
        assert_eq!(adc.read_channel(7).unwrap(), 4095);
        adc.release().done();
    }

    #[test]
    fn clock_limit_follows_the_supply() {
        let k = McpKind::Mcp3008;
        assert_eq!(k.clock_limit_hz(None), 1_350_000);
        assert_eq!(k.clock_limit_hz(Some(2.7)), 1_350_000);
        assert_eq!(k.clock_limit_hz(Some(5.0)), 3_600_000);
        assert_eq!(k.clock_limit_hz(Some(5.5)), 3_600_000);
        // 3.3 V: 1.35 + (0.6 / 2.3) · 2.25 MHz
        assert_eq!(k.clock_limit_hz(Some(3.3)), 1_936_956);
        let k = McpKind::Mcp3208;
        assert_eq!(k.clock_limit_hz(None), 1_000_000);
        assert_eq!(k.clock_limit_hz(Some(3.85)), 1_500_000);
        assert_eq!(k.clock_limit_hz(Some(5.0)), 2_000_000);
    }

    #[test]
    fn channel_out_of_range_touches_no_bus() {
        let mut adc = Mcp3x08::new(Mock::new(&[]), McpKind::Mcp3008);
        assert_eq!(
            adc.read_channel(8),
            Err(DriverError::NoChannel { ch: 8, max: 8 })
        );
        adc.release().done();
    }
}
