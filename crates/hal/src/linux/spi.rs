//! An embedded-hal 1.0 [`SpiDevice`] over Linux spidev that allocates
//! nothing per transaction. linux-embedded-hal 0.4 collects every
//! transaction's transfers into a `Vec`, and an MCP3x08 conversion is one
//! transaction per channel per frame: here they are built in a fixed array
//! on the stack ([`Transfers`]) and handed to one `SPI_IOC_MESSAGE` ioctl,
//! so that chip select stays asserted across the whole transaction.

use std::fmt;
use std::io;
use std::path::Path;

use embedded_hal::spi::{self, ErrorType, Operation, SpiDevice};
use nix::errno::Errno;
use spidev::{SpiModeFlags, Spidev, SpidevOptions, SpidevTransfer};

/// Most spidev transfers one transaction may need. Our MCP3x08 driver
/// needs one or two; a `Transfer` of unequal lengths takes two, a long
/// `DelayNs` one per 65.535 ms.
pub const MAX_TRANSFERS: usize = 8;

/// The longest delay one transfer carries: the kernel's `delay_usecs` is a
/// `u16` of microseconds.
const MAX_DELAY_US: u32 = u16::MAX as u32;

/// Why a transaction failed. `Copy` and allocation-free, so that a bus
/// failing on every frame costs nothing to report.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum SpiError {
    /// The `SPI_IOC_MESSAGE` ioctl failed with this errno.
    Os(Errno),
    /// The operations need more than [`MAX_TRANSFERS`] transfers.
    TooManyTransfers { needed: usize },
}

impl SpiError {
    fn from_io(e: io::Error) -> Self {
        SpiError::Os(
            e.raw_os_error()
                .map_or(Errno::UnknownErrno, Errno::from_raw),
        )
    }
}

impl fmt::Display for SpiError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            // Errno's Display names it, with nix's words ("ENOTTY: Not a
            // typewriter"): ENOTTY gets a hint in ours.
            SpiError::Os(e) => {
                write!(f, "SPI_IOC_MESSAGE: {e}")?;
                if *e == Errno::ENOTTY {
                    f.write_str(" (not a spidev device?)")?;
                }
                Ok(())
            }
            SpiError::TooManyTransfers { needed } => write!(
                f,
                "SPI transaction needs {needed} transfers, at most {MAX_TRANSFERS} supported"
            ),
        }
    }
}

/// The same words as Display: the drivers' `DriverError` prints a bus error
/// with `{:?}` (embedded-hal errors need only Debug), and the daemon's line
/// should read as words.
impl fmt::Debug for SpiError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl std::error::Error for SpiError {}

impl spi::Error for SpiError {
    fn kind(&self) -> spi::ErrorKind {
        // No errno of spidev means overrun, mode fault or framing.
        spi::ErrorKind::Other
    }
}

/// Microseconds that last at least `ns`: rounded up, where
/// linux-embedded-hal rounds down (1.5 µs gave 1 µs).
fn delay_us(ns: u32) -> u32 {
    ns.div_ceil(1000)
}

/// How many transfers `op` takes.
fn transfers_of(op: &Operation<'_, u8>) -> usize {
    match op {
        Operation::Read(_) | Operation::Write(_) | Operation::TransferInPlace(_) => 1,
        Operation::Transfer(r, w) if r.len() == w.len() => 1,
        Operation::Transfer(..) => 2,
        Operation::DelayNs(ns) => delay_us(*ns).div_ceil(MAX_DELAY_US) as usize,
    }
}

/// The transfers of one transaction, on the stack.
pub type Transfers<'a> = super::Stacked<SpidevTransfer<'a, 'a>, MAX_TRANSFERS>;

/// Add `t` to `list`. `transfers` counted first, so this never fails; an
/// error, not a panic, if a miscount ever let it.
fn push<'a>(list: &mut Transfers<'a>, t: SpidevTransfer<'a, 'a>) -> Result<(), SpiError> {
    let needed = list.as_slice().len() + 1;
    list.push(t).ok_or(SpiError::TooManyTransfers { needed })
}

