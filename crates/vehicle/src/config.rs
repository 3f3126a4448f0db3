//! The configuration tables `[site]`, `[mavlink]` and `[dvl]` as written
//! in the daemon's TOML (serde, unknown keys refused), and one validator
//! per table that turns each into typed settings. An error names the table
//! and the key; the caller adds the file.

use crate::dvl::client::DvlSettings;
use crate::mav::inbound::{DepthSource, InputConfig};
use crate::mav::link::Endpoint;
use crate::mav::outbound::{MissingStd, OutputConfig};
use crate::mav::signing::{KeyForm, SigningConfig, SigningKey};
use crate::mav::task::MavlinkSettings;
use crate::ned::{NedVec, Site};
use crate::readings::MaxAge;
use lightpose_core::Angle;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A key with a value that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("[{table}] {key}: {msg}")]
pub struct ConfigError {
    pub table: &'static str,
    pub key: &'static str,
    pub msg: String,
}

fn err(table: &'static str, key: &'static str, msg: impl Into<String>) -> ConfigError {
    ConfigError {
        table,
        key,
        msg: msg.into(),
    }
}

/// A finite number within `lo..=hi` (the default when absent).
fn within(
    table: &'static str,
    key: &'static str,
    v: Option<f64>,
    default: f64,
    lo: f64,
    hi: f64,
) -> Result<f64, ConfigError> {
    let v = v.unwrap_or(default);
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        // 1e-300 written out is 300 digits: a line to read, not to scroll.
        let shown = if v != 0.0 && v.is_finite() && !(1e-3..1e9).contains(&v.abs()) {
            format!("{v:e}")
        } else {
            format!("{v}")
        };
        Err(err(table, key, format!("{shown} is not within {lo}..{hi}")))
    }
}

/// `[site]`: where the beacon is and where it points.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteTable {
    /// Heading of the beacon's optical axis, degrees, in the autopilot's
    /// yaw reference (true north when it applies the declination), not a
    /// magnetic compass bearing.
    pub beacon_heading_deg: f64,
    /// Depth of the beacon below the surface, m.
    pub beacon_depth_m: f64,
    /// The beacon's position [N, E, D] in the autopilot's local frame, m
    /// (default zero: positions relative to the beacon, D to its depth).
    #[serde(default)]
    pub beacon_ned_m: Option<[f64; 3]>,
}

impl SiteTable {
    pub fn validate(&self) -> Result<Site, ConfigError> {
        let h = within(
            "site",
            "beacon_heading_deg",
            Some(self.beacon_heading_deg),
            0.0,
            -360.0,
            360.0,
        )?;
        let d = within(
            "site",
            "beacon_depth_m",
            Some(self.beacon_depth_m),
            0.0,
            0.0,
            11_000.0,
        )?;
        let ned = self.beacon_ned_m.unwrap_or_default();
        if !ned.iter().all(|v| v.is_finite() && v.abs() < 1e6) {
            return Err(err(
                "site",
                "beacon_ned_m",
                format!("{ned:?} is not three finite metres"),
            ));
        }
        let mut site = Site::new(Angle::from_deg(h), d);
        site.beacon_ned = NedVec(ned);
        Ok(site)
    }
}

/// `[mavlink]`: the link to the autopilot.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MavlinkTable {
    /// `udpout:HOST:PORT`, `udpin:ADDR:PORT` or `serial:PATH:BAUD`.
    pub connection: String,
    pub system_id: Option<u8>,
    pub component_id: Option<u8>,
    /// The autopilot's system id (default: learned from the first
    /// autopilot HEARTBEAT of `autopilot_component_id`).
    pub autopilot_system_id: Option<u8>,
    /// The autopilot's component id (default 1, MAV_COMP_ID_AUTOPILOT1).
    /// Readings are taken, and poses sent on `udpin`, only from the
    /// autopilot: a GCS or a second vehicle on the LAN is not it.
    pub autopilot_component_id: Option<u8>,
    pub attitude: Option<bool>,
    /// `global_position_int` (default), `vfr_hud` or `none`.
    pub depth: Option<String>,
    pub temperature: Option<bool>,
    pub attitude_max_age_s: Option<f64>,
    pub depth_max_age_s: Option<f64>,
    pub temperature_max_age_s: Option<f64>,
    pub depth_range_m: Option<[f64; 2]>,
    pub position_rate_hz: Option<f64>,
    pub speed: Option<bool>,
    pub heartbeat_hz: Option<f64>,
    pub roll_std_deg: Option<f64>,
    pub side_speed_std_mps: Option<f64>,
    /// `skip` or `assume`.
    pub missing_std: Option<String>,
    pub assume_position_std_m: Option<f64>,
    pub assume_angle_std_deg: Option<f64>,
    pub assume_surge_std_mps: Option<f64>,
    /// `[mavlink.signing]`: MAVLink 2 signing (docs/vehicle.md).
    pub signing: Option<SigningTable>,
    /// Listen (`udpin`) on an address beyond this host without signing:
    /// refused unless true (anyone who reaches the port is the autopilot).
    pub allow_remote: Option<bool>,
}

