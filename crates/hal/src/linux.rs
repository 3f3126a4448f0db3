//! The real buses: Linux spidev and i2c-dev through `linux-embedded-hal`,
//! compiled only with feature `linux` so that simulator builds and tests
//! need no device files.

use linux_embedded_hal::spidev::{SpiModeFlags, SpidevOptions};
use linux_embedded_hal::{I2cdev, SpidevDevice};

use crate::bank::{BoardSource, I2cBank, I2cSlot, SpiBank, StdDelay};
use crate::config::{Common, I2cChipPlan, ValidBackend};
use crate::drivers::ads1115::Ads1115;
use crate::drivers::ads7828::Ads7828;
use crate::drivers::mcp3x08::Mcp3x08;
use crate::pace::Stop;
use crate::{FrameSource, HalError};

fn open_buses(buses: &[String]) -> Result<Vec<(String, I2cdev)>, HalError> {
    buses
        .iter()
        .map(|b| {
            I2cdev::new(b)
                .map(|d| (b.clone(), d))
                .map_err(|e| HalError::Open {
                    place: b.clone(),
                    msg: e.to_string(),
                })
        })
        .collect()
}

fn i2c_source<C: crate::bank::I2cAdc + 'static>(
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
    let mut bank =
        I2cBank::new(open_buses(buses)?, slots, StdDelay).map_err(|msg| HalError::Open {
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
    Ok(Box::new(BoardSource::new(
        bank,
        common.map,
        common.temp.clone().start(),
        common.pacer(stop),
    )))
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
                let mut d = SpidevDevice::open(&c.device).map_err(|e| HalError::Open {
                    place: place.clone(),
                    msg: e.to_string(),
                })?;
                let opts = SpidevOptions::new()
                    .bits_per_word(8)
                    .max_speed_hz(c.max_speed_hz)
                    .mode(SpiModeFlags::SPI_MODE_0)
                    .build();
                d.0.configure(&opts).map_err(|e| HalError::Open {
                    place,
                    msg: e.to_string(),
                })?;
                devs.push((c.name.clone(), Mcp3x08::new(d, *kind)));
            }
            Ok(Box::new(BoardSource::new(
                SpiBank::new(devs),
                common.map,
                common.temp.clone().start(),
                common.pacer(stop),
            )))
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
