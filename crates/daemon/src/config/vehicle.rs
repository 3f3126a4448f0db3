//! `[site]`, `[mavlink]` and `[dvl]`: the daemon as a component of the
//! vehicle (docs/vehicle.md). The tables and their validators are
//! lightpose-vehicle's (`SiteTable`, `MavlinkTable`, `DvlTable`); this file
//! only reads them out of the file with their spans and turns the vehicle
//! crate's `[table] key: msg` into `file:line: table.key: msg`.
//!
//! `[mavlink]` needs `[site]` (the beacon's heading and depth tie the beam
//! frame to the autopilot's NED); `[dvl]` does not (its velocity is in the
//! vehicle's own frame).

use super::backend::key_of;
use super::locate::Ctx;
use super::places::{self, Places};
use super::ConfigError;
use lightpose_vehicle::{DvlSettings, Endpoint, MavlinkSettings, MaxAge, Site};
use lightpose_vehicle::{DvlTable, MavlinkTable, SiteTable};
use serde::de::DeserializeOwned;
use toml::Spanned;

/// The vehicle link as configured: what the MAVLink task, the DVL client
/// and the frame thread's input need.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleConfig {
    pub mavlink: Option<MavlinkSettings>,
    pub dvl: Option<DvlSettings>,
    /// How old each reading may be and still go with a frame.
    pub max_age: MaxAge,
    /// `[mavlink] blueos_endpoint = true`: the endpoint to ask BlueOS's
    /// autopilot manager for at start (crate::blueos).
    pub blueos: Option<crate::blueos::BlueosEndpoint>,
}

/// The link tables as written (each left whole, with its span, for the
/// vehicle crate's serde structs); `[site]` goes through [`site`].
pub(super) struct RawVehicle<'a> {
    pub mavlink: Option<&'a Spanned<toml::Table>>,
    pub dvl: Option<&'a Spanned<toml::Table>>,
}

/// `[site]` alone, and its heading in degrees as written (the
/// `[attitude]` input needs it too).
pub(super) fn site(
    ctx: &Ctx,
    raw: Option<&Spanned<toml::Table>>,
) -> Result<Option<(Site, f64)>, ConfigError> {
    let Some(t) = raw else { return Ok(None) };
    let table: SiteTable = deserialize(ctx, t, "site")?;
    let site = table
        .validate()
        .map_err(|e| vehicle_error(ctx, t.span().start, &e))?;
    Ok(Some((site, table.beacon_heading_deg)))
}

/// `None` unless `[mavlink]` or `[dvl]` is there.
pub(super) fn validate(
    ctx: &Ctx,
    raw: &RawVehicle,
    site: Option<Site>,
    at: &mut Places,
) -> Result<Option<VehicleConfig>, ConfigError> {
    let mut max_age = MaxAge::default();
    let mut blueos = None;
    let mavlink = match raw.mavlink {
        None => None,
        Some(t) => {
            // The daemon's own keys, not the vehicle crate's.
            let (ours, rest) = blueos_keys(ctx, t)?;
            let table: MavlinkTable = deserialize_table(ctx, t.span().start, &rest, "mavlink")?;
            let Some(site) = site else {
                return Err(ctx.at(
                    ctx.line(t.span().start),
                    "mavlink",
                    "needs [site] (beacon_heading_deg, beacon_depth_m) to refer poses to the autopilot's north, east and down",
                ));
            };
            let (s, age) = table
                .validate_in(site, ctx.base_dir)
                .map_err(|e| vehicle_error(ctx, t.span().start, &e))?;
            no_port_0(ctx, t.span().start, &s.endpoint)?;
            if let Some(url) = ours {
                let e = crate::blueos::BlueosEndpoint::new(&url, &s.endpoint).map_err(|msg| {
                    ctx.at(
                        ctx.line_of_key(t.span().start, "blueos_endpoint"),
                        "mavlink.blueos_endpoint",
                        msg,
                    )
                })?;
                blueos = Some(e);
            }
            // A udpin address is bound: `wiring::check` tries it.
            at.set(
                places::MAVLINK,
                ctx.line_of_key(t.span().start, "connection"),
            );
            max_age = age;
            Some(s)
        }
    };
    let dvl = match raw.dvl {
        None => None,
        Some(t) => {
            let table: DvlTable = deserialize(ctx, t, "dvl")?;
            let (s, age) = table
                .validate()
                .map_err(|e| vehicle_error(ctx, t.span().start, &e))?;
            max_age.velocity = age;
            Some(s)
        }
    };
    if mavlink.is_none() && dvl.is_none() {
        return Ok(None);
    }
    Ok(Some(VehicleConfig {
        mavlink,
        dvl,
        max_age,
        blueos,
    }))
}

