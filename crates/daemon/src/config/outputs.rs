//! `[outputs]`: where POSE, STATUS and VERSION datagrams go — unicast
//! destinations and an optional multicast group — and how often STATUS.
//!
//! Ranges: at most 64 destinations, none on port 0 or to the unspecified
//! address; `status_interval_s` 0.1..=3600 s; multicast `ttl` 0..=255.

use super::locate::{socket_addr, within, AddrUse, Ctx};
use super::ConfigError;
use serde::Deserialize;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;
use toml::Spanned;

/// Most unicast destinations a config may give.
pub const MAX_DESTINATIONS: usize = 64;

#[derive(Debug, Clone, PartialEq)]
pub struct Multicast {
    pub group: SocketAddr,
    pub ttl: u32,
    /// Local address of the interface to send from; unspecified = the
    /// kernel's choice by route.
    pub interface: Ipv4Addr,
    pub loopback: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Outputs {
    pub destinations: Vec<SocketAddr>,
    pub multicast: Option<Multicast>,
    pub status_interval: Duration,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOutputs {
    destinations: Option<Vec<Spanned<String>>>,
    status_interval_s: Option<Spanned<f64>>,
    multicast: Option<RawMulticast>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMulticast {
    enabled: Option<bool>,
    group: Spanned<String>,
    ttl: Option<Spanned<i64>>,
    interface: Option<Spanned<String>>,
    loopback: Option<bool>,
}

pub(super) fn validate(ctx: &Ctx, raw: Option<&RawOutputs>) -> Result<Outputs, ConfigError> {
    let mut destinations = Vec::new();
    for d in raw
        .and_then(|o| o.destinations.as_ref())
        .into_iter()
        .flatten()
    {
        if destinations.len() == MAX_DESTINATIONS {
            let msg = format!("more than {MAX_DESTINATIONS} destinations");
            return Err(ctx.err(d.span(), "outputs.destinations", msg));
        }
        destinations.push(socket_addr(
            ctx,
            d,
            "outputs.destinations",
            AddrUse::SendTo,
        )?);
    }
    let status_interval = match raw.and_then(|o| o.status_interval_s.as_ref()) {
        Some(v) => Duration::from_secs_f64(within(
            ctx,
            v,
            "outputs.status_interval_s",
            (0.1, 3600.0),
            " s",
        )?),
        None => Duration::from_secs(1),
    };
    let multicast = match raw.and_then(|o| o.multicast.as_ref()) {
        Some(m) if m.enabled.unwrap_or(true) => Some(multicast(ctx, m)?),
        _ => None,
    };
    Ok(Outputs {
        destinations,
        multicast,
        status_interval,
    })
}

fn multicast(ctx: &Ctx, m: &RawMulticast) -> Result<Multicast, ConfigError> {
    let group = socket_addr(ctx, &m.group, "outputs.multicast.group", AddrUse::SendTo)?;
    if !group.ip().is_multicast() {
        return Err(ctx.err(
            m.group.span(),
            "outputs.multicast.group",
            format!(
                "{} is not a multicast address (224.0.0.0/4 or ff00::/8)",
                group.ip()
            ),
        ));
    }
    let ttl = match &m.ttl {
        Some(t) if (0..=255).contains(t.get_ref()) => *t.get_ref() as u32,
        Some(t) => {
            return Err(ctx.err(
                t.span(),
                "outputs.multicast.ttl",
                format!("{} is not in 0..255", t.get_ref()),
            ))
        }
        None => 1,
    };
    let interface = match &m.interface {
        Some(i) => match i.get_ref().parse::<IpAddr>() {
            Ok(IpAddr::V4(a)) => a,
            _ => {
                return Err(ctx.err(
                    i.span(),
                    "outputs.multicast.interface",
                    format!(
                        "\"{}\" is not the IPv4 address of a local interface",
                        lightpose_core::textfile::excerpt(i.get_ref(), 60)
                    ),
                ))
            }
        },
        None => Ipv4Addr::UNSPECIFIED,
    };
    Ok(Multicast {
        group,
        ttl,
        interface,
        loopback: m.loopback.unwrap_or(true),
    })
}
