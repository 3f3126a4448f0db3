//! `[attitude]`: the optional input of the vehicle's AHRS readings.

use super::locate::{positive, socket_addr, Ctx};
use super::ConfigError;
use serde::Deserialize;
use std::net::{Ipv4Addr, SocketAddr};
use std::time::Duration;
use toml::Spanned;

#[derive(Debug, Clone, PartialEq)]
pub struct AttitudeInput {
    pub listen: SocketAddr,
    /// Compass heading that the beacon's optical axis (+x of B) points to.
    pub beacon_axis_heading_deg: f64,
    /// A reading older than this is not attached to a frame.
    pub max_age: Duration,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAttitude {
    enabled: Option<bool>,
    listen: Option<Spanned<String>>,
    beacon_axis_heading_deg: Option<Spanned<f64>>,
    max_age_s: Option<Spanned<f64>>,
}

/// `None` unless the table says `enabled = true`.
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&RawAttitude>,
) -> Result<Option<AttitudeInput>, ConfigError> {
    let Some(a) = raw.filter(|a| a.enabled.unwrap_or(false)) else {
        return Ok(None);
    };
    let listen = match &a.listen {
        Some(l) => socket_addr(ctx, l, "attitude.listen")?,
        None => SocketAddr::from((Ipv4Addr::LOCALHOST, 17151)),
    };
    let beacon_axis_heading_deg = match &a.beacon_axis_heading_deg {
        Some(h) if h.get_ref().is_finite() => *h.get_ref(),
        Some(h) => {
            return Err(ctx.err(
                h.span(),
                "attitude.beacon_axis_heading_deg",
                "must be a finite number of degrees",
            ))
        }
        None => {
            return Err(ctx.whole(
                "attitude.beacon_axis_heading_deg: missing (needed to refer yaw to the beam)",
            ))
        }
    };
    let max_age = match &a.max_age_s {
        Some(v) => Duration::from_secs_f64(positive(ctx, v, "attitude.max_age_s")?.min(3600.0)),
        None => Duration::from_millis(500),
    };
    Ok(Some(AttitudeInput {
        listen,
        beacon_axis_heading_deg,
        max_age,
    }))
}
