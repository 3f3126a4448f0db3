//! Whole frames from scripted buses: the channel map, the board order, a bus
//! error in the middle of a frame and the retry on the next frame.

mod common;

use common::{ads7828s, bare_source};
use embedded_hal::i2c::ErrorKind;
use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as DelayT};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as I2cT};
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiT};
use lightpose_core::NDET;
use lightpose_hal::bank::{BoardSource, I2cBank, I2cSlot, SpiBank};
use lightpose_hal::chanmap::{BoardSpec, ChannelMap, MapEntry};
use lightpose_hal::drivers::ads1115::{config_word, Ads1115, DataRate, Fsr};
use lightpose_hal::drivers::ads7828::{self, command, Ads7828, PowerMode};
use lightpose_hal::drivers::mcp3x08::{Mcp3x08, McpKind};
use lightpose_hal::pace::Pacer;
use lightpose_hal::temp::{TempKind, TempReader};
use lightpose_hal::{Bank, FrameSource, SourceError};

/// A mock SPI device that fails its `fail_at`-th transaction (0-based)
/// without consuming an expectation: the SPI mock cannot script errors.
struct FlakySpi {
    inner: SpiMock<u8>,
    calls: usize,
    fail_at: Option<usize>,
}

impl ErrorType for FlakySpi {
    type Error = embedded_hal::spi::ErrorKind;
}

impl SpiDevice for FlakySpi {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Self::Error> {
        let n = self.calls;
        self.calls += 1;
        if Some(n) == self.fail_at {
            return Err(embedded_hal::spi::ErrorKind::ModeFault);
        }
        self.inner
            .transaction(ops)
            .map_err(|_| embedded_hal::spi::ErrorKind::Other)
    }
}

/// Expectations for one MCP3008 reading `value` on `ch`.
fn mcp_read(ch: u8, value: u16) -> Vec<SpiT<u8>> {
    vec![
        SpiT::transaction_start(),
        SpiT::transfer_in_place(
            McpKind::Mcp3008.command(ch).to_vec(),
            vec![0, (value >> 8) as u8, value as u8],
        ),
        SpiT::transaction_end(),
    ]
}

/// Detector k wired to board k / 8, channel 7 − k % 8 (reversed, so that
/// the map is not the identity).
fn reversed_map() -> (Vec<MapEntry>, Vec<BoardSpec>) {
    let boards: Vec<BoardSpec> = (0..4)
        .map(|i| BoardSpec {
            name: format!("u{i}"),
            channels: 8,
        })
        .collect();
    let map = (0..NDET)
        .map(|k| MapEntry {
            r: k / 5,
            c: k % 5,
            board: format!("u{}", k / 8),
            channel: 7 - (k % 8) as u8,
        })
        .collect();
    (map, boards)
}

fn value_of(k: usize) -> u16 {
    (k as u16) * 40 + 3
}

/// The expected transactions of one frame for chip `b`: its used channels
/// in ascending channel order.
fn frame_script(b: usize) -> Vec<SpiT<u8>> {
    let mut ex = Vec::new();
    for ch in 0..8u8 {
        let k = b * 8 + (7 - ch as usize);
        if k < NDET {
            ex.extend(mcp_read(ch, value_of(k)));
        }
    }
    ex
}