/// `[mavlink.signing]`: the key, in a file of its own (not in the
/// configuration, which is readable by more people than the key should
/// be), as 64 hex digits or as a passphrase.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SigningTable {
    pub key_file: Option<String>,
    pub passphrase_file: Option<String>,
    /// Default 0.
    pub link_id: Option<u8>,
    /// Default false: only signed frames are taken.
    pub allow_unsigned: Option<bool>,
}

impl SigningTable {
    /// The key read, with relative paths taken from `base_dir`.
    fn validate(&self, base_dir: Option<&Path>) -> Result<SigningConfig, ConfigError> {
        let path = |p: &str| match base_dir {
            Some(d) if Path::new(p).is_relative() => d.join(p),
            _ => PathBuf::from(p),
        };
        let (key, file, form) = match (&self.key_file, &self.passphrase_file) {
            (Some(k), None) => ("signing.key_file", k, KeyForm::Hex),
            (None, Some(p)) => ("signing.passphrase_file", p, KeyForm::Passphrase),
            (Some(_), Some(_)) => {
                return Err(err(
                    M,
                    "signing",
                    "key_file and passphrase_file both given: want one",
                ))
            }
            (None, None) => {
                return Err(err(
                    M,
                    "signing",
                    "no key: want key_file (64 hex digits) or passphrase_file",
                ))
            }
        };
        let file = path(file);
        let key = SigningKey::load(&file, form).map_err(|e| err(M, key, e))?;
        warn_if_others_read(&file);
        Ok(SigningConfig {
            key,
            link_id: self.link_id.unwrap_or(0),
            allow_unsigned: self.allow_unsigned.unwrap_or(false),
        })
    }
}

/// A warning (not a refusal: the operator may have reasons) when the key
/// file may be read by others than its owner, as ssh warns of a key.
fn warn_if_others_read(file: &Path) {
    use std::os::unix::fs::PermissionsExt;
    if let Ok(m) = std::fs::metadata(file) {
        let mode = m.permissions().mode();
        if mode & 0o077 != 0 {
            tracing::warn!(
                "mavlink: the signing key file {} may be read by others (mode {:o}): \
                 chmod 600 it, owned by lightposed's user",
                file.display(),
                mode & 0o777
            );
        }
    }
}

const M: &str = "mavlink";

impl MavlinkTable {
    fn input(&self) -> Result<InputConfig, ConfigError> {
        let depth = match self.depth.as_deref().unwrap_or("global_position_int") {
            "vfr_hud" => DepthSource::VfrHud,
            "global_position_int" => DepthSource::GlobalPositionInt,
            "none" => DepthSource::Off,
            o => {
                return Err(err(
                    M,
                    "depth",
                    format!("\"{o}\": want global_position_int, vfr_hud or none"),
                ))
            }
        };
        let range = self.depth_range_m.unwrap_or([-10.0, 1000.0]);
        if !(range[0].is_finite() && range[1].is_finite() && range[0] < range[1]) {
            return Err(err(
                M,
                "depth_range_m",
                format!("{range:?} is not [shallowest, deepest]"),
            ));
        }
        for (key, v) in [
            ("autopilot_system_id", self.autopilot_system_id),
            ("autopilot_component_id", self.autopilot_component_id),
        ] {
            if v == Some(0) {
                return Err(err(
                    M,
                    key,
                    "0 is the broadcast id, not a sender's: want 1..=255",
                ));
            }
        }
        Ok(InputConfig {
            attitude: self.attitude.unwrap_or(true),
            depth,
            temperature: self.temperature.unwrap_or(true),
            autopilot_system: self.autopilot_system_id,
            autopilot_component: self.autopilot_component_id.unwrap_or(1),
            depth_range_m: range,
            ..InputConfig::default()
        })
    }

