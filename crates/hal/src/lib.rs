//! Hardware abstraction: every way the daemon can get a frame of the array
//! (ADC boards over SPI, I²C and serial, the simulator, a recorded log)
//! behind one trait, so that the daemon cannot tell them apart.
//!
//! A program validates the `[backend]` table of its config
//! ([`BackendConfig::validate`], once, at load) into a [`ValidBackend`],
//! opens it with [`open`] — the one call for every kind — and then calls
//! [`FrameSource::next_frame`] in a loop; [`FrameSource::health`] gives the
//! counters worth reporting, and a [`Stop`] ends every wait of the source.
//!
//! - [`config`]: what the config file says, validated, one file per family
//!   of kinds;
//! - [`drivers`]: MCP3008/MCP3208 (SPI), ADS1115 and ADS7828 (I²C), generic
//!   over embedded-hal 1.0;
//! - [`serial`]: the `$LPADC` line protocol of microcontroller boards, and
//!   their LPBST bursts for a blinking beacon;
//! - [`chanmap`]: which board channel feeds which detector;
//! - [`bank`]: boards read together into one frame, paced ([`pace`]),
//!   stamped on the machine's monotonic clock ([`clock`]);
//! - [`linux`]: the real spidev / i2c-dev buses those boards sit on;
//! - [`temp`]: fixed, DS18B20 and thermistor temperature with fallback;
//! - [`text`]: the words of a [`SourceError`], cheap to clone and build;
//! - [`sim`]: the simulator as a source, with injectable faults;
//! - [`replay`]: a recorded log (JSON Lines or MCAP, read through
//!   lightpose-logs) as a source.
//!
//! Feature `linux` adds the real spidev / i2c-dev buses; without it the
//! SPI and I²C kinds are refused by [`open`] with a clear error, so a
//! simulator build needs no device files. Serial boards and replay work
//! everywhere; feature `sim` (default) adds the simulator.

use std::time::Duration;

use lightpose_core::samples::{BeaconInfo, Burst};
use lightpose_core::Frame;

pub mod bank;
pub mod chanmap;
pub mod clock;
pub mod config;
pub mod drivers;
#[cfg(feature = "linux")]
pub mod linux;
pub mod pace;
pub mod replay;
pub mod serial;
#[cfg(feature = "sim")]
pub mod sim;
pub mod temp;
pub mod text;

pub use bank::{Bank, BoardSource};
pub use chanmap::{ChannelMap, MapEntry, MapError};
pub use config::{BackendConfig, Env, Pace, PlainEnv, TempConfig, ValidBackend};
pub use pace::Stop;
pub use temp::TempHealth;
pub use text::{Recent, Text};

/// Why a source could not give a frame. The daemon counts and logs these and
/// keeps going; `Ended` means there will be no more frames (a log or a
/// non-looping simulation ran out).
///
/// Its words are [`Text`], so that a source failing on every frame does
/// not allocate per frame: a board's place is built once, at open, and
/// cloned; a message is static, short (inline), or built only when it
/// changes ([`Recent`]).
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("{place}: bus error: {msg}")]
    Bus { place: Text, msg: Text },
    #[error("{place}: timed out waiting for data")]
    Timeout { place: Text },
    #[error("{place}: device unavailable: {msg}")]
    Unavailable { place: Text, msg: Text },
    #[error("{place}: bad data: {msg}")]
    BadData { place: Text, msg: Text },
    #[error("source ended")]
    Ended,
    /// A wait ended because the source's [`Stop`] was raised.
    #[error("stopped")]
    Stopped,
}

/// Counters a source keeps for the daemon's health report. All are totals
/// since the source was opened.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SourceHealth {
    /// The temperature source, if the source has one of ours.
    pub temp: Option<TempHealth>,
    /// Serial lines that did not parse (garbage, wrong checksum, ...).
    pub bad_lines: u64,
    /// Serial lines from a board id not expected on that port.
    pub wrong_board_lines: u64,
    /// Serial lines a board sent that no frame used: a newer line of the
    /// same board came first (the board streams faster than frames are
    /// taken; not an error, but bandwidth spent for nothing).
    pub superseded_lines: u64,
    /// Serial bursts (LPBST): breaks in a board's sample index (a packet
    /// lost, damaged or cut short).
    pub burst_gaps: u64,
    /// Serial bursts: frames begun and dropped unfinished (a gap, a board
    /// reset): never handed on as part of a burst.
    pub bursts_dropped: u64,
    /// The last bad line's (or packet's) error.
    pub last_bad_line: Option<String>,
    /// Devices reopened after a failure.
    pub reopens: u64,
    /// Faults the mock injected (bus errors, drops).
    pub injected_faults: u64,
    /// Replay: frames skipped as out of order (see core's `FrameOrder`).
    pub skipped_frames: u64,
    /// Replay: forward steps of `t` past the gap bound, not slept through.
    pub time_jumps: u64,
    /// Replay: log lines of other classes passed over.
    pub other_lines: u64,
    /// Replay: lone frames out of line in `seq` or `t` gone over, the
    /// frames after them kept (core's `FrameOrder::glitches`).
    pub glitches: u64,
    /// Replay: malformed own-sensor readings dropped (their frames kept),
    /// and the last one's place and reason.
    pub bad_readings: u64,
    pub last_bad_reading: Option<String>,
}

