//! `[temperature]`: the water temperature used when a frame carries none.

use super::locate::Ctx;
use super::ConfigError;
use serde::Deserialize;
use toml::Spanned;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTemperature {
    fallback_c: Option<Spanned<f64>>,
}

/// The fallback temperature, if any.
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&RawTemperature>,
) -> Result<Option<f64>, ConfigError> {
    match raw.and_then(|t| t.fallback_c.as_ref()) {
        Some(v) if v.get_ref().is_finite() && (-5.0..=45.0).contains(v.get_ref()) => {
            Ok(Some(*v.get_ref()))
        }
        Some(v) => Err(ctx.err(
            v.span(),
            "temperature.fallback_c",
            format!("{} °C is not a water temperature (-5..45)", v.get_ref()),
        )),
        None => Ok(None),
    }
}
