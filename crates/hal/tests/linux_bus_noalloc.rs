//! The real Linux buses (`lightpose_hal::linux::{spi, i2c}`) without a
//! device: the mapping of embedded-hal operations to what the kernel reads
//! (`spi_ioc_transfer`s, `i2c_msg`s) checked field by field, and a regular
//! file opened as the device, whose ioctls fail (ENOTTY; ENOSYS under
//! qemu-user, the ARM runner), for the errors.
//! A counting global allocator (per thread, so tests may run in parallel)
//! shows that none of it allocates: a transaction is per frame.
#![cfg(feature = "linux")]

mod common;

use std::fmt::{self, Write as _};
use std::mem::{align_of, size_of};

use common::{map_tables, validate};
use embedded_hal::i2c::{self, Error as _, I2c, NoAcknowledgeSource};
use embedded_hal::spi::{self, Error as _, Operation as SpiOp, SpiDevice};
use lightpose_hal::drivers::ads7828::{Ads7828, PowerMode};
use lightpose_hal::drivers::mcp3x08::{Mcp3x08, McpKind};
use lightpose_hal::drivers::DriverError;
use lightpose_hal::linux::i2c::{messages, I2cError, LinuxI2c, MAX_MESSAGES};
use lightpose_hal::linux::spi::{transfers, LinuxSpi, SpiError, MAX_TRANSFERS};
use lightpose_hal::Stop;
use lightpose_testkit::alloc::Counting;
use nix::errno::Errno;

#[global_allocator]
static A: Counting = Counting::new();

/// Formats into a fixed buffer: shows that an error's words cost nothing.
struct Stack {
    buf: [u8; 160],
    len: usize,
}

impl Stack {
    fn new() -> Self {
        Stack {
            buf: [0; 160],
            len: 0,
        }
    }
    fn as_str(&self) -> &str {
        std::str::from_utf8(&self.buf[..self.len]).unwrap()
    }
}

