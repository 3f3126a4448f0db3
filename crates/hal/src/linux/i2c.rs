//! An embedded-hal 1.0 [`I2c`] over Linux i2c-dev that allocates nothing
//! per transaction. linux-embedded-hal 0.4 collects every transaction's
//! messages into a `Vec`, and reopens the device file whenever the address
//! changes (several ADS1115 on one bus: every transaction). Here the
//! messages are built in a fixed array on the stack ([`Messages`]), each
//! carrying its address, and go to the kernel in one `I2C_RDWR` ioctl on
//! the bus (`LinuxI2CBus`): one syscall per transaction, no reopen.

use std::fmt;
use std::path::Path;

use embedded_hal::i2c::{self, ErrorType, I2c, NoAcknowledgeSource, Operation, SevenBitAddress};
use i2cdev::core::{I2CMessage, I2CTransfer};
use i2cdev::linux::{I2CMessageFlags, LinuxI2CBus, LinuxI2CDevice, LinuxI2CError, LinuxI2CMessage};
use nix::errno::Errno;

/// Most messages one transaction may have (the kernel takes 42). Our ADS1115
/// and ADS7828 drivers use one (write, read) or two (write_read).
pub const MAX_MESSAGES: usize = 8;

/// Why a transaction failed. `Copy` and allocation-free, so that a chip
/// failing on every frame costs nothing to report.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum I2cError {
    /// The ioctl `call` failed with `errno` for the chip at `addr`.
    Os {
        call: &'static str,
        addr: u16,
        errno: Errno,
    },
    /// The operations are more than [`MAX_MESSAGES`] messages.
    TooManyMessages { needed: usize },
    /// A buffer longer than an I²C message can say (its `len` is a `u16`).
    TooLong { len: usize },
}

/// The errno of an i2cdev error (its `Io` holds an OS error; a kernel call
/// gives `Errno`).
fn errno_of(e: &LinuxI2CError) -> Errno {
    match e {
        LinuxI2CError::Errno(n) => Errno::from_raw(*n),
        LinuxI2CError::Io(e) => e
            .raw_os_error()
            .map_or(Errno::UnknownErrno, Errno::from_raw),
    }
}

impl fmt::Display for I2cError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            // Errno's Display names it, with nix's words ("ENXIO: No such
            // device or address"); two get a hint.
            I2cError::Os { call, addr, errno } => {
                write!(f, "{call} to 0x{addr:02X}: {errno}")?;
                match errno {
                    Errno::ENOTTY => f.write_str(" (not an i2c-dev bus?)"),
                    Errno::EBUSY => f.write_str(" (a kernel driver has claimed the address)"),
                    _ => Ok(()),
                }
            }
            I2cError::TooManyMessages { needed } => write!(
                f,
                "I2C transaction of {needed} messages, at most {MAX_MESSAGES} supported"
            ),
            I2cError::TooLong { len } => {
                write!(
                    f,
                    "I2C message of {len} bytes, at most {} possible",
                    u16::MAX
                )
            }
        }
    }
}

/// The same words as Display: the drivers' `DriverError` prints a bus error
/// with `{:?}` (embedded-hal errors need only Debug), and the daemon's line
/// should read as words.
impl fmt::Debug for I2cError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl std::error::Error for I2cError {}

impl i2c::Error for I2cError {
    /// The kernel's I²C fault codes (Documentation/i2c/fault-codes.rst):
    /// ENXIO, no ACK to the address; EREMOTEIO, what many adapters (bcm2835,
    /// designware) return for a NAK of address or data; EAGAIN, arbitration
    /// lost. The rest (EIO, ETIMEDOUT, ENOTTY, ...) say nothing more precise.
    fn kind(&self) -> i2c::ErrorKind {
        use i2c::ErrorKind;
        match self {
            // I2C_SLAVE's errors are about the address, not the wire.
            I2cError::Os {
                call: "I2C_SLAVE", ..
            } => ErrorKind::Other,
            I2cError::Os { errno, .. } => match errno {
                Errno::ENXIO => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address),
                Errno::EREMOTEIO => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Unknown),
                Errno::EAGAIN => ErrorKind::ArbitrationLoss,
                _ => ErrorKind::Other,
            },
            I2cError::TooManyMessages { .. } | I2cError::TooLong { .. } => ErrorKind::Other,
        }
    }
}

/// The messages of one transaction, on the stack.
pub type Messages<'a> = super::Stacked<LinuxI2CMessage<'a>, MAX_MESSAGES>;

