//! `[recording]`: raw frames written as intensity logs, rotated by size or
//! age, behind a bounded queue; JSON Lines (the default) or MCAP (frames,
//! estimates and STATUS), pushed to the disk every `flush_s`.
//!
//! Ranges: `rotate_mb` 0.01..=1048576 MiB (10 kB to 1 TiB);
//! `rotate_minutes` 0.1..=525600 (six seconds to a year); `queue`
//! 1..=1000000 frames; `flush_s` (0, 3600]; `keep_free_mb` 0..=1048576
//! MiB; `max_total_mb` 1..=16777216 MiB, with `rotate_mb` at most that.
//!
//! MCAP with neither rotation key rotates by [`Recording::rotation`]'s
//! default: every [`MCAP_ROTATE_AFTER`] or [`MCAP_MAX_CHUNKS`] chunks,
//! whichever comes first; a configured rotation replaces it. JSONL has no
//! default: its writer keeps nothing per line, so an endless file costs
//! disk, not memory.

use super::locate::{positive_to, within, Ctx};
use super::places::{self, Places};
use super::ConfigError;
use serde::Deserialize;
use std::path::PathBuf;
use std::time::Duration;
use toml::Spanned;

#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub dir: PathBuf,
    /// Start a new file when the current one reaches this size (MCAP with
    /// neither this nor `rotate_after`: see [`Recording::rotation`]).
    pub rotate_bytes: Option<u64>,
    /// Start a new file when the current one is this old.
    pub rotate_after: Option<Duration>,
    /// Frames that may wait for the disk before they are counted as lost.
    pub queue: usize,
    pub format: RecFormat,
    /// How often what was written is pushed to the disk (MCAP: the open
    /// chunk closed; both: the file synced): a power loss loses at most
    /// this much.
    pub flush: Duration,
    /// `keep_free_mb`: free space to keep on the disk, pruning the oldest
    /// recordings for it; `None`: the recorder's own guard (scaled to the
    /// filesystem, `outputs::recorder::default_floor`), no pruning.
    pub keep_free_bytes: Option<u64>,
    /// `max_total_mb`: the recordings in `dir` are kept under this, the
    /// oldest pruned first.
    pub max_total_bytes: Option<u64>,
    /// Spec v3, a source that samples faster than its frames: what its
    /// frames are recorded as (`samples`).
    pub samples: RecSamples,
    /// `format = "ros2"`: the node's namespace and frames (`[ros2]`) and
    /// the site (`[site]`, for `/tf_static`), so that a bag holds what the
    /// node publishes; set by [`super::Config::parse`] from those tables.
    pub bag: lightpose_logs::Ros2BagOptions,
}

/// What a recording holds of a source that gives bursts (spec v3); a
/// source of one sample a frame records its counts whatever this says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RecSamples {
    /// BURST lines: the samples as the ADC took them, so that a replay
    /// demodulates them again (with a better demodulator, another
    /// configuration). 25 × N numbers a frame.
    #[default]
    Raw,
    /// Demodulated frames (each beacon's amplitudes, the ambient, the
    /// clipped counts): about 75 numbers a frame whatever N.
    Demodulated,
}

/// The container of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RecFormat {
    /// JSON Lines (FORMATS.md): frames only, each line written whole.
    #[default]
    Jsonl,
    /// MCAP: frames, estimates and STATUS, with Foxglove's channels.
    Mcap,
    /// A ROS 2 bag (MCAP, profile `ros2`, docs/ros2.md): each `ok`
    /// estimate as the ROS 2 node publishes it and each STATUS as
    /// `/diagnostics`; no frames (nothing to replay or calibrate from).
    Ros2,
}

impl RecFormat {
    /// Whether the file is an MCAP (chunks, a summary, rotation by
    /// default, cut back to a chunk's end).
    pub fn is_mcap(self) -> bool {
        matches!(self, RecFormat::Mcap | RecFormat::Ros2)
    }

    /// The config's word for it (STATUS `recording.format`).
    pub fn as_str(self) -> &'static str {
        match self {
            RecFormat::Jsonl => "jsonl",
            RecFormat::Mcap => "mcap",
            RecFormat::Ros2 => "ros2",
        }
    }
}

/// `flush_s` when not given.
pub const DEFAULT_FLUSH: Duration = Duration::from_secs(2);

/// An MCAP recording without `rotate_mb` / `rotate_minutes` starts a new
/// file this often. The `mcap` writer keeps a chunk index (≈ 104 B) in
/// memory per chunk until the file closes, and the open file is never
/// pruned: without rotation the daemon grows for as long as it runs. An
/// hour (≈ 35 MB at 5 Hz, 1800 chunks at `flush_s` = 2) is what the
/// shipped configurations use, and a unit pruning can free.
pub const MCAP_ROTATE_AFTER: Duration = Duration::from_secs(3600);

/// …and at most this many chunks per file, so that the index stays under
/// 1 MiB (8192 × 104 B ≈ 0.85 MB) whatever the rate and `flush_s`: at
/// 1 kHz (full 64 KiB chunks) that is a file of about 512 MiB.
pub const MCAP_MAX_CHUNKS: u64 = 8192;

/// When a recording starts a new file: at `bytes`, at the age `after` or
/// at `chunks` MCAP chunks, whichever comes first (`None`: no such limit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rotation {
    pub bytes: Option<u64>,
    pub after: Option<Duration>,
    pub chunks: Option<u64>,
}

