//! The board kinds' tables — MCP3008/MCP3208 on SPI, ADS1115 and ADS7828 on
//! I²C, microcontroller boards on serial — and one validator per kind. What
//! they share (rate, boards, channel map, temperature) is [`Common`].

use std::time::Duration;

use serde::Deserialize;

use super::temp::{temp_plan, TempConfig, TempPlan};
use super::{err, positive_to, rate, unique_names, Env, ValidBackend};
use crate::chanmap::{BoardSpec, ChannelMap, MapEntry, MAX_CH};
use crate::drivers::ads1115::{self, DataRate, Fsr};
use crate::drivers::ads7828::{self, PowerMode};
use crate::drivers::mcp3x08::McpKind;
use crate::pace::{Pacer, Stop};
use crate::serial::SerialBoard;
use crate::HalError;

/// Highest reference or supply voltage a table may give: far above any ADC's.
pub const MAX_V: f64 = 50.0;
/// Longest wait for a serial board's line; a stop ends it sooner anyway.
pub const MAX_TIMEOUT_MS: u64 = 60_000;

fn v5() -> f64 {
    5.0
}
fn baud_default() -> u32 {
    115_200
}
fn eight() -> u8 {
    8
}
fn ten_bits() -> u8 {
    10
}
fn timeout_default() -> u64 {
    1000
}
fn fsr_default() -> f64 {
    4.096
}
fn dr_default() -> u16 {
    860
}

/// MCP3008 / MCP3208 chips, one spidev device (chip select) each.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpiConfig {
    /// Absent: the env's rate.
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// ADC reference (for a thermistor channel).
    #[serde(default = "v5")]
    pub v_ref: f64,
    pub chips: Vec<SpiChipConfig>,
    pub map: Vec<MapEntry>,
    #[serde(default)]
    pub temperature: TempConfig,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpiChipConfig {
    pub name: String,
    /// e.g. `/dev/spidev0.0`
    pub device: String,
    /// Defaults to the chip's maximum at 5 V.
    #[serde(default)]
    pub max_speed_hz: Option<u32>,
}