    fn output(&self) -> Result<OutputConfig, ConfigError> {
        let rate = match self.position_rate_hz {
            None => None,
            Some(r) => Some(within(M, "position_rate_hz", Some(r), 0.0, 0.01, 1000.0)?),
        };
        let missing_std = match self.missing_std.as_deref().unwrap_or("skip") {
            "skip" => MissingStd::Skip,
            "assume" => MissingStd::Assume {
                position_m: within(
                    M,
                    "assume_position_std_m",
                    self.assume_position_std_m,
                    1.0,
                    1e-3,
                    100.0,
                )?,
                angle: Angle::from_deg(within(
                    M,
                    "assume_angle_std_deg",
                    self.assume_angle_std_deg,
                    10.0,
                    1e-3,
                    90.0,
                )?),
                surge_mps: within(
                    M,
                    "assume_surge_std_mps",
                    self.assume_surge_std_mps,
                    0.5,
                    1e-3,
                    10.0,
                )?,
            },
            o => {
                return Err(err(
                    M,
                    "missing_std",
                    format!("\"{o}\": want skip or assume"),
                ))
            }
        };
        Ok(OutputConfig {
            position_rate_hz: rate,
            speed: self.speed.unwrap_or(true),
            roll_std: Angle::from_deg(within(
                M,
                "roll_std_deg",
                self.roll_std_deg,
                5.0,
                0.0,
                90.0,
            )?),
            side_speed_std_mps: within(
                M,
                "side_speed_std_mps",
                self.side_speed_std_mps,
                0.1,
                0.0,
                10.0,
            )?,
            missing_std,
        })
    }

    /// As [`MavlinkTable::validate_in`], with relative key files taken
    /// from the working directory.
    pub fn validate(&self, site: Site) -> Result<(MavlinkSettings, MaxAge), ConfigError> {
        self.validate_in(site, None)
    }

    /// The link's settings, and how old its readings may be (velocity's
    /// age is `[dvl]`'s and is left at its default here). A signing key
    /// file's relative path is taken from `base_dir` (the configuration's
    /// directory), and the file is read here.
    /// A listening link on an address beyond this host takes frames from
    /// whoever reaches it: unsigned (or taking unsigned frames too), any
    /// host on the network is the autopilot for the daemon (its attitude,
    /// its depth) and becomes the poses' destination. That is a decision,
    /// as for `[foxglove]`: `allow_remote = true`, or signing.
    fn remote_listen(&self, s: &MavlinkSettings) -> Result<(), ConfigError> {
        let Some(addr) = s.endpoint.listen_addr() else {
            return Ok(());
        };
        let signed = s.signing.as_ref().is_some_and(|g| !g.allow_unsigned);
        if addr.ip().is_loopback() || signed || self.allow_remote == Some(true) {
            return Ok(());
        }
        Err(err(
            M,
            "connection",
            format!(
                "{} listens on {addr}, not a loopback address, without signing: anyone who reaches the port is the autopilot for the daemon (its attitude and depth) and gets the poses; configure [mavlink.signing], or set allow_remote = true on a trusted network, or listen on 127.0.0.1",
                s.endpoint
            ),
        ))
    }

    pub fn validate_in(
        &self,
        site: Site,
        base_dir: Option<&Path>,
    ) -> Result<(MavlinkSettings, MaxAge), ConfigError> {
        let endpoint: Endpoint = self
            .connection
            .parse()
            .map_err(|e| err(M, "connection", e))?;
        let mut s = MavlinkSettings::new(endpoint, site);
        s.system_id = self.system_id.unwrap_or(1);
        s.component_id = self.component_id.unwrap_or(197);
        if s.system_id == 0 || s.component_id == 0 {
            return Err(err(M, "system_id", "0 is the broadcast id, not a sender's"));
        }
        s.input = self.input()?;
        s.output = self.output()?;
        s.signing = match &self.signing {
            Some(t) => Some(t.validate(base_dir)?),
            None => None,
        };
        self.remote_listen(&s)?;
        let hz = within(M, "heartbeat_hz", self.heartbeat_hz, 1.0, 0.1, 10.0)?;
        s.heartbeat_period = Duration::from_secs_f64(1.0 / hz);
        // Below a millisecond no reading is fresh at any frame: the input
        // would be off without a word.
        let age = |key, v, d| within(M, key, v, d, 0.001, 3600.0).map(Duration::from_secs_f64);
        let max_age = MaxAge {
            attitude: age("attitude_max_age_s", self.attitude_max_age_s, 0.25)?,
            depth: age("depth_max_age_s", self.depth_max_age_s, 0.5)?,
            temperature: age("temperature_max_age_s", self.temperature_max_age_s, 10.0)?,
            ..MaxAge::default()
        };
        Ok((s, max_age))
    }
}

