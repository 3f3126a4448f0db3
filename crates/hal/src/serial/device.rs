//! A serial port as the reader keeps it, and the wait for its next bytes.
//!
//! On Unix the wait is a `poll` of the port's descriptor, not serialport's
//! read timeout: serialport reports an expired timeout as an `io::Error`
//! built anew each time (a boxed message, converted twice: about six
//! allocations), so a silent board, waited for on every frame for hours,
//! would allocate on every frame. Elsewhere the read itself waits.

use std::time::Duration;

use serialport::SerialPortBuilder;

/// An open port.
#[cfg(unix)]
pub(super) type Device = serialport::TTYPort;
/// An open port.
#[cfg(not(unix))]
pub(super) type Device = Box<dyn serialport::SerialPort>;

pub(super) fn open(b: SerialPortBuilder) -> serialport::Result<Device> {
    #[cfg(unix)]
    {
        b.open_native()
    }
    #[cfg(not(unix))]
    {
        b.open()
    }
}

/// Wait up to `wait` (rounded up to a millisecond) until `dev` has bytes
/// to read, has hung up or has failed: true then, and the read says
/// which. False: nothing came (or a signal ended the wait), and there is
/// no need to read. Allocates nothing.
#[cfg(unix)]
pub(super) fn readable(dev: &Device, wait: Duration) -> bool {
    use nix::errno::Errno;
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    use std::os::fd::{AsRawFd, BorrowedFd};

    // SAFETY: the descriptor is `dev`'s, and `dev` is borrowed (so open)
    // for as long as `fd` lives: until this function returns.
    let fd = unsafe { BorrowedFd::borrow_raw(dev.as_raw_fd()) };
    let mut fds = [PollFd::new(fd, PollFlags::POLLIN)];
    let ms = wait.as_micros().div_ceil(1000).min(u128::from(u16::MAX)) as u16;
    match poll(&mut fds, PollTimeout::from(ms)) {
        Ok(0) | Err(Errno::EINTR) => false,
        // Bytes, a hang-up, or a poll that failed: the read tells.
        Ok(_) | Err(_) => true,
    }
}

/// Elsewhere the read waits, with the port's timeout.
#[cfg(not(unix))]
pub(super) fn readable(_: &Device, _: Duration) -> bool {
    true
}
