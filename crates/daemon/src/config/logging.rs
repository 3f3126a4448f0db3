//! `[logging]`: the log format and level.

use super::locate::Ctx;
use super::ConfigError;
use lightpose_core::textfile::excerpt;
use serde::Deserialize;
use toml::Spanned;

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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLogging {
    format: Option<Spanned<String>>,
    level: Option<Spanned<String>>,
}

pub(super) fn validate(ctx: &Ctx, raw: Option<&RawLogging>) -> Result<Logging, ConfigError> {
    let format = match raw.and_then(|l| l.format.as_ref()) {
        None => LogFormat::Plain,
        Some(f) => match f.get_ref().as_str() {
            "plain" => LogFormat::Plain,
            "json" => LogFormat::Json,
            other => {
                return Err(ctx.err(
                    f.span(),
                    "logging.format",
                    format!("\"{}\" is not \"plain\" or \"json\"", excerpt(other, 40)),
                ))
            }
        },
    };
    let level = match raw.and_then(|l| l.level.as_ref()) {
        None => "info".to_string(),
        Some(v) if ["error", "warn", "info", "debug", "trace"].contains(&v.get_ref().as_str()) => {
            v.get_ref().clone()
        }
        Some(v) => {
            return Err(ctx.err(
                v.span(),
                "logging.level",
                format!(
                    "\"{}\" is not error, warn, info, debug or trace",
                    excerpt(v.get_ref(), 40)
                ),
            ))
        }
    };
    Ok(Logging { format, level })
}
