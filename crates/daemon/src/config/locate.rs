//! Naming the place of a refusal: toml gives byte spans, a person wants
//! `file:line: key: msg`. Every table's validator builds its errors here,
//! and every message is cut to one bounded line (a value quoted from a
//! 60 MB file is an excerpt), and the range checks every number goes
//! through.

use super::ConfigError;
use lightpose_core::bounds::shown;
use lightpose_core::textfile::{excerpt, one_line};
use lightpose_core::textpos::line_of_offset;
use std::net::SocketAddr;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The file being validated: its name for messages, its text for line
/// numbers, its directory for relative paths.
pub(super) struct Ctx<'a> {
    pub file: &'a str,
    pub src: &'a str,
    pub base_dir: Option<&'a Path>,
}

impl Ctx<'_> {
    /// An error at the line of `span`.
    pub fn err(&self, span: Range<usize>, key: &str, msg: impl Into<String>) -> ConfigError {
        self.at(line_of_offset(self.src, span.start), key, msg)
    }

    /// The line of a byte offset.
    pub fn line(&self, offset: usize) -> usize {
        line_of_offset(self.src, offset)
    }

    /// The line of an optional key's value, else of its table (a default
    /// is said at the table that took it): where a place is recorded.
    pub fn line_of_value<T, V>(&self, table: &Spanned<T>, value: Option<&Spanned<V>>) -> usize {
        self.line(value.map_or(table.span().start, |v| v.span().start))
    }

    /// An error at `line`.
    pub fn at(&self, line: usize, key: &str, msg: impl Into<String>) -> ConfigError {
        ConfigError::At {
            file: self.file.to_string(),
            line,
            key: excerpt(key, 80),
            msg: one_line(&msg.into()),
        }
    }

    /// An error about the whole file (a missing key has no line).
    pub fn whole(&self, msg: impl Into<String>) -> ConfigError {
        ConfigError::Whole {
            file: self.file.to_string(),
            msg: one_line(&msg.into()),
        }
    }

    /// A path written in the file: relative ones are taken from the
    /// config's directory so that a config and its files travel together.
    pub fn path(&self, text: &str) -> PathBuf {
        let p = PathBuf::from(text);
        match self.base_dir {
            Some(d) if p.is_relative() => d.join(p),
            _ => p,
        }
    }

    /// The line of `key = ...` inside the table that starts at `table_start`
    /// (the table's own line when the key is not written there).
    pub fn line_of_key(&self, table_start: usize, key: &str) -> usize {
        line_of_key_in_table(self.src, table_start, key)
    }

    /// toml's refusal of the file as a whole (syntax, a wrong type, an
    /// unknown key), at the line of its span.
    pub fn toml_error(&self, e: &toml::de::Error) -> ConfigError {
        let msg = e.message().trim().replace('\n', " ");
        let Some(s) = e.span() else {
            return self.whole(msg);
        };
        let line = line_of_offset(self.src, s.start);
        match key_on_line(self.src, s.start) {
            Some(key) => self.at(line, &key, msg),
            // A line that is no `key =` (a syntax error): no key to name.
            None => ConfigError::Line {
                file: self.file.to_string(),
                line,
                msg: one_line(&msg),
            },
        }
    }
}

/// The key written on the line of `offset`, for errors whose span points at
/// a value (or the table of a `[table]` line); `None` when the line holds
/// neither.
pub(super) fn key_on_line(src: &str, offset: usize) -> Option<String> {
    let start = src[..offset.min(src.len())]
        .rfind('\n')
        .map_or(0, |i| i + 1);
    let line = src[start..].lines().next().unwrap_or("");
    match line.split_once('=') {
        Some((k, _)) if !k.trim().is_empty() && !k.trim_start().starts_with('[') => {
            let key = k.trim().trim_matches('"');
            Some(match enclosing_table(&src[..start]) {
                Some(table) => format!("{table}.{key}"),
                None => key.to_string(),
            })
        }
        _ => {
            let t = line.trim();
            t.starts_with('[')
                .then(|| t.trim_matches(|c| c == '[' || c == ']').to_string())
        }
    }
}

/// The table a key line belongs to: the last `[table]` (or `[[table]]`)
/// header in `before`, without brackets or a trailing comment; `None` at
/// the top level. So that a refusal names `outputs.destinaton`, not a bare
/// `destinaton` the reader has to place.
fn enclosing_table(before: &str) -> Option<String> {
    before.lines().rev().find_map(|l| {
        let t = l.trim();
        let t = t.split_once('#').map_or(t, |(h, _)| h).trim();
        let name = t.strip_prefix('[')?.strip_suffix(']')?;
        let name = name.trim_matches(|c| c == '[' || c == ']').trim();
        (!name.is_empty()).then(|| name.to_string())
    })
}

/// Line of `key = ...` inside the table that starts at `table_start`, or
/// the table's own line when the key is not written there.
pub(super) fn line_of_key_in_table(src: &str, table_start: usize, key: &str) -> usize {
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

/// A number in `(0, hi]` (`unit` says of what), else refused at its line.
pub(super) fn positive_to(
    ctx: &Ctx,
    v: &Spanned<f64>,
    key: &str,
    hi: f64,
    unit: &str,
) -> Result<f64, ConfigError> {
    let x = *v.get_ref();
    if x.is_finite() && x > 0.0 && x <= hi {
        Ok(x)
    } else {
        Err(ctx.err(
            v.span(),
            key,
            format!("{} is not in (0, {hi}]{unit}", shown(x)),
        ))
    }
}

/// A number in `lo..=hi`, else refused at its line.
pub(super) fn within(
    ctx: &Ctx,
    v: &Spanned<f64>,
    key: &str,
    (lo, hi): (f64, f64),
    unit: &str,
) -> Result<f64, ConfigError> {
    let x = *v.get_ref();
    if x.is_finite() && (lo..=hi).contains(&x) {
        Ok(x)
    } else {
        Err(ctx.err(
            v.span(),
            key,
            format!("{} is not in {lo}..={hi}{unit}", shown(x)),
        ))
    }
}

/// What an address is for: a listener may take every interface
/// (0.0.0.0), a destination must name a host.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum AddrUse {
    Listen,
    /// A listener whose port is told where it is found: port 0 takes a
    /// free port, said in the log and STATUS (`[web] listen`: the tests
    /// bind port 0).
    ListenTold,
    SendTo,
}

/// An `address:port`; port 0 is refused (no one listens on it, and a
/// listener there gets a port nobody knows), and as a destination so is
/// the unspecified address.
pub(super) fn socket_addr(
    ctx: &Ctx,
    v: &Spanned<String>,
    key: &str,
    used: AddrUse,
) -> Result<SocketAddr, ConfigError> {
    let written = excerpt(v.get_ref(), 60);
    let a = v.get_ref().parse::<SocketAddr>().map_err(|_| {
        let msg = format!("\"{written}\" is not an address:port (e.g. \"127.0.0.1:17150\")");
        ctx.err(v.span(), key, msg)
    })?;
    if a.port() == 0 && used != AddrUse::ListenTold {
        let msg = format!("{a}: port 0 is no port to send to or listen on (1..=65535)");
        return Err(ctx.err(v.span(), key, msg));
    }
    if used == AddrUse::SendTo && a.ip().is_unspecified() {
        let msg = format!("{a}: the unspecified address is no destination; name the host");
        return Err(ctx.err(v.span(), key, msg));
    }
    Ok(a)
}
