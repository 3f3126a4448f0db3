//! The daemon's configuration: TOML parsed with spans, then validated into a
//! typed [`Config`] so that every later stage can trust it. A file that is
//! refused is refused at start, in one line naming the file, the line and the
//! key (toml's byte span turned into a line number), never half-way through a
//! dive.
//!
//! One validator per table, each in its own file: [`top`] (the top-level
//! keys), [`backend`] (handed to lightpose-hal), [`temperature`],
//! [`outputs`], [`recording`], [`attitude`], [`logging`], [`foxglove`], [`web`],
//! [`vehicle`] (`[site]`, `[mavlink]`, `[dvl]`); [`across`] what involves
//! two tables (two inputs on one port);
//! [`locate`] turns spans into lines and [`embedded`] resolves
//! `embedded:NAME`.
//!
//! What the file names outside itself (a scene, the recording directory,
//! an address to bind) is judged only against this machine, at
//! `--check-config` and before a start ([`machine`], `wiring::check`);
//! [`places`] keeps where those keys are written, so that such a refusal
//! names its line too.

mod across;
pub mod attitude;
pub mod backend;
pub mod embedded;
pub mod foxglove;
mod locate;
pub mod logging;
pub mod machine;
pub mod outputs;
pub mod places;
pub mod recording;
pub mod ros2;
pub mod ros2in;
pub mod temperature;
pub mod top;
pub mod vehicle;
pub mod web;

pub use attitude::AttitudeInput;
pub use foxglove::Foxglove;
pub use logging::{LogFormat, Logging};
pub use outputs::{Multicast, Outputs};
pub use places::Places;
pub use recording::{RecFormat, RecSamples, Recording};
pub use ros2::Ros2;
pub use vehicle::VehicleConfig;
pub use web::Web;

use lightpose_core::textfile::{excerpt, one_line, read_text, TextError, TextSource};
use lightpose_hal::ValidBackend;
use locate::Ctx;
use serde::Deserialize;
use std::path::Path;
use toml::Spanned;

/// The validated configuration: everything the daemon needs, typed.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// Where it came from (a path, or "embedded default").
    pub origin: String,
    pub rate_hz: f64,
    /// A frame is late when it is done more than this fraction of a period
    /// after it was due.
    pub late_tolerance: f64,
    pub estimator: String,
    pub calibration: TextSource,
    /// Where `estimator` and `calibration` are written: what is wrong with
    /// them shows only when they are used (a calibration that cannot be
    /// read, a name this build does not know), and is then refused at
    /// their line like every other key.
    pub estimator_at: KeyAt,
    pub calibration_at: KeyAt,
    /// Where frames come from, validated by lightpose-hal; opened with
    /// `lightpose_hal::open`, the daemon never looks inside.
    pub backend: ValidBackend,
    /// Used when a frame carries no temperature.
    pub fallback_temp_c: Option<f64>,
    pub outputs: Outputs,
    pub recording: Option<Recording>,
    pub attitude: Option<AttitudeInput>,
    pub logging: Logging,
    /// The live view (Foxglove WebSocket), if configured.
    pub foxglove: Option<Foxglove>,
    /// The web page and REST API (`[web]`), if configured.
    pub web: Option<Web>,
    /// The ROS 2 node (`[ros2]`), if configured.
    pub ros2: Option<Ros2>,
    /// `[site]`: the beacon's heading and depth, if given.
    pub site: Option<lightpose_vehicle::Site>,
    /// The autopilot and DVL links (`[mavlink]`, `[dvl]`), if configured.
    pub vehicle: Option<VehicleConfig>,
    /// Where the keys that name files, directories and addresses are
    /// written (keys in [`places`]).
    pub places: Places,
}

/// Where a key is written, shown `FILE:LINE` (`FILE` alone for a key left
/// out, which has no line).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyAt {
    pub file: String,
    pub line: Option<usize>,
}

impl KeyAt {
    /// A refusal of `key`, written here: `FILE:LINE: key: msg` (`FILE:
    /// key: msg` without a line), one bounded line.
    pub fn refuse(&self, key: &str, msg: impl Into<String>) -> ConfigError {
        let (key, msg) = (excerpt(key, 80), one_line(&msg.into()));
        match self.line {
            Some(line) => ConfigError::At {
                file: self.file.clone(),
                line,
                key,
                msg,
            },
            None => ConfigError::Whole {
                file: self.file.clone(),
                msg: format!("{key}: {msg}"),
            },
        }
    }
}

