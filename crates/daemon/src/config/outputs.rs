//! `[outputs]`: where POSE, STATUS and VERSION datagrams go — unicast
//! destinations and an optional multicast group — and how often STATUS.
//!
//! Ranges: at most 64 destinations, none on port 0 or to the unspecified
//! address, none twice (nor the multicast group again), and not an empty
//! list without a multicast group; `status_interval_s` 0.1..=3600 s;
//! multicast `ttl` 0..=255, `interface` only for an IPv4 group.

use super::locate::{socket_addr, within, AddrUse, Ctx};
use super::places::{self, Places};
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
    destinations: Option<Spanned<Vec<Spanned<String>>>>,
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

pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&RawOutputs>,
    at: &mut Places,
) -> Result<Outputs, ConfigError> {
    let multicast = match raw.and_then(|o| o.multicast.as_ref()) {
        Some(m) => places::when_on(m.enabled.unwrap_or(true), at, |at| multicast(ctx, m, at))?,
        None => None,
    };
    let destinations = match raw.and_then(|o| o.destinations.as_ref()) {
        Some(list) => destinations(ctx, list, multicast.as_ref(), at)?,
        None => Vec::new(),
    };
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
    Ok(Outputs {
        destinations,
        multicast,
        status_interval,
    })
}

/// The unicast destinations: at least one when the key is written (an
/// empty list without a multicast group sends every datagram nowhere),
/// none twice (each would get every datagram twice), none the multicast
/// group again.
fn destinations(
    ctx: &Ctx,
    list: &Spanned<Vec<Spanned<String>>>,
    multicast: Option<&Multicast>,
    at: &mut Places,
) -> Result<Vec<SocketAddr>, ConfigError> {
    const KEY: &str = "outputs.destinations";
    if list.get_ref().is_empty() && multicast.is_none() {
        return Err(ctx.err(
            list.span(),
            KEY,
            "empty: POSE, STATUS and VERSION would be sent nowhere; give at least one \"address:port\" (or remove the key when poses go only to the autopilot or a recording)",
        ));
    }
    let mut out: Vec<SocketAddr> = Vec::with_capacity(list.get_ref().len());
    for (i, d) in list.get_ref().iter().enumerate() {
        if out.len() == MAX_DESTINATIONS {
            let msg = format!("more than {MAX_DESTINATIONS} destinations");
            return Err(ctx.err(d.span(), KEY, msg));
        }
        let a = socket_addr(ctx, d, KEY, AddrUse::SendTo)?;
        if let Some(first) = out.iter().position(|&b| same_place(a, b)) {
            let msg = format!(
                "{a} is given twice (items {} and {}): every datagram would be sent to it twice",
                first + 1,
                i + 1
            );
            return Err(ctx.err(d.span(), KEY, msg));
        }
        if let Some(m) = multicast.filter(|m| same_place(a, m.group)) {
            let msg = format!(
                "{a} is also outputs.multicast.group {}: every datagram would be sent to it twice",
                m.group
            );
            return Err(ctx.err(d.span(), KEY, msg));
        }
        at.set(places::destination(i), ctx.line(d.span().start));
        out.push(a);
    }
    Ok(out)
}

/// Whether two addresses are one place to the kernel: an IPv4 address and
/// its IPv4-mapped IPv6 form (`[::ffff:127.0.0.1]`) are.
pub(super) fn same_place(a: SocketAddr, b: SocketAddr) -> bool {
    a.port() == b.port() && a.ip().to_canonical() == b.ip().to_canonical()
}

fn multicast(ctx: &Ctx, m: &RawMulticast, at: &mut Places) -> Result<Multicast, ConfigError> {
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
    at.set(places::MULTICAST_GROUP, ctx.line(m.group.span().start));
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
        Some(i) => interface(ctx, i, group, at)?,
        None => Ipv4Addr::UNSPECIFIED,
    };
    Ok(Multicast {
        group,
        ttl,
        interface,
        loopback: m.loopback.unwrap_or(true),
    })
}

/// `interface`: the IPv4 address of a local interface (whether it is one
/// shows only on this machine: `wiring::check`), for an IPv4 group (an
/// IPv6 group's datagrams leave by the route, and the key would be
/// ignored).
fn interface(
    ctx: &Ctx,
    i: &Spanned<String>,
    group: SocketAddr,
    at: &mut Places,
) -> Result<Ipv4Addr, ConfigError> {
    const KEY: &str = "outputs.multicast.interface";
    let a = match i.get_ref().parse::<IpAddr>() {
        Ok(IpAddr::V4(a)) => a,
        _ => {
            let msg = format!(
                "\"{}\" is not the IPv4 address of a local interface",
                lightpose_core::textfile::excerpt(i.get_ref(), 60)
            );
            return Err(ctx.err(i.span(), KEY, msg));
        }
    };
    if group.is_ipv6() && !a.is_unspecified() {
        let msg = format!("{a} would be ignored: the IPv6 group {group} is sent by the route; remove the key (or give an IPv4 group)");
        return Err(ctx.err(i.span(), KEY, msg));
    }
    at.set(places::MULTICAST_INTERFACE, ctx.line(i.span().start));
    Ok(a)
}
