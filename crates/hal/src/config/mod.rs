//! The backend's part of a config file: serde structs that a program embeds
//! (unknown keys refused, so a typo is an error and not a silently ignored
//! setting), and [`BackendConfig::validate`], which turns them into a
//! [`ValidBackend`] — typed values, ready for [`crate::open`] — or one clear
//! error naming the key. One file per family of kinds:
//!
//! - [`boards`]: MCP3008/MCP3208 (SPI), ADS1115 and ADS7828 (I²C), serial;
//! - [`temp`]: the boards' temperature source;
//! - [`sim`]: the simulator (`sim`, and `mock` with injected faults);
//! - [`replay`]: a recorded log.
//!
//! What a table leaves to the program that reads it (the rate of a table
//! that gives none, where relative paths start, what a scene or trajectory
//! name means) comes from an [`Env`], so that hal never needs to know how the
//! daemon resolves `embedded:NAME`.
//!
//! Rates: `rate_hz` defaults to the env's (5 Hz, the paper's, in
//! [`PlainEnv`]); `rate_hz = 0` means as fast as the source can go.

pub mod boards;
pub mod replay;
pub mod serial_bursts;
pub mod sim;
pub mod temp;
pub mod timing;

use std::path::PathBuf;

use lightpose_core::textfile::TextSource;
use serde::Deserialize;

use crate::drivers::ads1115::{DataRate, Fsr};
use crate::drivers::ads7828::PowerMode;
use crate::drivers::mcp3x08::McpKind;
use crate::serial::SerialBoard;
use crate::HalError;

pub use boards::{
    Ads1115Config, Ads7828Config, Common, I2cChipConfig, I2cChipPlan, SerialBoardConfig,
    SerialConfig, SpiChipConfig, SpiChipPlan, SpiConfig,
};
pub use replay::{ReplayConfig, ReplayPlan};
pub use sim::{FaultConfig, Faults, MockConfig, SimConfig, SimPlan, StuckChannel};
pub use temp::{TempConfig, TempPlan};

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
    Mock(MockConfig),
    Replay(ReplayConfig),
}

/// Whether a source keeps its own time or hands frames out as fast as they
/// are asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pace {
    /// Frames at their own time: the configured rate, or a log's timestamps.
    Realtime,
    /// As fast as the machine goes (benchmarks, offline replay).
    Fast,
}

impl Pace {
    /// `pace = ...` of a table; `realtime_word` is the kind's own word for
    /// realtime ("realtime", or "recorded" for a replay), which is accepted
    /// besides "realtime".
    pub(crate) fn parse(written: Option<&str>, realtime_word: &str) -> Result<Pace, HalError> {
        match written {
            None => Ok(Pace::Realtime),
            Some("fast") => Ok(Pace::Fast),
            Some(w) if w == realtime_word || w == "realtime" => Ok(Pace::Realtime),
            Some(w) => Err(err(
                "pace",
                format!(
                    "\"{}\" is not a pace (\"{realtime_word}\" or \"fast\")",
                    lightpose_core::textfile::excerpt(w, 40)
                ),
            )),
        }
    }
}

/// A validated backend, ready to open with [`crate::open`].
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
        timeout: std::time::Duration,
        common: Common,
    },
    Sim(SimPlan),
    Replay(ReplayPlan),
}

impl ValidBackend {
    /// The config's `kind`, for messages, VERSION and STATUS.
    pub fn kind(&self) -> &'static str {
        match self {
            ValidBackend::Spi { kind, .. } => match kind {
                McpKind::Mcp3008 => "mcp3008",
                McpKind::Mcp3208 => "mcp3208",
            },
            ValidBackend::Ads1115 { .. } => "ads1115",
            ValidBackend::Ads7828 { .. } => "ads7828",
            ValidBackend::Serial { .. } => "serial",
            ValidBackend::Sim(s) => s.kind,
            ValidBackend::Replay(_) => "replay",
        }
    }

    /// For benchmarks: the same backend looping and handing out frames as
    /// fast as they are asked for, the simulator's clock set to
    /// `sim_clock_hz` when given. `None` for boards, which cannot go faster
    /// than they convert.
    pub fn free_running(&self, sim_clock_hz: Option<f64>) -> Option<ValidBackend> {
        let mut v = self.clone();
        match &mut v {
            ValidBackend::Sim(s) => {
                s.pace = Pace::Fast;
                s.looping = true;
                if let Some(r) = sim_clock_hz {
                    s.rate_hz = Some(r);
                }
            }
            ValidBackend::Replay(r) => {
                r.pace = Pace::Fast;
                r.looping = true;
            }
            _ => return None,
        }
        Some(v)
    }
}

/// What a backend table leaves to the program that reads it.
pub trait Env {
    /// Frames per second of a backend whose table gives no `rate_hz`.
    fn default_rate_hz(&self) -> f64;
    /// A path written in the table (a log), made usable: the daemon takes
    /// relative paths from its config file's directory.
    fn path(&self, written: &str) -> PathBuf;
    /// The text that `key` names (a scene, a trajectory), or the program's
    /// default for `key` when the table does not write it; `Err` is the
    /// reason, said of `key`.
    fn text(&self, key: &str, written: Option<&str>) -> Result<TextSource, String>;
}