/// Port 0, as everywhere in this file: no one listens there, and a
/// listener there gets a port nobody knows.
fn no_port_0(ctx: &Ctx, start: usize, ep: &Endpoint) -> Result<(), ConfigError> {
    let port = match ep {
        Endpoint::UdpOut { port, .. } | Endpoint::TcpOut { port, .. } => *port,
        Endpoint::UdpIn(a) | Endpoint::TcpIn(a) => a.port(),
        Endpoint::Serial { .. } => return Ok(()),
    };
    if port != 0 {
        return Ok(());
    }
    Err(ctx.at(
        ctx.line_of_key(start, "connection"),
        "mavlink.connection",
        format!("{ep}: port 0 is no port to send to or listen on (1..=65535)"),
    ))
}

/// `blueos_endpoint` and `blueos_url` taken out of `[mavlink]` (the
/// daemon's keys: the vehicle crate knows no BlueOS): the manager's URL
/// when the endpoint is asked for, and the rest of the table.
fn blueos_keys(
    ctx: &Ctx,
    t: &Spanned<toml::Table>,
) -> Result<(Option<String>, toml::Table), ConfigError> {
    let start = t.span().start;
    let mut rest = t.get_ref().clone();
    let on = match rest.remove("blueos_endpoint") {
        None => false,
        Some(toml::Value::Boolean(b)) => b,
        Some(_) => {
            return Err(ctx.at(
                ctx.line_of_key(start, "blueos_endpoint"),
                "mavlink.blueos_endpoint",
                "want true or false",
            ))
        }
    };
    let url = match rest.remove("blueos_url") {
        None => crate::blueos::DEFAULT_URL.to_string(),
        Some(toml::Value::String(u)) => u,
        Some(_) => {
            return Err(ctx.at(
                ctx.line_of_key(start, "blueos_url"),
                "mavlink.blueos_url",
                "want a string, e.g. \"http://127.0.0.1/ardupilot-manager\"",
            ))
        }
    };
    Ok((on.then_some(url), rest))
}

/// A table into the vehicle crate's struct; serde's refusal (an unknown
/// key, a wrong type) at the line of the key it is about.
fn deserialize<T: DeserializeOwned>(
    ctx: &Ctx,
    t: &Spanned<toml::Table>,
    name: &str,
) -> Result<T, ConfigError> {
    deserialize_table(ctx, t.span().start, t.get_ref(), name)
}

fn deserialize_table<T: DeserializeOwned>(
    ctx: &Ctx,
    start: usize,
    table: &toml::Table,
    name: &str,
) -> Result<T, ConfigError> {
    T::deserialize(toml::Value::Table(table.clone())).map_err(|e: toml::de::Error| {
        let msg = e.message().trim().to_string();
        match key_of(table, &msg) {
            Some(key) => {
                let first = key.split('.').next().unwrap_or("");
                ctx.at(ctx.line_of_key(start, first), &format!("{name}.{key}"), msg)
            }
            None => ctx.at(ctx.line(start), name, msg),
        }
    })
}

/// The vehicle crate's `[table] key: msg` at the line of the key.
fn vehicle_error(ctx: &Ctx, start: usize, e: &lightpose_vehicle::ConfigError) -> ConfigError {
    ctx.at(
        sub_table_line(ctx, e.table, e.key).unwrap_or_else(|| ctx.line_of_key(start, e.key)),
        &format!("{}.{}", e.table, e.key),
        e.msg.clone(),
    )
}

/// The line of a key of a sub-table (`signing.key_file` of `[mavlink]` is
/// `key_file` under `[mavlink.signing]`), or of the sub-table's header.
fn sub_table_line(ctx: &Ctx, table: &str, key: &str) -> Option<usize> {
    let (sub, rest) = key.split_once('.').unwrap_or((key, ""));
    let header = format!("[{table}.{sub}]");
    let mut at = 0;
    for line in ctx.src.split_inclusive('\n') {
        if line.trim() == header {
            let key_line = if rest.is_empty() { sub } else { rest };
            return Some(ctx.line_of_key(at, key_line));
        }
        at += line.len();
    }
    None
}

