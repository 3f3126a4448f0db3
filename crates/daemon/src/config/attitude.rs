//! `[attitude]`: the optional input of the vehicle's AHRS readings.
//!
//! Ranges: `listen` not on port 0; `beacon_axis_heading_deg` -360..=360;
//! `max_age_s` 0.001..=60 s; `allow_from` a non-empty list of sender
//! addresses, each an IP (any port) or an IP:port.
//!
//! The datagrams carry no authentication, so whoever reaches the port
//! steers the estimate's pitch and yaw: a `listen` that is not loopback
//! needs `allow_from` (who may send) or an explicit `allow_remote = true`,
//! as the live view's does.
//!
//! The beacon's heading is `[site] beacon_heading_deg`, which the MAVLink
//! link uses too; `beacon_axis_heading_deg` here is the older spelling,
//! still accepted alone. Both at once must agree: two headings for one
//! beacon would make the two inputs disagree about yaw.

use super::locate::{socket_addr, within, AddrUse, Ctx};
use super::places::{self, Places};
use super::ConfigError;
use lightpose_core::textfile::excerpt;
use serde::Deserialize;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;
use toml::Spanned;

#[derive(Debug, Clone, PartialEq)]
pub struct AttitudeInput {
    pub listen: SocketAddr,
    /// Compass heading that the beacon's optical axis (+x of B) points to.
    pub beacon_axis_heading_deg: f64,
    /// A reading older than this is not attached to a frame.
    pub max_age: Duration,
    /// The senders whose datagrams are read; `None`: any.
    pub allow_from: Option<Vec<Sender>>,
}

/// One entry of `allow_from`: an address, and a port when one was given.
///
/// An address alone is the usual entry: an AHRS (or the bridge in front
/// of it) keeps its address but often sends from an ephemeral port that
/// changes at each restart; a port pins the sender down further when the
/// host runs other programs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sender {
    pub ip: IpAddr,
    pub port: Option<u16>,
}

impl Sender {
    /// Whether a datagram from `from` is this sender's. An IPv4 sender
    /// seen on a dual-stack socket (`::ffff:a.b.c.d`) is the same sender.
    #[inline]
    pub fn admits(&self, from: SocketAddr) -> bool {
        from.ip().to_canonical() == self.ip && self.port.is_none_or(|p| p == from.port())
    }
}

impl std::fmt::Display for Sender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.port {
            Some(p) => write!(f, "{}", SocketAddr::new(self.ip, p)),
            None => write!(f, "{}", self.ip),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAttitude {
    enabled: Option<bool>,
    listen: Option<Spanned<String>>,
    beacon_axis_heading_deg: Option<Spanned<f64>>,
    max_age_s: Option<Spanned<f64>>,
    allow_from: Option<Spanned<Vec<Spanned<String>>>>,
    allow_remote: Option<bool>,
}

/// `None` unless the table says `enabled = true`; the heading from
/// `[site]` (`site_heading_deg`) unless the table gives its own. A table
/// that is off is checked all the same ([`places::when_on`]); only what it
/// needs of another table (the heading) is asked of it when it is on.
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&Spanned<RawAttitude>>,
    site_heading_deg: Option<f64>,
    at: &mut Places,
) -> Result<Option<AttitudeInput>, ConfigError> {
    let Some(table) = raw else { return Ok(None) };
    let enabled = table.get_ref().enabled.unwrap_or(false);
    // Off, the table's own heading is checked, not against [site]'s.
    let site = site_heading_deg.filter(|_| enabled);
    let Some(checked) = places::when_on(enabled, at, |at| check(ctx, table, site, at))? else {
        return Ok(None);
    };
    let Some(beacon_axis_heading_deg) = checked.heading else {
        return Err(ctx.whole(
            "[site] beacon_heading_deg: missing (the [attitude] input needs it to refer yaw to the beam)",
        ));
    };
    Ok(Some(AttitudeInput {
        listen: checked.listen,
        beacon_axis_heading_deg,
        max_age: checked.max_age,
        allow_from: checked.allow_from,
    }))
}

/// The table's own values, checked; the heading is `None` when neither it
/// nor `[site]` gives one.
struct Checked {
    listen: SocketAddr,
    heading: Option<f64>,
    max_age: Duration,
    allow_from: Option<Vec<Sender>>,
}

