//! The simulator's tables. Two spellings of one source, kept apart because
//! their keys and defaults differ and configs in use rely on both:
//!
//! - `kind = "sim"`: the simulator flown along a trajectory, as the
//!   daemon's default run uses it: `scene` and `trajectory` name texts that
//!   the [`Env`] resolves (the daemon: a path relative to its config, or
//!   `embedded:NAME`, and its defaults when absent), the rate is the env's,
//!   `pace = "realtime" | "fast"`, `loop`, `seed` (default 1);
//! - `kind = "mock"`: the same simulator with injected faults (bus errors,
//!   dropped frames, stuck channels) for robustness tests: paths taken as
//!   written, no scene = the simulator's default tank, its own `rate_hz`
//!   (0 = free-running), `loop` (`looping`, its first spelling, still
//!   read), `seed` (default 0), `faults`.
//!
//! Both validate into one [`SimPlan`], opened by one source.

use std::path::PathBuf;

use lightpose_core::textfile::TextSource;
use lightpose_core::{COLS, ROWS};
use serde::Deserialize;

use super::{err, positive_to, rate, true_, Env, Pace};
use crate::HalError;

fn one() -> u64 {
    1
}

/// `kind = "sim"`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// A scene (MODEL.md); absent: the env's default.
    #[serde(default)]
    pub scene: Option<String>,
    /// A trajectory CSV (`t,x,y,z,pitch,yaw`); absent: the env's default.
    #[serde(default)]
    pub trajectory: Option<String>,
    /// Start again at the trajectory's beginning when it ends.
    #[serde(rename = "loop", default = "true_")]
    pub looping: bool,
    #[serde(default = "one")]
    pub seed: u64,
    /// "realtime" (the env's rate) or "fast".
    #[serde(default)]
    pub pace: Option<String>,
}

/// `kind = "mock"`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MockConfig {
    /// Absent: the env's rate; 0: as fast as asked.
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// Scene file; absent = the simulator's default (the tank).
    #[serde(default)]
    pub scene: Option<PathBuf>,
    /// Trajectory CSV (`t,x,y,z,pitch,yaw`).
    pub trajectory: PathBuf,
    /// Start again at the trajectory's beginning when it ends. `loop`, as
    /// for sim and replay; `looping`, the mock's first spelling, is still
    /// read so that configs written for it keep working.
    #[serde(rename = "loop", alias = "looping", default = "true_")]
    pub looping: bool,
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub faults: FaultConfig,
}

/// Faults the mock injects, for robustness tests of the daemon.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultConfig {
    /// A bus error on every N-th frame.
    #[serde(default)]
    pub bus_error_every: Option<u64>,
    /// A bus error with this probability per frame.
    #[serde(default)]
    pub bus_error_prob: f64,
    /// A dropped frame (its seq is skipped) on every N-th frame.
    #[serde(default)]
    pub drop_every: Option<u64>,
    #[serde(default)]
    pub drop_prob: f64,
    /// Channels that always read the same value.
    #[serde(default)]
    pub stuck: Vec<StuckChannel>,
    /// The DVL's velocity turned by this much about its down axis (°): a
    /// DVL mounted turned with its mounting rotation unset (180: backwards).
    /// Needs a scene with `[dvl]`.
    #[serde(default)]
    pub dvl_turned_deg: f64,
    /// Added to every depth reading (m): a beacon depth surveyed wrong, a
    /// pressure sensor zeroed elsewhere. Needs a scene with `[depth]`.
    #[serde(default)]
    pub depth_bias_m: f64,
    /// Added to every attitude reading's pitch (°): an AHRS mounted askew
    /// of the dome. Needs a scene with `[attitude]`.
    #[serde(default)]
    pub pitch_bias_deg: f64,
    /// Seed of the fault draws (apart from the simulator's).
    #[serde(default)]
    pub seed: u64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StuckChannel {
    pub r: usize,
    pub c: usize,
    pub value: u16,
}

/// Faults to inject, validated.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    pub bus_error_every: Option<u64>,
    pub bus_error_prob: f64,
    pub drop_every: Option<u64>,
    pub drop_prob: f64,
    /// (detector index, value)
    pub stuck: Vec<(usize, u16)>,
    /// Radians; 0 for none.
    pub dvl_turned: f64,
    /// Metres added to each depth reading; 0 for none.
    pub depth_bias: f64,
    /// Radians added to each attitude reading's pitch; 0 for none.
    pub pitch_bias: f64,
    pub seed: u64,
}

