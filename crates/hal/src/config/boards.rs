//! The board kinds' tables — MCP3008/MCP3208 on SPI, ADS1115 and ADS7828 on
//! I²C, microcontroller boards on serial — and one validator per kind. What
//! they share (rate, boards, channel map, temperature) is [`Common`].

use std::time::Duration;

use serde::Deserialize;

use super::temp::{temp_plan, DividerSupply, TempConfig, TempPlan};
use super::{err, positive_to, rate, timing, unique_names, within, Env, ValidBackend};
use crate::chanmap::{BoardSpec, ChannelMap, MapEntry, MAX_CH};
use crate::drivers::ads1115::{self, DataRate, Fsr};
use crate::drivers::ads7828::{self, PowerMode};
use crate::drivers::mcp3x08::McpKind;
use crate::pace::{Pacer, Stop};
use crate::serial::SerialBoard;
use crate::HalError;
use lightpose_core::modulation::{check_beacons, BeaconFreq};
use lightpose_core::samples::{BeaconInfo, MAX_BEACONS};

mod i2c;
pub(super) use i2c::{ads1115, ads7828};

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
fn block_default() -> u16 {
    16
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

/// A beacon of a board's `beacons` list: its id and blink frequency (Hz;
/// 0 is steady), as a v3 scene's `[[beacons]]` gives them.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeaconConfig {
    pub id: String,
    pub mod_hz: f64,
}

/// MCP3008 / MCP3208 chips, one spidev device (chip select) each.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpiConfig {
    /// Absent: the env's rate.
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// Samples of every channel per second (spec v3: a whole multiple N of
    /// `rate_hz`, each frame N samples of every channel, for a blinking
    /// beacon). Absent: one sample per frame. Refused above what the bus
    /// gives (`config::timing`).
    #[serde(default)]
    pub sample_hz: Option<f64>,
    /// Spec v3: the beacons the samples carry, for the daemon's
    /// demodulator (`[backend] beacons = [{ id = "beacon", mod_hz = 250.0 }]`),
    /// checked with `sample_hz` and `rate_hz` by MODEL.md's rules. Needed
    /// with `sample_hz`; refused without it.
    #[serde(default)]
    pub beacons: Vec<BeaconConfig>,
    /// ADC reference (for a thermistor channel).
    #[serde(default = "v5")]
    pub v_ref: f64,
    /// The chips' supply, 2.7..=5.5 V: sets their SCLK limit. Absent: the
    /// 2.7 V limit, safe at any supply.
    #[serde(default)]
    pub vdd_v: Option<f64>,
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
    /// Defaults to the chip's limit at the table's `vdd_v` (without it, at
    /// 2.7 V).
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
    /// Samples of every channel per second (spec v3: a whole multiple N of
    /// `rate_hz`, each frame N samples of every channel, for a blinking
    /// beacon). Absent: one sample per frame. Refused above what the bus
    /// gives (`config::timing`).
    #[serde(default)]
    pub sample_hz: Option<f64>,
    /// Spec v3: the beacons the samples carry, for the daemon's
    /// demodulator (`[backend] beacons = [{ id = "beacon", mod_hz = 250.0 }]`),
    /// checked with `sample_hz` and `rate_hz` by MODEL.md's rules. Needed
    /// with `sample_hz`; refused without it.
    #[serde(default)]
    pub beacons: Vec<BeaconConfig>,
    /// PGA full scale in volts: 6.144, 4.096, 2.048, 1.024, 0.512, 0.256.
    #[serde(default = "fsr_default")]
    pub fsr_v: f64,
    /// 8, 16, 32, 64, 128, 250, 475 or 860.
    #[serde(default = "dr_default")]
    pub data_rate_sps: u16,
    /// The chips' supply, 2.0..=5.5 V: a full scale above it is refused
    /// (the inputs only reach VDD). Absent: not checked.
    #[serde(default)]
    pub vdd_v: Option<f64>,
    /// SCL of the buses (the slowest), for the frame-time check only (the
    /// kernel sets it, e.g. dtparam=i2c_arm_baudrate). Absent: 100 kHz.
    #[serde(default)]
    pub i2c_clock_hz: Option<u32>,
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
    /// Samples of every channel per second (spec v3: a whole multiple N of
    /// `rate_hz`, each frame N samples of every channel, for a blinking
    /// beacon). Absent: one sample per frame. Refused above what the bus
    /// gives (`config::timing`).
    #[serde(default)]
    pub sample_hz: Option<f64>,
    /// Spec v3: the beacons the samples carry, for the daemon's
    /// demodulator (`[backend] beacons = [{ id = "beacon", mod_hz = 250.0 }]`),
    /// checked with `sample_hz` and `rate_hz` by MODEL.md's rules. Needed
    /// with `sample_hz`; refused without it.
    #[serde(default)]
    pub beacons: Vec<BeaconConfig>,
    /// SCL of the buses (the slowest), for the sample-time check only
    /// (the kernel sets it). Absent: 100 kHz.
    #[serde(default)]
    pub i2c_clock_hz: Option<u32>,
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
    /// Samples of every channel per second. Absent: one `$LPADC` line a
    /// frame. Above `rate_hz` (a whole multiple N, for a blinking beacon)
    /// the boards send LPBST bursts sampled on their own timer
    /// (docs/serial-protocol.md, "Bursts"), refused where a board's baud
    /// cannot carry them.
    #[serde(default)]
    pub sample_hz: Option<f64>,
    /// Spec v3: the beacons the samples carry, as for the SPI and I²C
    /// boards (`beacons = [{ id = "beacon", mod_hz = 250.0 }]`). Needed
    /// with `sample_hz`; refused without it.
    #[serde(default)]
    pub beacons: Vec<BeaconConfig>,
    /// Bursts: between consecutive channels' conversions, s, as the
    /// boards' firmware spaces them (lpadc.ino `SPACING_US`; MODEL.md
    /// `channel_skew_s`). Needed with `sample_hz`.
    #[serde(default)]
    pub channel_skew_s: Option<f64>,
    /// Bursts: samples a packet holds (lpadc.ino `BLOCK`), for the
    /// bandwidth check only: packets of any size are read.
    #[serde(default = "block_default")]
    pub block_samples: u16,
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
    /// N: samples of every channel in a frame (`sample_hz` / `rate_hz`;
    /// 1 without `sample_hz`).
    pub samples_per_frame: u32,
    /// Samples of every channel per second when `samples_per_frame` > 1.
    pub sample_hz: Option<f64>,
    /// The beacons the samples carry (with `sample_hz`).
    pub beacons: Vec<BeaconInfo>,
    /// Between consecutive channels' conversions, s, as the bank's clocks
    /// and transfers give it (MODEL.md `channel_skew_s`; 0 where not
    /// known: serial boards).
    pub channel_skew_s: f64,
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
    /// Spec v3: how the bank samples when a frame is N > 1 samples of
    /// every channel (`None`: one sample a frame, as v1/v2).
    pub fn sampling(&self) -> Option<crate::Sampling> {
        let hz = self.sample_hz?;
        (self.samples_per_frame > 1).then(|| crate::Sampling {
            sample_hz: hz,
            samples_per_frame: self.samples_per_frame as usize,
            channel_skew_s: self.channel_skew_s,
            beacons: self.beacons.clone(),
        })
    }
    /// Per board, the channels a frame reads: the map's and a thermistor's.
    pub fn wanted(&self) -> Vec<u16> {
        let mut w = self.map.wanted(self.boards.len());
        if let TempPlan::Thermistor { params, .. } = &self.temp {
            if let Some(m) = w.get_mut(params.board) {
                *m |= 1 << params.channel;
            }
        }
        w
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
    sample_hz: Option<f64>,
    map: &'a [MapEntry],
    temp: &'a TempConfig,
    bits: u8,
    v_ref: f64,
    /// What a thermistor divider's supply defaults to.
    supply: DividerSupply,
}

