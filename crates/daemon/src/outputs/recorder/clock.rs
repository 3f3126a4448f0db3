//! What ties a recording's log time to the wall clock. A board's `t` is
//! seconds since boot (docs/spec-notes.md), so an MCAP shows 1970 plus the
//! uptime; an operator matching it against the autopilot's logs needs the
//! Unix time of some `t`, and whether the wall clock was right (a computer
//! without an RTC boots with a stale clock until NTP or GPS sets it).
//!
//! Each file gets a pair (t, Unix time) taken together when it opens: in
//! its HEADER (`clock`, JSONL and MCAP) and, in MCAP, as a
//! [`CLOCK_METADATA`] record. The recorder thread compares the wall clock
//! with the monotonic one every [`EVERY`]; when it has stepped by more than
//! [`STEP_S`] (the clock was set), or the kernel's word on its
//! synchronization changed, an MCAP gets another record (metadata may come
//! anywhere in the file). Never on the frame thread.

use lightpose_logs::foxglove::Stamp;
use lightpose_logs::schema::{clock_key as key, CLOCK_METADATA};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// How often the recorder thread compares the clocks.
pub const EVERY: Duration = Duration::from_secs(1);

/// A step of the wall clock against the monotonic one larger than this
/// (seconds) is a clock that was set: a new record.
pub const STEP_S: f64 = 1.0;

/// What the frames' `t` counts from ([`lightpose_hal::FrameSource::t_is_monotonic`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Epoch {
    /// A board: CLOCK_MONOTONIC, seconds since the computer booted.
    Monotonic,
    /// The simulator's or a replayed log's own time.
    Source,
}

impl Epoch {
    pub fn of(t_is_monotonic: bool) -> Epoch {
        if t_is_monotonic {
            Epoch::Monotonic
        } else {
            Epoch::Source
        }
    }
    pub fn as_str(self) -> &'static str {
        match self {
            Epoch::Monotonic => "monotonic",
            Epoch::Source => "source",
        }
    }
}

/// Whether the kernel says the wall clock is synchronized (its STA_UNSYNC
/// status bit, as `adjtimex` reads it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Synced {
    Yes,
    No,
    /// The kernel could not be asked (not Linux, or the call failed).
    Unknown,
}

impl Synced {
    pub fn as_str(self) -> &'static str {
        match self {
            Synced::Yes => "true",
            Synced::No => "false",
            Synced::Unknown => "unknown",
        }
    }
    /// In JSON: a value not known is `null` (FORMATS.md).
    fn json(self) -> serde_json::Value {
        match self {
            Synced::Yes => true.into(),
            Synced::No => false.into(),
            Synced::Unknown => serde_json::Value::Null,
        }
    }
}

/// The kernel's word on the wall clock: `adjtimex` with no mode set only
/// reads its state (no privilege needed).
#[cfg(target_os = "linux")]
pub fn kernel_synced() -> Synced {
    use nix::libc;
    // SAFETY: timex is a plain C struct, valid zeroed; with `modes` 0 the
    // call only fills it in, and keeps no pointer to it.
    let mut tx: libc::timex = unsafe { std::mem::zeroed() };
    if unsafe { libc::adjtimex(&mut tx) } == -1 {
        Synced::Unknown
    } else if tx.status & libc::STA_UNSYNC != 0 {
        Synced::No
    } else {
        Synced::Yes
    }
}

#[cfg(not(target_os = "linux"))]
pub fn kernel_synced() -> Synced {
    Synced::Unknown
}

/// The monotonic and wall clocks read together, and the kernel's word on
/// the wall clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clocks {
    /// Seconds since boot ([`lightpose_hal::clock::monotonic_s`]).
    pub mono: f64,
    /// Unix seconds.
    pub unix: f64,
    pub synced: Synced,
}

/// Reads the clocks; tests put one under the recorder whose wall clock
/// steps.
pub type ReadClocks = fn() -> Clocks;

/// The machine's clocks: the wall clock between two monotonic reads, the
/// monotonic time their middle.
pub fn read_clocks() -> Clocks {
    let a = lightpose_hal::clock::monotonic_s();
    let unix = super::unix_now();
    let b = lightpose_hal::clock::monotonic_s();
    Clocks {
        mono: a + (b - a) / 2.0,
        unix,
        synced: kernel_synced(),
    }
}

/// Why a record was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    Open,
    /// The wall clock stepped against the monotonic clock.
    Step,
    /// The kernel's word on its synchronization changed.
    Sync,
}

impl Reason {
    pub fn as_str(self) -> &'static str {
        match self {
            Reason::Open => "open",
            Reason::Step => "step",
            Reason::Sync => "sync",
        }
    }
}

