//! Spec v3: board banks read bursts (N samples of every channel a frame,
//! 1 / sample_hz apart) into the caller's `Burst`. Scripted transactions
//! (embedded-hal-mock, each ending in `.done()`) show the conversions: an
//! MCP3008 bank in detector order through the channel map, an ADS1115
//! bank in its overlapped rounds, a bus error mid-burst dropping only its
//! frame.

use std::sync::{Arc, Mutex};

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use embedded_hal_mock::eh1::delay::{CheckedDelay, Transaction as DelayT};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as I2cT};
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiT};
use lightpose_core::samples::{BeaconInfo, Burst};
use lightpose_core::NDET;
use lightpose_hal::bank::{BoardSource, I2cBank, I2cSlot, SpiBank};
use lightpose_hal::chanmap::{BoardSpec, ChannelMap, MapEntry};
use lightpose_hal::drivers::ads1115::{config_word, Ads1115, DataRate, Fsr};
use lightpose_hal::drivers::mcp3x08::{Mcp3x08, McpKind};
use lightpose_hal::pace::Pacer;
use lightpose_hal::temp::{TempKind, TempReader};
use lightpose_hal::{FrameSource, Sampling, SourceError, Take};

/// Samples a frame in these tests, and their rate: 25 ms apart, so that a
/// loaded test machine does not start a sample late.
const N: usize = 4;
const SAMPLE_HZ: f64 = 40.0;

fn sampling(skew: f64) -> Option<Sampling> {
    Some(Sampling {
        sample_hz: SAMPLE_HZ,
        samples_per_frame: N,
        channel_skew_s: skew,
        beacons: vec![BeaconInfo {
            id: "beacon".into(),
            mod_hz: 10.0,
        }],
    })
}

/// Sample `i` of detector `k`.
fn value(k: usize, i: usize) -> u16 {
    (k * 40 + i * 7 + 3) as u16
}

/// An MCP3008 on a mock that logs which chip each transaction went to
/// (the order across chips) and fails its `fail_at`-th transaction
/// (0-based) without consuming an expectation.
struct LoggedSpi {
    inner: SpiMock<u8>,
    chip: usize,
    log: Arc<Mutex<Vec<usize>>>,
    calls: usize,
    fail_at: Option<usize>,
}

impl ErrorType for LoggedSpi {
    type Error = embedded_hal::spi::ErrorKind;
}

impl SpiDevice for LoggedSpi {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Self::Error> {
        let n = self.calls;
        self.calls += 1;
        if Some(n) == self.fail_at {
            return Err(embedded_hal::spi::ErrorKind::ModeFault);
        }
        if let Ok(mut l) = self.log.lock() {
            l.push(self.chip);
        }
        self.inner
            .transaction(ops)
            .map_err(|_| embedded_hal::spi::ErrorKind::Other)
    }
}

fn mcp_read(ch: u8, v: u16) -> Vec<SpiT<u8>> {
    vec![
        SpiT::transaction_start(),
        SpiT::transfer_in_place(
            McpKind::Mcp3008.command(ch).to_vec(),
            vec![0, (v >> 8) as u8, v as u8],
        ),
        SpiT::transaction_end(),
    ]
}

/// Detector k on chip k % 4, channel k / 4: consecutive detectors on
/// different chips, so that a bank reading chip after chip is not in
/// detector order.
fn interleaved() -> ChannelMap {
    let boards: Vec<BoardSpec> = (0..4)
        .map(|i| BoardSpec {
            name: format!("u{i}"),
            channels: 8,
        })
        .collect();
    let map: Vec<MapEntry> = (0..NDET)
        .map(|k| MapEntry {
            r: k / 5,
            c: k % 5,
            board: format!("u{}", k % 4),
            channel: (k / 4) as u8,
        })
        .collect();
    ChannelMap::new(&map, &boards).unwrap()
}

/// Chip `b`'s transactions of sample `i`: its detectors in detector order
/// (`upto`: only those before detector `upto`).
fn chip_sample(b: usize, i: usize, upto: usize) -> Vec<SpiT<u8>> {
    (0..NDET.min(upto))
        .filter(|k| k % 4 == b)
        .flat_map(|k| mcp_read((k / 4) as u8, value(k, i)))
        .collect()
}

fn chip_frame(b: usize) -> Vec<SpiT<u8>> {
    (0..N).flat_map(|i| chip_sample(b, i, NDET)).collect()
}

