//! Results go to stdout through here, never `print!`: that panics when the
//! reader has gone (`| head`, `| true`). A closed pipe ends the program
//! quietly with success, as Unix tools do (everything is written to its
//! files before a result is printed); any other failure to write is one
//! line and exit 1.

use std::io::Write;

/// Write `args` to stdout, flushed, so that a closed pipe shows here and
/// not in the unchecked flush at exit.
pub fn print(args: std::fmt::Arguments) {
    let mut o = std::io::stdout().lock();
    if let Err(e) = o.write_fmt(args).and_then(|()| o.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("lightpose: writing to stdout: {e}");
        std::process::exit(1);
    }
}

/// `print!` through [`print`].
macro_rules! out {
    ($($t:tt)*) => {
        $crate::stdout::print(format_args!($($t)*))
    };
}

/// `println!` through [`print`].
macro_rules! outln {
    ($($t:tt)*) => {
        $crate::stdout::print(format_args!("{}\n", format_args!($($t)*)))
    };
}

pub(crate) use {out, outln};