fn common(s: Shared, boards: Vec<BoardSpec>, env: &dyn Env) -> Result<Common, HalError> {
    let rate_hz = rate(s.rate_hz, env)?;
    let samples_per_frame = timing::samples_per_frame(s.sample_hz, rate_hz)?;
    let map = ChannelMap::new(s.map, &boards)?;
    let temp = temp_plan(s.temp, &boards, &map, s.bits, s.v_ref, &s.supply)?;
    Ok(Common {
        rate_hz,
        samples_per_frame,
        sample_hz: s.sample_hz,
        beacons: Vec::new(),
        channel_skew_s: 0.0,
        boards,
        map,
        temp,
        bits: s.bits,
    })
}

/// The `beacons` list into `common`, checked with the rates by MODEL.md's
/// rules (core's `check_beacons`: each blinks at an even number of samples
/// a period and a whole number of periods a frame, no two alike): refused
/// at `beacons`. Checked after the bus, so that `--check-config` says what
/// the bank can give first.
fn with_beacons(common: &mut Common, list: &[BeaconConfig]) -> Result<(), HalError> {
    if list.is_empty() {
        if let (Some(hz), true) = (common.sample_hz, common.samples_per_frame > 1) {
            return Err(err(
                "beacons",
                format!(
                    "sample_hz = {} is {} samples a frame, which only a blinking beacon needs, and no beacon blinks: name them, e.g. beacons = [{{ id = \"beacon\", mod_hz = 250.0 }}]",
                    lightpose_core::bounds::shown(hz),
                    common.samples_per_frame
                ),
            ));
        }
        return Ok(());
    }
    common.beacons = beacons(list, common.sample_hz, common.rate_hz)?;
    Ok(())
}

