//! The daemon's configuration: TOML parsed with spans, then validated into a
//! typed [`Config`] so that every later stage can trust it. A file that is
//! refused is refused at start, in one line naming the file, the line and the
//! key (toml's byte span turned into a line number), never half-way through a
//! dive.

use lightpose_core::textpos::line_of_offset;
use serde::Deserialize;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Spanned;

/// Resources compiled into the binary: the default config runs from
/// anywhere because it refers to these by `embedded:NAME`.
pub mod embedded {
    pub const DEFAULT_CONFIG: &str = include_str!("../../../config/lightposed.toml");

    /// The text of an `embedded:NAME` resource.
    pub fn lookup(name: &str) -> Option<&'static str> {
        Some(match name {
            "tank-scene" => include_str!("../../../config/scenes/tank.toml"),
            // The tank with the vehicle's attitude sensor (AHRS), as most
            // vehicles carry one: the default run shows what `auto` gives.
            "tank-ahrs-scene" => include_str!("../../../config/scenes/tank-ahrs.toml"),
            "harbour-scene" => include_str!("../../../config/scenes/harbour.toml"),
            "dive" => include_str!("../../../config/trajectories/dive.csv"),
            "zigzag" => include_str!("../../../config/trajectories/zigzag.csv"),
            "tank-calibration" => include_str!("../../../config/calibration/tank.toml"),
            "harbour-calibration" => include_str!("../../../config/calibration/harbour.toml"),
            _ => return None,
        })
    }

    /// Every name `lookup` knows, for error messages.
    pub const NAMES: &str = "tank-scene, tank-ahrs-scene, harbour-scene, dive, zigzag, tank-calibration, harbour-calibration";
}

/// Where a config, scene, trajectory or calibration comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Resource {
    File(PathBuf),
    Embedded { name: String, text: &'static str },
}

impl Resource {
    /// How messages name it.
    pub fn describe(&self) -> String {
        match self {
            Resource::File(p) => p.display().to_string(),
            Resource::Embedded { name, .. } => format!("embedded:{name}"),
        }
    }

    /// The text, read now (a file may have changed since start: SIGHUP).
    pub fn read(&self) -> std::io::Result<String> {
        match self {
            Resource::File(p) => std::fs::read_to_string(p),
            Resource::Embedded { text, .. } => Ok((*text).to_string()),
        }
    }
}

/// Where frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Backend {
    /// The simulator flown along a trajectory (the embedded default).
    Sim(SimBackend),
    /// A recorded intensity log, through the same path as live frames.
    Replay(ReplayBackend),
    /// A board (or hal's fault-injecting mock) handled by lightpose-hal,
    /// validated by hal at load time.
    Hardware {
        kind: String,
        /// Frames per second the board is paced at; `None` = free-running.
        rate_hz: Option<f64>,
        hal: Box<lightpose_hal::BackendConfig>,
    },
}

