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
    ads1115_supply(c.vdd_v, fsr)?;
    let scl = match c.i2c_clock_hz {
        Some(hz) if (10_000..=ads1115::MAX_CLOCK_HZ).contains(&hz) => Some(hz),
        Some(hz) => {
            return Err(err(
                "i2c_clock_hz",
                format!("{hz} is not in 10000..={}", ads1115::MAX_CLOCK_HZ),
            ))
        }
        None => None,
    };
    let (buses, chips) = i2c_layout(&c.chips, ads1115::ADDR_MIN, ads1115::ADDR_MAX)?;
    let boards = i2c_boards(&chips, ads1115::CHANNELS);
    let shared = Shared {
        rate_hz: c.rate_hz,
        sample_hz: c.sample_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: ads1115::BITS,
        v_ref: fsr.volts(),
        supply: DividerSupply::Required(format!(
            "an ADS1115's reference is its PGA full scale (fsr_v = {} V), inside the chip and not the divider's supply; give the voltage the divider hangs off (e.g. 3.3)",
            fsr.volts()
        )),
    };
    let mut common = common(shared, boards, env)?;
    match c.sample_hz {
        // One sample a frame: the frame rule as it always was.
        None => ads1115_frame_fits(&common, data_rate, scl)?,
        Some(_) => {
            let wanted = wanted_counts(&common);
            let rounds = wanted.iter().copied().max().unwrap_or(0);
            let n: u32 = wanted.iter().sum();
            let hz = scl.unwrap_or(timing::DEFAULT_I2C_HZ);
            let what = format!(
                "{rounds} conversions of 1.1/DR at data_rate_sps = {}, {n} channels' I2C transfers at {} kHz",
                data_rate.sps(),
                hz / 1000
            );
            timing::keeps_up(
                &mut common,
                c.sample_hz,
                timing::ads1115(rounds, n, data_rate, hz),
                &what,
            )?;
        }
    }
    with_beacons(&mut common, &c.beacons)?;
    Ok(ValidBackend::Ads1115 {
        fsr,
        data_rate,
        buses,
        chips,
        common,
    })
}

/// With the supply declared, a full scale above it is refused: the inputs
/// are measured only up to VDD, so the top counts (and saturation) never
/// come.
fn ads1115_supply(vdd_v: Option<f64>, fsr: Fsr) -> Result<(), HalError> {
    let Some(v) = vdd_v else { return Ok(()) };
    let vdd = within("vdd_v", v, 2.0, 5.5, " V")?;
    if fsr.volts() <= vdd {
        return Ok(());
    }
    let top = (vdd / fsr.volts() * 32767.0).round();
    let fits = [6.144, 4.096, 2.048, 1.024, 0.512, 0.256]
        .into_iter()
        .find(|&f| f <= vdd)
        .unwrap_or(0.256);
    Err(err(
        "fsr_v",
        format!(
            "{} V is above vdd_v = {vdd} V: the inputs are measured only up to VDD, so counts stop near {top} of 32767 and saturation is never seen; use fsr_v = {fits} or lower",
            fsr.volts()
        ),
    ))
}

/// The frame must be read well within its period: the ADS1115 converts
/// for 1.1/DR a channel (the bank overlaps one channel of every chip) and
/// every channel costs bus time. Above 80 % of the period the pacer would
/// slip behind and the frames' rate be a lie.
fn ads1115_frame_fits(common: &Common, dr: DataRate, scl: Option<u32>) -> Result<(), HalError> {
    let Some(rate) = common.rate_hz else {
        return Ok(());
    };
    let wanted = common.wanted();
    let rounds = wanted.iter().map(|m| m.count_ones()).max().unwrap_or(0);
    let channels: u32 = wanted.iter().map(|m| m.count_ones()).sum();
    let hz = scl.unwrap_or(100_000);
    let secs = ads1115::frame_read_ns(rounds, channels, dr, hz) as f64 * 1e-9;
    if rate * secs <= 0.8 {
        return Ok(());
    }
    let assumed = if scl.is_some() {
        ""
    } else {
        ", assumed: no i2c_clock_hz"
    };
    // What else would shorten the read: a faster chip, else a faster bus.
    let remedy = if dr.sps() < 860 {
        "or raise data_rate_sps"
    } else if hz < 400_000 {
        "or raise i2c_clock_hz (400 kHz fast mode)"
    } else {
        "or spread the channels over more chips"
    };
    Err(err(
        "rate_hz",
        format!(
            "{rate} Hz with data_rate_sps = {}: reading a frame takes {:.1} ms ({rounds} conversions of 1.1/DR in turn, {channels} channels' I2C transfers at {} kHz{assumed}), over 80 % of the {:.1} ms period; at most {:.2} Hz fits, {remedy}",
            dr.sps(),
            secs * 1e3,
            hz as f64 / 1e3,
            1e3 / rate,
            0.8 / secs
        ),
    ))
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
    let supply = match power {
        PowerMode::InternalRef => DividerSupply::Required(
            "with internal_ref = true the reference is the chip's own 2.5 V, the divider's supply only if it hangs off REFOUT (then give 2.5); give the voltage the divider hangs off".into(),
        ),
        _ => DividerSupply::IsRef,
    };
    let scl = match c.i2c_clock_hz {
        None => timing::DEFAULT_I2C_HZ,
        Some(hz) if (10_000..=ads7828::MAX_CLOCK_HZ).contains(&hz) => hz,
        Some(hz) => {
            return Err(err(
                "i2c_clock_hz",
                format!("{hz} is not in 10000..={}", ads7828::MAX_CLOCK_HZ),
            ))
        }
    };
    let shared = Shared {
        rate_hz: c.rate_hz,
        sample_hz: c.sample_hz,
        map: &c.map,
        temp: &c.temperature,
        bits: 12,
        v_ref,
        supply,
    };
    let mut common = common(shared, boards, env)?;
    let n: u32 = wanted_counts(&common).iter().sum();
    let what = format!(
        "{n} conversions of {} I2C clocks at {} kHz and two messages of {:.0} µs each",
        timing::ADS7828_CLOCKS_PER_CHANNEL,
        scl / 1000,
        timing::I2C_MESSAGE_OVERHEAD_S * 1e6
    );
    timing::keeps_up(&mut common, c.sample_hz, timing::ads7828(n, scl), &what)?;
    with_beacons(&mut common, &c.beacons)?;
    Ok(ValidBackend::Ads7828 {
        power,
        buses,
        chips,
        common,
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