fn beacons(
    list: &[BeaconConfig],
    sample_hz: Option<f64>,
    rate_hz: Option<f64>,
) -> Result<Vec<BeaconInfo>, HalError> {
    let (Some(hz), Some(rate)) = (sample_hz, rate_hz) else {
        if list.is_empty() {
            return Ok(Vec::new());
        }
        return Err(err(
            "beacons",
            "given without sample_hz: one sample a frame sees only steady light (give sample_hz, a whole multiple of rate_hz, to demodulate blinking beacons)",
        ));
    };
    if list.len() > MAX_BEACONS {
        return Err(err(
            "beacons",
            format!("{} beacons, at most {MAX_BEACONS}", list.len()),
        ));
    }
    unique_names("beacons", list.iter().map(|b| b.id.as_str()))?;
    let freqs: Vec<BeaconFreq> = list
        .iter()
        .map(|b| BeaconFreq {
            id: &b.id,
            mod_hz: b.mod_hz,
        })
        .collect();
    if let Some(b) = list
        .iter()
        .find(|b| !(b.mod_hz.is_finite() && b.mod_hz >= 0.0))
    {
        return Err(err(
            "beacons",
            format!(
                "beacon \"{}\": mod_hz = {} is not a frequency (>= 0 Hz)",
                b.id, b.mod_hz
            ),
        ));
    }
    check_beacons(rate, hz, &freqs).map_err(|e| err("beacons", e.to_string()))?;
    Ok(list
        .iter()
        .map(|b| BeaconInfo {
            id: b.id.clone(),
            mod_hz: b.mod_hz,
        })
        .collect())
}

/// Wanted channels per board, in board order.
fn wanted_counts(common: &Common) -> Vec<u32> {
    common.wanted().iter().map(|m| m.count_ones()).collect()
}

/// `kind = "mcp3008"` / `"mcp3208"`.
pub(super) fn spi(c: &SpiConfig, kind: McpKind, env: &dyn Env) -> Result<ValidBackend, HalError> {
    unique_names("chips", c.chips.iter().map(|c| c.name.as_str()))?;
    let vdd = c
        .vdd_v
        .map(|v| within("vdd_v", v, 2.7, 5.5, " V"))
        .transpose()?;
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
        let hz = spi_clock(ch, kind, vdd)?;
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
        sample_hz: c.sample_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: kind.bits(),
        v_ref: positive_to("v_ref", c.v_ref, MAX_V, " V")?,
        supply: DividerSupply::IsRef,
    };
    let mut common = common(shared, boards, env)?;
    let per_chip: Vec<(u32, u32)> = chips
        .iter()
        .zip(wanted_counts(&common))
        .map(|(ch, n)| (ch.max_speed_hz, n))
        .collect();
    let n: u32 = per_chip.iter().map(|c| c.1).sum();
    let what = format!(
        "{n} transfers of 24 clocks at the chips' max_speed_hz, one after another, and {:.0} µs of the kernel's each",
        timing::SPI_TRANSFER_OVERHEAD_S * 1e6
    );
    timing::keeps_up(&mut common, c.sample_hz, timing::spi(&per_chip), &what)?;
    with_beacons(&mut common, &c.beacons)?;
    Ok(ValidBackend::Spi {
        kind,
        chips,
        common,
    })
}

/// A chip's SCLK: as given or the limit at the supply, at most that limit
/// ([`McpKind::clock_limit_hz`]).
fn spi_clock(ch: &SpiChipConfig, kind: McpKind, vdd: Option<f64>) -> Result<u32, HalError> {
    let limit = kind.clock_limit_hz(vdd);
    let hz = ch.max_speed_hz.unwrap_or(limit);
    if (1..=limit).contains(&hz) {
        return Ok(hz);
    }
    let (name, hi) = (kind.name(), kind.max_clock_hz());
    let why = match vdd {
        _ if hz == 0 => format!("0 is not in 1..={limit}"),
        Some(v) => format!(
            "{hz} is above {limit}, the {name}'s limit at vdd_v = {v} V (on the line from {} at 2.7 V to {hi} at 5 V)",
            kind.low_supply_clock_hz()
        ),
        None => format!(
            "{hz} is above {limit}, the {name}'s limit at 2.7 V; declare the chips' supply as vdd_v to allow more (up to {hi} at 5 V)"
        ),
    };
    Err(err(format!("chips.{}.max_speed_hz", ch.name), why))
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
        sample_hz: c.sample_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: c.adc_bits,
        v_ref: positive_to("v_ref", c.v_ref, MAX_V, " V")?,
        supply: DividerSupply::IsRef,
    };
    let mut common = common(shared, specs, env)?;
    if common.samples_per_frame > 1 {
        super::serial_bursts::check(c, &boards, &mut common)?;
    } else if c.channel_skew_s.is_some() {
        return Err(err(
            "channel_skew_s",
            "given without sample_hz above rate_hz: one $LPADC line a frame has no bursts to space",
        ));
    }
    with_beacons(&mut common, &c.beacons)?;
    Ok(ValidBackend::Serial {
        boards,
        timeout: Duration::from_millis(c.timeout_ms),
        common,
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