/// A validated simulator backend.
#[derive(Debug, Clone, PartialEq)]
pub struct SimPlan {
    /// The config's kind, "sim" or "mock", for messages.
    pub kind: &'static str,
    /// `None`: the simulator's default tank.
    pub scene: Option<TextSource>,
    pub trajectory: TextSource,
    /// Frames per second of the simulated clock; `None`: free-running, the
    /// clock at the scene's ADC rate.
    pub rate_hz: Option<f64>,
    /// `Fast`: the frame times of `rate_hz`, handed out as fast as asked.
    pub pace: Pace,
    pub looping: bool,
    pub seed: u64,
    pub faults: Faults,
}

/// `kind = "sim"`.
pub(super) fn sim(c: &SimConfig, env: &dyn Env) -> Result<SimPlan, HalError> {
    let text = |key: &str, written: Option<&String>| {
        env.text(key, written.map(String::as_str))
            .map_err(|msg| err(key, msg))
    };
    Ok(SimPlan {
        kind: "sim",
        scene: Some(text("scene", c.scene.as_ref())?),
        trajectory: text("trajectory", c.trajectory.as_ref())?,
        // The program's rate as it is (the daemon's top-level `rate_hz`, which
        // it checked): this table has no rate of its own to bound.
        rate_hz: Some(positive_to(
            "rate_hz",
            env.default_rate_hz(),
            10_000.0,
            " Hz",
        )?),
        pace: Pace::parse(c.pace.as_deref(), "realtime")?,
        looping: c.looping,
        seed: c.seed,
        faults: Faults::default(),
    })
}

/// `kind = "mock"`.
pub(super) fn mock(c: &MockConfig, env: &dyn Env) -> Result<SimPlan, HalError> {
    Ok(SimPlan {
        kind: "mock",
        // Relative paths are the env's to resolve (the daemon: from its
        // config file's directory), as for every other path of a table.
        scene: c
            .scene
            .as_ref()
            .map(|p| TextSource::File(env.path(&p.to_string_lossy()))),
        trajectory: TextSource::File(env.path(&c.trajectory.to_string_lossy())),
        rate_hz: rate(c.rate_hz, env)?,
        pace: Pace::Realtime,
        looping: c.looping,
        seed: c.seed,
        faults: faults(&c.faults)?,
    })
}

fn faults(f: &FaultConfig) -> Result<Faults, HalError> {
    for (key, p) in [
        ("faults.bus_error_prob", f.bus_error_prob),
        ("faults.drop_prob", f.drop_prob),
    ] {
        if !(0.0..=1.0).contains(&p) {
            return Err(err(key, format!("{p} is not a probability in 0..=1")));
        }
    }
    for (key, n) in [
        ("faults.bus_error_every", f.bus_error_every),
        ("faults.drop_every", f.drop_every),
    ] {
        if n == Some(0) {
            return Err(err(key, "must be at least 1"));
        }
    }
    let mut stuck = Vec::with_capacity(f.stuck.len());
    for (i, s) in f.stuck.iter().enumerate() {
        if s.r >= ROWS || s.c >= COLS {
            return Err(err(
                format!("faults.stuck[{i}]"),
                format!("detector ({}, {}) is outside the array", s.r, s.c),
            ));
        }
        stuck.push((s.r * COLS + s.c, s.value));
    }
    if !(f.dvl_turned_deg.is_finite() && f.dvl_turned_deg.abs() <= 360.0) {
        return Err(err(
            "faults.dvl_turned_deg",
            format!("{} is not an angle within ±360°", f.dvl_turned_deg),
        ));
    }
    // A bias past these is a sensor unplugged or a wrong unit, not an
    // offset (the tracker's own limits on the readings: 20 m of depth).
    if !(f.depth_bias_m.is_finite() && f.depth_bias_m.abs() <= 100.0) {
        return Err(err(
            "faults.depth_bias_m",
            format!("{} is not a depth bias within ±100 m", f.depth_bias_m),
        ));
    }
    if !(f.pitch_bias_deg.is_finite() && f.pitch_bias_deg.abs() <= 90.0) {
        return Err(err(
            "faults.pitch_bias_deg",
            format!("{} is not a pitch bias within ±90°", f.pitch_bias_deg),
        ));
    }
    Ok(Faults {
        bus_error_every: f.bus_error_every,
        bus_error_prob: f.bus_error_prob,
        drop_every: f.drop_every,
        drop_prob: f.drop_prob,
        stuck,
        dvl_turned: f.dvl_turned_deg.to_radians(),
        depth_bias: f.depth_bias_m,
        pitch_bias: f.pitch_bias_deg.to_radians(),
        seed: f.seed,
    })
}