#[test]
fn an_mcp3008_bank_reads_a_burst_in_detector_order_and_drops_a_frame_with_a_bus_error() {
    let log = Arc::new(Mutex::new(Vec::new()));
    // Frame 0 whole; frame 1 fails at chip u2's first transfer of its
    // third sample (after detectors 0 and 1 of that sample were read);
    // frame 2 whole.
    let chips = (0..4)
        .map(|b| {
            let mut ex = chip_frame(b);
            let before = ex.len() / 3;
            ex.extend(chip_sample(b, 0, NDET));
            ex.extend(chip_sample(b, 1, NDET));
            let mut fail_at = None;
            if b == 2 {
                fail_at = Some(before + 2 * chip_sample(b, 0, NDET).len() / 3);
            } else {
                ex.extend(chip_sample(b, 2, 2));
            }
            ex.extend(chip_frame(b));
            let spi = LoggedSpi {
                inner: SpiMock::new(&ex),
                chip: b,
                log: log.clone(),
                calls: 0,
                fail_at,
            };
            (format!("u{b}"), Mcp3x08::new(spi, McpKind::Mcp3008))
        })
        .collect();
    let skew = 24.0 / 1.35e6 + 10e-6;
    let mut src = BoardSource::new(
        SpiBank::new(chips),
        interleaved(),
        TempReader::new(TempKind::Fixed(18.5), 18.5),
        Pacer::new(None),
    )
    .with_sampling(sampling(skew));
    let s = src.sampling().expect("a source of bursts");
    assert_eq!((s.samples_per_frame, s.sample_hz), (N, SAMPLE_HZ));
    assert_eq!(s.channel_skew_s, skew);
    assert_eq!(s.beacons[0].id, "beacon");
    assert!(src.describe().contains("4 samples a frame at 40 Hz"));
    // A source of bursts gives no frames of one sample.
    let mut burst = Burst::default();

    let before = lightpose_hal::clock::monotonic_s();
    assert_eq!(src.next_take(&mut burst).unwrap(), Take::Burst);
    assert_eq!((burst.seq, burst.n(), burst.adc_bits), (0, N, 10));
    assert_eq!(burst.temp_c, Some(18.5));
    for k in 0..NDET {
        let want: Vec<u16> = (0..N).map(|i| value(k, i)).collect();
        assert_eq!(burst.channel(k), &want[..], "detector {k}");
    }
    // t is the first sample's: at or after the call, and the burst lasted
    // (N − 1) sample periods after it.
    let after = lightpose_hal::clock::monotonic_s();
    assert!(burst.t >= before, "{} >= {before}", burst.t);
    assert!(after - burst.t >= (N - 1) as f64 / SAMPLE_HZ - 1e-6);
    // Detector order: chips 0, 1, 2, 3, 0, 1, ... in every sample.
    let order: Vec<usize> = log.lock().unwrap().drain(..).collect();
    let want: Vec<usize> = (0..N).flat_map(|_| (0..NDET).map(|k| k % 4)).collect();
    assert_eq!(order, want);

    let e = src.next_take(&mut burst).unwrap_err();
    assert!(matches!(e, SourceError::Bus { .. }), "{e}");
    assert!(
        e.to_string().contains("board u2 (MCP3008) channel 0"),
        "{e}"
    );

    let t0 = burst.t;
    assert_eq!(src.next_take(&mut burst).unwrap(), Take::Burst);
    assert_eq!(burst.seq, 2, "the dropped frame leaves a gap in seq");
    assert!(burst.t > t0);
    for k in 0..NDET {
        let want: Vec<u16> = (0..N).map(|i| value(k, i)).collect();
        assert_eq!(burst.channel(k), &want[..], "detector {k}");
    }
    assert!(matches!(src.next_frame(), Err(SourceError::BadData { .. })));
    for (_, chip) in src.into_bank().into_chips() {
        chip.release().inner.done();
    }
}

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

/// Seven ADS1115 on two buses (detector k on chip k / 4, channel k % 4):
/// every sample is the bank's four rounds (start the n-th channel of
/// every chip, one wait, collect), N of them a frame.
#[test]
fn an_ads1115_bank_reads_a_burst_in_rounds() {
    let dr = DataRate::from_sps(860).unwrap();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut waits = Vec::new();
    for i in 0..N {
        for ch in 0..4u8 {
            let chips: Vec<usize> = (0..7).filter(|&c| c * 4 + (ch as usize) < NDET).collect();
            for &c in &chips {
                let ex = if c < 4 { &mut a } else { &mut b };
                ex.push(ads1115_start(0x48 + (c % 4) as u8, ch, dr));
            }
            for &c in &chips {
                let ex = if c < 4 { &mut a } else { &mut b };
                let code = value(c * 4 + ch as usize, i) as i16 * 8;
                ex.extend(ads1115_collect(0x48 + (c % 4) as u8, code));
            }
            waits.push(DelayT::delay_ns(dr.conversion_ns()));
        }
    }
    let buses = vec![
        ("/dev/i2c-1".to_string(), I2cMock::new(&a)),
        ("/dev/i2c-3".to_string(), I2cMock::new(&b)),
    ];
    let slots = (0..7)
        .map(|c| I2cSlot {
            name: format!("a{c}"),
            bus: usize::from(c >= 4),
            chip: Ads1115::new(0x48 + (c % 4) as u8, Fsr::V4_096, dr),
        })
        .collect();
    let mut delay = CheckedDelay::new(&waits);
    let bank = I2cBank::new(buses, slots, delay.clone()).unwrap();
    let mut src = BoardSource::new(
        bank,
        ChannelMap::sequential(4),
        TempReader::new(TempKind::None, 0.0),
        Pacer::new(None),
    )
    .with_sampling(sampling(1e-3));
    let mut burst = Burst::new(1);
    assert_eq!(src.next_take(&mut burst).unwrap(), Take::Burst);
    assert_eq!((burst.n(), burst.adc_bits, burst.temp_c), (N, 15, None));
    for k in 0..NDET {
        let want: Vec<u16> = (0..N).map(|i| value(k, i) * 8).collect();
        assert_eq!(burst.channel(k), &want[..], "detector {k}");
    }
    for (_, mut bus) in src.into_bank().into_buses() {
        bus.done();
    }
    delay.done();
}

