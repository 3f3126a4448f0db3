//! The backend's part of the daemon's config file: serde structs that the
//! daemon embeds (unknown keys refused, so a typo is an error and not a
//! silently ignored setting), and [`BackendConfig::validate`], which turns
//! them into typed values or one clear error naming the key.
//!
//! Rates: `rate_hz` defaults to 5 Hz (the paper's); `rate_hz = 0` means as
//! fast as the source can go.

use std::path::PathBuf;
use std::time::Duration;

use lightpose_core::{COLS, ROWS};
use serde::Deserialize;

use crate::chanmap::{BoardSpec, ChannelMap, MapEntry, MAX_CH};
use crate::drivers::ads1115::{self, DataRate, Fsr};
use crate::drivers::ads7828::{self, PowerMode};
use crate::drivers::mcp3x08::McpKind;
use crate::serial::SerialBoard;
use crate::temp::{Ds18b20, TempKind, TempReader, Thermistor, ThermistorPosition};
use crate::HalError;

fn rate_default() -> f64 {
    5.0
}
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
fn w1_root() -> PathBuf {
    PathBuf::from("/sys/bus/w1/devices")
}
fn w1_interval() -> f64 {
    2.0
}
fn w1_max_age() -> f64 {
    10.0
}
fn true_() -> bool {
    true
}
// A common 10 kΩ (B ≈ 3950) NTC.
fn sh_a() -> f64 {
    1.009249522e-3
}
fn sh_b() -> f64 {
    2.378405444e-4
}
fn sh_c() -> f64 {
    2.019202697e-7
}
fn min_c() -> f64 {
    -5.0
}
fn max_c() -> f64 {
    45.0
}
fn low() -> ThermistorPosition {
    ThermistorPosition::Low
}

/// Which source of frames, and its settings. `kind` selects the variant.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum BackendConfig {
    Mcp3008(SpiConfig),
    Mcp3208(SpiConfig),
    Ads1115(Ads1115Config),
    Ads7828(Ads7828Config),
    Serial(SerialConfig),
    Sim(SimConfig),
}

/// MCP3008 / MCP3208 chips, one spidev device (chip select) each.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpiConfig {
    #[serde(default = "rate_default")]
    pub rate_hz: f64,
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
    #[serde(default = "rate_default")]
    pub rate_hz: f64,
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
    #[serde(default = "rate_default")]
    pub rate_hz: f64,
    /// Use the internal 2.5 V reference; otherwise `v_ref` is required.
    #[serde(default = "true_")]
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
    #[serde(default = "rate_default")]
    pub rate_hz: f64,
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

/// The simulator as a source (see `mock.rs`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    #[serde(default = "rate_default")]
    pub rate_hz: f64,
    /// Scene file; absent = the simulator's default (the tank).
    #[serde(default)]
    pub scene: Option<PathBuf>,
    /// Trajectory CSV (`t,x,y,z,pitch,yaw`).
    pub trajectory: PathBuf,
    /// Start again at the trajectory's beginning when it ends.
    #[serde(default = "true_")]
    pub looping: bool,
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub faults: FaultConfig,
}

/// Faults the mock injects, for robustness tests of the daemon.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultConfig {
    /// A bus error on every N-th frame.
    #[serde(default)]
    pub bus_error_every: Option<u64>,
    /// A bus error with this probability per frame.
    #[serde(default)]
    pub bus_error_prob: f64,
    /// A dropped frame (its seq is skipped) on every N-th frame.
    #[serde(default)]
    pub drop_every: Option<u64>,
    #[serde(default)]
    pub drop_prob: f64,
    /// Channels that always read the same value.
    #[serde(default)]
    pub stuck: Vec<StuckChannel>,
    /// Seed of the fault draws (apart from the simulator's).
    #[serde(default)]
    pub seed: u64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StuckChannel {
    pub r: usize,
    pub c: usize,
    pub value: u16,
}