impl std::fmt::Display for KeyAt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}:{l}", self.file),
            None => f.write_str(&self.file),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Unreadable, too large or not UTF-8 (the message names the file).
    #[error(transparent)]
    Text(#[from] TextError),
    #[error("{file}:{line}: {key}: {msg}")]
    At {
        file: String,
        line: usize,
        key: String,
        msg: String,
    },
    /// At a line that names no key (toml's syntax errors).
    #[error("{file}:{line}: {msg}")]
    Line {
        file: String,
        line: usize,
        msg: String,
    },
    #[error("{file}: {msg}")]
    Whole { file: String, msg: String },
}

/// The file as written, each table left to its validator (the top-level
/// keys to [`top`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    rate_hz: Option<Spanned<f64>>,
    late_tolerance: Option<Spanned<f64>>,
    estimator: Option<Spanned<String>>,
    calibration: Option<Spanned<String>>,
    backend: Option<Spanned<toml::Table>>,
    temperature: Option<temperature::RawTemperature>,
    outputs: Option<outputs::RawOutputs>,
    recording: Option<Spanned<recording::RawRecording>>,
    attitude: Option<Spanned<attitude::RawAttitude>>,
    logging: Option<logging::RawLogging>,
    foxglove: Option<Spanned<foxglove::RawFoxglove>>,
    web: Option<Spanned<web::RawWeb>>,
    ros2: Option<Spanned<ros2::RawRos2>>,
    site: Option<Spanned<toml::Table>>,
    mavlink: Option<Spanned<toml::Table>>,
    dvl: Option<Spanned<toml::Table>>,
}

