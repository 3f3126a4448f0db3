//! ADS1115: 16-bit, 4-channel delta-sigma ADC on I²C with a programmable
//! gain amplifier, up to 4 on one bus (addresses 0x48..=0x4B).
//!
//! Why not the `ads1x1x` crate: it selects channels by type (one type per
//! input), owns its bus (four chips on a bus would need a bus-sharing
//! wrapper) and polls through `nb`; a frame here picks channels from a
//! runtime map over many chips on one bus. The protocol is three register
//! accesses, so this driver does them directly and borrows the bus; the
//! tests script those accesses byte for byte (embedded-hal-mock), which a
//! wrapped crate would hide. (`ads1x1x` is therefore not a dependency.)
//!
//! Counts: the chip gives a signed 16-bit code, −32768..32767 over ±FSR.
//! Photodiode channels are single-ended (AINx against GND), where the code
//! can only be ≥ 0 save for offset noise near 0 V, so only 15 bits carry
//! information. The driver clamps negative codes to 0 and reports 15-bit
//! counts 0..32767 with V = counts / 32767 · FSR (the true LSB is FSR/32768;
//! the 3·10⁻⁵ relative difference is far below the light model's noise).
//! Frames from ADS1115 boards therefore have `adc_bits = 15`, so that the
//! frame's full scale is a count the chip can actually reach.

use embedded_hal::{delay::DelayNs, i2c::I2c};

use super::DriverError;

pub const ADDR_MIN: u8 = 0x48;
pub const ADDR_MAX: u8 = 0x4B;
pub const MAX_CLOCK_HZ: u32 = 3_400_000;
pub const CHANNELS: u8 = 4;
/// Resolution of the counts this driver returns (see the module comment).
pub const BITS: u8 = 15;

const REG_CONVERSION: u8 = 0x00;
const REG_CONFIG: u8 = 0x01;
/// OS bit: write 1 to start a single-shot conversion; reads 1 when idle.
const OS: u16 = 0x8000;

/// Full-scale range of the PGA (config bits 11:9).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fsr {
    V6_144 = 0,
    V4_096 = 1,
    V2_048 = 2,
    V1_024 = 3,
    V0_512 = 4,
    V0_256 = 5,
}

impl Fsr {
    pub fn from_volts(v: f64) -> Option<Fsr> {
        [
            Fsr::V6_144,
            Fsr::V4_096,
            Fsr::V2_048,
            Fsr::V1_024,
            Fsr::V0_512,
            Fsr::V0_256,
        ]
        .into_iter()
        .find(|f| (f.volts() - v).abs() < 1e-9)
    }
    pub fn volts(self) -> f64 {
        match self {
            Fsr::V6_144 => 6.144,
            Fsr::V4_096 => 4.096,
            Fsr::V2_048 => 2.048,
            Fsr::V1_024 => 1.024,
            Fsr::V0_512 => 0.512,
            Fsr::V0_256 => 0.256,
        }
    }
}

/// Data rate in samples per second (config bits 7:5).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataRate(u8);

impl DataRate {
    const SPS: [u16; 8] = [8, 16, 32, 64, 128, 250, 475, 860];
    pub fn from_sps(sps: u16) -> Option<DataRate> {
        Self::SPS
            .iter()
            .position(|&s| s == sps)
            .map(|i| DataRate(i as u8))
    }
    pub fn sps(self) -> u16 {
        Self::SPS[self.0 as usize]
    }
    /// Nominal conversion time plus the datasheet's 10 % rate tolerance.
    pub fn conversion_ns(self) -> u32 {
        (1.1e9 / self.sps() as f64).ceil() as u32
    }
}

/// Config register for a single-shot, single-ended conversion of `ch`:
/// OS=1, MUX=1 0 0+ch (AINch vs GND), PGA, MODE=1, DR, comparator off
/// (COMP_QUE = 11).
#[inline]
pub fn config_word(ch: u8, fsr: Fsr, dr: DataRate) -> u16 {
    OS | ((0b100 | ch as u16) << 12) | ((fsr as u16) << 9) | 0x0100 | ((dr.0 as u16) << 5) | 0x0003
}

/// Signed code to 15-bit single-ended counts (negative = below ground by
/// noise, i.e. 0).
#[inline]
pub fn code_to_counts(code: i16) -> u16 {
    code.max(0) as u16
}