/// One mapping: `t` in the log's epoch and the Unix time of that instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockPair {
    pub epoch: Epoch,
    pub t: f64,
    pub unix: f64,
    pub synced: Synced,
    pub reason: Reason,
}

impl ClockPair {
    /// The name and keys of its MCAP metadata record (all strings).
    pub fn metadata(&self) -> (&'static str, BTreeMap<String, String>) {
        let mut m = BTreeMap::new();
        let mut put = |k: &str, v: String| {
            m.insert(k.to_string(), v);
        };
        put(key::EPOCH, self.epoch.as_str().into());
        put(key::T, self.t.to_string());
        if let Some(s) = Stamp::of(self.t) {
            put(key::LOG_TIME, s.nanos().to_string());
        }
        put(key::UNIX, self.unix.to_string());
        put(key::OFFSET, (self.unix - self.t).to_string());
        put(key::SYNCED, self.synced.as_str().into());
        put(key::REASON, self.reason.as_str().into());
        (CLOCK_METADATA, m)
    }

    /// The HEADER's `clock` object (FORMATS.md: a header may carry more).
    pub fn header_json(&self) -> serde_json::Value {
        serde_json::json!({
            key::EPOCH: self.epoch.as_str(),
            key::T: self.t,
            key::UNIX: self.unix,
            key::SYNCED: self.synced.json(),
        })
    }
}

/// The recorder thread's watch on the wall clock.
pub struct ClockWatch {
    epoch: Epoch,
    pub(super) read: ReadClocks,
    pub(super) every: Duration,
    /// unix − mono when the last record's pair was taken.
    offset: f64,
    synced: Synced,
    check_at: Option<Instant>,
    /// `Source`: a record owed (and the step seen), written with the next
    /// frame (whose `t` and arrival are the pair; there is no other
    /// reading of its clock).
    owed: Option<(Reason, f64)>,
}

impl ClockWatch {
    pub fn new(epoch: Epoch) -> ClockWatch {
        ClockWatch {
            epoch,
            read: read_clocks,
            every: EVERY,
            offset: 0.0,
            synced: Synced::Unknown,
            check_at: None,
            owed: None,
        }
    }

    /// The pair of a file that opens with a frame at `t` that arrived at
    /// `wall_unix`: a board's `t` is the monotonic clock, read now with the
    /// wall clock; another epoch's pair is that frame's.
    pub fn open(&mut self, t: f64, wall_unix: f64, now: Instant) -> ClockPair {
        self.owed = None;
        self.check_at = Some(now + self.every);
        self.take(Reason::Open, t, wall_unix)
    }

    fn take(&mut self, reason: Reason, t: f64, wall_unix: f64) -> ClockPair {
        let c = (self.read)();
        self.offset = c.unix - c.mono;
        self.synced = c.synced;
        self.pair(c, reason, t, wall_unix)
    }

    /// The pair of clocks `c` read for `reason`: a board's is `c` itself,
    /// another epoch's the frame's `t` and its arrival `wall_unix`.
    fn pair(&self, c: Clocks, reason: Reason, t: f64, wall_unix: f64) -> ClockPair {
        let (t, unix) = match self.epoch {
            Epoch::Monotonic => (c.mono, c.unix),
            Epoch::Source => (t, wall_unix),
        };
        ClockPair {
            epoch: self.epoch,
            t,
            unix,
            synced: c.synced,
            reason,
        }
    }

    /// Compare the clocks, once every `every` (a file is open): a board's
    /// new pair when the wall clock stepped or its synchronization changed
    /// (another epoch's waits for [`ClockWatch::frame`]), and the step
    /// seen (seconds, the wall clock against the monotonic one).
    pub fn check(&mut self, now: Instant) -> Option<(ClockPair, f64)> {
        if self.check_at.is_none_or(|at| now < at) {
            return None;
        }
        self.check_at = Some(now + self.every);
        let c = (self.read)();
        let step = (c.unix - c.mono) - self.offset;
        let reason = if step.abs() > STEP_S {
            Reason::Step
        } else if c.synced != self.synced {
            Reason::Sync
        } else {
            return None;
        };
        self.offset = c.unix - c.mono;
        self.synced = c.synced;
        match self.epoch {
            Epoch::Monotonic => Some((self.pair(c, reason, c.mono, c.unix), step)),
            Epoch::Source => {
                // Not twice for one change while the record is owed.
                self.owed.get_or_insert((reason, step));
                None
            }
        }
    }

    /// The record owed (another epoch than a board's), with the frame just
    /// written at `t` that arrived at `wall_unix`.
    pub fn frame(&mut self, t: f64, wall_unix: f64) -> Option<(ClockPair, f64)> {
        let (reason, step) = self.owed.take()?;
        Some((self.take(reason, t, wall_unix), step))
    }
}