#[cfg(test)]
mod tests {
    use crate::config::Config;
    use lightpose_vehicle::mav::inbound::DepthSource;
    use lightpose_vehicle::mav::signing::SigningKey;
    use std::time::Duration;

    const BASE: &str = "calibration = \"c.toml\"\n[backend]\nkind = \"sim\"\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n";
    const SITE: &str = "[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n";

    fn parse(extra: &str) -> Result<Config, String> {
        Config::parse(&format!("{BASE}{extra}"), "t.toml", None).map_err(|e| e.to_string())
    }

    #[test]
    fn the_tables_validate_into_settings() {
        let c = parse(SITE).unwrap();
        assert!(c.vehicle.is_none());
        assert!((c.site.unwrap().axis_heading.deg() - 30.0).abs() < 1e-12);
        let c = parse(&format!(
            "{SITE}[mavlink]\nconnection = \"udpout:127.0.0.1:14550\"\ndepth = \"global_position_int\"\nattitude_max_age_s = 0.1\n[dvl]\naddress = \"192.168.194.95:16171\"\nmax_age_s = 0.5\n"
        ))
        .unwrap();
        let v = c.vehicle.unwrap();
        let m = v.mavlink.unwrap();
        assert_eq!(m.endpoint.to_string(), "udpout:127.0.0.1:14550");
        assert_eq!((m.system_id, m.component_id), (1, 197));
        assert_eq!(m.input.depth, DepthSource::GlobalPositionInt);
        assert_eq!(v.dvl.unwrap().address, "192.168.194.95:16171");
        assert_eq!(v.max_age.attitude, Duration::from_millis(100));
        assert_eq!(v.max_age.velocity, Duration::from_millis(500));
        let v = parse("[dvl]\naddress = \"10.0.0.2:16171\"\n")
            .unwrap()
            .vehicle
            .unwrap();
        assert!(v.mavlink.is_none() && v.dvl.is_some());
    }