/// I²C clocks one channel costs: the start (address, pointer, 2 config
/// bytes), one status poll and the result read (each address + pointer,
/// repeated START, address + 2 bytes): 14 bytes of 9 clocks, plus about 2
/// clocks for each of the 5 START / repeated START / STOP conditions.
pub const BUS_CLOCKS_PER_CHANNEL: u64 = 14 * 9 + 5 * 2;

/// How long a frame of these chips takes to read, in ns: `rounds`
/// conversions one after another (the bank starts the same slot on every
/// chip, so a frame takes as many conversions as the busiest chip has
/// channels) at the driver's 1.1/DR each, plus `channels` channels' bus
/// transfers at `scl_hz`, one at a time.
pub fn frame_read_ns(rounds: u32, channels: u32, dr: DataRate, scl_hz: u32) -> u64 {
    let convert = rounds as u64 * dr.conversion_ns() as u64;
    let bus =
        (channels as u64 * BUS_CLOCKS_PER_CHANNEL * 1_000_000_000).div_ceil(scl_hz.max(1) as u64);
    convert + bus
}

/// One ADS1115 at `address`.
#[derive(Debug, Clone, Copy)]
pub struct Ads1115 {
    address: u8,
    fsr: Fsr,
    dr: DataRate,
    /// Extra status polls after the nominal conversion time before giving up.
    pub max_polls: u32,
    /// A conversion may still be running: it was started and never seen
    /// done (a `NotReady`, or a frame given up between start and result).
    /// While the chip converts it ignores a start (OS = 1) but takes the
    /// new MUX, so a start now could give the old channel's result under
    /// the new channel; the next [`Ads1115::start`] first waits for OS = 1.
    busy: bool,
}

impl Ads1115 {
    pub fn new(address: u8, fsr: Fsr, dr: DataRate) -> Self {
        Ads1115 {
            address,
            fsr,
            dr,
            max_polls: 4,
            busy: false,
        }
    }
    pub fn address(&self) -> u8 {
        self.address
    }
    pub fn fsr(&self) -> Fsr {
        self.fsr
    }
    pub fn data_rate(&self) -> DataRate {
        self.dr
    }
    /// Whether a conversion may still be running (see [`Ads1115::start`]).
    pub fn busy(&self) -> bool {
        self.busy
    }