/// `[dvl]`: a Water Linked DVL on TCP.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DvlTable {
    /// HOST:PORT; the DVL serves on port 16171.
    pub address: String,
    pub max_age_s: Option<f64>,
    pub max_speed_mps: Option<f64>,
    pub reconnect_max_s: Option<f64>,
    pub silence_timeout_s: Option<f64>,
}

const D: &str = "dvl";

impl DvlTable {
    /// The client's settings and the velocity reading's maximum age.
    pub fn validate(&self) -> Result<(DvlSettings, Duration), ConfigError> {
        let a = self.address.trim();
        let port_ok = a
            .rsplit_once(':')
            .is_some_and(|(h, p)| !h.is_empty() && p.parse::<u16>().is_ok_and(|p| p > 0));
        if !port_ok {
            return Err(err(
                D,
                "address",
                format!("\"{a}\" is not HOST:PORT (the DVL serves on 16171)"),
            ));
        }
        let mut s = DvlSettings::new(a);
        s.max_speed_mps = within(D, "max_speed_mps", self.max_speed_mps, 5.0, 0.01, 50.0)?;
        s.reconnect_max = Duration::from_secs_f64(within(
            D,
            "reconnect_max_s",
            self.reconnect_max_s,
            5.0,
            0.1,
            600.0,
        )?);
        s.reconnect_first = s.reconnect_first.min(s.reconnect_max);
        s.silence = Duration::from_secs_f64(within(
            D,
            "silence_timeout_s",
            self.silence_timeout_s,
            3.0,
            0.1,
            600.0,
        )?);
        let age = within(D, "max_age_s", self.max_age_s, 1.0, 0.001, 3600.0)?;
        Ok((s, Duration::from_secs_f64(age)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Deserialize)]
    struct File {
        site: SiteTable,
        mavlink: MavlinkTable,
        dvl: DvlTable,
    }

    #[test]
    fn the_documented_tables_validate() {
        let f: File = toml::from_str(
            r#"
            [site]
            beacon_heading_deg = 30.0
            beacon_depth_m = 3.0
            [mavlink]
            connection = "udpout:127.0.0.1:14550"
            depth = "vfr_hud"
            position_rate_hz = 5.0
            [dvl]
            address = "192.168.2.95:16171"
            "#,
        )
        .unwrap();
        let site = f.site.validate().unwrap();
        let (m, age) = f.mavlink.validate(site).unwrap();
        assert_eq!((m.system_id, m.component_id), (1, 197));
        assert_eq!(
            (m.input.autopilot_system, m.input.autopilot_component),
            (None, 1)
        );
        assert_eq!(m.input.depth, DepthSource::VfrHud);
        assert_eq!(m.output.position_rate_hz, Some(5.0));
        assert_eq!(age.attitude, Duration::from_millis(250));
        let (d, vage) = f.dvl.validate().unwrap();
        assert_eq!(d.address, "192.168.2.95:16171");
        assert_eq!(vage, Duration::from_secs(1));
    }

    /// ArduSub's VFR_HUD.alt is the depth only with an EKF origin at sea
    /// level; GLOBAL_POSITION_INT.relative_alt is the depth on ArduSub and
    /// PX4 alike.
    #[test]
    fn depth_comes_from_global_position_int_unless_asked() {
        let site = Site::new(Angle::ZERO, 3.0);
        let m = MavlinkTable {
            connection: "udpout:127.0.0.1:14550".into(),
            ..Default::default()
        };
        let (s, _) = m.validate(site).unwrap();
        assert_eq!(s.input.depth, DepthSource::GlobalPositionInt);
        for (word, want) in [
            ("vfr_hud", DepthSource::VfrHud),
            ("global_position_int", DepthSource::GlobalPositionInt),
            ("none", DepthSource::Off),
        ] {
            let m = MavlinkTable {
                depth: Some(word.into()),
                ..m.clone()
            };
            assert_eq!(m.validate(site).unwrap().0.input.depth, want);
        }
    }

    /// A listening link beyond loopback needs signing (without
    /// `allow_unsigned`) or `allow_remote = true`; loopback, `udpout` and
    /// serial need neither.
    #[test]
    fn a_remote_listen_needs_signing_or_allow_remote() {
        let site = Site::new(Angle::ZERO, 3.0);
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("p"), "pass\n").unwrap();
        let ok = |connection: &str, allow_remote, signing: Option<bool>| {
            MavlinkTable {
                connection: connection.into(),
                allow_remote,
                signing: signing.map(|allow_unsigned| SigningTable {
                    passphrase_file: Some("p".into()),
                    allow_unsigned: Some(allow_unsigned),
                    ..Default::default()
                }),
                ..Default::default()
            }
            .validate_in(site, Some(dir.path()))
            .map_err(|e| e.key)
        };
        for remote in [
            "udpin:0.0.0.0:14550",
            "udpin:[::]:14550",
            "udpin:192.168.2.2:14550",
        ] {
            assert_eq!(ok(remote, None, None).err(), Some("connection"), "{remote}");
            assert_eq!(ok(remote, Some(false), None).err(), Some("connection"));
            assert_eq!(ok(remote, None, Some(true)).err(), Some("connection"));
            assert!(ok(remote, Some(true), None).is_ok(), "{remote}");
            assert!(ok(remote, None, Some(false)).is_ok(), "{remote}");
        }
        for local in [
            "udpin:127.0.0.1:14550",
            "udpin:[::1]:14550",
            "udpout:0.0.0.0:14550",
            "udpout:192.168.2.1:14550",
            "serial:/dev/ttyACM0:115200",
        ] {
            assert!(ok(local, None, None).is_ok(), "{local}");
        }
    }