/// An I²C chip: which bus device and which address.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct I2cChipConfig {
    pub name: String,
    /// e.g. `/dev/i2c-1`
    pub bus: String,
    pub address: u8,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ads1115Config {
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// PGA full scale in volts: 6.144, 4.096, 2.048, 1.024, 0.512, 0.256.
    #[serde(default = "fsr_default")]
    pub fsr_v: f64,
    /// 8, 16, 32, 64, 128, 250, 475 or 860.
    #[serde(default = "dr_default")]
    pub data_rate_sps: u16,
    pub chips: Vec<I2cChipConfig>,
    pub map: Vec<MapEntry>,
    #[serde(default)]
    pub temperature: TempConfig,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ads7828Config {
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// Use the internal 2.5 V reference; otherwise `v_ref` is required.
    #[serde(default = "super::true_")]
    pub internal_ref: bool,
    #[serde(default)]
    pub v_ref: Option<f64>,
    pub chips: Vec<I2cChipConfig>,
    pub map: Vec<MapEntry>,
    #[serde(default)]
    pub temperature: TempConfig,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialConfig {
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// Resolution every line must declare.
    #[serde(default = "ten_bits")]
    pub adc_bits: u8,
    #[serde(default = "v5")]
    pub v_ref: f64,
    /// How long a frame waits for a fresh line of each board.
    #[serde(default = "timeout_default")]
    pub timeout_ms: u64,
    pub boards: Vec<SerialBoardConfig>,
    pub map: Vec<MapEntry>,
    #[serde(default)]
    pub temperature: TempConfig,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialBoardConfig {
    pub name: String,
    /// The `<board>` field its lines carry.
    pub id: u8,
    pub path: String,
    #[serde(default = "baud_default")]
    pub baud: u32,
    #[serde(default = "eight")]
    pub channels: u8,
}

/// What every board backend has: rate, boards, map and temperature.
#[derive(Debug, Clone, PartialEq)]
pub struct Common {
    /// `None`: as fast as possible.
    pub rate_hz: Option<f64>,
    pub boards: Vec<BoardSpec>,
    pub map: ChannelMap,
    pub temp: TempPlan,
    pub bits: u8,
}

impl Common {
    /// The pacer of these boards, its waits ended early by `stop`.
    pub fn pacer(&self, stop: &Stop) -> Pacer {
        Pacer::from_rate(self.rate_hz).stoppable(stop.clone())
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct SpiChipPlan {
    pub name: String,
    pub device: String,
    pub max_speed_hz: u32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct I2cChipPlan {
    pub name: String,
    /// Index into the backend's `buses`.
    pub bus: usize,
    pub address: u8,
}

/// The part every board kind checks the same way.
struct Shared<'a> {
    rate_hz: Option<f64>,
    map: &'a [MapEntry],
    temp: &'a TempConfig,
    bits: u8,
    v_ref: f64,
}

fn common(s: Shared, boards: Vec<BoardSpec>, env: &dyn Env) -> Result<Common, HalError> {
    let rate_hz = rate(s.rate_hz, env)?;
    let map = ChannelMap::new(s.map, &boards)?;
    let temp = temp_plan(s.temp, &boards, &map, s.bits, s.v_ref)?;
    Ok(Common {
        rate_hz,
        boards,
        map,
        temp,
        bits: s.bits,
    })
}

/// `kind = "mcp3008"` / `"mcp3208"`.
pub(super) fn spi(c: &SpiConfig, kind: McpKind, env: &dyn Env) -> Result<ValidBackend, HalError> {
    unique_names("chips", c.chips.iter().map(|c| c.name.as_str()))?;
    let mut devices: Vec<&str> = Vec::new();
    let mut chips = Vec::new();
    for ch in &c.chips {
        if devices.contains(&ch.device.as_str()) {
            return Err(err(
                format!("chips.{}.device", ch.name),
                format!("{} is used by two chips", ch.device),
            ));
        }
        devices.push(&ch.device);
        let hz = ch.max_speed_hz.unwrap_or(kind.max_clock_hz());
        if hz == 0 || hz > kind.max_clock_hz() {
            return Err(err(
                format!("chips.{}.max_speed_hz", ch.name),
                format!(
                    "{hz} is not in 1..={} for {}",
                    kind.max_clock_hz(),
                    kind.name()
                ),
            ));
        }
        chips.push(SpiChipPlan {
            name: ch.name.clone(),
            device: ch.device.clone(),
            max_speed_hz: hz,
        });
    }
    let boards = chips
        .iter()
        .map(|ch| BoardSpec {
            name: ch.name.clone(),
            channels: 8,
        })
        .collect();
    let shared = Shared {
        rate_hz: c.rate_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: kind.bits(),
        v_ref: positive_to("v_ref", c.v_ref, MAX_V, " V")?,
    };
    Ok(ValidBackend::Spi {
        kind,
        chips,
        common: common(shared, boards, env)?,
    })
}

/// `kind = "ads1115"`.
pub(super) fn ads1115(c: &Ads1115Config, env: &dyn Env) -> Result<ValidBackend, HalError> {
    let fsr = Fsr::from_volts(c.fsr_v).ok_or_else(|| {
        err(
            "fsr_v",
            format!(
                "{} is not one of 6.144, 4.096, 2.048, 1.024, 0.512, 0.256",
                c.fsr_v
            ),
        )
    })?;
    let data_rate = DataRate::from_sps(c.data_rate_sps).ok_or_else(|| {
        err(
            "data_rate_sps",
            format!(
                "{} is not one of 8, 16, 32, 64, 128, 250, 475, 860",
                c.data_rate_sps
            ),
        )
    })?;
    let (buses, chips) = i2c_layout(&c.chips, ads1115::ADDR_MIN, ads1115::ADDR_MAX)?;
    let boards = i2c_boards(&chips, ads1115::CHANNELS);
    let shared = Shared {
        rate_hz: c.rate_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: ads1115::BITS,
        v_ref: fsr.volts(),
    };
    Ok(ValidBackend::Ads1115 {
        fsr,
        data_rate,
        buses,
        chips,
        common: common(shared, boards, env)?,
    })
}

/// `kind = "ads7828"`.
pub(super) fn ads7828(c: &Ads7828Config, env: &dyn Env) -> Result<ValidBackend, HalError> {
    let (power, v_ref) = match (c.internal_ref, c.v_ref) {
        (true, None) => (PowerMode::InternalRef, 2.5),
        (true, Some(v)) if (v - 2.5).abs() < 1e-9 => (PowerMode::InternalRef, 2.5),
        (true, Some(v)) => {
            return Err(err(
                "v_ref",
                format!("{v} V given with internal_ref = true (the internal reference is 2.5 V)"),
            ))
        }
        (false, Some(v)) => (
            PowerMode::ExternalRef,
            positive_to("v_ref", v, MAX_V, " V")?,
        ),
        (false, None) => return Err(err("v_ref", "required when internal_ref = false")),
    };
    let (buses, chips) = i2c_layout(&c.chips, ads7828::ADDR_MIN, ads7828::ADDR_MAX)?;
    let boards = i2c_boards(&chips, ads7828::CHANNELS);
    let shared = Shared {
        rate_hz: c.rate_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: 12,
        v_ref,
    };
    Ok(ValidBackend::Ads7828 {
        power,
        buses,
        chips,
        common: common(shared, boards, env)?,
    })
}

/// `kind = "serial"`.
pub(super) fn serial(c: &SerialConfig, env: &dyn Env) -> Result<ValidBackend, HalError> {
    if !(1..=16).contains(&c.adc_bits) {
        return Err(err("adc_bits", format!("{} is not in 1..=16", c.adc_bits)));
    }
    if !(1..=MAX_TIMEOUT_MS).contains(&c.timeout_ms) {
        return Err(err(
            "timeout_ms",
            format!("{} is not in 1..={MAX_TIMEOUT_MS} ms", c.timeout_ms),
        ));
    }
    unique_names("boards", c.boards.iter().map(|b| b.name.as_str()))?;
    let mut boards: Vec<SerialBoard> = Vec::new();
    for b in &c.boards {
        serial_board(b, &boards)?;
        boards.push(SerialBoard {
            name: b.name.clone(),
            id: b.id,
            path: b.path.clone(),
            baud: b.baud,
            channels: b.channels,
        });
    }
    let specs = boards
        .iter()
        .map(|b| BoardSpec {
            name: b.name.clone(),
            channels: b.channels,
        })
        .collect();
    let shared = Shared {
        rate_hz: c.rate_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: c.adc_bits,
        v_ref: positive_to("v_ref", c.v_ref, MAX_V, " V")?,
    };
    Ok(ValidBackend::Serial {
        boards,
        timeout: Duration::from_millis(c.timeout_ms),
        common: common(shared, specs, env)?,
    })
}

/// One serial board, against the ones before it.
fn serial_board(b: &SerialBoardConfig, before: &[SerialBoard]) -> Result<(), HalError> {
    if before.iter().any(|x| x.id == b.id) {
        return Err(err(
            format!("boards.{}.id", b.name),
            format!("id {} is used twice", b.id),
        ));
    }
    if before.iter().any(|x| x.path == b.path) {
        return Err(err(
            format!("boards.{}.path", b.name),
            format!("{} is used twice", b.path),
        ));
    }
    if b.channels == 0 || b.channels as usize > MAX_CH {
        return Err(err(
            format!("boards.{}.channels", b.name),
            format!("{} is not in 1..={MAX_CH}", b.channels),
        ));
    }
    if !(50..=4_000_000).contains(&b.baud) {
        return Err(err(
            format!("boards.{}.baud", b.name),
            format!("{} is not in 50..=4000000", b.baud),
        ));
    }
    Ok(())
}

fn i2c_boards(chips: &[I2cChipPlan], channels: u8) -> Vec<BoardSpec> {
    chips
        .iter()
        .map(|p| BoardSpec {
            name: p.name.clone(),
            channels,
        })
        .collect()
}

/// Buses in order of first use, and each chip's bus index; two chips on one
/// bus and address are refused.
fn i2c_layout(
    chips: &[I2cChipConfig],
    lo: u8,
    hi: u8,
) -> Result<(Vec<String>, Vec<I2cChipPlan>), HalError> {
    unique_names("chips", chips.iter().map(|c| c.name.as_str()))?;
    let mut buses: Vec<String> = Vec::new();
    let mut plans: Vec<I2cChipPlan> = Vec::new();
    for c in chips {
        if !(lo..=hi).contains(&c.address) {
            return Err(err(
                format!("chips.{}.address", c.name),
                format!("0x{:02X} is not in 0x{lo:02X}..=0x{hi:02X}", c.address),
            ));
        }
        let bus = match buses.iter().position(|b| *b == c.bus) {
            Some(i) => i,
            None => {
                buses.push(c.bus.clone());
                buses.len() - 1
            }
        };
        if let Some(other) = plans
            .iter()
            .find(|p| p.bus == bus && p.address == c.address)
        {
            return Err(err(
                format!("chips.{}.address", c.name),
                format!(
                    "0x{:02X} on {} is also chip \"{}\"",
                    c.address, c.bus, other.name
                ),
            ));
        }
        plans.push(I2cChipPlan {
            name: c.name.clone(),
            bus,
            address: c.address,
        });
    }
    Ok((buses, plans))
}