fn check(
    ctx: &Ctx,
    table: &Spanned<RawAttitude>,
    site_heading_deg: Option<f64>,
    at: &mut Places,
) -> Result<Checked, ConfigError> {
    let a = table.get_ref();
    // Whether it can be bound shows only on this machine: `wiring::check`.
    at.set(
        places::ATTITUDE_LISTEN,
        ctx.line_of_value(table, a.listen.as_ref()),
    );
    let allow_from = match &a.allow_from {
        Some(list) => Some(senders(ctx, list)?),
        None => None,
    };
    let listen = match &a.listen {
        Some(l) => {
            let addr = socket_addr(ctx, l, "attitude.listen", AddrUse::Listen)?;
            if addr.ip().is_multicast() || addr.ip() == Ipv4Addr::BROADCAST {
                return Err(ctx.err(
                    l.span(),
                    "attitude.listen",
                    format!("{addr} is a multicast or broadcast address: the input binds it without joining a group, so nothing would arrive; listen on this host's address (or 0.0.0.0) and have the AHRS send to it"),
                ));
            }
            // Beyond this host anyone who reaches the port sets the
            // vehicle's pitch and yaw in the estimate: a decision, said.
            if !addr.ip().is_loopback() && allow_from.is_none() && a.allow_remote != Some(true) {
                return Err(ctx.err(
                    l.span(),
                    "attitude.listen",
                    format!("{addr} is not a loopback address: the input has no authentication, so anyone who reaches it feeds the estimate; name the AHRS in allow_from = [\"192.168.2.10\"], or set allow_remote = true on a trusted network"),
                ));
            }
            addr
        }
        None => SocketAddr::from((Ipv4Addr::LOCALHOST, 17151)),
    };
    let heading = match (&a.beacon_axis_heading_deg, site_heading_deg) {
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
                _ => Some(own),
            }
        }
        (None, site_deg) => site_deg,
    };
    let max_age = match &a.max_age_s {
        // Below a millisecond no reading is fresh at any frame (1e-300
        // rounded to a zero Duration turned the input off unsaid).
        Some(v) => {
            Duration::from_secs_f64(within(ctx, v, "attitude.max_age_s", (0.001, 60.0), " s")?)
        }
        None => Duration::from_millis(500),
    };
    Ok(Checked {
        listen,
        heading,
        max_age,
        allow_from,
    })
}

/// `allow_from`: each entry an IP or an IP:port; not empty (that would
/// refuse every reading: leave the input off instead).
fn senders(ctx: &Ctx, list: &Spanned<Vec<Spanned<String>>>) -> Result<Vec<Sender>, ConfigError> {
    const KEY: &str = "attitude.allow_from";
    if list.get_ref().is_empty() {
        let msg = "empty: it would refuse every sender; name the AHRS's address, or leave the key out to accept any";
        return Err(ctx.err(list.span(), KEY, msg));
    }
    let one = |v: &Spanned<String>| {
        let text = v.get_ref().trim();
        let s = match (text.parse::<SocketAddr>(), text.parse::<IpAddr>()) {
            (Ok(a), _) if a.port() != 0 => Sender {
                ip: a.ip().to_canonical(),
                port: Some(a.port()),
            },
            (_, Ok(ip)) => Sender {
                ip: ip.to_canonical(),
                port: None,
            },
            _ => {
                let written = excerpt(v.get_ref(), 60);
                let msg = format!("\"{written}\" is not an address or address:port with a port in 1..=65535 (e.g. \"192.168.2.10\")");
                return Err(ctx.err(v.span(), KEY, msg));
            }
        };
        // No datagram comes from these: an entry naming one is a mistake
        // that would silently refuse the AHRS.
        if s.ip.is_unspecified() || s.ip.is_multicast() {
            let msg = format!("{s}: no datagram comes from an unspecified or multicast address; name the AHRS's own");
            return Err(ctx.err(v.span(), KEY, msg));
        }
        Ok(s)
    };
    list.get_ref().iter().map(one).collect()
}

#[cfg(test)]
mod tests {
    use super::Sender;
    use crate::config::Config;
    use std::net::SocketAddr;

    const BASE: &str = "calibration = \"c.toml\"\n[backend]\nkind = \"sim\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n[attitude]\nenabled = true\nbeacon_axis_heading_deg = 0.0\n";

    fn parse(extra: &str) -> Result<Config, String> {
        Config::parse(&format!("{BASE}{extra}"), "t.toml", None).map_err(|e| e.to_string())
    }

    fn from(a: &str) -> SocketAddr {
        a.parse().expect("test address")
    }