    #[test]
    fn bad_values_name_table_and_key() {
        let site = SiteTable {
            beacon_heading_deg: 30.0,
            beacon_depth_m: -1.0,
            beacon_ned_m: None,
        };
        assert_eq!(
            site.validate().unwrap_err().to_string(),
            "[site] beacon_depth_m: -1 is not within 0..11000"
        );
        let ok_site = Site::new(Angle::ZERO, 3.0);
        let t = |f: fn(&mut MavlinkTable)| {
            let mut m = MavlinkTable {
                connection: "udpin:0.0.0.0:14550".into(),
                ..Default::default()
            };
            f(&mut m);
            m.validate(ok_site).unwrap_err().to_string()
        };
        assert!(t(|m| m.connection = "tcp:x:1".into())
            .starts_with("[mavlink] connection: unknown transport"));
        assert!(t(|m| m.depth = Some("baro".into())).starts_with("[mavlink] depth:"));
        assert!(t(|m| m.roll_std_deg = Some(f64::NAN)).starts_with("[mavlink] roll_std_deg:"));
        assert!(t(|m| m.missing_std = Some("guess".into())).starts_with("[mavlink] missing_std:"));
        assert!(t(|m| m.autopilot_system_id = Some(0))
            .starts_with("[mavlink] autopilot_system_id: 0 is the broadcast id"));
        assert!(t(|m| m.autopilot_component_id = Some(0))
            .starts_with("[mavlink] autopilot_component_id: 0 is the broadcast id"));
        // Issue 44: unsigned on 0.0.0.0 started without a word.
        let e = t(|_| {});
        assert!(
            e.starts_with("[mavlink] connection: udpin:0.0.0.0:14550 listens on 0.0.0.0:14550, not a loopback address, without signing"),
            "{e}"
        );
        assert!(e.contains("allow_remote = true"), "{e}");
        let dvl = DvlTable {
            address: "192.168.2.95".into(),
            ..Default::default()
        };
        assert!(dvl
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("[dvl] address:"));
        assert!(toml::from_str::<SiteTable>(
            "beacon_heading_deg = 1\nbeacon_depth_m = 2\nbeacon_dept = 3"
        )
        .is_err());
    }
}