    /// A key file is read at start-up, its relative path taken from the
    /// configuration's directory (so a config and its key travel together).
    #[test]
    fn a_signing_key_file_is_read_beside_the_config() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("mav.pass"), "sea trial 7\n").unwrap();
        let src = format!(
            "{BASE}{SITE}[mavlink]\nconnection = \"udpin:0.0.0.0:14550\"\n[mavlink.signing]\npassphrase_file = \"mav.pass\"\nlink_id = 9\n"
        );
        let c = Config::parse(&src, "t.toml", Some(dir.path())).unwrap();
        let sg = c.vehicle.unwrap().mavlink.unwrap().signing.unwrap();
        assert_eq!(sg.key, SigningKey::from_passphrase("sea trial 7"));
        assert_eq!((sg.link_id, sg.allow_unsigned), (9, false));
        // Both forms at once is one too many.
        let both = format!("{src}key_file = \"k.hex\"\n");
        let e = Config::parse(&both, "t.toml", Some(dir.path())).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("t.toml:11: mavlink.signing: key_file and passphrase_file both"),
            "{e}"
        );
    }

    #[test]
    fn the_attitude_input_takes_its_heading_from_site() {
        let att = "[attitude]\nenabled = true\n";
        let a = parse(&format!("{SITE}{att}")).unwrap().attitude.unwrap();
        assert_eq!(a.beacon_axis_heading_deg, 30.0);
        // The older key alone, and both when they agree.
        let old = format!("{att}beacon_axis_heading_deg = 12.0\n");
        let a = parse(&old).unwrap().attitude.unwrap();
        assert_eq!(a.beacon_axis_heading_deg, 12.0);
        let same = format!("{att}beacon_axis_heading_deg = 30.0\n{SITE}");
        assert_eq!(
            parse(&same)
                .unwrap()
                .attitude
                .unwrap()
                .beacon_axis_heading_deg,
            30.0
        );
        let e = parse(&format!("{old}{SITE}")).unwrap_err();
        assert_eq!(
            e,
            "t.toml:8: attitude.beacon_axis_heading_deg: 12° conflicts with [site] beacon_heading_deg = 30°: give the beacon's heading once, in [site]"
        );
        let e = parse(att).unwrap_err();
        assert!(
            e.starts_with("t.toml: [site] beacon_heading_deg: missing"),
            "{e}"
        );
    }

    #[test]
    fn refusals_name_line_and_key() {
        let e = parse("[mavlink]\nconnection = \"udpout:127.0.0.1:14550\"\n").unwrap_err();
        assert!(e.starts_with("t.toml:6: mavlink: needs [site]"), "{e}");
        let e = parse(&format!(
            "{SITE}[mavlink]\nconnection = \"udpin:127.0.0.1:0\"\n"
        ))
        .unwrap_err();
        assert!(
            e.starts_with("t.toml:10: mavlink.connection: udpin:127.0.0.1:0: port 0"),
            "{e}"
        );
        // Issue 44: unsigned on every address, refused at its line.
        let e = parse(&format!(
            "{SITE}[mavlink]\nconnection = \"udpin:0.0.0.0:14550\"\n"
        ))
        .unwrap_err();
        assert!(
            e.starts_with("t.toml:10: mavlink.connection: udpin:0.0.0.0:14550 listens on 0.0.0.0:14550, not a loopback address, without signing"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1, "{e}");
        let remote =
            format!("{SITE}[mavlink]\nconnection = \"udpin:0.0.0.0:14550\"\nallow_remote = true\n");
        assert!(parse(&remote).is_ok());
        let e = parse(&format!("{SITE}[mavlink]\nconnection = \"tcp:x:1\"\n")).unwrap_err();
        assert!(
            e.starts_with("t.toml:10: mavlink.connection: unknown transport"),
            "{e}"
        );
        let e = parse(&format!(
            "{SITE}[mavlink]\nconnection = \"udpin:0.0.0.0:14550\"\nroll_std_deg = 200.0\n"
        ))
        .unwrap_err();
        assert!(
            e.starts_with("t.toml:11: mavlink.roll_std_deg: 200 is not within"),
            "{e}"
        );
        let e = parse(&format!(
            "{SITE}[mavlink]\nconnection = \"udpin:0.0.0.0:14550\"\nrate = 3\n"
        ))
        .unwrap_err();
        assert!(
            e.starts_with("t.toml:11: mavlink.rate: unknown field `rate`"),
            "{e}"
        );
        let e = parse(&format!(
            "{SITE}[mavlink]\nconnection = \"udpin:0.0.0.0:14550\"\n[mavlink.signing]\nlink_id = 2\nkey_file = \"/nonexistent/k\"\n"
        ))
        .unwrap_err();
        assert!(
            e.starts_with("t.toml:13: mavlink.signing.key_file: /nonexistent/k: No such file"),
            "{e}"
        );
        let e = parse(&format!(
            "{SITE}[mavlink]\nconnection = \"udpin:0.0.0.0:14550\"\n[mavlink.signing]\nlink_id = 2\n"
        ))
        .unwrap_err();
        assert!(
            e.starts_with("t.toml:11: mavlink.signing: no key: want key_file"),
            "{e}"
        );
        let e = parse("[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = -2.0\n").unwrap_err();
        assert!(
            e.starts_with("t.toml:8: site.beacon_depth_m: -2 is not within"),
            "{e}"
        );
        let e = parse("[site]\nbeacon_heading_deg = 30.0\n").unwrap_err();
        assert!(
            e.starts_with("t.toml:6: site: missing field `beacon_depth_m`"),
            "{e}"
        );
        let e = parse("[dvl]\naddress = \"192.168.2.95\"\n").unwrap_err();
        assert!(e.starts_with("t.toml:7: dvl.address: "), "{e}");
        let e = parse("[dvl]\naddress = \"h:1\"\nmax_age_s = \"x\"\n").unwrap_err();
        assert!(e.starts_with("t.toml:8: dvl.max_age_s: "), "{e}");
        // Audit: an age no reading can be younger than turned a reading
        // off unsaid.
        let e = parse("[dvl]\naddress = \"h:1\"\nmax_age_s = 0.0\n").unwrap_err();
        assert!(
            e.contains("dvl") && e.contains("max_age_s") && e.contains("0.001"),
            "{e}"
        );
        let e = parse(&format!("{SITE}[mavlink]\nconnection = \"udpout:127.0.0.1:14550\"\nattitude_max_age_s = 1e-300\n")).unwrap_err();
        assert!(
            e.contains("attitude_max_age_s") && e.contains("0.001"),
            "{e}"
        );
    }
}
