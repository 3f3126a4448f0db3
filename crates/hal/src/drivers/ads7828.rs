//! ADS7828: 12-bit, 8-channel SAR ADC on I²C, up to 4 on one bus
//! (addresses 0x48..=0x4B from pins A1 A0).
//!
//! A conversion is: write the command byte, then read 2 bytes (the chip
//! converts while being addressed for reading). The driver holds no bus: the
//! methods borrow it, so several chips share one `I2c` without a bus-sharing
//! wrapper.

use embedded_hal::i2c::I2c;

use super::DriverError;

/// Lowest and highest 7-bit addresses (1 0 0 1 0 A1 A0).
pub const ADDR_MIN: u8 = 0x48;
pub const ADDR_MAX: u8 = 0x4B;
/// Datasheet maximum SCL in high-speed mode.
pub const MAX_CLOCK_HZ: u32 = 3_400_000;
pub const CHANNELS: u8 = 8;
/// How long the internal reference is given to settle after it is turned
/// on, before the first conversion that counts. The datasheet (SBAS181C,
/// "Reading with reference on/off") says the reference is off at power-up,
/// turns on at the STOP (or repeated START) after a command byte with
/// PD1 = 1, and must settle to reach 12-bit accuracy; it gives the time only
/// as a typical plot (Internal VREF vs Turn-On Time), which depends on the
/// REFIN/REFOUT capacitor and whose numbers were not at hand here. 10 ms is
/// a conservative choice, to be checked against that plot for the
/// capacitor fitted (a large one settles slower).
pub const REF_SETTLE_NS: u32 = 10_000_000;

/// Power-down selection PD1 PD0 (datasheet table 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PowerMode {
    /// 00: power down between conversions (external reference only; the
    /// internal one would need to settle again before every conversion).
    PowerDownBetween = 0b00,
    /// 01: internal reference off, converter on (external reference).
    ExternalRef = 0b01,
    /// 11: internal 2.5 V reference on, converter on.
    InternalRef = 0b11,
}

/// Command byte: SD C2 C1 C0 PD1 PD0 x x.
///
/// SD = 1 single-ended. The channel code is interleaved: even channels are
/// C2 = 0 and odd ones C2 = 1, with C1 C0 = ch / 2 (CH0 000, CH1 100, CH2
/// 001, CH3 101, ..., CH7 111; datasheet table 2).
#[inline]
pub const fn command(ch: u8, pd: PowerMode) -> u8 {
    0x80 | ((ch & 0x01) << 6) | ((ch >> 1) << 4) | ((pd as u8) << 2)
}

/// One ADS7828 at `address`.
#[derive(Debug, Clone, Copy)]
pub struct Ads7828 {
    address: u8,
    pd: PowerMode,
}

impl Ads7828 {
    pub fn new(address: u8, pd: PowerMode) -> Self {
        Ads7828 { address, pd }
    }
    pub fn address(&self) -> u8 {
        self.address
    }

    /// Turn the internal reference on: one conversion of channel 0 with
    /// PD = 11, its result discarded; the reference starts at that
    /// transaction's STOP and needs [`REF_SETTLE_NS`] before a conversion
    /// counts (the caller waits, once for all chips). Returns that time, or
    /// 0 without a bus transaction when the chip uses an external reference.
    pub fn power_up_reference<I: I2c>(&self, bus: &mut I) -> Result<u32, DriverError<I::Error>> {
        if self.pd != PowerMode::InternalRef {
            return Ok(0);
        }
        self.read_channel(bus, 0)?;
        Ok(REF_SETTLE_NS)
    }

    /// One single-ended conversion of `ch`; the top 4 bits the chip sends are
    /// zeros by the datasheet and masked anyway.
    pub fn read_channel<I: I2c>(&self, bus: &mut I, ch: u8) -> Result<u16, DriverError<I::Error>> {
        if ch >= CHANNELS {
            return Err(DriverError::NoChannel { ch, max: CHANNELS });
        }
        let mut rx = [0u8; 2];
        bus.write_read(self.address, &[command(ch, self.pd)], &mut rx)
            .map_err(DriverError::Bus)?;
        Ok((((rx[0] & 0x0F) as u16) << 8) | rx[1] as u16)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::i2c::ErrorKind;
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

    #[test]
    fn command_byte_uses_the_interleaved_channel_code() {
        let codes: Vec<u8> = (0..8)
            .map(|ch| (command(ch, PowerMode::PowerDownBetween) >> 4) & 0x07)
            .collect();
        assert_eq!(
            codes,
            vec![0b000, 0b100, 0b001, 0b101, 0b010, 0b110, 0b011, 0b111]
        );
        assert_eq!(command(0, PowerMode::InternalRef), 0x8C);
        assert_eq!(command(1, PowerMode::ExternalRef), 0xC4);
        assert_eq!(command(7, PowerMode::PowerDownBetween), 0xF0);
    }

    #[test]
    fn reads_twelve_bits_from_two_bytes() {
        let ex = [
            T::write_read(0x49, vec![0x8C], vec![0x0A, 0xBC]),
            T::write_read(0x49, vec![0xFC], vec![0xFF, 0xFF]),
            T::write_read(0x49, vec![0x9C], vec![0x00, 0x00]),
        ];
        let mut bus = Mock::new(&ex);
        let adc = Ads7828::new(0x49, PowerMode::InternalRef);
        assert_eq!(adc.read_channel(&mut bus, 0).unwrap(), 0xABC);
        assert_eq!(adc.read_channel(&mut bus, 7).unwrap(), 4095);
        assert_eq!(adc.read_channel(&mut bus, 2).unwrap(), 0);
        bus.done();
    }

    #[test]
    fn internal_reference_is_turned_on_by_a_discarded_conversion() {
        // PD = 11 in the command (0x8C), the result thrown away
        let ex = [T::write_read(0x4A, vec![0x8C], vec![0x0F, 0xFF])];
        let mut bus = Mock::new(&ex);
        let adc = Ads7828::new(0x4A, PowerMode::InternalRef);
        assert_eq!(adc.power_up_reference(&mut bus), Ok(REF_SETTLE_NS));
        // an external reference needs nothing
        let ext = Ads7828::new(0x4B, PowerMode::ExternalRef);
        assert_eq!(ext.power_up_reference(&mut bus), Ok(0));
        bus.done();
    }

    #[test]
    fn bus_error_is_returned_not_panicked() {
        let ex = [T::write_read(0x48, vec![0xC4], vec![0, 0]).with_error(ErrorKind::Other)];
        let mut bus = Mock::new(&ex);
        let adc = Ads7828::new(0x48, PowerMode::ExternalRef);
        assert_eq!(
            adc.read_channel(&mut bus, 1),
            Err(DriverError::Bus(ErrorKind::Other))
        );
        assert!(matches!(
            adc.read_channel(&mut bus, 9),
            Err(DriverError::NoChannel { ch: 9, .. })
        ));
        bus.done();
    }
}