/// Four ADS7828 on one bus (detector k on chip k / 8, channel k % 8): a
/// chip that converts while read goes in detector order in a burst (a
/// frame of one sample reads in rounds), one command and read a channel.
#[test]
fn an_ads7828_bank_reads_a_burst_in_detector_order() {
    use lightpose_hal::drivers::ads7828::{command, Ads7828, PowerMode};
    let mut ex = Vec::new();
    for i in 0..N {
        for k in 0..NDET {
            let v = value(k, i);
            ex.push(I2cT::write_read(
                0x48 + (k / 8) as u8,
                vec![command((k % 8) as u8, PowerMode::InternalRef)],
                vec![(v >> 8) as u8, v as u8],
            ));
        }
    }
    let slots = (0..4u8)
        .map(|c| I2cSlot {
            name: format!("adc{c}"),
            bus: 0,
            chip: Ads7828::new(0x48 + c, PowerMode::InternalRef),
        })
        .collect();
    let bus = I2cMock::new(&ex);
    let bank = I2cBank::new(
        vec![("/dev/i2c-1".into(), bus)],
        slots,
        embedded_hal_mock::eh1::delay::NoopDelay::new(),
    )
    .unwrap();
    let mut src = BoardSource::new(
        bank,
        ChannelMap::sequential(8),
        TempReader::new(TempKind::None, 0.0),
        Pacer::new(None),
    )
    .with_sampling(sampling(1e-4));
    let mut burst = Burst::default();
    assert_eq!(src.next_take(&mut burst).unwrap(), Take::Burst);
    assert_eq!((burst.n(), burst.adc_bits), (N, 12));
    for k in 0..NDET {
        let want: Vec<u16> = (0..N).map(|i| value(k, i)).collect();
        assert_eq!(burst.channel(k), &want[..], "detector {k}");
    }
    for (_, mut bus) in src.into_bank().into_buses() {
        bus.done();
    }
}

/// A stop raised while a slow burst waits for its next sample (2 s
/// apart) ends it there, as it ends every wait of a source: sample 0 read,
/// sample 1 never asked for.
#[test]
fn a_stop_ends_a_burst_between_samples() {
    let stop = lightpose_hal::Stop::new();
    let chips = (0..4)
        .map(|b| {
            let spi = LoggedSpi {
                inner: SpiMock::new(&chip_sample(b, 0, NDET)),
                chip: b,
                log: Arc::new(Mutex::new(Vec::new())),
                calls: 0,
                fail_at: None,
            };
            (format!("u{b}"), Mcp3x08::new(spi, McpKind::Mcp3008))
        })
        .collect();
    let mut slow = sampling(0.0);
    if let Some(s) = slow.as_mut() {
        s.sample_hz = 0.5;
    }
    let mut src = BoardSource::new(
        SpiBank::new(chips),
        interleaved(),
        TempReader::new(TempKind::None, 0.0),
        Pacer::new(None).stoppable(stop.clone()),
    )
    .with_sampling(slow);
    let raiser = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(100));
            stop.raise();
        })
    };
    let started = std::time::Instant::now();
    let mut burst = Burst::default();
    let e = src.next_take(&mut burst);
    assert!(matches!(e, Err(SourceError::Stopped)), "{e:?}");
    // Before sample 1 was due.
    assert!(started.elapsed() < std::time::Duration::from_secs(2));
    raiser.join().unwrap();
    for (_, chip) in src.into_bank().into_chips() {
        chip.release().inner.done();
    }
}

/// Without a sampling of N > 1 a board source is what it was: frames.
#[test]
fn a_source_without_sampling_gives_frames() {
    let chips = vec![(
        "u0".to_string(),
        Mcp3x08::new(SpiMock::new(&[]), McpKind::Mcp3008),
    )];
    let src = BoardSource::new(
        SpiBank::new(chips),
        ChannelMap::sequential(8),
        TempReader::new(TempKind::None, 0.0),
        Pacer::new(None),
    );
    let mut one = sampling(0.0);
    if let Some(s) = one.as_mut() {
        s.samples_per_frame = 1;
    }
    let src = src.with_sampling(one);
    assert!(src.sampling().is_none());
    for (_, chip) in src.into_bank().into_chips() {
        chip.release().done();
    }
}