/// Spec v3: how a source that takes N > 1 samples of every channel per
/// frame samples, for the demodulator the daemon sets up from it and for
/// a recording's header (FORMATS.md `sample_hz`, `channel_skew_s`,
/// `beacons`).
#[derive(Debug, Clone, PartialEq)]
pub struct Sampling {
    pub sample_hz: f64,
    /// N: samples of every channel per frame.
    pub samples_per_frame: usize,
    /// Channel k is converted k · channel_skew_s after channel 0.
    pub channel_skew_s: f64,
    /// The beacons whose light the samples carry.
    pub beacons: Vec<BeaconInfo>,
}

/// What [`FrameSource::next_take`] gave: a frame (counts, or amplitudes
/// already demodulated), or the caller's burst filled with the next
/// frame's samples.
#[derive(Debug, Clone, Copy, PartialEq)]
// A frame is held by value, as everywhere (fixed size, never on the heap).
#[allow(clippy::large_enum_variant)]
pub enum Take {
    Frame(Frame),
    Burst,
}

/// "Give me the next frame": 25 channels in MODEL.md's order, the ADC
/// resolution, the capture time and the temperature.
///
/// `next_frame` blocks until the frame is due (a source paces itself at its
/// configured rate, or as fast as possible where that is configured). After
/// an error other than `Ended`, the next call tries again.
pub trait FrameSource: Send {
    fn next_frame(&mut self) -> Result<Frame, SourceError>;
    /// ADC resolution of the frames this source gives.
    fn adc_bits(&self) -> u8;
    /// One line saying what this source is (for logs and STATUS).
    fn describe(&self) -> String;
    /// The period it keeps between frames, for deadline accounting; `None`
    /// when it hands frames out as fast as they are asked for.
    fn period(&self) -> Option<Duration> {
        None
    }
    /// Frames per second of the clock its frames' `t` runs on (what a
    /// recording's header says), paced or not; `None` when it has none.
    fn rate_hz(&self) -> Option<f64> {
        self.period().map(|p| 1.0 / p.as_secs_f64())
    }
    /// Counters for the health report (temperature fallbacks, skipped
    /// lines, reopens, injected faults).
    fn health(&self) -> SourceHealth {
        SourceHealth::default()
    }
    /// Whether its frames' `t` is [`clock::monotonic_s`] at capture (live
    /// boards), so that a reader of that clock at arrival knows how long
    /// ago the frame was captured. Not so (the default) for simulated or
    /// recorded time, whose capture is taken to be its arrival.
    fn t_is_monotonic(&self) -> bool {
        false
    }
    /// Spec v3: `Some` when the source samples faster than its frames and
    /// gives bursts ([`FrameSource::next_take`]); `None` (the default):
    /// frames of one sample, as v1/v2.
    fn sampling(&self) -> Option<Sampling> {
        None
    }
    /// The next frame or burst: a source with [`FrameSource::sampling`]
    /// fills `burst` (its buffer reused: no allocation once it has the
    /// size) and says [`Take::Burst`]; the others give their frame.
    fn next_take(&mut self, burst: &mut Burst) -> Result<Take, SourceError> {
        let _ = burst;
        self.next_frame().map(Take::Frame)
    }
}

/// Said by the `next_frame` of a source that gives bursts: its frames
/// need the demodulator, which [`FrameSource::next_take`]'s caller runs.
pub(crate) fn bursts_only(place: &'static str) -> SourceError {
    SourceError::BadData {
        place: Text::from_static(place),
        msg: Text::from_static("gives bursts of samples: read with next_take"),
    }
}

