//! `kind = "replay"`: a recorded intensity log as the source, at its
//! recorded pace (`pace = "recorded"`) or as fast as possible (`"fast"`),
//! looping or not.

use std::path::PathBuf;

use serde::Deserialize;

use super::{err, positive_to, Env, Pace};
use crate::HalError;

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayConfig {
    /// The log; a relative path is the env's to resolve.
    pub log: String,
    /// "recorded" (the log's own timestamps) or "fast".
    #[serde(default)]
    pub pace: Option<String>,
    /// Start again at the log's beginning when it ends (seq and t keep
    /// increasing).
    #[serde(rename = "loop", default)]
    pub looping: bool,
    /// A forward step of t larger than this (seconds) is a jump: counted,
    /// logged once and not slept through at recorded pace.
    #[serde(default)]
    pub max_gap_s: Option<f64>,
}

/// A validated replay backend.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayPlan {
    pub log: PathBuf,
    pub pace: Pace,
    pub looping: bool,
    pub max_gap_s: f64,
}

/// Largest `max_gap_s`: an hour.
pub const MAX_GAP_BOUND_S: f64 = 3600.0;

pub(super) fn replay(c: &ReplayConfig, env: &dyn Env) -> Result<ReplayPlan, HalError> {
    if c.log.trim().is_empty() {
        return Err(err("log", "empty path"));
    }
    let max_gap_s = match c.max_gap_s {
        Some(g) => positive_to("max_gap_s", g, MAX_GAP_BOUND_S, " s")?,
        None => lightpose_core::log::DEFAULT_MAX_GAP_S,
    };
    Ok(ReplayPlan {
        log: env.path(&c.log),
        pace: Pace::parse(c.pace.as_deref(), "recorded")?,
        looping: c.looping,
        max_gap_s,
    })
}
