//! A pseudo-terminal standing for a device on a USB serial port (an ADC
//! board, an autopilot): the slave is the port the code under test opens,
//! through a symlink as udev would name it; the master is the device.
//! "Unplug and replug" is: drop it, plug a new one behind the same link.

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use std::fs::File;
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::Path;

/// The device's end of a raw pty pair, and the port's end kept open so
/// that the pty lives until this is dropped.
pub struct Pty {
    pub master: File,
    _slave: OwnedFd,
}

impl Pty {
    /// A new raw pty whose port is reached through `link` (a link left
    /// there by an earlier one is replaced).
    pub fn plug(link: &Path) -> Pty {
        let pty = openpty(None, None).expect("openpty");
        let mut t = tcgetattr(&pty.slave).expect("tcgetattr");
        cfmakeraw(&mut t);
        tcsetattr(&pty.slave, SetArg::TCSANOW, &t).expect("tcsetattr");
        let name = nix::unistd::ttyname(&pty.slave).expect("ttyname");
        let _ = std::fs::remove_file(link);
        std::os::unix::fs::symlink(name, link).expect("symlink");
        Pty {
            master: File::from(pty.master),
            _slave: pty.slave,
        }
    }

    /// The same with non-blocking writes on the device's side: a device
    /// whose port nobody reads must not stall the thread that feeds it.
    pub fn nonblocking(self) -> Pty {
        fcntl(
            self.master.as_raw_fd(),
            FcntlArg::F_SETFL(OFlag::O_NONBLOCK),
        )
        .expect("O_NONBLOCK");
        self
    }
}