/// Where each frame's temperature comes from.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum TempConfig {
    /// Frames carry no temperature.
    #[default]
    None,
    Fixed {
        value_c: f64,
    },
    Ds18b20 {
        fallback_c: f64,
        #[serde(default = "w1_root")]
        root: PathBuf,
        #[serde(default)]
        device: Option<String>,
        #[serde(default = "w1_interval")]
        interval_s: f64,
        #[serde(default = "w1_max_age")]
        max_age_s: f64,
    },
    Thermistor {
        fallback_c: f64,
        board: String,
        channel: u8,
        r_fixed_ohm: f64,
        #[serde(default = "low")]
        position: ThermistorPosition,
        /// Divider supply; defaults to the ADC reference (ratiometric).
        #[serde(default)]
        v_supply: Option<f64>,
        #[serde(default = "sh_a")]
        a: f64,
        #[serde(default = "sh_b")]
        b: f64,
        #[serde(default = "sh_c")]
        c: f64,
        #[serde(default = "min_c")]
        min_c: f64,
        #[serde(default = "max_c")]
        max_c: f64,
    },
}

/// A validated temperature source, not yet started.
#[derive(Debug, Clone, PartialEq)]
pub enum TempPlan {
    None,
    Fixed(f64),
    Ds18b20 {
        sensor_root: PathBuf,
        device: Option<String>,
        interval: Duration,
        max_age: Duration,
        fallback_c: f64,
    },
    Thermistor {
        params: Thermistor,
        fallback_c: f64,
    },
}

impl TempPlan {
    /// Start it (the DS18B20 gets its reading thread).
    pub fn start(self) -> TempReader {
        match self {
            TempPlan::None => TempReader::new(TempKind::None, 0.0),
            TempPlan::Fixed(v) => TempReader::new(TempKind::Fixed(v), v),
            TempPlan::Ds18b20 {
                sensor_root,
                device,
                interval,
                max_age,
                fallback_c,
            } => TempReader::new(
                TempKind::Ds18b20(crate::temp::Ds18b20Watcher::spawn(
                    Ds18b20 {
                        root: sensor_root,
                        device,
                    },
                    interval,
                    max_age,
                )),
                fallback_c,
            ),
            TempPlan::Thermistor { params, fallback_c } => {
                TempReader::new(TempKind::Thermistor(params), fallback_c)
            }
        }
    }
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

/// A validated backend, ready to open.
#[derive(Debug, Clone, PartialEq)]
pub enum ValidBackend {
    Spi {
        kind: McpKind,
        chips: Vec<SpiChipPlan>,
        common: Common,
    },
    Ads1115 {
        fsr: Fsr,
        data_rate: DataRate,
        buses: Vec<String>,
        chips: Vec<I2cChipPlan>,
        common: Common,
    },
    Ads7828 {
        power: PowerMode,
        buses: Vec<String>,
        chips: Vec<I2cChipPlan>,
        common: Common,
    },
    Serial {
        boards: Vec<SerialBoard>,
        timeout: Duration,
        common: Common,
    },
    Sim(SimConfig),
}

fn err(key: impl Into<String>, msg: impl Into<String>) -> HalError {
    HalError::Config {
        key: key.into(),
        msg: msg.into(),
    }
}

fn rate(r: f64) -> Result<Option<f64>, HalError> {
    if !r.is_finite() || !(0.0..=10_000.0).contains(&r) {
        return Err(err(
            "rate_hz",
            format!("{r} is not in 0..=10000 (0 = as fast as possible)"),
        ));
    }
    Ok((r > 0.0).then_some(r))
}

fn positive(key: &str, v: f64) -> Result<f64, HalError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(err(key, format!("{v} must be a positive number")))
    }
}

fn unique_names<'a>(what: &str, names: impl Iterator<Item = &'a str>) -> Result<(), HalError> {
    let mut seen: Vec<&str> = Vec::new();
    for n in names {
        if n.is_empty() {
            return Err(err(what, "a name is empty"));
        }
        if seen.contains(&n) {
            return Err(err(what, format!("name \"{n}\" is used twice")));
        }
        seen.push(n);
    }
    if seen.is_empty() {
        return Err(err(what, "none configured"));
    }
    if seen.len() > 64 {
        return Err(err(what, format!("{} configured, at most 64", seen.len())));
    }
    Ok(())
}