    /// Audit: a max age that rounds to nothing, and a multicast listen
    /// (bound without joining: nothing arrives), were taken and turned
    /// the input off unsaid.
    #[test]
    fn a_listen_and_a_max_age_that_get_nothing_are_refused() {
        for (extra, key, what) in [
            (
                "max_age_s = 1e-300\n",
                "attitude.max_age_s",
                "not in 0.001..=60",
            ),
            (
                "max_age_s = 0.0009\n",
                "attitude.max_age_s",
                "not in 0.001..=60",
            ),
            (
                "listen = \"239.1.2.3:27151\"\nallow_remote = true\n",
                "attitude.listen",
                "multicast or broadcast",
            ),
            (
                "listen = \"255.255.255.255:27151\"\nallow_remote = true\n",
                "attitude.listen",
                "multicast or broadcast",
            ),
        ] {
            let e = parse(extra).unwrap_err();
            assert!(
                e.contains(key) && e.contains(what) && !e.contains('\n'),
                "{extra}: {e}"
            );
        }
        let c = parse("max_age_s = 0.001\n").unwrap().attitude.unwrap();
        assert_eq!(c.max_age, std::time::Duration::from_millis(1));
    }

    /// Audit: a listen beyond loopback is a decision (allow_from or
    /// allow_remote), refused at its line otherwise.
    #[test]
    fn a_remote_listen_needs_allow_from_or_allow_remote() {
        let c = parse("").unwrap().attitude.unwrap();
        assert!(c.listen.ip().is_loopback() && c.allow_from.is_none());
        let e = parse("listen = \"0.0.0.0:17151\"\n").unwrap_err();
        assert!(
            e.starts_with("t.toml:9: attitude.listen: 0.0.0.0:17151 is not a loopback address")
                && e.contains("allow_from")
                && !e.contains('\n'),
            "{e}"
        );
        let e = parse("listen = \"[::]:17151\"\nallow_remote = false\n").unwrap_err();
        assert!(e.starts_with("t.toml:9: attitude.listen: "), "{e}");
        let c = parse("listen = \"0.0.0.0:17151\"\nallow_remote = true\n").unwrap();
        assert_eq!(c.attitude.unwrap().allow_from, None);
        let c = parse(
            "listen = \"0.0.0.0:17151\"\nallow_from = [\"192.168.2.10\", \"10.0.0.5:14555\"]\n",
        )
        .unwrap()
        .attitude
        .unwrap();
        assert_eq!(
            c.allow_from.unwrap(),
            [
                Sender {
                    ip: "192.168.2.10".parse().unwrap(),
                    port: None
                },
                Sender {
                    ip: "10.0.0.5".parse().unwrap(),
                    port: Some(14555)
                },
            ]
        );
        // Loopback needs neither; allow_from still filters there.
        let c = parse("listen = \"127.0.0.1:17151\"\nallow_from = [\"127.0.0.1\"]\n").unwrap();
        assert_eq!(c.attitude.unwrap().allow_from.map(|v| v.len()), Some(1));
    }

    #[test]
    fn bad_allow_from_entries_are_refused_at_their_line() {
        for (extra, want) in [
            ("allow_from = []\n", "t.toml:9: attitude.allow_from: empty"),
            (
                "allow_from = [\n\"192.168.2.10\",\n\"ahrs.local\"]\n",
                "t.toml:11: attitude.allow_from: \"ahrs.local\" is not an address",
            ),
            (
                "allow_from = [\"10.0.0.5:0\"]\n",
                "t.toml:9: attitude.allow_from: \"10.0.0.5:0\" is not an address",
            ),
            (
                "allow_from = [\"0.0.0.0\"]\n",
                "t.toml:9: attitude.allow_from: 0.0.0.0: no datagram",
            ),
            (
                "allow_from = [\"239.1.2.3:5000\"]\n",
                "t.toml:9: attitude.allow_from: 239.1.2.3:5000: no datagram",
            ),
            (
                "allow_from = \"10.0.0.5\"\n",
                "t.toml:9: attitude.allow_from: ",
            ),
        ] {
            let e = parse(extra).unwrap_err();
            assert!(e.starts_with(want) && !e.contains('\n'), "{extra}: {e}");
        }
    }

    #[test]
    fn a_sender_admits_its_address_and_port_only() {
        let any_port = Sender {
            ip: "192.168.2.10".parse().unwrap(),
            port: None,
        };
        assert!(any_port.admits(from("192.168.2.10:40000")));
        assert!(any_port.admits(from("[::ffff:192.168.2.10]:1")));
        assert!(!any_port.admits(from("192.168.2.11:40000")));
        let pinned = Sender {
            ip: "192.168.2.10".parse().unwrap(),
            port: Some(14555),
        };
        assert!(pinned.admits(from("192.168.2.10:14555")));
        assert!(!pinned.admits(from("192.168.2.10:14556")));
        assert_eq!(pinned.to_string(), "192.168.2.10:14555");
    }
}
