//! `[web]`: the daemon's own web page and REST API (docs/blueos.md), what
//! a BlueOS extension shows in BlueOS's interface. Off unless the table is
//! there (no port opens without it); read-only unless `control = true`.

use super::locate::{socket_addr, AddrUse, Ctx};
use super::places::{self, Places};
use super::ConfigError;
use serde::Deserialize;
use std::net::SocketAddr;
use toml::Spanned;

#[derive(Debug, Clone, PartialEq)]
pub struct Web {
    pub listen: SocketAddr,
    /// Whether the page may act (recordings, reloads, config checks);
    /// without it every request that would change something is refused.
    pub control: bool,
    /// Connections served at once (page loads, API calls and live feeds
    /// alike); more are answered 503 and closed.
    pub max_clients: usize,
    /// Of them, from one source address, so that one host (a script in a
    /// loop, a tablet with many tabs) cannot take every place.
    pub max_clients_per_addr: usize,
    /// Live feed updates a second (the page's heatmap and pose).
    pub updates_hz: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawWeb {
    enabled: Option<bool>,
    listen: Option<Spanned<String>>,
    control: Option<bool>,
    max_clients: Option<Spanned<i64>>,
    max_clients_per_addr: Option<Spanned<i64>>,
    updates_hz: Option<Spanned<f64>>,
}

/// The most connections a daemon on a Pi is asked to hold.
const MAX_CLIENTS: i64 = 1024;

/// `None` when the table is absent or not enabled (checked all the same:
/// [`places::when_on`]).
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&Spanned<RawWeb>>,
    at: &mut Places,
) -> Result<Option<Web>, ConfigError> {
    let Some(table) = raw else { return Ok(None) };
    let enabled = table.get_ref().enabled.unwrap_or(true);
    places::when_on(enabled, at, |at| check(ctx, table, at))
}

fn check(ctx: &Ctx, table: &Spanned<RawWeb>, at: &mut Places) -> Result<Web, ConfigError> {
    let r = table.get_ref();
    at.set(
        places::WEB_LISTEN,
        ctx.line_of_value(table, r.listen.as_ref()),
    );
    // No default port: a page on the vehicle's network is a decision, and
    // the line that makes it says where.
    let Some(l) = &r.listen else {
        return Err(ctx.at(
            ctx.line(table.span().start),
            "web.listen",
            "missing: the address to serve the page on, e.g. \"0.0.0.0:17160\" on a vehicle (BlueOS reaches it there) or \"127.0.0.1:17160\"",
        ));
    };
    let listen = socket_addr(ctx, l, "web.listen", AddrUse::ListenTold)?;
    let max_clients = match &r.max_clients {
        Some(q) if (1..=MAX_CLIENTS).contains(q.get_ref()) => *q.get_ref() as usize,
        Some(q) => {
            return Err(ctx.err(
                q.span(),
                "web.max_clients",
                format!("{} is not in 1..={MAX_CLIENTS}", q.get_ref()),
            ))
        }
        None => 32,
    };
    let per_addr = match &r.max_clients_per_addr {
        Some(q) if !(1..=max_clients as i64).contains(q.get_ref()) => {
            return Err(ctx.err(
                q.span(),
                "web.max_clients_per_addr",
                format!("{} is not in 1..={max_clients} (max_clients)", q.get_ref()),
            ))
        }
        Some(q) => *q.get_ref() as usize,
        // Half the places by default: BlueOS's proxy (one address for
        // every browser behind it) has many, another host always finds one.
        None => (max_clients / 2).max(1),
    };
    let updates_hz = match &r.updates_hz {
        Some(h) if (1.0..=50.0).contains(h.get_ref()) => *h.get_ref(),
        Some(h) => {
            return Err(ctx.err(
                h.span(),
                "web.updates_hz",
                format!("{} is not in 1..=50", h.get_ref()),
            ))
        }
        None => 10.0,
    };
    Ok(Web {
        listen,
        control: r.control.unwrap_or(false),
        max_clients,
        max_clients_per_addr: per_addr,
        updates_hz,
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
    fn off_without_the_table_read_only_by_default_listen_required() {
        assert_eq!(parse("").unwrap().web, None);
        // Off, it is checked all the same (places::when_on).
        let off = "[web]\nenabled = false\nlisten = \"0.0.0.0:17160\"\n";
        assert_eq!(parse(off).unwrap().web, None);
        assert!(parse("[web]\nenabled = false\n").is_err());
        let w = parse("[web]\nlisten = \"0.0.0.0:17160\"\n")
            .unwrap()
            .web
            .unwrap();
        assert_eq!(w.listen.port(), 17160);
        assert!(!w.control);
        assert_eq!((w.max_clients, w.max_clients_per_addr), (32, 16));
        assert_eq!(w.updates_hz, 10.0);
        let e = parse("[web]\ncontrol = true\n").unwrap_err();
        assert!(e.starts_with("t.toml:6: web.listen: missing"), "{e}");
        let e = parse("[web]\nlisten = \"nowhere\"\n").unwrap_err();
        assert!(e.starts_with("t.toml:7: web.listen:"), "{e}");
        let e = parse("[web]\nlisten = \"127.0.0.1:0\"\nmax_clients = 0\n").unwrap_err();
        assert_eq!(e, "t.toml:8: web.max_clients: 0 is not in 1..=1024");
        let e =
            parse("[web]\nlisten = \"127.0.0.1:0\"\nmax_clients = 4\nmax_clients_per_addr = 5\n")
                .unwrap_err();
        assert_eq!(
            e,
            "t.toml:9: web.max_clients_per_addr: 5 is not in 1..=4 (max_clients)"
        );
        let e = parse("[web]\nlisten = \"127.0.0.1:0\"\nupdates_hz = 0.5\n").unwrap_err();
        assert_eq!(e, "t.toml:8: web.updates_hz: 0.5 is not in 1..=50");
        let e = parse("[web]\nlisten = \"127.0.0.1:0\"\nport = 1\n").unwrap_err();
        assert!(
            e.starts_with("t.toml:8: web.port: unknown field `port`"),
            "{e}"
        );
    }
}
