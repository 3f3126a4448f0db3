//! `[foxglove]`: the live view, the recording's channels served over
//! Foxglove's WebSocket protocol (docs/foxglove.md). Off unless the table
//! is there; loopback unless `allow_remote = true`.

use super::locate::{socket_addr, AddrUse, Ctx};
use super::places::{self, Places};
use super::ConfigError;
use serde::Deserialize;
use std::net::{Ipv4Addr, SocketAddr};
use toml::Spanned;

#[derive(Debug, Clone, PartialEq)]
pub struct Foxglove {
    pub listen: SocketAddr,
    /// Messages that may wait for one client before that client's next
    /// ones are dropped (and counted).
    pub client_queue: usize,
    /// Clients served at once; more are turned away.
    pub max_clients: usize,
    /// Of them, from one source address (loopback like any other), so
    /// that one host cannot take every place.
    pub max_clients_per_addr: usize,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFoxglove {
    enabled: Option<bool>,
    listen: Option<Spanned<String>>,
    allow_remote: Option<bool>,
    client_queue: Option<Spanned<i64>>,
    max_clients: Option<Spanned<i64>>,
    max_clients_per_addr: Option<Spanned<i64>>,
}

/// Where the live view listens unless told otherwise (Foxglove's default
/// port).
pub const DEFAULT_LISTEN: SocketAddr =
    SocketAddr::new(std::net::IpAddr::V4(Ipv4Addr::LOCALHOST), 8765);

/// `None` when the table is absent or not enabled (checked all the same:
/// [`places::when_on`]).
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&Spanned<RawFoxglove>>,
    at: &mut Places,
) -> Result<Option<Foxglove>, ConfigError> {
    let Some(table) = raw else { return Ok(None) };
    let enabled = table.get_ref().enabled.unwrap_or(true);
    places::when_on(enabled, at, |at| check(ctx, table, at))
}

fn check(
    ctx: &Ctx,
    table: &Spanned<RawFoxglove>,
    at: &mut Places,
) -> Result<Foxglove, ConfigError> {
    let r = table.get_ref();
    // Whether it can be bound shows only on this machine: `wiring::check`.
    at.set(
        places::FOXGLOVE_LISTEN,
        ctx.line_of_value(table, r.listen.as_ref()),
    );
    let listen = match &r.listen {
        Some(l) => {
            let a = socket_addr(ctx, l, "foxglove.listen", AddrUse::Listen)?;
            // The protocol has neither authentication nor encryption:
            // whoever reaches the port sees every frame and pose and costs
            // the vehicle CPU. Serving beyond this host is a decision.
            if !a.ip().is_loopback() && !r.allow_remote.unwrap_or(false) {
                return Err(ctx.err(
                    l.span(),
                    "foxglove.listen",
                    format!("{a} is not a loopback address: the live view has no authentication or encryption, so anyone who reaches it sees the vehicle's data; set allow_remote = true to serve it on a trusted network, or listen on 127.0.0.1 and use an SSH tunnel"),
                ));
            }
            a
        }
        None => DEFAULT_LISTEN,
    };
    let count = |v: &Option<Spanned<i64>>, key: &str, max: i64, default: usize| match v {
        Some(q) if (1..=max).contains(q.get_ref()) => Ok(*q.get_ref() as usize),
        Some(q) => Err(ctx.err(
            q.span(),
            key,
            format!("{} is not in 1..={max}", q.get_ref()),
        )),
        None => Ok(default),
    };
    let max_clients = count(&r.max_clients, "foxglove.max_clients", 64, 4)?;
    // All but one place by default: another host always finds one, and
    // the viewers that share an SSH tunnel (all 127.0.0.1) have the rest.
    let per_addr = match &r.max_clients_per_addr {
        Some(q) if !(1..=max_clients as i64).contains(q.get_ref()) => {
            return Err(ctx.err(
                q.span(),
                "foxglove.max_clients_per_addr",
                format!("{} is not in 1..={max_clients} (max_clients)", q.get_ref()),
            ))
        }
        Some(q) => *q.get_ref() as usize,
        None => max_clients.saturating_sub(1).max(1),
    };
    Ok(Foxglove {
        listen,
        client_queue: count(&r.client_queue, "foxglove.client_queue", 100_000, 256)?,
        max_clients,
        max_clients_per_addr: per_addr,
    })
}

#[cfg(test)]
mod tests {
    use crate::config::Config;

    const BASE: &str = "calibration = \"c.toml\"\n[backend]\nkind = \"sim\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n";

    fn parse(extra: &str) -> Result<Config, String> {
        Config::parse(&format!("{BASE}{extra}"), "t.toml", None).map_err(|e| e.to_string())
    }

    #[test]
    fn off_by_default_loopback_by_default_remote_only_when_allowed() {
        assert_eq!(parse("").unwrap().foxglove, None);
        let c = parse("[foxglove]\n").unwrap().foxglove.unwrap();
        assert_eq!(c.listen, super::DEFAULT_LISTEN);
        assert_eq!(
            (c.client_queue, c.max_clients, c.max_clients_per_addr),
            (256, 4, 3)
        );
        assert_eq!(
            parse("[foxglove]\nenabled = false\n").unwrap().foxglove,
            None
        );
        let e = parse("[foxglove]\nlisten = \"0.0.0.0:8765\"\n").unwrap_err();
        assert!(
            e.starts_with("t.toml:7: foxglove.listen: 0.0.0.0:8765 is not a loopback address"),
            "{e}"
        );
        let c = parse("[foxglove]\nlisten = \"0.0.0.0:8765\"\nallow_remote = true\n").unwrap();
        assert_eq!(c.foxglove.unwrap().listen.port(), 8765);
        let c = parse("[foxglove]\nlisten = \"[::1]:9000\"\n").unwrap();
        assert!(c.foxglove.unwrap().listen.ip().is_loopback());
        let e = parse("[foxglove]\nclient_queue = 0\n").unwrap_err();
        assert_eq!(e, "t.toml:7: foxglove.client_queue: 0 is not in 1..=100000");
        let per = |t: &str| parse(t).map(|c| c.foxglove.unwrap().max_clients_per_addr);
        assert_eq!(per("[foxglove]\nmax_clients = 1\n"), Ok(1));
        assert_eq!(per("[foxglove]\nmax_clients = 8\n"), Ok(7));
        assert_eq!(per("[foxglove]\nmax_clients_per_addr = 4\n"), Ok(4));
        assert_eq!(
            per("[foxglove]\nmax_clients = 2\nmax_clients_per_addr = 3\n"),
            Err("t.toml:8: foxglove.max_clients_per_addr: 3 is not in 1..=2 (max_clients)".into())
        );
        assert_eq!(
            per("[foxglove]\nmax_clients_per_addr = 0\n"),
            Err("t.toml:7: foxglove.max_clients_per_addr: 0 is not in 1..=4 (max_clients)".into())
        );
        let e = parse("[foxglove]\nport = 1\n").unwrap_err();
        assert!(
            e.starts_with("t.toml:7: foxglove.port: unknown field `port`"),
            "{e}"
        );
    }
}
