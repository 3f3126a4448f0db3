//! Resources compiled into the binary: the default config runs from
//! anywhere because it refers to these by `embedded:NAME`. A name is
//! resolved here, to its text, before any library sees it.

use super::locate::Ctx;
use lightpose_core::textfile::TextSource;
use std::borrow::Cow;

pub const DEFAULT_CONFIG: &str = include_str!("../../../../config/lightposed.toml");

/// The text of an `embedded:NAME` resource.
pub fn lookup(name: &str) -> Option<&'static str> {
    Some(match name {
        "tank-scene" => include_str!("../../../../config/scenes/tank.toml"),
        // The tank with the vehicle's attitude sensor (AHRS), as most
        // vehicles carry one: the default run shows what `auto` gives.
        "tank-ahrs-scene" => include_str!("../../../../config/scenes/tank-ahrs.toml"),
        "harbour-scene" => include_str!("../../../../config/scenes/harbour.toml"),
        "dive" => include_str!("../../../../config/trajectories/dive.csv"),
        "zigzag" => include_str!("../../../../config/trajectories/zigzag.csv"),
        "tank-calibration" => include_str!("../../../../config/calibration/tank.toml"),
        "harbour-calibration" => include_str!("../../../../config/calibration/harbour.toml"),
        _ => return None,
    })
}

/// Every name `lookup` knows, for error messages.
pub const NAMES: &str = "tank-scene, tank-ahrs-scene, harbour-scene, dive, zigzag, tank-calibration, harbour-calibration";

/// What a config value naming a text means: `embedded:NAME` (its text, or
/// why not) or a path, relative ones taken from the config's directory.
pub(super) fn resolve(ctx: &Ctx, written: &str) -> Result<TextSource, String> {
    if let Some(name) = written.strip_prefix("embedded:") {
        return match lookup(name) {
            Some(text) => Ok(TextSource::Held {
                name: written.to_string(),
                text: Cow::Borrowed(text),
            }),
            None => Err(format!(
                "\"{}\" is not embedded in this build (known: {NAMES}; a name is missing when its file was absent at build time)",
                lightpose_core::textfile::excerpt(written, 60)
            )),
        };
    }
    if written.trim().is_empty() {
        return Err("empty path".into());
    }
    Ok(TextSource::File(ctx.path(written)))
}