impl Backend {
    pub fn kind(&self) -> &str {
        match self {
            Backend::Sim(_) => "sim",
            Backend::Replay(_) => "replay",
            Backend::Hardware { kind, .. } => kind,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pace {
    /// Frames at their own time: the configured rate, or the log's timestamps.
    Realtime,
    /// As fast as the machine goes (benchmarks, offline replay).
    Fast,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SimBackend {
    pub scene: Resource,
    pub trajectory: Resource,
    pub looping: bool,
    pub seed: u64,
    pub pace: Pace,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ReplayBackend {
    pub log: PathBuf,
    pub pace: Pace,
    pub looping: bool,
}

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

#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub dir: PathBuf,
    /// Start a new file when the current one reaches this size.
    pub rotate_bytes: Option<u64>,
    /// Start a new file when the current one is this old.
    pub rotate_after: Option<Duration>,
    /// Frames that may wait for the disk before they are counted as lost.
    pub queue: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct AttitudeInput {
    pub listen: SocketAddr,
    /// Compass heading that the beacon's optical axis (+x of B) points to.
    pub beacon_axis_heading_deg: f64,
    /// A reading older than this is not attached to a frame.
    pub max_age: Duration,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    Plain,
    Json,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Logging {
    pub format: LogFormat,
    pub level: String,
}

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
    pub calibration: Resource,
    pub backend: Backend,
    /// Used when a frame carries no temperature.
    pub fallback_temp_c: Option<f64>,
    pub outputs: Outputs,
    pub recording: Option<Recording>,
    pub attitude: Option<AttitudeInput>,
    pub logging: Logging,
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{file}: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}: {key}: {msg}")]
    At {
        file: String,
        line: usize,
        key: String,
        msg: String,
    },
    #[error("{file}: {msg}")]
    Whole { file: String, msg: String },
}

// ---- raw, as written -------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    rate_hz: Option<Spanned<f64>>,
    late_tolerance: Option<Spanned<f64>>,
    estimator: Option<Spanned<String>>,
    calibration: Option<Spanned<String>>,
    backend: Option<Spanned<toml::Table>>,
    temperature: Option<RawTemperature>,
    outputs: Option<RawOutputs>,
    recording: Option<RawRecording>,
    attitude: Option<RawAttitude>,
    logging: Option<RawLogging>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTemperature {
    fallback_c: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutputs {
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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRecording {
    enabled: Option<bool>,
    dir: Option<Spanned<String>>,
    rotate_mb: Option<Spanned<f64>>,
    rotate_minutes: Option<Spanned<f64>>,
    queue: Option<Spanned<i64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAttitude {
    enabled: Option<bool>,
    listen: Option<Spanned<String>>,
    beacon_axis_heading_deg: Option<Spanned<f64>>,
    max_age_s: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLogging {
    format: Option<Spanned<String>>,
    level: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSim {
    #[allow(dead_code)] // read as the tag
    kind: String,
    scene: Option<String>,
    trajectory: Option<String>,
    #[serde(rename = "loop")]
    looping: Option<bool>,
    seed: Option<u64>,
    pace: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReplay {
    #[allow(dead_code)] // read as the tag
    kind: String,
    log: String,
    pace: Option<String>,
    #[serde(rename = "loop")]
    looping: Option<bool>,
}

// ---- locating errors ------------------------------------------------------

/// The key written on the line of `offset`, for errors whose span points at
/// a value; "?" when the line holds no `key =`.
fn key_on_line(src: &str, offset: usize) -> String {
    let start = src[..offset.min(src.len())]
        .rfind('\n')
        .map_or(0, |i| i + 1);
    let line = src[start..].lines().next().unwrap_or("");
    match line.split_once('=') {
        Some((k, _)) if !k.trim().is_empty() && !k.trim_start().starts_with('[') => {
            k.trim().trim_matches('"').to_string()
        }
        _ => {
            let t = line.trim();
            if t.starts_with('[') {
                t.trim_matches(|c| c == '[' || c == ']').to_string()
            } else {
                "?".into()
            }
        }
    }
}

/// Line of `key = ...` inside the table that starts at `table_start`, or
/// the table's own line when the key is not written there.
fn line_of_key_in_table(src: &str, table_start: usize, key: &str) -> usize {
    let from = table_start.min(src.len());
    let base = line_of_offset(src, from);
    for (i, line) in src[from..].lines().enumerate() {
        let t = line.trim_start();
        if i > 0 && t.starts_with('[') {
            break;
        }
        if let Some((k, _)) = t.split_once('=') {
            if k.trim().trim_matches('"') == key {
                return base + i;
            }
        }
    }
    base
}

struct Ctx<'a> {
    file: &'a str,
    src: &'a str,
    base_dir: Option<&'a Path>,
}

impl Ctx<'_> {
    fn err(&self, span: std::ops::Range<usize>, key: &str, msg: impl Into<String>) -> ConfigError {
        ConfigError::At {
            file: self.file.to_string(),
            line: line_of_offset(self.src, span.start),
            key: key.to_string(),
            msg: msg.into(),
        }
    }

    /// `embedded:NAME` or a path, relative paths taken from the config's
    /// directory so that a config and its files travel together.
    fn resource(
        &self,
        text: &str,
        span: std::ops::Range<usize>,
        key: &str,
    ) -> Result<Resource, ConfigError> {
        if let Some(name) = text.strip_prefix("embedded:") {
            return match embedded::lookup(name) {
                Some(t) => Ok(Resource::Embedded {
                    name: name.to_string(),
                    text: t,
                }),
                None => Err(self.err(
                    span,
                    key,
                    format!(
                        "\"{text}\" is not embedded in this build (known: {}; a name is missing when its file was absent at build time)",
                        embedded::NAMES
                    ),
                )),
            };
        }
        if text.trim().is_empty() {
            return Err(self.err(span, key, "empty path"));
        }
        Ok(Resource::File(self.path(text)))
    }

    fn path(&self, text: &str) -> PathBuf {
        let p = PathBuf::from(text);
        match self.base_dir {
            Some(d) if p.is_relative() => d.join(p),
            _ => p,
        }
    }
}

fn positive(ctx: &Ctx, v: &Spanned<f64>, key: &str) -> Result<f64, ConfigError> {
    let x = *v.get_ref();
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(ctx.err(v.span(), key, format!("{x} must be a positive number")))
    }
}

fn socket_addr(ctx: &Ctx, v: &Spanned<String>, key: &str) -> Result<SocketAddr, ConfigError> {
    v.get_ref().parse::<SocketAddr>().map_err(|_| {
        ctx.err(
            v.span(),
            key,
            format!(
                "\"{}\" is not an address:port (e.g. \"127.0.0.1:17150\")",
                v.get_ref()
            ),
        )
    })
}

fn pace(
    ctx: &Ctx,
    table_start: usize,
    v: Option<&str>,
    realtime_word: &str,
) -> Result<Pace, ConfigError> {
    match v {
        None => Ok(Pace::Realtime),
        Some("fast") => Ok(Pace::Fast),
        Some(w) if w == realtime_word || w == "realtime" => Ok(Pace::Realtime),
        Some(w) => Err(ConfigError::At {
            file: ctx.file.into(),
            line: line_of_key_in_table(ctx.src, table_start, "pace"),
            key: "backend.pace".into(),
            msg: format!("\"{w}\" is not a pace (\"{realtime_word}\" or \"fast\")"),
        }),
    }
}

/// Deserialize the backend table into one kind's struct, naming the line of
/// the offending key (the table was parsed once already, without spans).
fn backend_kind<T: serde::de::DeserializeOwned>(
    ctx: &Ctx,
    table: &toml::Table,
    start: usize,
) -> Result<T, ConfigError> {
    T::deserialize(toml::Value::Table(table.clone())).map_err(|e| {
        let msg = e.message().trim().to_string();
        // serde names the field in backquotes: find that key's line.
        let key = msg
            .split('`')
            .nth(1)
            .filter(|k| table.contains_key(*k))
            .unwrap_or("")
            .to_string();
        let line = if key.is_empty() {
            line_of_offset(ctx.src, start)
        } else {
            line_of_key_in_table(ctx.src, start, &key)
        };
        ConfigError::At {
            file: ctx.file.into(),
            line,
            key: if key.is_empty() {
                "backend".into()
            } else {
                format!("backend.{key}")
            },
            msg,
        }
    })
}

impl Config {
    /// Read and validate a config file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let file = path.display().to_string();
        let src = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            file: file.clone(),
            source,
        })?;
        Config::parse(&src, &file, path.parent())
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
        let raw: Raw = toml::from_str(src).map_err(|e| {
            let (line, key) = match e.span() {
                Some(s) => (line_of_offset(src, s.start), key_on_line(src, s.start)),
                None => (0, "?".into()),
            };
            let msg = e.message().trim().replace('\n', " ");
            if line == 0 {
                ConfigError::Whole {
                    file: file.into(),
                    msg,
                }
            } else {
                ConfigError::At {
                    file: file.into(),
                    line,
                    key,
                    msg,
                }
            }
        })?;

        let rate_hz = match &raw.rate_hz {
            Some(v) => positive(&ctx, v, "rate_hz")?,
            None => 5.0,
        };
        let late_tolerance = match &raw.late_tolerance {
            Some(v) => positive(&ctx, v, "late_tolerance")?,
            None => 0.5,
        };
        let estimator = match &raw.estimator {
            Some(v) if v.get_ref().trim().is_empty() => {
                return Err(ctx.err(v.span(), "estimator", "empty estimator name"))
            }
            Some(v) => v.get_ref().clone(),
            None => "auto".into(),
        };
        let calibration = match &raw.calibration {
            Some(v) => ctx.resource(v.get_ref(), v.span(), "calibration")?,
            None => return Err(ConfigError::Whole {
                file: file.into(),
                msg: "calibration: missing (a calibration file, or \"embedded:tank-calibration\")"
                    .into(),
            }),
        };

        let backend = match &raw.backend {
            None => {
                return Err(ConfigError::Whole {
                    file: file.into(),
                    msg: "[backend]: missing (kind = \"sim\", \"replay\" or a board)".into(),
                })
            }
            Some(b) => {
                let start = b.span().start;
                let table = b.get_ref();
                let kind = match table.get("kind") {
                    Some(toml::Value::String(k)) => k.clone(),
                    Some(_) => {
                        return Err(ConfigError::At {
                            file: file.into(),
                            line: line_of_key_in_table(src, start, "kind"),
                            key: "backend.kind".into(),
                            msg: "must be a string".into(),
                        })
                    }
                    None => {
                        return Err(ConfigError::At {
                            file: file.into(),
                            line: line_of_offset(src, start),
                            key: "backend.kind".into(),
                            msg: "missing (\"sim\", \"replay\" or a board)".into(),
                        })
                    }
                };
                match kind.as_str() {
                    "sim" => {
                        let r: RawSim = backend_kind(&ctx, table, start)?;
                        let res = |text: Option<String>, key: &str, default: &str| {
                            let text = text.unwrap_or_else(|| default.to_string());
                            let line = line_of_key_in_table(src, start, key);
                            // A span that lands on the key's line.
                            let off = src
                                .lines()
                                .take(line - 1)
                                .map(|l| l.len() + 1)
                                .sum::<usize>();
                            ctx.resource(&text, off..off, &format!("backend.{key}"))
                        };
                        Backend::Sim(SimBackend {
                            scene: res(r.scene, "scene", "embedded:tank-scene")?,
                            trajectory: res(r.trajectory, "trajectory", "embedded:zigzag")?,
                            looping: r.looping.unwrap_or(true),
                            seed: r.seed.unwrap_or(1),
                            pace: pace(&ctx, start, r.pace.as_deref(), "realtime")?,
                        })
                    }
                    "replay" => {
                        let r: RawReplay = backend_kind(&ctx, table, start)?;
                        Backend::Replay(ReplayBackend {
                            log: ctx.path(&r.log),
                            pace: pace(&ctx, start, r.pace.as_deref(), "recorded")?,
                            looping: r.looping.unwrap_or(false),
                        })
                    }
                    "mcp3008" | "mcp3208" | "ads1115" | "ads7828" | "serial" | "mock" => {
                        // hal's simulator with fault injection is its kind
                        // "sim"; here "sim" is the daemon's own (embedded
                        // files), so hal's is called "mock".
                        let mut t = table.clone();
                        if kind == "mock" {
                            t.insert("kind".into(), "sim".into());
                        }
                        // The top-level rate paces the board unless its
                        // table says otherwise.
                        if !t.contains_key("rate_hz") {
                            t.insert("rate_hz".into(), rate_hz.into());
                        }
                        let hal: lightpose_hal::BackendConfig = backend_kind(&ctx, &t, start)?;
                        if let Err(e) = hal.validate() {
                            let (key, msg) = match &e {
                                lightpose_hal::HalError::Config { key, msg } => (key.clone(), msg.clone()),
                                lightpose_hal::HalError::Map(m) => ("map".to_string(), m.to_string()),
                                other => (String::new(), other.to_string()),
                            };
                            // hal names keys like "map[3].channel": the
                            // first segment is what is written in the table.
                            let first = key.split(['.', '[']).next().unwrap_or("");
                            return Err(ConfigError::At {
                                file: file.into(),
                                line: line_of_key_in_table(src, start, first),
                                key: if key.is_empty() { "backend".into() } else { format!("backend.{key}") },
                                msg,
                            });
                        }
                        let rate = match t.get("rate_hz") {
                            Some(toml::Value::Float(r)) => *r,
                            Some(toml::Value::Integer(r)) => *r as f64,
                            _ => 5.0,
                        };
                        Backend::Hardware {
                            kind,
                            rate_hz: (rate > 0.0).then_some(rate),
                            hal: Box::new(hal),
                        }
                    }
                    other => {
                        return Err(ConfigError::At {
                            file: file.into(),
                            line: line_of_key_in_table(src, start, "kind"),
                            key: "backend.kind".into(),
                            msg: format!(
                                "unknown backend \"{other}\" (sim, replay, mock, mcp3008, mcp3208, ads1115, ads7828, serial)"
                            ),
                        })
                    }
                }
            }
        };

        let fallback_temp_c = match raw.temperature.as_ref().and_then(|t| t.fallback_c.as_ref()) {
            Some(v) if v.get_ref().is_finite() && (-5.0..=45.0).contains(v.get_ref()) => {
                Some(*v.get_ref())
            }
            Some(v) => {
                return Err(ctx.err(
                    v.span(),
                    "temperature.fallback_c",
                    format!("{} °C is not a water temperature (-5..45)", v.get_ref()),
                ))
            }
            None => None,
        };

        let outputs = {
            let o = raw.outputs.as_ref();
            let mut destinations = Vec::new();
            for d in o
                .and_then(|o| o.destinations.as_ref())
                .into_iter()
                .flatten()
            {
                destinations.push(socket_addr(&ctx, d, "outputs.destinations")?);
            }
            let status_interval = match o.and_then(|o| o.status_interval_s.as_ref()) {
                Some(v) => Duration::from_secs_f64(
                    positive(&ctx, v, "outputs.status_interval_s")?.min(3600.0),
                ),
                None => Duration::from_secs(1),
            };
            let multicast = match o.and_then(|o| o.multicast.as_ref()) {
                Some(m) if m.enabled.unwrap_or(true) => {
                    let group = socket_addr(&ctx, &m.group, "outputs.multicast.group")?;
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
                                        i.get_ref()
                                    ),
                                ))
                            }
                        },
                        None => Ipv4Addr::UNSPECIFIED,
                    };
                    Some(Multicast {
                        group,
                        ttl,
                        interface,
                        loopback: m.loopback.unwrap_or(true),
                    })
                }
                _ => None,
            };
            Outputs {
                destinations,
                multicast,
                status_interval,
            }
        };

        let recording = match &raw.recording {
            Some(r) if r.enabled.unwrap_or(true) => {
                let dir = match &r.dir {
                    Some(d) if !d.get_ref().trim().is_empty() => ctx.path(d.get_ref()),
                    Some(d) => return Err(ctx.err(d.span(), "recording.dir", "empty path")),
                    None => std::env::var_os("STATE_DIRECTORY")
                        .map(PathBuf::from)
                        .unwrap_or_else(|| PathBuf::from("/var/lib/lightposed")),
                };
                let rotate_bytes = match &r.rotate_mb {
                    Some(v) => Some(
                        (positive(&ctx, v, "recording.rotate_mb")? * 1024.0 * 1024.0).max(1.0)
                            as u64,
                    ),
                    None => None,
                };
                let rotate_after = match &r.rotate_minutes {
                    Some(v) => Some(Duration::from_secs_f64(
                        positive(&ctx, v, "recording.rotate_minutes")?.min(1e6) * 60.0,
                    )),
                    None => None,
                };
                let queue = match &r.queue {
                    Some(q) if (1..=1_000_000).contains(q.get_ref()) => *q.get_ref() as usize,
                    Some(q) => {
                        return Err(ctx.err(
                            q.span(),
                            "recording.queue",
                            format!("{} is not in 1..1000000", q.get_ref()),
                        ))
                    }
                    None => 4096,
                };
                Some(Recording {
                    dir,
                    rotate_bytes,
                    rotate_after,
                    queue,
                })
            }
            _ => None,
        };

        let attitude = match &raw.attitude {
            Some(a) if a.enabled.unwrap_or(false) => {
                let listen = match &a.listen {
                    Some(l) => socket_addr(&ctx, l, "attitude.listen")?,
                    None => SocketAddr::from((Ipv4Addr::LOCALHOST, 17151)),
                };
                let beacon_axis_heading_deg = match &a.beacon_axis_heading_deg {
                    Some(h) if h.get_ref().is_finite() => *h.get_ref(),
                    Some(h) => return Err(ctx.err(h.span(), "attitude.beacon_axis_heading_deg", "must be a finite number of degrees")),
                    None => {
                        return Err(ConfigError::Whole {
                            file: file.into(),
                            msg: "attitude.beacon_axis_heading_deg: missing (needed to refer yaw to the beam)".into(),
                        })
                    }
                };
                let max_age = match &a.max_age_s {
                    Some(v) => Duration::from_secs_f64(
                        positive(&ctx, v, "attitude.max_age_s")?.min(3600.0),
                    ),
                    None => Duration::from_millis(500),
                };
                Some(AttitudeInput {
                    listen,
                    beacon_axis_heading_deg,
                    max_age,
                })
            }
            _ => None,
        };

        let logging = {
            let l = raw.logging.as_ref();
            let format = match l.and_then(|l| l.format.as_ref()) {
                None => LogFormat::Plain,
                Some(f) => match f.get_ref().as_str() {
                    "plain" => LogFormat::Plain,
                    "json" => LogFormat::Json,
                    other => {
                        return Err(ctx.err(
                            f.span(),
                            "logging.format",
                            format!("\"{other}\" is not \"plain\" or \"json\""),
                        ))
                    }
                },
            };
            let level = match l.and_then(|l| l.level.as_ref()) {
                None => "info".to_string(),
                Some(v) => {
                    let ok =
                        ["error", "warn", "info", "debug", "trace"].contains(&v.get_ref().as_str());
                    if !ok {
                        return Err(ctx.err(
                            v.span(),
                            "logging.level",
                            format!(
                                "\"{}\" is not error, warn, info, debug or trace",
                                v.get_ref()
                            ),
                        ));
                    }
                    v.get_ref().clone()
                }
            };
            Logging { format, level }
        };

        if outputs.destinations.is_empty() && outputs.multicast.is_none() {
            tracing::warn!("{file}: no outputs.destinations and no multicast: poses go nowhere");
        }

        Ok(Config {
            origin: file.to_string(),
            rate_hz,
            late_tolerance,
            estimator,
            calibration,
            backend,
            fallback_temp_c,
            outputs,
            recording,
            attitude,
            logging,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn minimal_file_validates_with_defaults() {
        let c = parse(MIN).expect("valid");
        assert_eq!(c.rate_hz, 50.0);
        assert_eq!(c.estimator, "auto");
        assert_eq!(c.calibration, Resource::File("/etc/lp/cal.toml".into()));
        assert_eq!(
            c.backend,
            Backend::Replay(ReplayBackend {
                log: "/etc/lp/x.jsonl".into(),
                pace: Pace::Fast,
                looping: false
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
        assert_eq!(e, "t.toml:2: rate_hz: -1 must be a positive number");
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
    }

    #[test]
    fn missing_calibration_and_backend_are_named() {
        assert!(err("[backend]\nkind=\"sim\"\n").contains("calibration: missing"));
        assert!(err("calibration = \"c\"\n").contains("[backend]: missing"));
    }

    #[test]
    fn line_helpers() {
        let s = "a = 1\n[t]\nb = 2\n";
        assert_eq!(line_of_offset(s, 0), 1);
        assert_eq!(line_of_offset(s, 6), 2);
        assert_eq!(line_of_key_in_table(s, 6, "b"), 3);
        assert_eq!(key_on_line(s, 14), "b");
    }
}