/// The spidev transfers that carry `ops`, in order: the pure half of
/// [`LinuxSpi::transaction`] (no ioctl), public so that tests check it.
///
/// As linux-embedded-hal does: a `Transfer` of unequal lengths is a
/// full-duplex transfer of the common length, then the rest of the longer
/// side alone (spidev's `read_write` requires equal lengths); a
/// `TransferInPlace` is one transfer whose tx and rx are the same buffer,
/// which spidev allows (the kernel copies tx into its own bounce buffer
/// before the transfer, rx back after it). Unlike it, a `DelayNs` is
/// rounded up to whole microseconds and one longer than 65.535 ms is
/// several delay transfers (it capped them), and a zero delay is none.
pub fn transfers<'a>(ops: &'a mut [Operation<'_, u8>]) -> Result<Transfers<'a>, SpiError> {
    let needed: usize = ops.iter().map(transfers_of).sum();
    if needed > MAX_TRANSFERS {
        return Err(SpiError::TooManyTransfers { needed });
    }
    let mut t = Transfers::new(Default::default());
    for op in ops.iter_mut() {
        match op {
            Operation::Read(buf) => push(&mut t, SpidevTransfer::read(buf))?,
            Operation::Write(buf) => push(&mut t, SpidevTransfer::write(buf))?,
            Operation::Transfer(read, write) => {
                let n = read.len().min(write.len());
                let (r, r_rest) = read.split_at_mut(n);
                let (w, w_rest) = write.split_at(n);
                push(&mut t, SpidevTransfer::read_write(w, r))?;
                if !r_rest.is_empty() {
                    push(&mut t, SpidevTransfer::read(r_rest))?;
                } else if !w_rest.is_empty() {
                    push(&mut t, SpidevTransfer::write(w_rest))?;
                }
            }
            Operation::TransferInPlace(buf) => {
                push(&mut t, SpidevTransfer::read_write_in_place(buf))?
            }
            Operation::DelayNs(ns) => {
                let mut us = delay_us(*ns);
                while us > 0 {
                    let step = us.min(MAX_DELAY_US);
                    push(
                        &mut t,
                        SpidevTransfer::delay(u16::try_from(step).unwrap_or(u16::MAX)),
                    )?;
                    us -= step;
                }
            }
        }
    }
    Ok(t)
}

/// One spidev device (one chip select) as an embedded-hal [`SpiDevice`].
pub struct LinuxSpi {
    dev: Spidev,
}

impl LinuxSpi {
    /// Open `path` (e.g. `/dev/spidev0.0`); nothing is configured yet.
    pub fn open(path: impl AsRef<Path>) -> io::Result<Self> {
        Spidev::open(path).map(|dev| LinuxSpi { dev })
    }

    /// What the MCP3x08 needs: SPI mode 0, 8-bit words, at most
    /// `max_speed_hz`.
    pub fn configure(&mut self, max_speed_hz: u32) -> io::Result<()> {
        let opts = SpidevOptions::new()
            .bits_per_word(8)
            .max_speed_hz(max_speed_hz)
            .mode(SpiModeFlags::SPI_MODE_0)
            .build();
        self.dev.configure(&opts)
    }
}

impl ErrorType for LinuxSpi {
    type Error = SpiError;
}

impl SpiDevice for LinuxSpi {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), SpiError> {
        let mut t = transfers(ops)?;
        if t.len == 0 {
            // Nothing to clock out (no operations, or zero delays only).
            return Ok(());
        }
        // One ioctl, no flush: SPI_IOC_MESSAGE is synchronous (the
        // `flush` linux-embedded-hal adds is a no-op on a File).
        self.dev
            .transfer_multiple(t.as_mut_slice())
            .map_err(SpiError::from_io)
    }
}
