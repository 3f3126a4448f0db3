//! Per-frame cost of the hardware layer: the bytes each chip puts on its bus
//! and the bus time at the chip's maximum clock (printed as a table), and
//! the CPU cost of assembling a frame from fake buses, with a check that the
//! frame path allocates nothing.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use embedded_hal::i2c::{self, I2c, Operation as I2cOp};
use embedded_hal::spi::{self, Operation as SpiOp, SpiDevice};
use lightpose_core::NDET;
use lightpose_hal::bank::{BoardSource, I2cAdc, I2cBank, I2cSlot, SpiBank};
use lightpose_hal::chanmap::ChannelMap;
use lightpose_hal::drivers::ads1115::{Ads1115, DataRate, Fsr};
use lightpose_hal::drivers::ads7828::{self, Ads7828, PowerMode};
use lightpose_hal::drivers::mcp3x08::{Mcp3x08, McpKind};
use lightpose_hal::pace::Pacer;
use lightpose_hal::serial::protocol::{format_line, parse_line, LineAssembler};
use lightpose_hal::temp::{TempKind, TempReader};
use lightpose_hal::FrameSource;
use lightpose_testkit::alloc::Counting;

/// Counts allocations, to check the frame path makes none.
#[global_allocator]
static A: Counting = Counting::new();

/// Bytes a fake bus saw.
#[derive(Default, Clone, Copy)]
struct Traffic {
    bytes: u64,
}