fn temp_plan(
    t: &TempConfig,
    boards: &[BoardSpec],
    map: &ChannelMap,
    bits: u8,
    v_ref: f64,
) -> Result<TempPlan, HalError> {
    let finite = |key: &str, v: f64| {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(err(key, "must be a finite number"))
        }
    };
    Ok(match t {
        TempConfig::None => TempPlan::None,
        TempConfig::Fixed { value_c } => TempPlan::Fixed(finite("temperature.value_c", *value_c)?),
        TempConfig::Ds18b20 {
            fallback_c,
            root,
            device,
            interval_s,
            max_age_s,
        } => TempPlan::Ds18b20 {
            sensor_root: root.clone(),
            device: device.clone(),
            interval: Duration::from_secs_f64(positive("temperature.interval_s", *interval_s)?),
            max_age: Duration::from_secs_f64(positive("temperature.max_age_s", *max_age_s)?),
            fallback_c: finite("temperature.fallback_c", *fallback_c)?,
        },
        TempConfig::Thermistor {
            fallback_c,
            board,
            channel,
            r_fixed_ohm,
            position,
            v_supply,
            a,
            b,
            c,
            min_c,
            max_c,
        } => {
            let bi = boards
                .iter()
                .position(|x| &x.name == board)
                .ok_or_else(|| err("temperature.board", format!("unknown board \"{board}\"")))?;
            if *channel >= boards[bi].channels {
                return Err(err(
                    "temperature.channel",
                    format!("board \"{board}\" has no channel {channel}"),
                ));
            }
            if map.uses(bi, *channel) {
                return Err(err(
                    "temperature.channel",
                    format!("board \"{board}\" channel {channel} already feeds a detector"),
                ));
            }
            if min_c.partial_cmp(max_c) != Some(std::cmp::Ordering::Less) {
                return Err(err("temperature.min_c", "must be below max_c"));
            }
            TempPlan::Thermistor {
                params: Thermistor {
                    board: bi,
                    channel: *channel,
                    a: finite("temperature.a", *a)?,
                    b: finite("temperature.b", *b)?,
                    c: finite("temperature.c", *c)?,
                    r_fixed_ohm: positive("temperature.r_fixed_ohm", *r_fixed_ohm)?,
                    position: *position,
                    v_supply: positive("temperature.v_supply", v_supply.unwrap_or(v_ref))?,
                    v_ref,
                    bits,
                    min_c: *min_c,
                    max_c: *max_c,
                },
                fallback_c: finite("temperature.fallback_c", *fallback_c)?,
            }
        }
    })
}