impl fmt::Write for Stack {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        self.buf
            .get_mut(self.len..end)
            .ok_or(fmt::Error)?
            .copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

// --- what the kernel reads ---------------------------------------------------

/// `struct spi_ioc_transfer`, include/uapi/linux/spi/spidev.h.
#[repr(C)]
struct KernelSpiTransfer {
    tx_buf: u64,
    rx_buf: u64,
    len: u32,
    speed_hz: u32,
    delay_usecs: u16,
    bits_per_word: u8,
    cs_change: u8,
    tx_nbits: u8,
    rx_nbits: u8,
    word_delay_usecs: u8,
    pad: u8,
}

/// `struct i2c_msg`, include/uapi/linux/i2c.h.
#[repr(C)]
struct KernelI2cMsg {
    addr: u16,
    flags: u16,
    len: u16,
    buf: *const u8,
}

const I2C_M_RD: u16 = 0x0001;
const I2C_M_NOSTART: u16 = 0x4000;

/// `items` as the kernel's struct `K` reads them: spidev and i2cdev keep
/// their fields private, and the layout the kernel sees is what matters.
fn as_kernel<T, K>(items: &[T]) -> &[K] {
    assert_eq!(size_of::<T>(), size_of::<K>(), "not the kernel's struct");
    assert!(align_of::<T>() >= align_of::<K>());
    // SAFETY: T is a #[repr(C)] twin of the kernel struct K (same size,
    // at least K's alignment, checked above), fully initialised by its
    // crate's constructors; the view borrows `items` and reads only.
    unsafe { std::slice::from_raw_parts(items.as_ptr().cast::<K>(), items.len()) }
}

fn addr_of(b: &[u8]) -> u64 {
    b.as_ptr() as usize as u64
}

/// A regular file to open as a bus device: its ioctls fail.
fn not_a_device() -> tempfile::NamedTempFile {
    tempfile::NamedTempFile::new().unwrap()
}

/// The errno of a bus ioctl on a regular file: ENOTTY from the kernel,
/// ENOSYS under qemu-user (.cargo/config.toml's runner for the ARM
/// targets), which does not pass ioctls it does not know through.
fn bad_ioctl() -> Errno {
    let f = not_a_device();
    let mut dev = LinuxSpi::open(f.path()).unwrap();
    let e = dev.configure(1_000_000).unwrap_err();
    let errno = Errno::from_raw(e.raw_os_error().unwrap());
    assert!(matches!(errno, Errno::ENOTTY | Errno::ENOSYS), "{errno}");
    errno
}

/// How our bus errors end for `errno`: ENOTTY (nix: "Not a typewriter")
/// gets a hint.
fn errno_words(errno: Errno, hint: &str) -> String {
    match errno {
        Errno::ENOTTY => format!("{errno} ({hint})"),
        _ => errno.to_string(),
    }
}

// --- SPI ---------------------------------------------------------------------

#[test]
fn the_counter_counts_this_threads_allocations() {
    let (v, n) = A.this_thread(|| Vec::<u8>::with_capacity(16));
    assert_eq!((v.capacity(), n), (16, 1));
    let (_, n) = A.this_thread(|| std::thread::spawn(|| vec![0u8; 16]).join());
    assert!(n >= 1, "spawning allocates on this thread");
}

#[test]
fn spi_operations_map_to_transfers_without_allocating() {
    let mut rd = [0u8; 3];
    let wr = [1u8, 2, 3];
    let (mut long_rd, short_wr) = ([0u8; 4], [9u8; 2]);
    let (mut short_rd, long_wr) = ([0u8; 1], [5u8; 3]);
    let mut in_place = [7u8; 2];
    let want = [
        // (tx, rx, len, delay_usecs)
        (0, addr_of(&rd), 3, 0),
        (addr_of(&wr), 0, 3, 0),
        (addr_of(&short_wr), addr_of(&long_rd), 2, 0),
        (0, addr_of(&long_rd[2..]), 2, 0),
        (addr_of(&long_wr), addr_of(&short_rd), 1, 0),
        (addr_of(&long_wr[1..]), 0, 2, 0),
        (addr_of(&in_place), addr_of(&in_place), 2, 0),
        (0, 0, 0, 2), // 1.5 µs, rounded up
    ];
    let mut ops = [
        SpiOp::Read(&mut rd),
        SpiOp::Write(&wr),
        SpiOp::Transfer(&mut long_rd, &short_wr),
        SpiOp::Transfer(&mut short_rd, &long_wr),
        SpiOp::TransferInPlace(&mut in_place),
        SpiOp::DelayNs(1500),
    ];
    let (t, n) = A.this_thread(|| transfers(&mut ops));
    assert_eq!(n, 0, "allocations building the transfers");
    let t = t.unwrap();
    let got = as_kernel::<_, KernelSpiTransfer>(t.as_slice());
    assert_eq!(got.len(), want.len());
    assert_eq!(got.len(), MAX_TRANSFERS);
    for (i, (k, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(
            (k.tx_buf, k.rx_buf, k.len, k.delay_usecs),
            w,
            "transfer {i}"
        );
        // Everything else zero: the device's speed and word size apply,
        // chip select held to the end of the transaction.
        let rest = [k.bits_per_word, k.cs_change, k.tx_nbits, k.rx_nbits];
        assert_eq!(
            (k.speed_hz, rest, k.word_delay_usecs, k.pad),
            (0, [0; 4], 0, 0)
        );
    }
}

#[test]
fn spi_delays_round_up_and_split_at_the_kernels_limit() {
    let delays = |ns: u32| {
        let mut ops = [SpiOp::DelayNs(ns)];
        let t = transfers(&mut ops).unwrap();
        as_kernel::<_, KernelSpiTransfer>(t.as_slice())
            .iter()
            .map(|k| (k.len, k.delay_usecs))
            .collect::<Vec<_>>()
    };
    assert_eq!(delays(0), vec![]);
    assert_eq!(delays(1), vec![(0, 1)]);
    assert_eq!(delays(2000), vec![(0, 2)]);
    assert_eq!(
        delays(200_000_000),
        vec![(0, 65535), (0, 65535), (0, 65535), (0, 3395)]
    );
}

#[test]
fn too_many_spi_transfers_is_an_error_not_a_panic() {
    let w = [0u8; 1];
    let mut ops: [SpiOp<'_, u8>; MAX_TRANSFERS + 1] = std::array::from_fn(|_| SpiOp::Write(&w));
    let (r, n) = A.this_thread(|| transfers(&mut ops).err());
    assert_eq!(n, 0);
    assert_eq!(r, Some(SpiError::TooManyTransfers { needed: 9 }));
    // A delay of u32::MAX ns is 66 transfers of 65.535 ms.
    let mut ops = [SpiOp::DelayNs(u32::MAX)];
    let e = transfers(&mut ops).err().unwrap();
    assert_eq!(e, SpiError::TooManyTransfers { needed: 66 });
    assert_eq!(e.kind(), spi::ErrorKind::Other);
    assert_eq!(
        e.to_string(),
        "SPI transaction needs 66 transfers, at most 8 supported"
    );
    // Through the device as well: refused before any ioctl.
    let file = not_a_device();
    let mut dev = LinuxSpi::open(file.path()).unwrap();
    let mut ops: [SpiOp<'_, u8>; 9] = std::array::from_fn(|_| SpiOp::Write(&w));
    assert_eq!(
        dev.transaction(&mut ops),
        Err(SpiError::TooManyTransfers { needed: 9 })
    );
}

#[test]
fn spi_on_a_regular_file_fails_with_enotty_and_allocates_nothing() {
    let file = not_a_device();
    let mut dev = LinuxSpi::open(file.path()).unwrap();
    // configure's ioctls fail too, with the io::Error the open code reports.
    let errno = bad_ioctl();
    let e = dev.configure(1_000_000).unwrap_err();
    assert_eq!(e.raw_os_error(), Some(errno as i32));
    let mut adc = Mcp3x08::new(dev, McpKind::Mcp3008);
    let mut words = Stack::new();
    let (r, n) = A.this_thread(|| {
        let mut last = None;
        for _ in 0..100 {
            last = adc.read_channel(3).err();
        }
        if let Some(e) = &last {
            write!(words, "{e}").unwrap();
        }
        last
    });
    assert_eq!(n, 0, "allocations in 100 failed conversions");
    let e = r.unwrap();
    assert_eq!(e, DriverError::Bus(SpiError::Os(errno)));
    let want = errno_words(errno, "not a spidev device?");
    assert_eq!(words.as_str(), format!("bus: SPI_IOC_MESSAGE: {want}"));
    if errno == Errno::ENOTTY {
        assert_eq!(
            words.as_str(),
            "bus: SPI_IOC_MESSAGE: ENOTTY: Not a typewriter (not a spidev device?)"
        );
    }
    let DriverError::Bus(bus) = e else {
        unreachable!()
    };
    assert_eq!(bus.kind(), spi::ErrorKind::Other);
}

// --- I²C ---------------------------------------------------------------------

#[test]
fn i2c_operations_map_to_messages_without_allocating() {
    let (w1, w2) = ([0x01u8, 0x84, 0x83], [0x00u8]);
    let (mut r1, mut r2) = ([0u8; 2], [0u8; 4]);
    let want = [
        // (addr, flags, len, buf)
        (0x48, 0, 3, addr_of(&w1)),
        (0x48, I2C_M_NOSTART, 1, addr_of(&w2)),
        (0x48, I2C_M_RD, 2, addr_of(&r1)),
        (0x48, I2C_M_RD | I2C_M_NOSTART, 4, addr_of(&r2)),
    ];
    let mut ops = [
        i2c::Operation::Write(&w1),
        i2c::Operation::Write(&w2),
        i2c::Operation::Read(&mut r1),
        i2c::Operation::Read(&mut r2),
    ];
    let (m, n) = A.this_thread(|| messages(0x48, &mut ops));
    assert_eq!(n, 0, "allocations building the messages");
    let m = m.unwrap();
    let got = as_kernel::<_, KernelI2cMsg>(m.as_slice());
    assert_eq!(got.len(), want.len());
    for (i, (k, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(
            (k.addr, k.flags, k.len, k.buf as usize as u64),
            w,
            "message {i}"
        );
    }
    // write_read, as the ADS1115 and ADS7828 drivers do: a repeated start.
    let mut rd = [0u8; 2];
    let mut ops = [i2c::Operation::Write(&w2), i2c::Operation::Read(&mut rd)];
    let m = messages(0x4B, &mut ops).unwrap();
    let got = as_kernel::<_, KernelI2cMsg>(m.as_slice());
    let flags: Vec<_> = got.iter().map(|k| (k.addr, k.flags, k.len)).collect();
    assert_eq!(flags, vec![(0x4B, 0, 1), (0x4B, I2C_M_RD, 2)]);
}

#[test]
fn too_many_or_too_long_i2c_messages_are_errors_not_panics() {
    let w = [0u8; 1];
    let mut ops: [i2c::Operation<'_>; MAX_MESSAGES + 1] =
        std::array::from_fn(|_| i2c::Operation::Write(&w));
    let (r, n) = A.this_thread(|| messages(0x48, &mut ops).err());
    assert_eq!(n, 0);
    let e = r.unwrap();
    assert_eq!(e, I2cError::TooManyMessages { needed: 9 });
    assert_eq!(e.kind(), i2c::ErrorKind::Other);
    assert_eq!(
        e.to_string(),
        "I2C transaction of 9 messages, at most 8 supported"
    );
    let big = vec![0u8; 65536];
    let mut ops = [i2c::Operation::Write(&big)];
    assert_eq!(
        messages(0x48, &mut ops).err(),
        Some(I2cError::TooLong { len: 65536 })
    );
    let file = not_a_device();
    let mut bus = LinuxI2c::open_unchecked(file.path()).unwrap();
    let mut ops: [i2c::Operation<'_>; 9] = std::array::from_fn(|_| i2c::Operation::Write(&w));
    assert_eq!(
        bus.transaction(0x48, &mut ops),
        Err(I2cError::TooManyMessages { needed: 9 })
    );
}

#[test]
fn i2c_on_a_regular_file_fails_with_enotty_and_allocates_nothing() {
    let errno = bad_ioctl();
    let file = not_a_device();
    // Refused at open with the words linux-embedded-hal gave (i2cdev's
    // I2C_SLAVE), and an address check fails the same way.
    let e = LinuxI2c::open(file.path()).err().unwrap();
    assert_eq!(e.to_string(), errno.to_string());
    let e = LinuxI2c::check_address(file.path(), 0x48).unwrap_err();
    let slave = I2cError::Os {
        call: "I2C_SLAVE",
        addr: 0x48,
        errno,
    };
    assert_eq!(e, slave);
    assert_eq!(slave.kind(), i2c::ErrorKind::Other);
    // Past the check, the transaction's own ioctl fails.
    let mut bus = LinuxI2c::open_unchecked(file.path()).unwrap();
    let adc = Ads7828::new(0x4A, PowerMode::InternalRef);
    let mut words = Stack::new();
    let (r, n) = A.this_thread(|| {
        let mut last = None;
        for _ in 0..100 {
            last = adc.read_channel(&mut bus, 5).err();
        }
        if let Some(e) = &last {
            write!(words, "{e}").unwrap();
        }
        last
    });
    assert_eq!(n, 0, "allocations in 100 failed conversions");
    let e = r.unwrap();
    let os = I2cError::Os {
        call: "I2C_RDWR",
        addr: 0x4A,
        errno,
    };
    assert_eq!(e, DriverError::Bus(os));
    assert_eq!(
        words.as_str(),
        format!(
            "bus: I2C_RDWR to 0x4A: {}",
            errno_words(errno, "not an i2c-dev bus?")
        )
    );
    assert_eq!(os.kind(), i2c::ErrorKind::Other);
    // The plain calls too.
    assert_eq!(bus.write(0x4A, &[0x84]), Err(os));
    let mut rd = [0u8; 2];
    assert_eq!(bus.read(0x4A, &mut rd), Err(os));
}

#[test]
fn i2c_errnos_give_embedded_hal_kinds() {
    let kind = |errno| {
        I2cError::Os {
            call: "I2C_RDWR",
            addr: 0x48,
            errno,
        }
        .kind()
    };
    use i2c::ErrorKind::*;
    assert_eq!(
        kind(Errno::ENXIO),
        NoAcknowledge(NoAcknowledgeSource::Address)
    );
    assert_eq!(
        kind(Errno::EREMOTEIO),
        NoAcknowledge(NoAcknowledgeSource::Unknown)
    );
    assert_eq!(kind(Errno::EAGAIN), ArbitrationLoss);
    for other in [Errno::EIO, Errno::ETIMEDOUT, Errno::ENOTTY, Errno::EBUSY] {
        assert_eq!(kind(other), Other, "{other}");
    }
    // I2C_SLAVE's errors concern the address, never a NAK on the wire.
    let slave = I2cError::Os {
        call: "I2C_SLAVE",
        addr: 0x48,
        errno: Errno::ENXIO,
    };
    assert_eq!(slave.kind(), Other);
    let busy = I2cError::Os {
        call: "I2C_SLAVE",
        addr: 0x48,
        errno: Errno::EBUSY,
    };
    assert_eq!(
        busy.to_string(),
        "I2C_SLAVE to 0x48: EBUSY: Device or resource busy (a kernel driver has claimed the address)"
    );
}

// --- opening, through the one `open` -----------------------------------------

fn open_error(toml_text: &str) -> String {
    lightpose_hal::open(&validate(toml_text).unwrap(), &Stop::new())
        .err()
        .unwrap()
        .to_string()
}

#[test]
fn a_file_that_is_no_bus_is_refused_at_open_naming_its_place() {
    // One file per chip select: two chips on one device are refused by
    // validation, before open.
    let files: Vec<_> = (0..4).map(|_| not_a_device()).collect();
    let chips: String = files
        .iter()
        .enumerate()
        .map(|(i, f)| {
            format!(
                "{{ name = \"u{i}\", device = \"{}\" }},",
                f.path().display()
            )
        })
        .collect();
    let spi = format!(
        "kind = \"mcp3008\"\nchips = [{chips}]\n{}",
        map_tables("u", 8)
    );
    let e = open_error(&spi);
    let p = files[0].path().display().to_string();
    // The words of spidev's io::Error, as before.
    let errno = bad_ioctl();
    let io = std::io::Error::from_raw_os_error(errno as i32);
    assert_eq!(e, format!("board u0 ({p}): {io}"));
    let chips: String = (0..4)
        .map(|i| {
            format!(
                "{{ name = \"b{i}\", bus = \"{p}\", address = {} }},",
                0x48 + i
            )
        })
        .collect();
    let i2c = format!(
        "kind = \"ads7828\"\nchips = [{chips}]\n{}",
        map_tables("b", 8)
    );
    // The bus is the place, and i2cdev's words, as before.
    assert_eq!(open_error(&i2c), format!("{p}: {errno}"));
}