/// Why a source could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum HalError {
    /// A config value is wrong; `key` is relative to the source's table.
    #[error("source config: {key}: {msg}")]
    Config { key: String, msg: String },
    // The map's refusal is in the message, not chained as a source, so that
    // a one-line report of the chain does not say it twice.
    #[error("source config: {0}")]
    Map(MapError),
    /// A device could not be opened or set up.
    #[error("{place}: {msg}")]
    Open { place: String, msg: String },
    /// The kind needs a feature this build does not have.
    #[error("source kind \"{kind}\" needs lightpose-hal built with feature \"{feature}\"")]
    NotBuilt {
        kind: &'static str,
        feature: &'static str,
    },
    /// The simulator's scene could not be read or is wrong.
    #[cfg(feature = "sim")]
    #[error(transparent)]
    Scene(#[from] lightpose_sim::SceneError),
    /// The simulator's trajectory could not be read or is wrong.
    #[cfg(feature = "sim")]
    #[error(transparent)]
    Trajectory(#[from] lightpose_sim::TrajectoryError),
    /// A replayed log could not be opened or has no header.
    #[error(transparent)]
    Log(#[from] lightpose_core::LogError),
}

impl From<MapError> for HalError {
    fn from(e: MapError) -> Self {
        HalError::Map(e)
    }
}

impl HalError {
    /// Whether the configuration is what is wrong (a value, a file it
    /// names): restarting the program cannot help. A device that cannot be
    /// opened may appear later, so that is not a refusal.
    pub fn refuses_config(&self) -> bool {
        !matches!(self, HalError::Open { .. })
    }
}

/// Check, before a start, everything [`open`] would read: the simulator's
/// scene and trajectory are read and parsed, a replayed log's header is
/// read; a board's device is not opened (it may appear later: that is not
/// a wrong configuration), but a kind this build lacks is refused.
pub fn check(cfg: &ValidBackend) -> Result<(), HalError> {
    match cfg {
        ValidBackend::Replay(plan) => {
            replay::ReplaySource::open(plan, &Stop::new())?;
            Ok(())
        }
        #[cfg(feature = "sim")]
        ValidBackend::Sim(plan) => sim::SimSource::open(plan, &Stop::new()).map(drop),
        #[cfg(not(feature = "sim"))]
        ValidBackend::Sim(_) => Err(HalError::NotBuilt {
            kind: cfg.kind(),
            feature: "sim",
        }),
        ValidBackend::Serial { .. } => Ok(()),
        #[cfg(feature = "linux")]
        _ => Ok(()),
        #[cfg(not(feature = "linux"))]
        _ => Err(HalError::NotBuilt {
            kind: cfg.kind(),
            feature: "linux",
        }),
    }
}

/// Open the source `cfg` describes: the one way every kind is opened. Its
/// waits (pacing, a replay's recorded time) end early when `stop` is
/// raised.
pub fn open(cfg: &ValidBackend, stop: &Stop) -> Result<Box<dyn FrameSource>, HalError> {
    match cfg {
        ValidBackend::Serial {
            boards,
            timeout,
            common,
        } => {
            let mut bank = serial::SerialBank::new(boards.clone(), common.bits, *timeout)
                .stoppable(stop.clone());
            let sampling = common.sampling();
            if let Some(s) = &sampling {
                // The boards sample and send bursts (docs/serial-protocol.md).
                bank = bank.with_bursts(serial::BurstPlan {
                    samples_per_frame: s.samples_per_frame,
                    sample_hz: s.sample_hz,
                });
            }
            Ok(Box::new(
                BoardSource::new(
                    bank,
                    common.map,
                    common.temp.clone().start(),
                    common.pacer(stop),
                )
                .with_sampling(sampling),
            ))
        }
        ValidBackend::Replay(plan) => Ok(Box::new(replay::ReplaySource::open(plan, stop)?)),
        #[cfg(feature = "sim")]
        ValidBackend::Sim(plan) => Ok(Box::new(sim::SimSource::open(plan, stop)?)),
        #[cfg(not(feature = "sim"))]
        ValidBackend::Sim(_) => Err(HalError::NotBuilt {
            kind: cfg.kind(),
            feature: "sim",
        }),
        #[cfg(feature = "linux")]
        hw => linux::open(hw, stop),
        #[cfg(not(feature = "linux"))]
        _ => Err(HalError::NotBuilt {
            kind: cfg.kind(),
            feature: "linux",
        }),
    }
}
