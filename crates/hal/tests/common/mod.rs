//! Set-up shared by hal's test binaries: a board table's `[[map]]`, the
//! validation a program does, serial boards on given ports, ADS7828s on
//! one bus, and a source that adds nothing to its bank's frame (no
//! temperature source, no pacing).
#![allow(dead_code)] // each test binary uses its own part

use std::path::PathBuf;
use std::time::Duration;

use lightpose_hal::bank::{BoardSource, I2cSlot};
use lightpose_hal::chanmap::ChannelMap;
use lightpose_hal::config::ValidBackend;
use lightpose_hal::drivers::ads7828::{Ads7828, PowerMode};
use lightpose_hal::pace::Pacer;
use lightpose_hal::serial::{SerialBank, SerialBoard};
use lightpose_hal::temp::{TempKind, TempReader};
use lightpose_hal::{BackendConfig, Bank, PlainEnv};

/// The `[[map]]` tables of the 25 detectors: detector k (row k / 5,
/// column k % 5) on board `{prefix}{k / per}`, channel k % per.
pub fn map_tables(prefix: &str, per: usize) -> String {
    (0..25)
        .map(|k| {
            format!(
                "[[map]]\nr = {}\nc = {}\nboard = \"{prefix}{}\"\nchannel = {}\n",
                k / 5,
                k % 5,
                k / per,
                k % per
            )
        })
        .collect()
}

/// A board table's TOML, parsed and validated as a program does; the
/// error's words.
pub fn validate(text: &str) -> Result<ValidBackend, String> {
    toml::from_str::<BackendConfig>(text)
        .map_err(|e| e.to_string())?
        .validate(&PlainEnv)
        .map_err(|e| e.to_string())
}

/// `bank` read through `map`, with no temperature and no pacing.
pub fn bare_source<B: Bank>(bank: B, map: ChannelMap) -> BoardSource<B> {
    BoardSource::new(
        bank,
        map,
        TempReader::new(TempKind::None, 0.0),
        Pacer::new(None),
    )
}

/// Serial boards b0, b1, … with ids 0, 1, … on `paths`, 16 channels each.
pub fn serial_boards(paths: &[PathBuf]) -> Vec<SerialBoard> {
    paths
        .iter()
        .enumerate()
        .map(|(i, p)| SerialBoard {
            name: format!("b{i}"),
            id: i as u8,
            path: p.display().to_string(),
            baud: 115_200,
            channels: 16,
        })
        .collect()
}

/// A bare source of [`serial_boards`] on `paths` (10 bits), waiting
/// `timeout_ms` for a frame.
pub fn serial_source(paths: &[PathBuf], timeout_ms: u64) -> BoardSource<SerialBank> {
    let bank = SerialBank::new(serial_boards(paths), 10, Duration::from_millis(timeout_ms));
    bare_source(bank, ChannelMap::sequential(16))
}

/// `n` ADS7828s with the internal reference on bus 0, at 0x48, 0x49, …,
/// named `{prefix}0`, `{prefix}1`, ….
pub fn ads7828s(prefix: &str, n: u8) -> Vec<I2cSlot<Ads7828>> {
    (0..n)
        .map(|i| I2cSlot {
            name: format!("{prefix}{i}"),
            bus: 0,
            chip: Ads7828::new(0x48 + i, PowerMode::InternalRef),
        })
        .collect()
}
