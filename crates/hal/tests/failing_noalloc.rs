//! A board that keeps failing costs no allocation a frame, once warmed up:
//! a serial board that is silent (every frame times out), one whose port
//! carries another board's lines, an I²C chip that NAKs, and a DS18B20
//! whose reads fail (the frame gets the fallback, the failure's text is
//! kept once, not cloned from the watcher on every frame). The error's
//! place is built once, at open, and cloned; its message is static, kept
//! inline, or built once while it repeats. A counting global allocator
//! shows it (its own test binary: the count is the whole process's).

mod common;

use std::io::Write;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use common::{ads7828s, bare_source, serial_source};
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::delay::NoopDelay;
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as I2cT};
use lightpose_hal::bank::I2cBank;
use lightpose_hal::chanmap::ChannelMap;
use lightpose_hal::drivers::ads7828::{command, PowerMode};
use lightpose_hal::serial::protocol::format_line;
use lightpose_hal::temp::{write_fake_w1, Ds18b20, Ds18b20Watcher, TempKind, TempReader};
use lightpose_hal::{FrameSource, SourceError};
use lightpose_testkit::alloc::Counting;
use lightpose_testkit::pty::Pty;

#[global_allocator]
static A: Counting = Counting::new();

/// The tests of this file count every thread's allocations: one at a time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Failed frames counted; more than this many allocations for them is
/// allocating per frame.
const FRAMES: u32 = 1000;
const AT_MOST: u64 = 50;

/// Allocations (every thread's) made by `frames` calls of `frame`.
fn allocations(frames: u32, mut frame: impl FnMut()) -> u64 {
    A.everywhere(|| {
        for _ in 0..frames {
            frame();
        }
    })
    .1
}

/// Audit: every failed frame built its error's place with `format!`, and
/// serialport's read timeout built an `io::Error` (about six allocations)
/// on every wait for a board that never speaks.
#[test]
fn a_silent_serial_board_does_not_allocate_per_frame() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("lpadc0");
    let _board = Pty::plug(&path);
    let mut src = serial_source(std::slice::from_ref(&path), 2);
    // Warm-up: the first frame opens the port.
    for _ in 0..3 {
        let e = src.next_frame().expect_err("silent");
        assert!(matches!(e, SourceError::Timeout { .. }), "{e}");
    }
    let e = src.next_frame().expect_err("silent");
    assert_eq!(
        e.to_string(),
        format!("board b0 ({}): timed out waiting for data", path.display())
    );
    let n = allocations(FRAMES, || {
        let e = src.next_frame().expect_err("silent");
        assert!(matches!(e, SourceError::Timeout { .. }), "{e}");
    });
    eprintln!("silent serial board: {n} allocations for {FRAMES} failed frames");
    assert!(n <= AT_MOST, "{n} allocations for {FRAMES} failed frames");
}

/// A port carrying only another board's lines (cables swapped): its
/// message, too long to be kept inline, is built once while it repeats.
#[test]
fn a_port_of_another_board_does_not_allocate_per_frame() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("lpadc0");
    let mut board = Pty::plug(&path);
    let mut src = serial_source(std::slice::from_ref(&path), 2);
    let mut foreign = Vec::new();
    format_line(7, 1, 10, &[5; 16], &mut foreign);
    let mut frame = || {
        board.master.write_all(&foreign).expect("write");
        src.next_frame().expect_err("another board's lines")
    };
    for _ in 0..3 {
        frame();
    }
    let said = "lines carry board id 7, expected 0 (no board is configured with id 7: a board's id set wrong?)";
    let e = frame();
    assert_eq!(
        e.to_string(),
        format!("board b0 ({}): bad data: {said}", path.display())
    );
    let n = allocations(FRAMES / 4, || {
        let e = frame();
        assert!(matches!(e, SourceError::BadData { .. }), "{e}");
    });
    eprintln!(
        "port of another board: {n} allocations for {} failed frames",
        FRAMES / 4
    );
    assert!(
        n <= AT_MOST / 4,
        "{n} allocations for {} failed frames",
        FRAMES / 4
    );
}

/// Four ADS7828 on a bus whose first chip NAKs its address on every frame
/// (scripted with embedded-hal-mock: the script is built before counting,
/// and the mock allocates nothing per transaction).
#[test]
fn an_i2c_chip_that_naks_does_not_allocate_per_frame() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let warm_up = 3;
    let nak = I2cT::write_read(0x48, vec![command(0, PowerMode::InternalRef)], vec![0, 0])
        .with_error(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address));
    let script = vec![nak; (warm_up + 1 + FRAMES) as usize];
    let slots = ads7828s("adc", 4);
    // A bus name long enough that the places are shared, not inline.
    let bus = "/dev/i2c-1 (the photodiode array's bus)";
    let buses = vec![(bus.to_string(), I2cMock::new(&script))];
    let bank = I2cBank::new(buses, slots, NoopDelay::new()).expect("bank");
    let mut src = bare_source(bank, ChannelMap::sequential(8));
    for _ in 0..warm_up {
        src.next_frame().expect_err("NAK");
    }
    let e = src.next_frame().expect_err("NAK");
    assert_eq!(
        e.to_string(),
        format!(
            "board adc0 (ADS7828 0x48 on {bus}) channel 0: bus error: bus: NoAcknowledge(Address)"
        )
    );
    let n = allocations(FRAMES, || {
        let e = src.next_frame().expect_err("NAK");
        assert!(matches!(e, SourceError::Bus { .. }), "{e}");
    });
    eprintln!("I2C chip that NAKs: {n} allocations for {FRAMES} failed frames");
    assert!(n <= AT_MOST, "{n} allocations for {FRAMES} failed frames");
    for (_, mut b) in src.into_bank().into_buses() {
        b.done();
    }
}

const BADCRC: &str = "72 01 4b 46 7f ff 0e 10 57 : crc=12 NO\n72 01 4b 46 7f ff 0e 10 57 t=23125\n";

/// Audit: `Ds18b20Watcher::latest` cloned the error (its path, a String)
/// for every frame while the sensor kept failing.
#[test]
fn a_failing_ds18b20_does_not_allocate_per_frame() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let dir = tempfile::tempdir().expect("tempdir");
    write_fake_w1(dir.path(), "28-aa", BADCRC).expect("fake sensor");
    // Read once, then not for an hour: its thread allocates nothing more.
    let w = Ds18b20Watcher::spawn(
        Ds18b20 {
            root: dir.path().to_path_buf(),
            device: None,
        },
        Duration::from_secs(3600),
        Duration::from_secs(5),
    );
    let t0 = Instant::now();
    while w.reads() < 1 {
        assert!(t0.elapsed() < Duration::from_secs(5), "never read");
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut r = TempReader::new(TempKind::Ds18b20(w), 19.5);
    let mut frames = |n: u32| allocations(n, || assert_eq!(r.for_frame(&[]), Some(19.5)));
    let first = frames(1);
    assert!(first > 0, "the failure's text is kept once");
    let more = frames(1000);
    assert_eq!(more, 0, "1000 frames of the same failure");
    let h = r.health();
    assert!(h.fallback_active && h.fallbacks == 1001, "{h:?}");
    assert!(
        h.last_error.as_deref().is_some_and(|e| e.contains("CRC")),
        "{h:?}"
    );
}