/// A fake SPI device answering every transfer with a mid-scale value.
#[derive(Default)]
struct FakeSpi(Traffic);
impl spi::ErrorType for FakeSpi {
    type Error = spi::ErrorKind;
}
impl SpiDevice for FakeSpi {
    fn transaction(&mut self, ops: &mut [SpiOp<'_, u8>]) -> Result<(), Self::Error> {
        for op in ops {
            if let SpiOp::TransferInPlace(b) = op {
                self.0.bytes += b.len() as u64;
                if let Some(last) = b.last_mut() {
                    *last = 0x55;
                }
            }
        }
        Ok(())
    }
}

/// A fake I²C bus: config register reads say "conversion done".
#[derive(Default)]
struct FakeI2c(Traffic);
impl i2c::ErrorType for FakeI2c {
    type Error = i2c::ErrorKind;
}
impl I2c for FakeI2c {
    fn transaction(&mut self, _addr: u8, ops: &mut [I2cOp<'_>]) -> Result<(), Self::Error> {
        for op in ops.iter_mut() {
            if let I2cOp::Read(b) = op {
                self.0.bytes += b.len() as u64;
                // OS bit set (ADS1115 done), then a mid-scale value
                for (i, x) in b.iter_mut().enumerate() {
                    *x = if i == 0 { 0x80 } else { 0x10 };
                }
            }
        }
        Ok(())
    }
}

/// SCL cycles: 9 per byte (8 + ACK), one per START/Sr and one per STOP
/// (one STOP per transaction, i.e. per write-read pair or single write).
fn i2c_clocks(bytes: u64, segments: u64) -> u64 {
    9 * bytes + 2 * segments
}

fn mcp_source(kind: McpKind) -> BoardSource<SpiBank<FakeSpi>> {
    let chips = (0..4)
        .map(|i| (format!("u{i}"), Mcp3x08::new(FakeSpi::default(), kind)))
        .collect();
    BoardSource::new(
        SpiBank::new(chips),
        ChannelMap::sequential(8),
        TempReader::new(TempKind::Fixed(20.0), 20.0),
        Pacer::new(None),
    )
}

fn i2c_source<C: I2cAdc>(
    chips: Vec<C>,
    per_bus: usize,
) -> BoardSource<I2cBank<FakeI2c, C, NoDelay>> {
    let nbus = chips.len().div_ceil(per_bus);
    let buses = (0..nbus)
        .map(|i| (format!("/dev/i2c-{i}"), FakeI2c::default()))
        .collect();
    let slots = chips
        .into_iter()
        .enumerate()
        .map(|(i, chip)| I2cSlot {
            name: format!("a{i}"),
            bus: i / per_bus,
            chip,
        })
        .collect();
    let bank = I2cBank::new(buses, slots, NoDelay).expect("layout");
    BoardSource::new(
        bank,
        ChannelMap::sequential(C::CHANNELS),
        TempReader::new(TempKind::Fixed(20.0), 20.0),
        Pacer::new(None),
    )
}

/// A delay that does not wait (the conversion times are added to the
/// table from the data rate).
#[derive(Default)]
struct NoDelay;
impl embedded_hal::delay::DelayNs for NoDelay {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// I²C bytes and clocks of one transaction pattern, computed from the
/// driver's own transactions on a counting bus.
struct I2cCount {
    bytes: u64,
    segments: u64,
}

struct CountBus(I2cCount);
impl i2c::ErrorType for CountBus {
    type Error = i2c::ErrorKind;
}
impl I2c for CountBus {
    fn transaction(&mut self, _a: u8, ops: &mut [I2cOp<'_>]) -> Result<(), Self::Error> {
        let mut last = None;
        for op in ops.iter_mut() {
            let r = matches!(op, I2cOp::Read(_));
            if last != Some(r) {
                self.0.segments += 1;
                self.0.bytes += 1; // address byte
                last = Some(r);
            }
            match op {
                I2cOp::Write(b) => self.0.bytes += b.len() as u64,
                I2cOp::Read(b) => {
                    self.0.bytes += b.len() as u64;
                    b.fill(0x80);
                }
            }
        }
        Ok(())
    }
}

fn print_table() {
    println!();
    println!(
        "{:<22} {:>11} {:>14} {:>15} {:>14}",
        "chip (25 channels)", "bytes/frame", "clock", "bus time/frame", "max frame Hz"
    );
    let row = |name: &str, bytes: u64, clock_hz: f64, secs: f64| {
        println!(
            "{:<22} {:>11} {:>11.1} MHz {:>12.1} µs {:>14.0}",
            name,
            bytes,
            clock_hz / 1e6,
            secs * 1e6,
            1.0 / secs
        );
    };
    for kind in [McpKind::Mcp3008, McpKind::Mcp3208] {
        let mut src = mcp_source(kind);
        src.next_frame().expect("fake bus");
        // measured on the fake buses: 25 transfers of 3 bytes, 8 SCLK a byte
        let bytes: u64 = src
            .into_bank()
            .into_chips()
            .into_iter()
            .map(|(_, c)| c.release().0.bytes)
            .sum();
        let clk = kind.max_clock_hz() as f64;
        row(
            &format!("{} x4 (SPI)", kind.name()),
            bytes,
            clk,
            (8 * bytes) as f64 / clk,
        );
    }
    // ADS7828: measured on a counting bus
    let mut bus = CountBus(I2cCount {
        bytes: 0,
        segments: 0,
    });
    let a = Ads7828::new(0x48, PowerMode::InternalRef);
    for k in 0..NDET {
        a.read_channel(&mut bus, (k % 8) as u8).expect("count bus");
    }
    let clocks = i2c_clocks(bus.0.bytes, bus.0.segments);
    row(
        "ADS7828 x4 (I2C HS)",
        bus.0.bytes,
        ads7828::MAX_CLOCK_HZ as f64,
        clocks as f64 / ads7828::MAX_CLOCK_HZ as f64,
    );
    row(
        "ADS7828 x4 (I2C 400k)",
        bus.0.bytes,
        400e3,
        clocks as f64 / 400e3,
    );
    // ADS1115: bus traffic plus the conversions at 860 SPS. The bank
    // starts the same slot on all 7 chips and waits once, so 25 channels
    // (4 a chip) take 4 conversion times.
    let dr = DataRate::from_sps(860).expect("860");
    let mut bus = CountBus(I2cCount {
        bytes: 0,
        segments: 0,
    });
    let mut a = Ads1115::new(0x48, Fsr::V4_096, dr);
    let mut d = NoDelay;
    for k in 0..NDET {
        a.read_channel(&mut bus, &mut d, (k % 4) as u8)
            .expect("count bus");
    }
    let clocks = i2c_clocks(bus.0.bytes, bus.0.segments);
    let bus_s = clocks as f64 / 3.4e6;
    row("ADS1115 x7 (bus only)", bus.0.bytes, 3.4e6, bus_s);
    row(
        "ADS1115 x7 (+860 SPS)",
        bus.0.bytes,
        3.4e6,
        bus_s + 4.0 * dr.conversion_ns() as f64 * 1e-9,
    );
    // serial: two 16-value 10-bit boards at 115200 8N1 (10 bit times/byte)
    let mut l = Vec::new();
    format_line(0, 123_456, 10, &[1023; 16], &mut l);
    let bytes = l.len() as u64;
    println!(
        "{:<22} {:>11} {:>11} bd {:>12.1} µs {:>14.0}   (per board, boards stream in parallel)",
        "LPADC serial, 16 ch",
        bytes,
        115_200,
        bytes as f64 * 10.0 / 115_200.0 * 1e6,
        115_200.0 / (bytes as f64 * 10.0)
    );
    println!();
}

fn allocations_per_frame(src: &mut dyn FrameSource, frames: u64) -> u64 {
    src.next_frame().ok();
    let ((), n) = A.everywhere(|| {
        for _ in 0..frames {
            black_box(src.next_frame().ok());
        }
    });
    n
}

fn bench(c: &mut Criterion) {
    print_table();
    let mut mcp = mcp_source(McpKind::Mcp3008);
    let mut a7828 = i2c_source(
        (0..4)
            .map(|i| Ads7828::new(0x48 + i, PowerMode::InternalRef))
            .collect(),
        4,
    );
    let dr = DataRate::from_sps(860).expect("860");
    let mut a1115 = i2c_source(
        (0..7)
            .map(|i| Ads1115::new(0x48 + (i % 4) as u8, Fsr::V4_096, dr))
            .collect(),
        4,
    );
    for (name, src) in [
        ("MCP3008", &mut mcp as &mut dyn FrameSource),
        ("ADS7828", &mut a7828),
        ("ADS1115", &mut a1115),
    ] {
        let n = allocations_per_frame(src, 1000);
        println!("{name}: {n} allocations in 1000 frames");
        assert_eq!(n, 0, "{name}: the frame path must not allocate");
    }
    c.bench_function("assemble frame: MCP3008 x4, fake SPI", |b| {
        b.iter(|| black_box(mcp.next_frame().ok()))
    });
    c.bench_function("assemble frame: ADS7828 x4, fake I2C", |b| {
        b.iter(|| black_box(a7828.next_frame().ok()))
    });
    c.bench_function("assemble frame: ADS1115 x7, fake I2C", |b| {
        b.iter(|| black_box(a1115.next_frame().ok()))
    });

    let mut lines = Vec::new();
    format_line(0, 1, 10, &[512; 16], &mut lines);
    format_line(1, 1, 10, &[511; 9], &mut lines);
    let mut asm = LineAssembler::default();
    c.bench_function("serial: split + parse two LPADC lines", |b| {
        b.iter(|| {
            let mut sum = 0u32;
            asm.push(black_box(&lines), |l| {
                if let Ok(s) = l.and_then(parse_line) {
                    sum += s.values[0] as u32;
                }
            });
            sum
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