    /// Start a single-shot conversion of `ch` and return at once; the
    /// result comes from [`Ads1115::finish`] after `conversion_ns`. If an
    /// earlier conversion was never seen to end, poll until the chip is
    /// idle first (bounded: `NotReady` if it stays busy).
    pub fn start<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        delay: &mut D,
        ch: u8,
    ) -> Result<(), DriverError<I::Error>> {
        if ch >= CHANNELS {
            return Err(DriverError::NoChannel { ch, max: CHANNELS });
        }
        if self.busy {
            self.wait_idle(bus, delay)?;
        }
        let [hi, lo] = config_word(ch, self.fsr, self.dr).to_be_bytes();
        // Marked first: a write that failed may still have reached the chip.
        self.busy = true;
        bus.write(self.address, &[REG_CONFIG, hi, lo])
            .map_err(DriverError::Bus)
    }

    /// Poll until a conversion left running ends: about a conversion time
    /// and a half at most (a tenth of one between polls), longer than a
    /// conversion started just before can still take.
    fn wait_idle<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        delay: &mut D,
    ) -> Result<(), DriverError<I::Error>> {
        let mut polls = 0;
        while !self.ready(bus)? {
            polls += 1;
            if polls > 10 + self.max_polls {
                return Err(DriverError::NotReady { polls });
            }
            delay.delay_ns(self.dr.conversion_ns() / 10);
        }
        self.busy = false;
        Ok(())
    }

    /// Whether the conversion started last is done (OS reads back 1).
    pub fn ready<I: I2c>(&self, bus: &mut I) -> Result<bool, DriverError<I::Error>> {
        let mut rx = [0u8; 2];
        bus.write_read(self.address, &[REG_CONFIG], &mut rx)
            .map_err(DriverError::Bus)?;
        Ok(u16::from_be_bytes(rx) & OS != 0)
    }

    /// The signed result of the last conversion.
    pub fn result<I: I2c>(&self, bus: &mut I) -> Result<i16, DriverError<I::Error>> {
        let mut rx = [0u8; 2];
        bus.write_read(self.address, &[REG_CONVERSION], &mut rx)
            .map_err(DriverError::Bus)?;
        Ok(i16::from_be_bytes(rx))
    }

    /// After a start and its conversion time: poll until done, read,
    /// 15-bit counts. `NotReady` leaves the chip marked busy.
    pub fn finish<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        delay: &mut D,
    ) -> Result<u16, DriverError<I::Error>> {
        let mut polls = 0;
        while !self.ready(bus)? {
            polls += 1;
            if polls > self.max_polls {
                return Err(DriverError::NotReady { polls });
            }
            // a tenth of a conversion: the chip is late only by its clock error
            delay.delay_ns(self.dr.conversion_ns() / 10);
        }
        self.busy = false;
        Ok(code_to_counts(self.result(bus)?))
    }

    /// Start, wait one conversion time, poll until done, read: 15-bit counts.
    pub fn read_channel<I: I2c, D: DelayNs>(
        &mut self,
        bus: &mut I,
        delay: &mut D,
        ch: u8,
    ) -> Result<u16, DriverError<I::Error>> {
        self.start(bus, delay, ch)?;
        delay.delay_ns(self.dr.conversion_ns());
        self.finish(bus, delay)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::i2c::ErrorKind;
    use embedded_hal_mock::eh1::delay::NoopDelay;
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

    #[test]
    fn config_word_matches_the_datasheet() {
        let dr860 = DataRate::from_sps(860).unwrap();
        // AIN0 vs GND, ±4.096 V, single shot, 860 SPS, comparator off.
        assert_eq!(config_word(0, Fsr::V4_096, dr860), 0xC3E3);
        // AIN3, ±2.048 V (the chip's reset PGA), 128 SPS.
        assert_eq!(
            config_word(3, Fsr::V2_048, DataRate::from_sps(128).unwrap()),
            0xF583
        );
        assert_eq!(Fsr::from_volts(0.256), Some(Fsr::V0_256));
        assert_eq!(Fsr::from_volts(5.0), None);
        assert_eq!(DataRate::from_sps(100), None);
    }

    #[test]
    fn single_shot_polls_then_reads_and_clamps_negative_codes() {
        let dr = DataRate::from_sps(860).unwrap();
        let ex = [
            // channel 2: start, busy once, done, result 0x1234
            T::write(0x4A, vec![0x01, 0xE3, 0xE3]),
            T::write_read(0x4A, vec![0x01], vec![0x63, 0xE3]),
            T::write_read(0x4A, vec![0x01], vec![0xE3, 0xE3]),
            T::write_read(0x4A, vec![0x00], vec![0x12, 0x34]),
            // channel 1: done at once, slightly negative (offset noise) -> 0
            T::write(0x4A, vec![0x01, 0xD3, 0xE3]),
            T::write_read(0x4A, vec![0x01], vec![0xD3, 0xE3]),
            T::write_read(0x4A, vec![0x00], vec![0xFF, 0xF0]),
            // full scale
            T::write(0x4A, vec![0x01, 0xD3, 0xE3]),
            T::write_read(0x4A, vec![0x01], vec![0x80, 0x00]),
            T::write_read(0x4A, vec![0x00], vec![0x7F, 0xFF]),
        ];
        let mut bus = Mock::new(&ex);
        let mut adc = Ads1115::new(0x4A, Fsr::V4_096, dr);
        let mut d = NoopDelay::new();
        assert_eq!(adc.read_channel(&mut bus, &mut d, 2).unwrap(), 0x1234);
        assert_eq!(adc.read_channel(&mut bus, &mut d, 1).unwrap(), 0);
        assert_eq!(adc.read_channel(&mut bus, &mut d, 1).unwrap(), 32767);
        bus.done();
    }

    #[test]
    fn a_chip_that_never_finishes_is_an_error() {
        let dr = DataRate::from_sps(8).unwrap();
        let mut ex = vec![T::write(0x48, vec![0x01, 0xC3, 0x03])];
        let mut adc = Ads1115::new(0x48, Fsr::V4_096, dr);
        adc.max_polls = 2;
        for _ in 0..3 {
            ex.push(T::write_read(0x48, vec![0x01], vec![0x43, 0x03]));
        }
        let mut bus = Mock::new(&ex);
        let r = adc.read_channel(&mut bus, &mut NoopDelay::new(), 0);
        assert_eq!(r, Err(DriverError::NotReady { polls: 3 }));
        bus.done();
    }

    /// After a NotReady the conversion may still run: the next start polls
    /// OS until idle before it writes the new MUX (a start while busy would
    /// be ignored and the result be the old channel's).
    #[test]
    fn after_not_ready_the_next_start_waits_for_the_old_conversion() {
        let dr = DataRate::from_sps(860).unwrap();
        let busy = vec![0x43, 0xE3];
        let idle = vec![0xC3, 0xE3];
        let ex = [
            // channel 0: never done within max_polls = 1
            T::write(0x48, vec![0x01, 0xC3, 0xE3]),
            T::write_read(0x48, vec![0x01], busy.clone()),
            T::write_read(0x48, vec![0x01], busy.clone()),
            // channel 1: first the old conversion is waited out
            T::write_read(0x48, vec![0x01], busy.clone()),
            T::write_read(0x48, vec![0x01], idle.clone()),
            T::write(0x48, vec![0x01, 0xD3, 0xE3]),
            T::write_read(0x48, vec![0x01], idle.clone()),
            T::write_read(0x48, vec![0x00], vec![0x01, 0x00]),
            // and then a start goes straight out again
            T::write(0x48, vec![0x01, 0xE3, 0xE3]),
        ];
        let mut bus = Mock::new(&ex);
        let mut adc = Ads1115::new(0x48, Fsr::V4_096, dr);
        adc.max_polls = 1;
        let mut d = NoopDelay::new();
        assert_eq!(
            adc.read_channel(&mut bus, &mut d, 0),
            Err(DriverError::NotReady { polls: 2 })
        );
        assert!(adc.busy());
        assert_eq!(adc.read_channel(&mut bus, &mut d, 1), Ok(0x100));
        assert!(!adc.busy());
        adc.start(&mut bus, &mut d, 2).unwrap();
        assert!(adc.busy(), "started, not yet seen done");
        bus.done();
    }

    #[test]
    fn a_chip_that_stays_busy_is_not_started_again() {
        let dr = DataRate::from_sps(860).unwrap();
        let mut adc = Ads1115::new(0x48, Fsr::V4_096, dr);
        adc.max_polls = 0;
        let mut ex = vec![
            T::write(0x48, vec![0x01, 0xC3, 0xE3]),
            T::write_read(0x48, vec![0x01], vec![0x43, 0xE3]),
        ];
        // the idle wait: 10 + max_polls polls after the first, no start
        for _ in 0..11 {
            ex.push(T::write_read(0x48, vec![0x01], vec![0x43, 0xE3]));
        }
        let mut bus = Mock::new(&ex);
        let mut d = NoopDelay::new();
        assert!(adc.read_channel(&mut bus, &mut d, 0).is_err());
        assert_eq!(
            adc.start(&mut bus, &mut d, 1),
            Err(DriverError::NotReady { polls: 11 })
        );
        assert!(adc.busy());
        bus.done();
    }

    #[test]
    fn frame_read_time_counts_conversions_and_bus_clocks() {
        let dr = DataRate::from_sps(128).unwrap();
        assert_eq!(dr.conversion_ns(), 8_593_750);
        // 25 channels at 100 kHz: 136 clocks each = 34 ms of bus
        assert_eq!(frame_read_ns(0, 25, dr, 100_000), 34_000_000);
        // one after another (the old driver): 215 ms of conversions
        assert_eq!(frame_read_ns(25, 25, dr, 100_000), 248_843_750);
        // 7 chips started together, 4 rounds
        assert_eq!(frame_read_ns(4, 25, dr, 100_000), 68_375_000);
    }

    #[test]
    fn bus_error_on_result_read() {
        let dr = DataRate::from_sps(860).unwrap();
        let ex = [
            T::write(0x48, vec![0x01, 0xC3, 0xE3]),
            T::write_read(0x48, vec![0x01], vec![0xC3, 0xE3]),
            T::write_read(0x48, vec![0x00], vec![0, 0]).with_error(ErrorKind::Other),
        ];
        let mut bus = Mock::new(&ex);
        let mut adc = Ads1115::new(0x48, Fsr::V4_096, dr);
        let r = adc.read_channel(&mut bus, &mut NoopDelay::new(), 0);
        assert_eq!(r, Err(DriverError::Bus(ErrorKind::Other)));
        assert!(!adc.busy(), "OS read 1: the conversion is over");
        assert!(matches!(
            adc.start(&mut bus, &mut NoopDelay::new(), 4),
            Err(DriverError::NoChannel { ch: 4, max: 4 })
        ));
        bus.done();
    }
}
