//! `[backend]`: where frames come from. The table is lightpose-hal's
//! ([`BackendConfig`]), validated by hal once, here, into the
//! [`ValidBackend`] that the daemon later opens without looking inside.
//! What the table leaves to the daemon — the top-level `rate_hz`, paths
//! relative to this file, `embedded:NAME` and the default scene and
//! trajectory — hal asks through [`DaemonEnv`]. hal's errors, which name a
//! key of the table, become `file:line: backend.KEY: msg`.

use super::locate::Ctx;
use super::places::{self, Places};
use super::{embedded, ConfigError};
use lightpose_core::textfile::TextSource;
use lightpose_hal::{BackendConfig, Env, HalError, ValidBackend};
use std::path::PathBuf;
use toml::Spanned;

/// The daemon's answers to what a backend table leaves open.
struct DaemonEnv<'a> {
    ctx: &'a Ctx<'a>,
    rate_hz: f64,
}

impl Env for DaemonEnv<'_> {
    fn default_rate_hz(&self) -> f64 {
        self.rate_hz
    }
    fn path(&self, written: &str) -> PathBuf {
        self.ctx.path(written)
    }
    fn text(&self, key: &str, written: Option<&str>) -> Result<TextSource, String> {
        // The embedded default run's scene and trajectory.
        let default = match key {
            "scene" => Some("embedded:tank-scene"),
            "trajectory" => Some("embedded:zigzag"),
            _ => None,
        };
        match written.or(default) {
            Some(w) => embedded::resolve(self.ctx, w),
            None => Err("missing".into()),
        }
    }
}

pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&Spanned<toml::Table>>,
    rate_hz: f64,
    at: &mut Places,
) -> Result<ValidBackend, ConfigError> {
    let Some(b) = raw else {
        return Err(ctx.whole("[backend]: missing (kind = \"sim\", \"replay\" or a board)"));
    };
    let (start, table) = (b.span().start, b.get_ref());
    check_kind(ctx, table, start)?;
    // The files hal reads: their refusals (no such file, a bad line) are
    // said at these keys (`wiring::check`), and so are a board's sampling's
    // that the demodulator refuses.
    for (key, name) in [
        (places::SCENE, "scene"),
        (places::TRAJECTORY, "trajectory"),
        (places::LOG, "log"),
        ("backend.sample_hz", "sample_hz"),
        ("backend.beacons", "beacons"),
        ("backend.channel_skew_s", "channel_skew_s"),
    ] {
        at.set(key, ctx.line_of_key(start, name));
    }
    let cfg: BackendConfig = deserialize(ctx, table, start)?;
    let env = DaemonEnv { ctx, rate_hz };
    cfg.validate(&env).map_err(|e| hal_error(ctx, start, &e))
}

/// `kind` is there, a string, and one hal knows.
fn check_kind(ctx: &Ctx, table: &toml::Table, start: usize) -> Result<(), ConfigError> {
    let line = ctx.line_of_key(start, "kind");
    match table.get("kind") {
        Some(toml::Value::String(k)) if BackendConfig::KINDS.split(", ").any(|x| x == k) => Ok(()),
        Some(toml::Value::String(other)) => Err(ctx.at(
            line,
            "backend.kind",
            format!("unknown backend \"{other}\" ({})", BackendConfig::KINDS),
        )),
        Some(_) => Err(ctx.at(line, "backend.kind", "must be a string")),
        None => Err(ctx.at(
            line,
            "backend.kind",
            "missing (\"sim\", \"replay\" or a board)",
        )),
    }
}

/// The table into hal's struct, naming the line of the offending key (the
/// table was parsed once already, without spans inside it).
fn deserialize(ctx: &Ctx, table: &toml::Table, start: usize) -> Result<BackendConfig, ConfigError> {
    serde::Deserialize::deserialize(toml::Value::Table(table.clone())).map_err(
        |e: toml::de::Error| {
            let msg = e.message().trim().to_string();
            match key_of(table, &msg) {
                None => ctx.at(ctx.line(start), "backend", msg),
                Some(key) => {
                    let first = key.split('.').next().unwrap_or("");
                    ctx.at(
                        ctx.line_of_key(start, first),
                        &format!("backend.{key}"),
                        msg,
                    )
                }
            }
        },
    )
}

/// The key serde's message is about: a field it names in backquotes
/// ("unknown field `speed`"), or else the key whose value it quotes
/// ("invalid value: integer `-1`", "invalid type: string \"one\""),
/// looked for in inline tables too (`faults.seed`).
pub(super) fn key_of(table: &toml::Table, msg: &str) -> Option<String> {
    let ticked = msg.split('`').nth(1);
    if let Some(k) = ticked.filter(|k| table.contains_key(*k)) {
        return Some(k.to_string());
    }
    let quoted = msg
        .split_once("string \"")
        .and_then(|(_, rest)| rest.rsplit_once('"'))
        .map(|(s, _)| s);
    let value = ticked.or(quoted)?;
    find_value(table, value)
}

fn find_value(table: &toml::Table, written: &str) -> Option<String> {
    table.iter().find_map(|(k, v)| {
        let same = match v {
            toml::Value::Integer(i) => i.to_string() == written,
            toml::Value::Float(f) => f.to_string() == written || format!("{f:?}") == written,
            toml::Value::String(s) => s == written,
            toml::Value::Boolean(b) => b.to_string() == written,
            toml::Value::Table(t) => return find_value(t, written).map(|sub| format!("{k}.{sub}")),
            _ => false,
        };
        same.then(|| k.clone())
    })
}

/// hal names keys like "map[3].channel": the first segment is what is
/// written in the table, and its line is the place.
fn hal_error(ctx: &Ctx, start: usize, e: &HalError) -> ConfigError {
    let (key, msg) = match e {
        HalError::Config { key, msg } => (key.clone(), msg.clone()),
        HalError::Map(m) => ("map".to_string(), m.to_string()),
        other => (String::new(), other.to_string()),
    };
    let first = key.split(['.', '[']).next().unwrap_or("");
    let key = if key.is_empty() {
        "backend".to_string()
    } else {
        format!("backend.{key}")
    };
    ctx.at(ctx.line_of_key(start, first), &key, msg)
}