impl Config {
    /// Read and validate a config file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let src = read_text(path)?;
        Config::parse(&src, &path.display().to_string(), path.parent())
    }

    /// The embedded default: the simulated tank, looping, publishing to
    /// 127.0.0.1:17150.
    pub fn embedded_default() -> Result<Config, ConfigError> {
        Config::parse(
            embedded::DEFAULT_CONFIG,
            "embedded default (config/lightposed.toml)",
            None,
        )
    }

    /// Parse and validate config text; `file` names it in errors and
    /// `base_dir` anchors relative paths.
    pub fn parse(src: &str, file: &str, base_dir: Option<&Path>) -> Result<Config, ConfigError> {
        let ctx = Ctx {
            file,
            src,
            base_dir,
        };
        let raw: Raw = toml::from_str(src).map_err(|e| ctx.toml_error(&e))?;
        let mut at = Places::new(file);
        let top = top::validate(&ctx, &raw)?;
        let backend = backend::validate(&ctx, raw.backend.as_ref(), top.rate_hz, &mut at)?;
        let fallback_temp_c = temperature::validate(&ctx, raw.temperature.as_ref())?;
        let outputs = outputs::validate(&ctx, raw.outputs.as_ref(), &mut at)?;
        let mut recording = recording::validate(&ctx, raw.recording.as_ref(), &mut at)?;
        let site = vehicle::site(&ctx, raw.site.as_ref())?;
        let heading = site.map(|s| s.1);
        let attitude = attitude::validate(&ctx, raw.attitude.as_ref(), heading, &mut at)?;
        let site = site.map(|s| s.0);
        let logging = logging::validate(&ctx, raw.logging.as_ref())?;
        let foxglove = foxglove::validate(&ctx, raw.foxglove.as_ref(), &mut at)?;
        let web = web::validate(&ctx, raw.web.as_ref(), &mut at)?;
        // Off, its names still name a ROS 2 recording's topics and frames.
        let ros2_named = ros2::validate(&ctx, raw.ros2.as_ref(), heading)?;
        let ros2 = ros2_named.as_ref().filter(|r| r.1).map(|r| r.0.clone());
        if let (Some(r), Some(a)) = (ros2.as_ref().and_then(|r| r.imu.as_ref()), &attitude) {
            return Err(ctx.whole(format!(
                "ros2.imu_topic {} and [attitude] listen {}: one attitude input at a time",
                r.topic, a.listen
            )));
        }
        #[cfg(not(feature = "ros2"))]
        if ros2.is_some() {
            return Err(ctx.whole("[ros2]: this lightposed was built without its ros2 feature"));
        }
        let tables = vehicle::RawVehicle {
            mavlink: raw.mavlink.as_ref(),
            dvl: raw.dvl.as_ref(),
        };
        if let Some(r) = recording.as_mut() {
            r.bag = ros2::bag_options(ros2_named.as_ref().map(|r| &r.0), site.as_ref());
        }
        let vehicle = vehicle::validate(&ctx, &tables, site, &mut at)?;
        ros2in::one_of_each(&ctx, ros2.as_ref(), vehicle.as_ref())?;
        across::validate(&outputs, attitude.as_ref(), vehicle.as_ref(), &at)?;
        if let Some(why) = across::fast_source_to_autopilot(&backend, vehicle.as_ref()) {
            tracing::warn!("{file}: {why}");
        }
        if outputs.destinations.is_empty() && outputs.multicast.is_none() {
            tracing::warn!("{file}: no outputs.destinations and no multicast: poses go nowhere");
        }
        Ok(Config {
            origin: file.to_string(),
            rate_hz: top.rate_hz,
            late_tolerance: top.late_tolerance,
            estimator: top.estimator,
            calibration: top.calibration,
            estimator_at: KeyAt {
                file: file.to_string(),
                line: top.estimator_line,
            },
            calibration_at: KeyAt {
                file: file.to_string(),
                line: Some(top.calibration_line),
            },
            backend,
            fallback_temp_c,
            outputs,
            recording,
            attitude,
            logging,
            foxglove,
            web,
            ros2,
            site,
            vehicle,
            places: at,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::locate::{key_on_line, line_of_key_in_table};
    use super::*;
    use lightpose_core::textpos::line_of_offset;
    use lightpose_hal::config::ReplayPlan;
    use lightpose_hal::Pace;
    use std::net::SocketAddr;
    use std::time::Duration;

    const MIN: &str = r#"
rate_hz = 50.0
calibration = "cal.toml"

[backend]
kind = "replay"
log = "x.jsonl"
pace = "fast"

[outputs]
destinations = ["127.0.0.1:9999"]
"#;

    fn parse(s: &str) -> Result<Config, ConfigError> {
        Config::parse(s, "t.toml", Some(Path::new("/etc/lp")))
    }

    #[test]
    fn a_fast_source_feeding_an_autopilot_is_warned_about() {
        let mav = "[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n[mavlink]\nconnection = \"udpout:127.0.0.1:14550\"\n";
        let fast = lightpose_testkit::logs::logged(|| {
            parse(&format!("{MIN}{mav}")).expect("valid: a bench may want it");
        });
        assert!(
            fast.contains("t.toml: backend replay at pace \"fast\" with [mavlink] udpout:127.0.0.1:14550: the autopilot gets poses faster than real time"),
            "{fast}"
        );
        let realtime = lightpose_testkit::logs::logged(|| {
            let text = format!("{MIN}{mav}").replace("pace = \"fast\"", "pace = \"realtime\"");
            parse(&text).expect("valid");
        });
        assert!(!realtime.contains("faster than real time"), "{realtime}");
        let no_autopilot = lightpose_testkit::logs::logged(|| {
            parse(MIN).expect("valid");
        });
        assert!(
            !no_autopilot.contains("faster than real time"),
            "{no_autopilot}"
        );
    }

    #[test]
    fn minimal_file_validates_with_defaults() {
        let c = parse(MIN).expect("valid");
        assert_eq!(c.rate_hz, 50.0);
        assert_eq!(c.estimator, "auto");
        assert_eq!(c.calibration, TextSource::File("/etc/lp/cal.toml".into()));
        assert_eq!(c.calibration_at.to_string(), "t.toml:3");
        assert_eq!(c.estimator_at.to_string(), "t.toml", "not written: no line");
        let c = parse(&MIN.replace("rate_hz = 50.0", "rate_hz = 50.0\nestimator = \"x\""))
            .expect("valid");
        assert_eq!(c.estimator_at.to_string(), "t.toml:3");
        assert_eq!(
            c.backend,
            ValidBackend::Replay(ReplayPlan {
                log: "/etc/lp/x.jsonl".into(),
                pace: Pace::Fast,
                looping: false,
                max_gap_s: 10.0
            })
        );
        assert_eq!(
            c.outputs.destinations,
            vec!["127.0.0.1:9999".parse::<SocketAddr>().unwrap()]
        );
        assert_eq!(c.outputs.status_interval, Duration::from_secs(1));
        assert!(c.recording.is_none() && c.attitude.is_none());
    }

    fn err(s: &str) -> String {
        parse(s).expect_err("must be refused").to_string()
    }

    #[test]
    fn bad_values_name_line_and_key() {
        let e = err(&MIN.replace("rate_hz = 50.0", "rate_hz = -1.0"));
        assert_eq!(
            e,
            "t.toml:2: rate_hz: -1 is not in 0.001..=10000 Hz (a frame at least every 1000 s)"
        );
        // Audit: 1e-300 Hz was taken and the pacer, its period past a
        // Duration, ran flat out.
        let e = err(&MIN.replace("rate_hz = 50.0", "rate_hz = 1e-300"));
        assert_eq!(
            e,
            "t.toml:2: rate_hz: 1e-300 is not in 0.001..=10000 Hz (a frame at least every 1000 s)"
        );
        assert!(parse(&MIN.replace("rate_hz = 50.0", "rate_hz = 0.001")).is_ok());
        let e = err(&MIN.replace("127.0.0.1:9999", "nowhere"));
        assert!(
            e.starts_with("t.toml:11: outputs.destinations: \"nowhere\""),
            "{e}"
        );
        let e = err(&format!(
            "{MIN}\n[outputs.multicast]\ngroup = \"10.0.0.1:5\"\n"
        ));
        assert!(
            e.starts_with("t.toml:14: outputs.multicast.group: 10.0.0.1 is not a multicast"),
            "{e}"
        );
        let e = err(&MIN.replace("pace = \"fast\"", "pace = \"slow\""));
        assert!(e.starts_with("t.toml:8: backend.pace:"), "{e}");
    }

    #[test]
    fn syntax_and_unknown_keys_name_line() {
        let e = err(&MIN.replace("rate_hz = 50.0", "rate_hz = 50.0\nrte = 3"));
        assert!(e.starts_with("t.toml:3: rte: unknown field `rte`"), "{e}");
        let e = err(&MIN.replace("rate_hz = 50.0", "rate_hz = \"fast\""));
        assert!(e.starts_with("t.toml:2: rate_hz:"), "{e}");
        let e = err(&MIN.replace("log = \"x.jsonl\"", "log = \"x.jsonl\"\nspeed = 2"));
        assert!(
            e.starts_with("t.toml:8: backend.speed: unknown field `speed`"),
            "{e}"
        );
        let e = err("rate_hz = [\n");
        assert!(
            e.starts_with("t.toml:2:") || e.starts_with("t.toml:1:"),
            "{e}"
        );
        assert!(!e.contains('\n'), "one line: {e}");
        // Audit: a line that is no `key =` was said with a key of "?".
        let e = err("this is [ not toml");
        assert!(e.starts_with("t.toml:1: expected "), "{e}");
        assert!(!e.contains('?'), "{e}");
    }

    #[test]
    fn missing_calibration_and_backend_are_named() {
        assert!(err("[backend]\nkind=\"sim\"\n").contains("calibration: missing"));
        assert!(err("calibration = \"c\"\n").contains("[backend]: missing"));
    }

    #[test]
    fn sim_backend_takes_the_top_rate_and_the_embedded_defaults() {
        let c = parse(&MIN.replace(
            "kind = \"replay\"\nlog = \"x.jsonl\"\npace = \"fast\"",
            "kind = \"sim\"\ntrajectory = \"embedded:dive\"",
        ))
        .expect("valid");
        let ValidBackend::Sim(s) = &c.backend else {
            panic!("{:?}", c.backend)
        };
        assert_eq!(c.backend.kind(), "sim");
        assert_eq!(s.rate_hz, Some(50.0));
        assert_eq!((s.pace, s.looping, s.seed), (Pace::Realtime, true, 1));
        assert_eq!(
            s.scene.as_ref().map(|t| t.describe()).as_deref(),
            Some("embedded:tank-scene")
        );
        assert_eq!(s.trajectory.describe(), "embedded:dive");
        let e = err(&MIN.replace(
            "kind = \"replay\"\nlog = \"x.jsonl\"\npace = \"fast\"",
            "kind = \"sim\"\ntrajectory = \"\"",
        ));
        assert_eq!(e, "t.toml:7: backend.trajectory: empty path");
    }

    #[test]
    fn hal_refusals_name_the_line_of_their_key() {
        let board = |body: &str| {
            err(&MIN.replace(
                "kind = \"replay\"\nlog = \"x.jsonl\"\npace = \"fast\"",
                body,
            ))
        };
        let e = board("kind = \"mock\"\ntrajectory = \"t.csv\"\nfaults = { drop_prob = 2.0 }");
        assert_eq!(
            e,
            "t.toml:8: backend.faults.drop_prob: 2 is not a probability in 0..=1"
        );
        let e = board("kind = \"mcp3008\"\nchips = []\nmap = []");
        assert_eq!(e, "t.toml:7: backend.chips: none configured");
        let e = board("kind = \"warp\"");
        assert!(
            e.starts_with("t.toml:6: backend.kind: unknown backend \"warp\" (sim, replay"),
            "{e}"
        );
        let e = board("log = \"x.jsonl\"");
        assert!(e.starts_with("t.toml:5: backend.kind: missing"), "{e}");
    }

    /// A table switched off is checked as if it were on: its mistake is
    /// met now, not on the day it is switched on. Only what it would ask of
    /// another table (the attitude input's heading from `[site]`) waits.
    #[test]
    fn a_table_switched_off_is_checked_all_the_same() {
        for (table, want) in [
            (
                "[attitude]\nenabled = false\nmax_age_s = nan\n",
                "t.toml:15: attitude.max_age_s: ",
            ),
            (
                "[attitude]\nlisten = \"0.0.0.0:17151\"\n",
                "t.toml:14: attitude.listen: 0.0.0.0:17151 is not a loopback address",
            ),
            (
                "[foxglove]\nenabled = false\nclient_queue = 0\n",
                "t.toml:15: foxglove.client_queue: 0 is not in 1..=100000",
            ),
            (
                "[recording]\nenabled = false\nrotate_mb = -1\n",
                "t.toml:15: recording.rotate_mb: ",
            ),
            (
                "[outputs.multicast]\nenabled = false\ngroup = \"10.0.0.1:5600\"\n",
                "t.toml:15: outputs.multicast.group: 10.0.0.1 is not a multicast address",
            ),
        ] {
            let e = parse(&format!("{MIN}\n{table}")).unwrap_err().to_string();
            assert!(e.starts_with(want), "{table}: {e}");
        }
        let off = "\n[attitude]\nenabled = false\nmax_age_s = 0.2\n[foxglove]\nenabled = false\n[recording]\nenabled = false\ndir = \"/tmp/r\"\n[outputs.multicast]\nenabled = false\ngroup = \"239.1.2.3:5600\"\n";
        let c = parse(&format!("{MIN}{off}")).expect("well-formed tables that are off");
        assert_eq!(
            (c.attitude, c.foxglove, c.recording, c.outputs.multicast),
            (None, None, None, None)
        );
        // An old heading of its own in a table that is off stops nothing;
        // on, it conflicts with [site]'s.
        let site = "\n[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n[attitude]\nenabled = false\nbeacon_axis_heading_deg = 10.0\n";
        let c = parse(&format!("{MIN}{site}")).expect("an attitude table that is off");
        assert_eq!(c.attitude, None);
        let e = parse(&format!("{MIN}{}", site.replace("false", "true"))).unwrap_err();
        assert!(e.to_string().contains("conflicts with [site]"), "{e}");
        // The same attitude table switched on needs the beacon's heading.
        let on = parse(&format!(
            "{MIN}{}",
            off.replacen("enabled = false", "enabled = true", 1)
        ));
        let e = on.unwrap_err().to_string();
        assert!(e.contains("[site] beacon_heading_deg: missing"), "{e}");
    }

    /// Issue 16: every number has a range, refused at its key's line.
    #[test]
    fn numbers_out_of_range_are_refused_at_their_line() {
        let rec = "\n[recording]\ndir = \"/tmp/r\"\n";
        let att = "\n[attitude]\nenabled = true\nbeacon_axis_heading_deg = 0.0\n";
        for (text, want) in [
            (
                MIN.replace("rate_hz = 50.0", "rate_hz = 1e9"),
                "t.toml:2: rate_hz: ",
            ),
            (
                MIN.replace("rate_hz = 50.0", "rate_hz = 50.0\nlate_tolerance = 1e6"),
                "t.toml:3: late_tolerance: ",
            ),
            (
                format!("{MIN}status_interval_s = 1e-9\n"),
                "t.toml:12: outputs.status_interval_s: ",
            ),
            (
                format!("{MIN}status_interval_s = 1e9\n"),
                "t.toml:12: outputs.status_interval_s: ",
            ),
            (
                format!("{MIN}{rec}rotate_mb = 1e12\n"),
                "t.toml:15: recording.rotate_mb: ",
            ),
            (
                format!("{MIN}{rec}rotate_minutes = 1e12\n"),
                "t.toml:15: recording.rotate_minutes: ",
            ),
            (
                format!("{MIN}{att}max_age_s = 1e9\n"),
                "t.toml:16: attitude.max_age_s: ",
            ),
            (
                format!("{MIN}{att}").replace("heading_deg = 0.0", "heading_deg = 1e9"),
                "t.toml:15: attitude.beacon_axis_heading_deg: ",
            ),
            (
                format!("{MIN}{att}").replace(
                    "heading_deg = 0.0",
                    "heading_deg = 0.0\nlisten = \"127.0.0.1:0\"",
                ),
                "t.toml:16: attitude.listen: ",
            ),
        ] {
            let e = err(&text);
            assert!(e.starts_with(want), "{want}: {e}");
            assert!(e.contains(" is not in ") || e.contains("port 0"), "{e}");
        }
    }

    /// Issue 16: port 0 and the unspecified address are no destination.
    #[test]
    fn port_0_and_unspecified_addresses_are_no_destination() {
        for (to, want) in [
            ("127.0.0.1:0", "port 0"),
            ("0.0.0.0:17150", "unspecified"),
            ("[::]:17150", "unspecified"),
        ] {
            let e = err(&MIN.replace("127.0.0.1:9999", to));
            assert!(e.starts_with("t.toml:11: outputs.destinations: "), "{e}");
            assert!(e.contains(want), "{want}: {e}");
        }
        let e = err(&format!(
            "{MIN}\n[outputs.multicast]\ngroup = \"239.1.2.3:0\"\n"
        ));
        assert!(e.starts_with("t.toml:14: outputs.multicast.group: "), "{e}");
    }

    /// Issue 16: a wrong value inside [backend] is named at its own line
    /// and key, even when serde's message does not name the key.
    #[test]
    fn a_wrong_backend_value_is_named_at_its_line() {
        let sim = MIN.replace(
            "kind = \"replay\"\nlog = \"x.jsonl\"\npace = \"fast\"",
            "kind = \"sim\"\ntrajectory = \"embedded:dive\"\nloop = true\nseed = -1",
        );
        let e = err(&sim);
        assert!(e.starts_with("t.toml:9: backend.seed: "), "{e}");
        let e = err(&sim.replace("seed = -1", "seed = 1.5"));
        assert!(e.starts_with("t.toml:9: backend.seed: "), "{e}");
        let e = err(&sim.replace("seed = -1", "seed = \"one\""));
        assert!(e.starts_with("t.toml:9: backend.seed: "), "{e}");
    }

    /// Issue 16: whatever is quoted of the file is an excerpt.
    #[test]
    fn refusals_quote_an_excerpt_of_the_file() {
        let long = "z".repeat(20_000);
        for text in [
            format!("{MIN}\n[logging]\nlevel = \"{long}\"\n"),
            MIN.replace("127.0.0.1:9999", &long),
            MIN.replace("pace = \"fast\"", &format!("pace = \"{long}\"")),
            MIN.replace("rate_hz = 50.0", &format!("rate_hz = \"{long}\"")),
            MIN.replace("log = \"x.jsonl\"", &format!("log = 7\n{long} = 1")),
        ] {
            let e = err(&text);
            assert!(e.chars().count() < 500, "{} chars: {}", e.len(), &e[..120]);
        }
    }

    #[test]
    fn line_helpers() {
        let s = "a = 1\n[t]\nb = 2\n";
        assert_eq!(line_of_offset(s, 0), 1);
        assert_eq!(line_of_offset(s, 6), 2);
        assert_eq!(line_of_key_in_table(s, 6, "b"), 3);
        assert_eq!(key_on_line(s, 14).as_deref(), Some("t.b"));
        assert_eq!(key_on_line(s, 0).as_deref(), Some("a"));
        assert_eq!(key_on_line(s, 6).as_deref(), Some("t"), "a header");
        assert_eq!(key_on_line("x y\n", 0), None, "no key on the line");
        // An array of tables, a header with a comment.
        let s = "[[x]] # boards\nc = 3\n";
        assert_eq!(key_on_line(s, 15).as_deref(), Some("x.c"));
    }
}