impl Recording {
    /// The rotation configured or, for MCAP with none, the default one
    /// ([`MCAP_ROTATE_AFTER`]). MCAP always keeps the chunk bound
    /// ([`MCAP_MAX_CHUNKS`]): a configured day-long file at 1 kHz would
    /// hold ~260 k chunk index entries (27 MB) in memory.
    pub fn rotation(&self) -> Rotation {
        let configured = self.rotate_bytes.is_some() || self.rotate_after.is_some();
        let mcap = self.format.is_mcap();
        Rotation {
            bytes: self.rotate_bytes,
            after: if configured || !mcap {
                self.rotate_after
            } else {
                Some(MCAP_ROTATE_AFTER)
            },
            chunks: mcap.then_some(MCAP_MAX_CHUNKS),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRecording {
    enabled: Option<bool>,
    dir: Option<Spanned<String>>,
    rotate_mb: Option<Spanned<f64>>,
    rotate_minutes: Option<Spanned<f64>>,
    queue: Option<Spanned<i64>>,
    format: Option<Spanned<RecFormat>>,
    flush_s: Option<Spanned<f64>>,
    keep_free_mb: Option<Spanned<f64>>,
    max_total_mb: Option<Spanned<f64>>,
    samples: Option<Spanned<RecSamples>>,
}

/// `None` when the table is absent or not enabled (checked all the same:
/// [`places::when_on`]).
pub(super) fn validate(
    ctx: &Ctx,
    raw: Option<&Spanned<RawRecording>>,
    at: &mut Places,
) -> Result<Option<Recording>, ConfigError> {
    let Some(table) = raw else { return Ok(None) };
    let enabled = table.get_ref().enabled.unwrap_or(true);
    places::when_on(enabled, at, |at| check(ctx, table, at))
}

fn check(
    ctx: &Ctx,
    table: &Spanned<RawRecording>,
    at: &mut Places,
) -> Result<Recording, ConfigError> {
    let r = table.get_ref();
    // Whether the directory can be (a file is not one): `wiring::check`.
    at.set(
        places::RECORDING_DIR,
        ctx.line_of_value(table, r.dir.as_ref()),
    );
    let dir = match &r.dir {
        Some(d) if !d.get_ref().trim().is_empty() => ctx.path(d.get_ref()),
        Some(d) => return Err(ctx.err(d.span(), "recording.dir", "empty path")),
        None => std::env::var_os("STATE_DIRECTORY")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from("/var/lib/lightposed")),
    };
    let rotate_bytes = match &r.rotate_mb {
        Some(v) => {
            let mb = within(ctx, v, "recording.rotate_mb", (0.01, 1_048_576.0), " MiB")?;
            Some((mb * 1024.0 * 1024.0) as u64)
        }
        None => None,
    };
    let rotate_after = match &r.rotate_minutes {
        Some(v) => Some(Duration::from_secs_f64(
            within(ctx, v, "recording.rotate_minutes", (0.1, 525_600.0), " min")? * 60.0,
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
    let flush = match &r.flush_s {
        Some(v) => Duration::from_secs_f64(positive_to(ctx, v, "recording.flush_s", 3600.0, " s")?),
        None => DEFAULT_FLUSH,
    };
    let (keep_free_bytes, max_total_bytes) = limits(ctx, r, rotate_bytes)?;
    Ok(Recording {
        dir,
        rotate_bytes,
        rotate_after,
        queue,
        format: r.format.as_ref().map_or(RecFormat::Jsonl, |f| *f.get_ref()),
        flush,
        keep_free_bytes,
        max_total_bytes,
        samples: r.samples.as_ref().map_or(RecSamples::Raw, |f| *f.get_ref()),
        bag: Default::default(),
    })
}

/// `keep_free_mb` and `max_total_mb`, in bytes; the latter needs rotation
/// by size up to it (the open file is never pruned).
fn limits(
    ctx: &Ctx,
    r: &RawRecording,
    rotate_bytes: Option<u64>,
) -> Result<(Option<u64>, Option<u64>), ConfigError> {
    let mib = |mb: f64| (mb * 1024.0 * 1024.0) as u64;
    let keep_free_bytes = match &r.keep_free_mb {
        Some(v) => Some(mib(within(
            ctx,
            v,
            "recording.keep_free_mb",
            (0.0, 1_048_576.0),
            " MiB",
        )?)),
        None => None,
    };
    let max_total_bytes = match &r.max_total_mb {
        Some(v) => {
            let max = mib(within(
                ctx,
                v,
                "recording.max_total_mb",
                (1.0, 16_777_216.0),
                " MiB",
            )?);
            // The open file is never pruned: rotation must bound it.
            let msg = match rotate_bytes {
                None => Some("needs rotate_mb (the open file is never pruned)".to_string()),
                Some(b) if b > max => Some(format!(
                    "{} MiB is less than rotate_mb = {} MiB: the open file is never pruned, so rotation must keep it within this",
                    v.get_ref(),
                    b as f64 / (1024.0 * 1024.0)
                )),
                _ => None,
            };
            if let Some(msg) = msg {
                return Err(ctx.err(v.span(), "recording.max_total_mb", msg));
            }
            Some(max)
        }
        None => None,
    };
    Ok((keep_free_bytes, max_total_bytes))
}
