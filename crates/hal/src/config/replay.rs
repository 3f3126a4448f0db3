//! `kind = "replay"`: a recorded intensity log as the source, at its
//! recorded pace (`pace = "recorded"`) or as fast as possible (`"fast"`),
//! looping or not.

use std::path::PathBuf;

use serde::Deserialize;

use super::{Env, Pace};
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
}

/// A validated replay backend.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayPlan {
    pub log: PathBuf,
    pub pace: Pace,
    pub looping: bool,
}

pub(super) fn replay(c: &ReplayConfig, env: &dyn Env) -> Result<ReplayPlan, HalError> {
    Ok(ReplayPlan {
        log: env.path(&c.log),
        pace: Pace::parse(c.pace.as_deref(), "recorded")?,
        looping: c.looping,
    })
}