#[test]
fn spi_frame_applies_the_map_and_recovers_after_a_mid_frame_bus_error() {
    let (map, boards) = reversed_map();
    let map = ChannelMap::new(&map, &boards).unwrap();
    // Frame 1 good; frame 2 fails on chip u2's third transfer; frame 3 good.
    let chips = (0..4)
        .map(|b| {
            let mut ex = frame_script(b);
            let per_frame = ex.len() / 3;
            let mut fail_at = None;
            if b == 2 {
                // frame 2: two good reads, then the failing one (not consumed),
                // and the rest of frame 2 is never asked for
                ex.extend(frame_script(b).into_iter().take(2 * 3));
                fail_at = Some(per_frame + 2);
            } else if b < 2 {
                ex.extend(frame_script(b));
            }
            ex.extend(frame_script(b));
            let spi = FlakySpi {
                inner: SpiMock::new(&ex),
                calls: 0,
                fail_at,
            };
            (format!("u{b}"), Mcp3x08::new(spi, McpKind::Mcp3008))
        })
        .collect();
    let bank = SpiBank::new(chips);
    assert_eq!(bank.bits(), 10);
    let mut src = BoardSource::new(
        bank,
        map,
        TempReader::new(TempKind::Fixed(18.5), 18.5),
        Pacer::new(None),
    );
    assert_eq!(src.adc_bits(), 10);
    assert!(src.describe().contains("MCP3008 x4"), "{}", src.describe());

    let f = src.next_frame().unwrap();
    assert_eq!(f.seq, 0);
    assert_eq!(f.adc_bits, 10);
    assert_eq!(f.temp_c, Some(18.5));
    let want: Vec<u16> = (0..NDET).map(value_of).collect();
    assert_eq!(f.counts.to_vec(), want);

    let e = src.next_frame().unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, SourceError::Bus { .. }), "{msg}");
    // chip u2 channels used: 0..=7 for k = 16..=23 → third read is channel 2
    assert!(
        msg.contains("board u2") && msg.contains("channel 2"),
        "{msg}"
    );

    let f3 = src.next_frame().unwrap();
    assert_eq!(f3.seq, 2, "the failed frame leaves a gap in seq");
    assert!(f3.t >= f.t);
    assert_eq!(f3.counts.to_vec(), want);

    for (_, chip) in src.into_bank().into_chips() {
        chip.release().inner.done();
    }
}

#[test]
fn ads7828_frame_over_one_bus_with_bus_error_mid_frame() {
    // four chips on one bus, detector k on chip k / 8 (0x48 + k/8), channel k % 8
    let map = ChannelMap::sequential(8);
    // The bank reads in rounds: channel n of every chip, then n + 1.
    let order: Vec<usize> = (0..8)
        .flat_map(|ch| (0..4).map(move |chip| chip * 8 + ch))
        .filter(|&k| k < NDET)
        .collect();
    let script = |fail_k: Option<usize>| {
        let mut ex = Vec::new();
        for &k in &order {
            let t = I2cT::write_read(
                0x48 + (k / 8) as u8,
                vec![command((k % 8) as u8, PowerMode::InternalRef)],
                vec![(value_of(k) >> 8) as u8, value_of(k) as u8],
            );
            if Some(k) == fail_k {
                ex.push(t.with_error(ErrorKind::NoAcknowledge(
                    embedded_hal::i2c::NoAcknowledgeSource::Address,
                )));
                break;
            }
            ex.push(t);
        }
        ex
    };
    let mut ex = script(None);
    ex.extend(script(Some(13)));
    ex.extend(script(None));
    let bus = I2cMock::new(&ex);
    let slots = ads7828s("adc", 4);
    let bank = I2cBank::new(vec![("/dev/i2c-1".into(), bus)], slots, NoopDelay::new()).unwrap();
    let mut src = bare_source(bank, map);
    let f = src.next_frame().unwrap();
    assert_eq!(f.adc_bits, 12);
    assert_eq!(f.temp_c, None);
    assert_eq!(
        f.counts.to_vec(),
        (0..NDET).map(value_of).collect::<Vec<_>>()
    );
    let msg = src.next_frame().unwrap_err().to_string();
    assert!(
        msg.contains("board adc1 (ADS7828 0x49 on /dev/i2c-1) channel 5"),
        "{msg}"
    );
    assert_eq!(src.next_frame().unwrap().seq, 2);
    for (_, mut b) in src.into_bank().into_buses() {
        b.done();
    }
}

/// One ADS1115 conversion as the bank does it: the start, and later its
/// poll (done) and result.
fn ads1115_start(addr: u8, ch: u8, dr: DataRate) -> I2cT {
    let cfg = config_word(ch, Fsr::V4_096, dr).to_be_bytes();
    I2cT::write(addr, vec![0x01, cfg[0], cfg[1]])
}
fn ads1115_collect(addr: u8, code: i16) -> Vec<I2cT> {
    vec![
        I2cT::write_read(addr, vec![0x01], vec![0x85, 0x83]),
        I2cT::write_read(addr, vec![0x00], code.to_be_bytes().to_vec()),
    ]
}

