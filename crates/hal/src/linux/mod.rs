//! The real buses: Linux spidev and i2c-dev, compiled only with feature
//! `linux` so that simulator builds and tests need no device files. The
//! embedded-hal implementations are our own ([`spi`], [`i2c`]), directly
//! over the `spidev` and `i2cdev` crates, because linux-embedded-hal 0.4
//! allocates a `Vec` in every transaction, i.e. on every frame.

pub mod i2c;
pub mod spi;

use crate::bank::{BoardSource, I2cAdc, I2cBank, I2cSlot, SpiBank, StdDelay};
use crate::config::{Common, I2cChipPlan, ValidBackend};
use crate::drivers::ads1115::Ads1115;
use crate::drivers::ads7828::Ads7828;
use crate::drivers::mcp3x08::Mcp3x08;
use crate::pace::Stop;
use crate::{FrameSource, HalError};
use i2c::LinuxI2c;
use spi::LinuxSpi;

/// Up to `N` items of one transaction on the stack (SPI transfers, I²C
/// messages): the kernel reads the ones in use as one array, and nothing
/// is allocated per transaction.
pub struct Stacked<T, const N: usize> {
    list: [T; N],
    len: usize,
}

impl<T, const N: usize> Stacked<T, N> {
    fn new(list: [T; N]) -> Self {
        Stacked { list, len: 0 }
    }

    /// Add `t`; `None` when all `N` are taken.
    fn push(&mut self, t: T) -> Option<()> {
        *self.list.get_mut(self.len)? = t;
        self.len += 1;
        Some(())
    }

    /// The items in use, in order: what the kernel reads.
    pub fn as_slice(&self) -> &[T] {
        &self.list[..self.len]
    }

    fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.list[..self.len]
    }
}

fn open_buses(buses: &[String]) -> Result<Vec<(String, LinuxI2c)>, HalError> {
    buses
        .iter()
        .map(|b| {
            LinuxI2c::open(b)
                .map(|d| (b.clone(), d))
                .map_err(|e| HalError::Open {
                    place: b.clone(),
                    msg: e.to_string(),
                })
        })
        .collect()
}

/// Refuse, at open, a chip whose address a kernel driver has claimed
/// ([`LinuxI2c::check_address`]); its place as the bank names it.
fn check_addresses<C: I2cAdc>(buses: &[String], chips: &[I2cChipPlan]) -> Result<(), HalError> {
    for p in chips {
        // A bus index out of range is I2cBank::new's to refuse.
        let Some(bus) = buses.get(p.bus) else {
            continue;
        };
        LinuxI2c::check_address(bus, p.address).map_err(|e| HalError::Open {
            place: format!(
                "board {} ({} 0x{:02X} on {bus})",
                p.name,
                C::NAME,
                p.address
            ),
            msg: e.to_string(),
        })?;
    }
    Ok(())
}

fn i2c_source<C: I2cAdc + 'static>(
    buses: &[String],
    chips: &[I2cChipPlan],
    make: impl Fn(u8) -> C,
    common: &Common,
    stop: &Stop,
) -> Result<Box<dyn FrameSource>, HalError> {
    let slots = chips
        .iter()
        .map(|p| I2cSlot {
            name: p.name.clone(),
            bus: p.bus,
            chip: make(p.address),
        })
        .collect();
    let opened = open_buses(buses)?;
    check_addresses::<C>(buses, chips)?;
    let mut bank = I2cBank::new(opened, slots, StdDelay).map_err(|msg| HalError::Open {
        place: "i2c".into(),
        msg,
    })?;
    // The ADS7828's internal reference is off at power-up: one discarded
    // conversion with PD = 11 per chip turns it on, then one wait for it to
    // settle (drivers::ads7828::REF_SETTLE_NS).
    bank.warm_up().map_err(|e| HalError::Open {
        place: "i2c".into(),
        msg: e.to_string(),
    })?;
    Ok(Box::new(
        BoardSource::new(
            bank,
            common.map,
            common.temp.clone().start(),
            common.pacer(stop),
        )
        .with_sampling(common.sampling()),
    ))
}

/// Open the SPI or I²C backend `v` describes.
pub fn open(v: &ValidBackend, stop: &Stop) -> Result<Box<dyn FrameSource>, HalError> {
    match v {
        ValidBackend::Spi {
            kind,
            chips,
            common,
        } => {
            let mut devs = Vec::with_capacity(chips.len());
            for c in chips {
                let place = format!("board {} ({})", c.name, c.device);
                let mut d = LinuxSpi::open(&c.device).map_err(|e| HalError::Open {
                    place: place.clone(),
                    msg: e.to_string(),
                })?;
                d.configure(c.max_speed_hz).map_err(|e| HalError::Open {
                    place,
                    msg: e.to_string(),
                })?;
                devs.push((c.name.clone(), Mcp3x08::new(d, *kind)));
            }
            Ok(Box::new(
                BoardSource::new(
                    SpiBank::new(devs),
                    common.map,
                    common.temp.clone().start(),
                    common.pacer(stop),
                )
                .with_sampling(common.sampling()),
            ))
        }
        ValidBackend::Ads1115 {
            fsr,
            data_rate,
            buses,
            chips,
            common,
        } => i2c_source(
            buses,
            chips,
            |a| Ads1115::new(a, *fsr, *data_rate),
            common,
            stop,
        ),
        ValidBackend::Ads7828 {
            power,
            buses,
            chips,
            common,
        } => i2c_source(buses, chips, |a| Ads7828::new(a, *power), common, stop),
        ValidBackend::Serial { .. } | ValidBackend::Sim(_) | ValidBackend::Replay(_) => {
            Err(HalError::Open {
                place: "source".into(),
                msg: "not a Linux bus backend".into(),
            })
        }
    }
}
