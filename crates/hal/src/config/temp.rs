//! Where a board backend's frames get their water temperature: none, a
//! fixed value, a DS18B20 on 1-Wire, or a thermistor on one of the boards'
//! own channels — each with a fallback, checked against the boards and the
//! channel map.

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;

use super::boards::MAX_V;
use super::{err, finite, positive_to, within};
use crate::chanmap::{BoardSpec, ChannelMap};
use crate::temp::{Ds18b20, TempKind, TempReader, Thermistor, ThermistorPosition};
use crate::HalError;

fn w1_root() -> PathBuf {
    PathBuf::from("/sys/bus/w1/devices")
}
fn w1_interval() -> f64 {
    2.0
}
fn w1_max_age() -> f64 {
    10.0
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
        /// Divider supply. Defaults to the ADC reference only where that
        /// is the divider's supply (MCP3x08, ADS7828 with an external
        /// reference, serial); required for ADS1115 and for ADS7828 on its
        /// internal reference (docs/hardware.md).
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

/// What a thermistor's `temperature.v_supply` may default to.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum DividerSupply {
    /// Ratiometric: the ADC's reference is the board voltage the divider
    /// hangs off, so `v_ref` is the default.
    IsRef,
    /// The ADC's reference exists nowhere on the board (a PGA full scale,
    /// an internal reference): `v_supply` must be given; the text says why.
    Required(String),
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

/// A positive number of seconds that a `Duration` can hold.
fn seconds(key: &str, v: f64, max: f64) -> Result<Duration, HalError> {
    Duration::try_from_secs_f64(positive_to(key, v, max, " s")?)
        .map_err(|_| err(key, format!("{v} s is too long")))
}

/// A water temperature: the daemon's own fallback range.
fn water(key: &str, v: f64) -> Result<f64, HalError> {
    within(key, v, -5.0, 45.0, " °C")
}

/// The thermistor divider's supply: as given, or the ADC's reference where
/// that is the divider's supply. Counts are volts over `v_ref`, the divider
/// gives a fraction of its supply: with the wrong supply every reading is
/// scaled by the ratio of the two (a 3.3 V divider read as 4.096 V: 24 %).
fn divider_supply(given: Option<f64>, v_ref: f64, supply: &DividerSupply) -> Result<f64, HalError> {
    let v = match (given, supply) {
        (Some(v), _) => v,
        (None, DividerSupply::IsRef) => v_ref,
        (None, DividerSupply::Required(why)) => {
            return Err(err("temperature.v_supply", format!("required: {why}")))
        }
    };
    positive_to("temperature.v_supply", v, MAX_V, " V")
}

pub(super) fn temp_plan(
    t: &TempConfig,
    boards: &[BoardSpec],
    map: &ChannelMap,
    bits: u8,
    v_ref: f64,
    supply: &DividerSupply,
) -> Result<TempPlan, HalError> {
    Ok(match t {
        TempConfig::None => TempPlan::None,
        TempConfig::Fixed { value_c } => TempPlan::Fixed(water("temperature.value_c", *value_c)?),
        TempConfig::Ds18b20 {
            fallback_c,
            root,
            device,
            interval_s,
            max_age_s,
        } => TempPlan::Ds18b20 {
            sensor_root: root.clone(),
            device: device.clone(),
            interval: seconds("temperature.interval_s", *interval_s, 3600.0)?,
            max_age: seconds("temperature.max_age_s", *max_age_s, 86_400.0)?,
            fallback_c: water("temperature.fallback_c", *fallback_c)?,
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
            // Within water's window: outside it every estimator refuses
            // the frame, where the fallback keeps the poses coming.
            let window = lightpose_core::light::WATER_TEMP_C;
            let (lo, hi) = (*window.start(), *window.end());
            within("temperature.min_c", *min_c, lo, hi, " °C")?;
            within("temperature.max_c", *max_c, lo, hi, " °C")?;
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
                    r_fixed_ohm: positive_to("temperature.r_fixed_ohm", *r_fixed_ohm, 1e9, " Ω")?,
                    position: *position,
                    v_supply: divider_supply(*v_supply, v_ref, supply)?,
                    v_ref,
                    bits,
                    min_c: *min_c,
                    max_c: *max_c,
                },
                fallback_c: water("temperature.fallback_c", *fallback_c)?,
            }
        }
    })
}