#[test]
fn ads1115_frame_across_two_buses_with_a_thermistor_channel() {
    // 7 chips: 4 on bus A, 3 on bus B; detector k on chip k / 4, channel k % 4.
    // Chip 6 channel 1 (unused by the map) carries a thermistor.
    let map = ChannelMap::sequential(4);
    let dr = DataRate::from_sps(860).unwrap();
    let chip = |i: usize| Ads1115::new(0x48 + (i % 4) as u8, Fsr::V4_096, dr);
    let code = |i: usize, ch: u8| {
        let k = i * 4 + ch as usize;
        if k < NDET {
            // detector 3 reads slightly negative: clamped to 0
            if k == 3 {
                -5
            } else {
                value_of(k) as i16 * 8
            }
        } else {
            16384 // thermistor at half of 4.096 V
        }
    };
    // Round n starts channel n on every chip that wants one (chip 6: 0, 1),
    // waits once, then collects them in the same order.
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut waits = Vec::new();
    for ch in 0..4u8 {
        let chips: Vec<usize> = (0..7).filter(|&i| i < 6 || ch < 2).collect();
        for &i in &chips {
            let ex = if i < 4 { &mut a } else { &mut b };
            ex.push(ads1115_start(0x48 + (i % 4) as u8, ch, dr));
        }
        for &i in &chips {
            let ex = if i < 4 { &mut a } else { &mut b };
            ex.extend(ads1115_collect(0x48 + (i % 4) as u8, code(i, ch)));
        }
        waits.push(DelayT::delay_ns(dr.conversion_ns()));
    }
    let buses = vec![
        ("/dev/i2c-1".to_string(), I2cMock::new(&a)),
        ("/dev/i2c-3".to_string(), I2cMock::new(&b)),
    ];
    let slots = (0..7)
        .map(|i| I2cSlot {
            name: format!("a{i}"),
            bus: usize::from(i >= 4),
            chip: chip(i),
        })
        .collect();
    let mut delay = CheckedDelay::new(&waits);
    let bank = I2cBank::new(buses, slots, delay.clone()).unwrap();
    let x = 16384.0 / 32767.0 * 4.096 / 3.3;
    let therm = lightpose_hal::temp::Thermistor {
        board: 6,
        channel: 1,
        // β = 3950, R0 = 10 kΩ at 25 °C, as Steinhart–Hart with C = 0
        a: 1.0 / 298.15 - 10_000f64.ln() / 3950.0,
        b: 1.0 / 3950.0,
        c: 0.0,
        r_fixed_ohm: 10_000.0 * (1.0 - x) / x,
        position: lightpose_hal::temp::ThermistorPosition::Low,
        v_supply: 3.3,
        v_ref: 4.096,
        bits: 15,
        min_c: -5.0,
        max_c: 45.0,
    };
    let mut src = BoardSource::new(
        bank,
        map,
        TempReader::new(TempKind::Thermistor(therm), 20.0),
        Pacer::new(None),
    );
    let f = src.next_frame().unwrap();
    assert_eq!(f.adc_bits, 15);
    assert_eq!(f.counts[3], 0);
    assert_eq!(f.counts[24], value_of(24) * 8);
    assert_eq!(f.counts[13], value_of(13) * 8);
    let t = f.temp_c.unwrap();
    assert!((t - 25.0).abs() < 1e-6, "{t}");
    assert!(!src.health().temp.unwrap().fallback_active);
    for (_, mut b) in src.into_bank().into_buses() {
        b.done();
    }
    // 4 waits of one conversion for 26 conversions on 7 chips
    delay.done();
}