fn common(
    rate_hz: f64,
    boards: Vec<BoardSpec>,
    map: &[MapEntry],
    temp: &TempConfig,
    bits: u8,
    v_ref: f64,
) -> Result<Common, HalError> {
    let rate_hz = rate(rate_hz)?;
    let map = ChannelMap::new(map, &boards)?;
    let temp = temp_plan(temp, &boards, &map, bits, v_ref)?;
    Ok(Common {
        rate_hz,
        boards,
        map,
        temp,
        bits,
    })
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

impl BackendConfig {
    /// The config's `kind`.
    pub fn kind(&self) -> &'static str {
        match self {
            BackendConfig::Mcp3008(_) => "mcp3008",
            BackendConfig::Mcp3208(_) => "mcp3208",
            BackendConfig::Ads1115(_) => "ads1115",
            BackendConfig::Ads7828(_) => "ads7828",
            BackendConfig::Serial(_) => "serial",
            BackendConfig::Sim(_) => "sim",
        }
    }

    /// Check everything that can be checked without opening a device.
    pub fn validate(&self) -> Result<ValidBackend, HalError> {
        match self {
            BackendConfig::Mcp3008(c) | BackendConfig::Mcp3208(c) => {
                let kind = if matches!(self, BackendConfig::Mcp3008(_)) {
                    McpKind::Mcp3008
                } else {
                    McpKind::Mcp3208
                };
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
                let boards = c
                    .chips
                    .iter()
                    .map(|ch| BoardSpec {
                        name: ch.name.clone(),
                        channels: 8,
                    })
                    .collect();
                let v_ref = positive("v_ref", c.v_ref)?;
                let common = common(
                    c.rate_hz,
                    boards,
                    &c.map,
                    &c.temperature,
                    kind.bits(),
                    v_ref,
                )?;
                Ok(ValidBackend::Spi {
                    kind,
                    chips,
                    common,
                })
            }
            BackendConfig::Ads1115(c) => {
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
                let boards = chips
                    .iter()
                    .map(|p| BoardSpec {
                        name: p.name.clone(),
                        channels: ads1115::CHANNELS,
                    })
                    .collect();
                let common = common(
                    c.rate_hz,
                    boards,
                    &c.map,
                    &c.temperature,
                    ads1115::BITS,
                    fsr.volts(),
                )?;
                Ok(ValidBackend::Ads1115 {
                    fsr,
                    data_rate,
                    buses,
                    chips,
                    common,
                })
            }
            BackendConfig::Ads7828(c) => {
                let (power, v_ref) = match (c.internal_ref, c.v_ref) {
                    (true, None) => (PowerMode::InternalRef, 2.5),
                    (true, Some(v)) if (v - 2.5).abs() < 1e-9 => (PowerMode::InternalRef, 2.5),
                    (true, Some(v)) => {
                        return Err(err("v_ref", format!("{v} V given with internal_ref = true (the internal reference is 2.5 V)")))
                    }
                    (false, Some(v)) => (PowerMode::ExternalRef, positive("v_ref", v)?),
                    (false, None) => return Err(err("v_ref", "required when internal_ref = false")),
                };
                let (buses, chips) = i2c_layout(&c.chips, ads7828::ADDR_MIN, ads7828::ADDR_MAX)?;
                let boards = chips
                    .iter()
                    .map(|p| BoardSpec {
                        name: p.name.clone(),
                        channels: ads7828::CHANNELS,
                    })
                    .collect();
                let common = common(c.rate_hz, boards, &c.map, &c.temperature, 12, v_ref)?;
                Ok(ValidBackend::Ads7828 {
                    power,
                    buses,
                    chips,
                    common,
                })
            }
            BackendConfig::Serial(c) => {
                if !(1..=16).contains(&c.adc_bits) {
                    return Err(err("adc_bits", format!("{} is not in 1..=16", c.adc_bits)));
                }
                if c.timeout_ms == 0 {
                    return Err(err("timeout_ms", "must be positive"));
                }
                unique_names("boards", c.boards.iter().map(|b| b.name.as_str()))?;
                let mut boards = Vec::new();
                for b in &c.boards {
                    if boards.iter().any(|x: &SerialBoard| x.id == b.id) {
                        return Err(err(
                            format!("boards.{}.id", b.name),
                            format!("id {} is used twice", b.id),
                        ));
                    }
                    if boards.iter().any(|x: &SerialBoard| x.path == b.path) {
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
                    if b.baud == 0 {
                        return Err(err(format!("boards.{}.baud", b.name), "must be positive"));
                    }
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
                let v_ref = positive("v_ref", c.v_ref)?;
                let common = common(c.rate_hz, specs, &c.map, &c.temperature, c.adc_bits, v_ref)?;
                Ok(ValidBackend::Serial {
                    boards,
                    timeout: Duration::from_millis(c.timeout_ms),
                    common,
                })
            }
            BackendConfig::Sim(c) => {
                rate(c.rate_hz)?;
                let f = &c.faults;
                for (key, p) in [
                    ("faults.bus_error_prob", f.bus_error_prob),
                    ("faults.drop_prob", f.drop_prob),
                ] {
                    if !(0.0..=1.0).contains(&p) {
                        return Err(err(key, format!("{p} is not a probability in 0..=1")));
                    }
                }
                for (key, n) in [
                    ("faults.bus_error_every", f.bus_error_every),
                    ("faults.drop_every", f.drop_every),
                ] {
                    if n == Some(0) {
                        return Err(err(key, "must be at least 1"));
                    }
                }
                for (i, s) in f.stuck.iter().enumerate() {
                    if s.r >= ROWS || s.c >= COLS {
                        return Err(err(
                            format!("faults.stuck[{i}]"),
                            format!("detector ({}, {}) is outside the array", s.r, s.c),
                        ));
                    }
                }
                Ok(ValidBackend::Sim(c.clone()))
            }
        }
    }
}
