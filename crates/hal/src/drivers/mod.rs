//! Drivers for the ADC chips the boards use, each generic over the
//! embedded-hal 1.0 bus traits so that they run on Linux spidev/i2c-dev, on
//! a microcontroller, or against scripted transactions in tests alike.

pub mod ads1115;
pub mod ads7828;
pub mod mcp3x08;

/// What can go wrong talking to one chip.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum DriverError<E: core::fmt::Debug> {
    /// The bus transaction itself failed.
    #[error("bus: {0:?}")]
    Bus(E),
    /// A channel the chip does not have (a config error caught late).
    #[error("no channel {ch} (chip has {max})")]
    NoChannel { ch: u8, max: u8 },
    /// The chip never said its conversion was done.
    #[error("conversion not finished after {polls} polls")]
    NotReady { polls: u32 },
}