/// A frame given up mid-round leaves other chips converting: on the next
/// frame each of them is polled until idle before its new start (a start
/// while busy is ignored by the chip but its MUX is taken).
#[test]
fn ads1115_chips_left_converting_by_a_failed_frame_are_waited_for() {
    let dr = DataRate::from_sps(860).unwrap();
    let idle = || I2cT::write_read(0x48, vec![0x01], vec![0x85, 0x83]);
    let mut ex = vec![
        // frame 1, round 0: both started, the first chip's poll fails
        ads1115_start(0x48, 0, dr),
        ads1115_start(0x49, 0, dr),
        I2cT::write_read(0x48, vec![0x01], vec![0, 0]).with_error(ErrorKind::Other),
        // frame 2, round 0: each chip waited for first
        idle(),
        ads1115_start(0x48, 0, dr),
        I2cT::write_read(0x49, vec![0x01], vec![0x05, 0x83]), // still busy
        I2cT::write_read(0x49, vec![0x01], vec![0x85, 0x83]),
        ads1115_start(0x49, 0, dr),
    ];
    ex.extend(ads1115_collect(0x48, 100));
    ex.extend(ads1115_collect(0x49, 200));
    for ch in 1..4u8 {
        ex.push(ads1115_start(0x48, ch, dr));
        ex.push(ads1115_start(0x49, ch, dr));
        ex.extend(ads1115_collect(0x48, 100 + ch as i16));
        ex.extend(ads1115_collect(0x49, 200 + ch as i16));
    }
    let slots = (0..2)
        .map(|i| I2cSlot {
            name: format!("a{i}"),
            bus: 0,
            chip: Ads1115::new(0x48 + i as u8, Fsr::V4_096, dr),
        })
        .collect();
    let bank = I2cBank::new(
        vec![("/dev/i2c-1".into(), I2cMock::new(&ex))],
        slots,
        NoopDelay::new(),
    )
    .unwrap();
    let mut src = bare_source(bank, ChannelMap::sequential(4));
    let e = src.next_frame().unwrap_err().to_string();
    assert!(
        e.contains("board a0 (ADS1115 0x48 on /dev/i2c-1) channel 0"),
        "{e}"
    );
    let f = src.next_frame().unwrap();
    assert_eq!(&f.counts[..8], &[100, 101, 102, 103, 200, 201, 202, 203]);
    for (_, mut b) in src.into_bank().into_buses() {
        b.done();
    }
}

#[test]
fn ads7828_internal_reference_is_turned_on_once_before_the_first_frame() {
    let ex = [
        I2cT::write_read(0x48, vec![0x8C], vec![0x00, 0x00]),
        I2cT::write_read(0x49, vec![0x8C], vec![0x00, 0x00]),
    ];
    // one wait for both chips
    warm_up_as_scripted(
        ads7828s("b", 2),
        &ex,
        &[DelayT::delay_ns(ads7828::REF_SETTLE_NS)],
    );
    // An external reference needs neither a command nor a wait.
    let slots = vec![I2cSlot {
        name: "b0".into(),
        bus: 0,
        chip: Ads7828::new(0x48, PowerMode::ExternalRef),
    }];
    warm_up_as_scripted(slots, &[], &[]);
}

/// Warms up a bank of `slots` on one bus: it makes exactly the `script`'s
/// transactions and the `waits`.
fn warm_up_as_scripted(slots: Vec<I2cSlot<Ads7828>>, script: &[I2cT], waits: &[DelayT]) {
    let mut delay = CheckedDelay::new(waits);
    let mut bank = I2cBank::new(
        vec![("/dev/i2c-1".into(), I2cMock::new(script))],
        slots,
        delay.clone(),
    )
    .unwrap();
    bank.warm_up().unwrap();
    for (_, mut b) in bank.into_buses() {
        b.done();
    }
    delay.done();
}

#[test]
fn i2c_bank_refuses_a_chip_on_a_missing_bus() {
    let slots = vec![I2cSlot {
        name: "x".into(),
        bus: 1,
        chip: Ads7828::new(0x48, PowerMode::ExternalRef),
    }];
    let mut m = I2cMock::new(&[]);
    let r = I2cBank::new(
        vec![("/dev/i2c-1".to_string(), m.clone())],
        slots,
        NoopDelay::new(),
    );
    assert_eq!(r.err().as_deref(), Some("board x: no bus 1"));
    m.done();
}