/// The env of a program with no defaults of its own: rate 5 Hz, paths as
/// written, no default texts.
#[derive(Debug, Clone, Copy, Default)]
pub struct PlainEnv;

impl Env for PlainEnv {
    fn default_rate_hz(&self) -> f64 {
        5.0
    }
    fn path(&self, written: &str) -> PathBuf {
        PathBuf::from(written)
    }
    fn text(&self, _key: &str, written: Option<&str>) -> Result<TextSource, String> {
        match written {
            Some(w) if !w.trim().is_empty() => Ok(TextSource::File(PathBuf::from(w))),
            Some(_) => Err("empty path".into()),
            None => Err("missing".into()),
        }
    }
}

impl BackendConfig {
    /// Every `kind` a table may give, for the message about an unknown one.
    pub const KINDS: &'static str = "sim, replay, mock, mcp3008, mcp3208, ads1115, ads7828, serial";

    /// The config's `kind`.
    pub fn kind(&self) -> &'static str {
        match self {
            BackendConfig::Mcp3008(_) => "mcp3008",
            BackendConfig::Mcp3208(_) => "mcp3208",
            BackendConfig::Ads1115(_) => "ads1115",
            BackendConfig::Ads7828(_) => "ads7828",
            BackendConfig::Serial(_) => "serial",
            BackendConfig::Sim(_) => "sim",
            BackendConfig::Mock(_) => "mock",
            BackendConfig::Replay(_) => "replay",
        }
    }

    /// Check everything that can be checked without opening a device or
    /// reading a file. Keys in errors are relative to the table.
    pub fn validate(&self, env: &dyn Env) -> Result<ValidBackend, HalError> {
        match self {
            BackendConfig::Mcp3008(c) => boards::spi(c, McpKind::Mcp3008, env),
            BackendConfig::Mcp3208(c) => boards::spi(c, McpKind::Mcp3208, env),
            BackendConfig::Ads1115(c) => boards::ads1115(c, env),
            BackendConfig::Ads7828(c) => boards::ads7828(c, env),
            BackendConfig::Serial(c) => boards::serial(c, env),
            BackendConfig::Sim(c) => sim::sim(c, env).map(ValidBackend::Sim),
            BackendConfig::Mock(c) => sim::mock(c, env).map(ValidBackend::Sim),
            BackendConfig::Replay(c) => replay::replay(c, env).map(ValidBackend::Replay),
        }
    }
}

// ---- checks every kind uses ----------------------------------------------

pub(crate) fn true_() -> bool {
    true
}

pub(crate) fn err(key: impl Into<String>, msg: impl Into<String>) -> HalError {
    HalError::Config {
        key: key.into(),
        msg: msg.into(),
    }
}

/// `rate_hz`, or the env's when absent; `None` = as fast as possible.
/// The slowest frame rate a source is paced at, Hz: a frame at least
/// every 1000 s. A rate whose period is past what a `Duration` holds
/// (1e-300 Hz) left the pacer without a period, frames as fast as they
/// came (a bad-input audit).
pub const MIN_RATE_HZ: f64 = 0.001;
/// The fastest, Hz.
pub const MAX_RATE_HZ: f64 = 10_000.0;

pub(crate) fn rate(r: Option<f64>, env: &dyn Env) -> Result<Option<f64>, HalError> {
    let r = r.unwrap_or_else(|| env.default_rate_hz());
    if r == 0.0 {
        return Ok(None);
    }
    if !r.is_finite() || !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&r) {
        return Err(err(
            "rate_hz",
            format!(
                "{} is not 0 (as fast as possible) or in {MIN_RATE_HZ}..={MAX_RATE_HZ} Hz (a frame at least every 1000 s)",
                lightpose_core::bounds::shown(r)
            ),
        ));
    }
    Ok(Some(r))
}

/// `v` if it is in `lo..=hi` (a finite number), else an error naming `key`
/// and the range.
pub(crate) fn within(key: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Result<f64, HalError> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(err(key, format!("{v} is not in {lo}..={hi}{unit}")))
    }
}

/// `v` if it is above 0 and at most `hi`.
pub(crate) fn positive_to(key: &str, v: f64, hi: f64, unit: &str) -> Result<f64, HalError> {
    if v.is_finite() && v > 0.0 && v <= hi {
        Ok(v)
    } else {
        Err(err(key, format!("{v} is not in (0, {hi}]{unit}")))
    }
}

pub(crate) fn finite(key: &str, v: f64) -> Result<f64, HalError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(err(key, "must be a finite number"))
    }
}

pub(crate) fn unique_names<'a>(
    what: &str,
    names: impl Iterator<Item = &'a str>,
) -> Result<(), HalError> {
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