/// The i2c-dev messages that carry `ops` to the chip at `addr`: the pure
/// half of [`LinuxI2c::transaction`] (no ioctl), public so that tests
/// check it.
///
/// Each message has the address and its direction (`I2C_M_RD` for a
/// read); one in the same direction as the one before it also has
/// `I2C_M_NOSTART`, so that the bytes follow on without a repeated start,
/// as embedded-hal's contract says of adjacent operations of one kind (and
/// as i2cdev's `LinuxI2CDevice`, under linux-embedded-hal, did).
pub fn messages<'a>(addr: u16, ops: &'a mut [Operation<'_>]) -> Result<Messages<'a>, I2cError> {
    let ops_len = ops.len();
    if ops_len > MAX_MESSAGES {
        return Err(I2cError::TooManyMessages { needed: ops_len });
    }
    let mut m = Messages::new(std::array::from_fn(|_| LinuxI2CMessage::write(&[])));
    let mut previous_read = None;
    for op in ops.iter_mut() {
        // i2cdev would cut the length to 16 bits without a word.
        let fits = |len: usize| {
            (len <= usize::from(u16::MAX))
                .then_some(())
                .ok_or(I2cError::TooLong { len })
        };
        let (read, msg) = match op {
            Operation::Read(buf) => {
                fits(buf.len())?;
                (true, LinuxI2CMessage::read(buf))
            }
            Operation::Write(buf) => {
                fits(buf.len())?;
                (false, LinuxI2CMessage::write(buf))
            }
        };
        let mut flags = I2CMessageFlags::empty();
        if read {
            flags |= I2CMessageFlags::READ;
        }
        if previous_read == Some(read) {
            flags |= I2CMessageFlags::NO_START;
        }
        previous_read = Some(read);
        // Counted above: there is room.
        m.push(msg.with_address(addr).with_flags(flags))
            .ok_or(I2cError::TooManyMessages { needed: ops_len })?;
    }
    Ok(m)
}

/// One i2c-dev bus (e.g. `/dev/i2c-1`) as an embedded-hal [`I2c`]: every
/// transaction names its chip, so one value serves every chip on the bus.
/// 7-bit addresses only (every chip we read has one).
pub struct LinuxI2c {
    bus: LinuxI2CBus,
}

impl LinuxI2c {
    /// Open `path` as linux-embedded-hal did: the `I2C_SLAVE` (address 0)
    /// and `I2C_PEC` ioctls of `LinuxI2CDevice::new` refuse a file that is
    /// not an i2c-dev bus here, at open, with the same error, not at the
    /// first frame.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, LinuxI2CError> {
        drop(LinuxI2CDevice::new(path.as_ref(), 0)?);
        Self::open_unchecked(path)
    }

    /// Open `path` without asking it anything (its first transaction
    /// fails if it is not an i2c-dev bus): tests open a regular file.
    pub fn open_unchecked(path: impl AsRef<Path>) -> Result<Self, LinuxI2CError> {
        LinuxI2CBus::new(path).map(|bus| LinuxI2c { bus })
    }

    /// Refuse `addr` on the bus at `path` if a kernel driver has claimed
    /// it (`I2C_SLAVE` answers EBUSY): `I2C_RDWR` does not check, and a
    /// chip read by a kernel driver and by us at once gives both garbage.
    /// linux-embedded-hal's `I2C_SLAVE` on each address change checked it
    /// at the chip's first transaction; this does once, at open.
    pub fn check_address(path: impl AsRef<Path>, addr: u8) -> Result<(), I2cError> {
        let addr = u16::from(addr);
        LinuxI2CDevice::new(path, addr)
            .map(drop)
            .map_err(|e| I2cError::Os {
                call: "I2C_SLAVE",
                addr,
                errno: errno_of(&e),
            })
    }
}

impl ErrorType for LinuxI2c {
    type Error = I2cError;
}

impl I2c<SevenBitAddress> for LinuxI2c {
    fn transaction(&mut self, address: u8, ops: &mut [Operation<'_>]) -> Result<(), I2cError> {
        let addr = u16::from(address);
        let mut m = messages(addr, ops)?;
        if m.len == 0 {
            // The kernel refuses an empty I2C_RDWR (EINVAL); there is
            // nothing to do.
            return Ok(());
        }
        self.bus
            .transfer(m.as_mut_slice())
            .map(drop)
            .map_err(|e| I2cError::Os {
                call: "I2C_RDWR",
                addr,
                errno: errno_of(&e),
            })
    }
}
