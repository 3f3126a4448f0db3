//! `[attitude]`: the optional input of the vehicle's AHRS readings.
//!
//! Ranges: `listen` not on port 0; `beacon_axis_heading_deg` -360..=360;
//! `max_age_s` (0, 60] s.
//!
//! The beacon's heading is `[site] beacon_heading_deg`, which the MAVLink
//! link uses too; `beacon_axis_heading_deg` here is the older spelling,
//! still accepted alone. Both at once must agree: two headings for one
//! beacon would make the two inputs disagree about yaw.

use super::locate::{positive_to, socket_addr, within, AddrUse, Ctx};
use super::places::{self, Places};
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

/// `None` unless the table says `enabled = true`; the heading from
/// `[site]` (`site_heading_deg`) unless the table gives its own.
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&Spanned<RawAttitude>>,
    site_heading_deg: Option<f64>,
    at: &mut Places,
) -> Result<Option<AttitudeInput>, ConfigError> {
    let Some(table) = raw.filter(|a| a.get_ref().enabled.unwrap_or(false)) else {
        return Ok(None);
    };
    let a = table.get_ref();
    // Whether it can be bound shows only on this machine: `wiring::check`.
    at.set(
        places::ATTITUDE_LISTEN,
        ctx.line_of_value(table, a.listen.as_ref()),
    );
    let listen = match &a.listen {
        Some(l) => socket_addr(ctx, l, "attitude.listen", AddrUse::Listen)?,
        None => SocketAddr::from((Ipv4Addr::LOCALHOST, 17151)),
    };
    let beacon_axis_heading_deg = match (&a.beacon_axis_heading_deg, site_heading_deg) {
        (Some(h), site_deg) => {
            let own = within(
                ctx,
                h,
                "attitude.beacon_axis_heading_deg",
                (-360.0, 360.0),
                " degrees",
            )?;
            match site_deg {
                Some(s) if (s - own).abs() > 1e-9 => {
                    return Err(ctx.err(
                        h.span(),
                        "attitude.beacon_axis_heading_deg",
                        format!("{own}° conflicts with [site] beacon_heading_deg = {s}°: give the beacon's heading once, in [site]"),
                    ))
                }
                _ => own,
            }
        }
        (None, Some(s)) => s,
        (None, None) => {
            return Err(ctx.whole(
                "[site] beacon_heading_deg: missing (the [attitude] input needs it to refer yaw to the beam)",
            ))
        }
    };
    let max_age = match &a.max_age_s {
        Some(v) => Duration::from_secs_f64(positive_to(ctx, v, "attitude.max_age_s", 60.0, " s")?),
        None => Duration::from_millis(500),
    };
    Ok(Some(AttitudeInput {
        listen,
        beacon_axis_heading_deg,
        max_age,
    }))
}
