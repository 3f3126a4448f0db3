//! Counters shared between the acquisition thread (which writes them without
//! locks or allocation, once per frame) and the async side (which reads them
//! for STATUS once a second), and a fixed latency histogram so that p50/p99
//! frame-to-datagram latency is known in flight, not only in benchmarks:
//! over the whole run, and over the last minute ([`recent`]).

mod recent;
pub use recent::{Recent, RECENT};

use lightpose_core::{ReadingUse, Status, NDET};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering::Relaxed};
use std::sync::Mutex;
use std::time::Duration;

/// Where the temperature of the last frame came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum TempSource {
    /// No frame yet.
    None = 0,
    /// The frame carried it (board sensor, simulator, log).
    Frame = 1,
    /// The frame had none: the configured fallback was used.
    Fallback = 2,
    /// The frame had none and there is no fallback.
    Missing = 3,
}

impl TempSource {
    pub fn as_str(self) -> &'static str {
        match self {
            TempSource::None => "none",
            TempSource::Frame => "frame",
            TempSource::Fallback => "fallback",
            TempSource::Missing => "missing",
        }
    }
    fn from_u8(v: u8) -> Self {
        match v {
            1 => TempSource::Frame,
            2 => TempSource::Fallback,
            3 => TempSource::Missing,
            _ => TempSource::None,
        }
    }
}

/// State of the acquisition side as STATUS reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum BackendState {
    Starting = 0,
    Running = 1,
    /// The last attempt to read a frame failed.
    Failing = 2,
    /// The source said it has no more frames (end of a log).
    Ended = 3,
    Stopped = 4,
}

impl BackendState {
    pub fn as_str(self) -> &'static str {
        match self {
            BackendState::Starting => "starting",
            BackendState::Running => "running",
            BackendState::Failing => "failing",
            BackendState::Ended => "ended",
            BackendState::Stopped => "stopped",
        }
    }
    fn from_u8(v: u8) -> Self {
        match v {
            1 => BackendState::Running,
            2 => BackendState::Failing,
            3 => BackendState::Ended,
            4 => BackendState::Stopped,
            _ => BackendState::Starting,
        }
    }
}

/// Latency histogram: 1 µs buckets to 20 ms, 1 ms buckets to 2 s (latency
/// counts from a board frame's capture, half a slow read before it
/// arrives: tens of ms), then one overflow bucket. Fixed size so that
/// recording a sample is an index and an increment.
pub struct Histogram {
    buckets: Box<[AtomicU64]>,
    max_ns: AtomicU64,
    /// The largest sample since the last [`Histogram::recent`].
    recent_max_ns: AtomicU64,
    /// The STATUS side's slots of recent samples (the frame thread never
    /// locks it).
    window: Mutex<recent::Window>,
}

/// The 1 µs buckets (to 20 ms).
const FINE: usize = 20_000;
/// The overflow bucket's index, after the 1 ms buckets from 20 ms to 2 s.
const BUCKETS: usize = FINE + 1_980;

/// The bucket of a sample.
#[inline]
fn bucket_of(d: Duration) -> usize {
    let us = d.as_micros();
    if us < FINE as u128 {
        return us as usize;
    }
    let ms = (d.as_millis() - (FINE / 1000) as u128).min((BUCKETS - FINE) as u128);
    FINE + ms as usize
}

/// The upper edge of bucket `i` < `BUCKETS`, in seconds.
fn upper_edge(i: usize) -> f64 {
    if i < FINE {
        (i + 1) as f64 * 1e-6
    } else {
        (FINE / 1000 + (i - FINE) + 1) as f64 * 1e-3
    }
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            buckets: (0..=BUCKETS).map(|_| AtomicU64::new(0)).collect(),
            max_ns: AtomicU64::new(0),
            recent_max_ns: AtomicU64::new(0),
            window: Mutex::new(recent::Window::new()),
        }
    }
}

impl Histogram {
    #[inline]
    pub fn record(&self, d: Duration) {
        self.buckets[bucket_of(d)].fetch_add(1, Relaxed);
        let ns = d.as_nanos().min(u64::MAX as u128) as u64;
        self.max_ns.fetch_max(ns, Relaxed);
        self.recent_max_ns.fetch_max(ns, Relaxed);
    }

    pub fn count(&self) -> u64 {
        self.buckets.iter().map(|b| b.load(Relaxed)).sum()
    }

    /// Upper edge of the bucket holding quantile `q` (0..1), in seconds,
    /// never above the largest sample; `None` before any sample.
    pub fn quantile(&self, q: f64) -> Option<f64> {
        let n = self.count();
        if n == 0 {
            return None;
        }
        let max = self.max_ns.load(Relaxed) as f64 * 1e-9;
        let counts = self.buckets.iter().map(|b| b.load(Relaxed)).enumerate();
        Some(bucket_of_rank(counts, n, q).map_or(max, |i| edge_within(i, max)))
    }

    pub fn max(&self) -> Option<f64> {
        let m = self.max_ns.load(Relaxed);
        (self.count() > 0).then_some(m as f64 * 1e-9)
    }

    /// The bucket counts now, so that the soak can take the quantiles of
    /// one stretch of a run (a later snapshot minus an earlier one).
    pub fn snapshot(&self) -> HistSnapshot {
        HistSnapshot(self.buckets.iter().map(|b| b.load(Relaxed)).collect())
    }
}

/// Bucket counts of a [`Histogram`] at one moment (its buckets, the last
/// one holding everything from 2 s up).
#[derive(Debug, Clone, PartialEq)]
pub struct HistSnapshot(Vec<u64>);

impl HistSnapshot {
    pub fn count(&self) -> u64 {
        self.0.iter().sum()
    }

    /// The samples recorded between `earlier` and `self`.
    pub fn since(&self, earlier: &HistSnapshot) -> HistSnapshot {
        HistSnapshot(
            self.0
                .iter()
                .zip(earlier.0.iter().chain(std::iter::repeat(&0)))
                .map(|(a, b)| a.saturating_sub(*b))
                .collect(),
        )
    }

    /// Upper edge of the bucket holding quantile `q`, in seconds (2 s for
    /// the overflow bucket: the snapshot has no max); `None` if empty.
    pub fn quantile(&self, q: f64) -> Option<f64> {
        let n = self.count();
        if n == 0 {
            return None;
        }
        let i = bucket_of_rank(self.0.iter().copied().enumerate(), n, q);
        Some(upper_edge(i.unwrap_or(BUCKETS - 1).min(BUCKETS - 1)))
    }
}

/// The bucket (index, count pairs in order) holding quantile `q` (0..1) of
/// `n` samples; `None` if the counts end first.
pub(crate) fn bucket_of_rank(
    counts: impl Iterator<Item = (usize, u64)>,
    n: u64,
    q: f64,
) -> Option<usize> {
    let rank = ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).max(1);
    let mut acc = 0;
    for (i, c) in counts {
        acc += c;
        if acc >= rank {
            return Some(i);
        }
    }
    None
}

/// Bucket `i`'s upper edge in seconds, never above the largest sample
/// `max`; the overflow bucket is `max` itself.
pub(crate) fn edge_within(i: usize, max: f64) -> f64 {
    if i >= BUCKETS {
        max
    } else {
        upper_edge(i).min(max)
    }
}

/// Per-destination send accounting: one unreachable destination shows here
/// and does not stop the others.
#[derive(Default)]
pub struct DestStats {
    pub sent: AtomicU64,
    pub errors: AtomicU64,
    /// Last error text; written only when an error happens.
    pub last_error: Mutex<Option<String>>,
}

/// Everything STATUS says about frames.
#[derive(Default)]
pub struct Stats {
    pub frames: AtomicU64,
    pub late: AtomicU64,
    pub failed: AtomicU64,
    /// Frames the source skipped (gaps in `seq`).
    pub lost: AtomicU64,
    pub last_seq: AtomicU64,
    pub state: AtomicU8,
    pub temp_source: AtomicU8,
    /// f64 bits of the last temperature used; NaN bits when none.
    pub temp_bits: AtomicU64,
    /// Index into lightpose_core::Status::ALL of the last estimate.
    pub last_status: AtomicU8,
    /// Estimates per status word, in Status::ALL order.
    pub by_status: [AtomicU64; Status::ALL.len()],
    pub frames_with_attitude: AtomicU64,
    /// What the estimator did with the frames' own-sensor readings: per
    /// reading (attitude, depth, velocity, core's `READINGS` order), frames
    /// per outcome in `ReadingUse::index` order (used, ignored, refused by
    /// reason; `absent` is not counted).
    pub readings: [[AtomicU64; ReadingUse::COUNT]; 3],
    /// Frames on which the estimator left each channel out as stuck
    /// (`PoseEstimate::excluded_channels`), by detector 5·row + col.
    pub excluded: [AtomicU64; NDET],
    /// The channels left out of the last frame (bit mask).
    pub excluded_now: AtomicU64,
    /// The reading check (`PoseEstimate::agreement`), per component in
    /// core's `CHECKED` order: f64 bits of its last window mean (valid when
    /// its bit in `agreement_known` is set: the last estimate had one),
    /// frames it disagreed with the light on, and the components
    /// disagreeing on the last frame (bit mask).
    pub agreement_bits: [AtomicU64; 6],
    pub agreement_known: AtomicU64,
    pub disagreed: [AtomicU64; 6],
    pub disagreeing_now: AtomicU64,
    /// The DVL checks (`Agreement::dvl_range_change_m`, `dvl_turned_deg`,
    /// `dvl_refused`): f64 bits of the last changes of range judged (the
    /// light's, the DVL's) and of the last turn, each valid once its
    /// `_known` is set, and whether the DVL stands refused.
    pub dvl_change_bits: [AtomicU64; 2],
    pub dvl_change_known: AtomicBool,
    pub dvl_turned_bits: AtomicU64,
    pub dvl_turned_known: AtomicBool,
    pub dvl_refused_now: AtomicBool,
    pub latency: Histogram,
    /// Last error of the source, for STATUS.
    pub last_error: Mutex<Option<String>>,
    pub calibration_reloads: AtomicU64,
    /// f64 bits of the water's K_D as the estimator has learned it
    /// (`Estimator::water_k_d`); 0 (0.0) while it learns none, as no
    /// learned water is that clear.
    pub water_k_d_bits: AtomicU64,
    /// f64 bits of the depth sensor's offset and its 1σ as the estimator
    /// has learned them (`Estimator::depth_offset`); 0 bits (0.0 with a σ
    /// of 0) while it estimates none, as no estimate has a σ of 0.
    pub depth_offset_bits: [AtomicU64; 2],
    /// The same for the attitude sensor's pitch offset (°).
    pub pitch_offset_bits: [AtomicU64; 2],
    /// The source's own counters (temperature sensor and its fallback,
    /// bad serial lines, reopens, injected faults), copied about once a
    /// second by the frame thread.
    pub source_health: Mutex<Option<lightpose_hal::SourceHealth>>,
    /// Spec v3: the demodulator's state, when the source gives bursts,
    /// copied with the source's counters.
    pub demod: Mutex<Option<DemodStatus>>,
    /// Spec v3: a docking station's beacons as the last estimate saw them.
    pub station: StationStats,
}

/// What STATUS says of a docking station (`station`): the frame thread
/// stores the last estimate's beacons seen and their SNRs (atomics), and
/// the names only when the set seen changes.
#[derive(Default)]
pub struct StationStats {
    /// Beacons of the station (0: one beacon, no station).
    pub size: AtomicU8,
    /// Bit b: beacon b seen in the last estimate.
    pub seen_now: AtomicU64,
    /// f64 bits of each beacon's Σ a²/σ² in the last estimate.
    pub snr2_bits: [AtomicU64; lightpose_core::MAX_BEACONS],
    /// Estimates by [`lightpose_core::StationMode`]: 6-DOF, roll
    /// observable, one beacon, dark.
    pub by_mode: [AtomicU64; 4],
    pub names: Mutex<Option<&'static lightpose_core::StationNames>>,
}

/// What STATUS says of the demodulator (`demodulator`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DemodStatus {
    pub sample_hz: f64,
    pub samples_per_frame: usize,
    pub channel_skew_s: f64,
    pub beacons: Vec<BeaconLock>,
    /// Frames demodulated, and bursts it refused (counted as failed).
    pub frames: u64,
    pub refused: u64,
    /// Clipped samples over the run, and in the last frame.
    pub clipped_total: u64,
    pub clipped_last: u64,
}

/// One beacon's clock as the demodulator holds it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BeaconLock {
    pub id: String,
    pub mod_hz: f64,
    pub locked: bool,
    pub detected: bool,
    pub freq_hz: f64,
    /// The matched filter's signal-to-noise of the last frame.
    pub detection: f64,
}

impl BeaconLock {
    /// The beacon's clock off its nominal frequency, ppm.
    pub fn offset_ppm(&self) -> f64 {
        if self.mod_hz > 0.0 {
            (self.freq_hz / self.mod_hz - 1.0) * 1e6
        } else {
            0.0
        }
    }
}

impl Stats {
    pub fn state(&self) -> BackendState {
        BackendState::from_u8(self.state.load(Relaxed))
    }
    pub fn set_state(&self, s: BackendState) {
        self.state.store(s as u8, Relaxed);
    }
    pub fn temp(&self) -> (Option<f64>, TempSource) {
        let t = f64::from_bits(self.temp_bits.load(Relaxed));
        (
            t.is_finite().then_some(t),
            TempSource::from_u8(self.temp_source.load(Relaxed)),
        )
    }
    pub fn water_k_d(&self) -> Option<f64> {
        let k = f64::from_bits(self.water_k_d_bits.load(Relaxed));
        (k.is_finite() && k > 0.0).then_some(k)
    }
    pub fn depth_offset(&self) -> Option<(f64, f64)> {
        load_pair(&self.depth_offset_bits)
    }
    pub fn set_depth_offset(&self, o: Option<(f64, f64)>) {
        store_pair(&self.depth_offset_bits, o);
    }
    pub fn pitch_offset_deg(&self) -> Option<(f64, f64)> {
        load_pair(&self.pitch_offset_bits)
    }
    pub fn set_pitch_offset_deg(&self, o: Option<(f64, f64)>) {
        store_pair(&self.pitch_offset_bits, o);
    }
    pub fn set_water_k_d(&self, k: Option<f64>) {
        self.water_k_d_bits.store(
            k.filter(|k| k.is_finite()).unwrap_or(0.0).to_bits(),
            Relaxed,
        );
    }
    pub fn set_temp(&self, t: Option<f64>, src: TempSource) {
        self.temp_bits
            .store(t.unwrap_or(f64::NAN).to_bits(), Relaxed);
        self.temp_source.store(src as u8, Relaxed);
    }
}

/// An estimate and its 1σ kept as f64 bits; none while the σ is 0 (no
/// estimate has a σ of 0).
fn load_pair(bits: &[AtomicU64; 2]) -> Option<(f64, f64)> {
    let [m, sd] = [0, 1].map(|i| f64::from_bits(bits[i].load(Relaxed)));
    (m.is_finite() && sd.is_finite() && sd > 0.0).then_some((m, sd))
}

fn store_pair(bits: &[AtomicU64; 2], o: Option<(f64, f64)>) {
    let (m, sd) = o.unwrap_or((0.0, 0.0));
    bits[0].store(m.to_bits(), Relaxed);
    bits[1].store(sd.to_bits(), Relaxed);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_known_samples() {
        let h = Histogram::default();
        assert_eq!(h.quantile(0.5), None);
        for us in 1..=100u64 {
            h.record(Duration::from_micros(us));
        }
        // 100 samples at 1..100 µs: the median sits in the 50 µs bucket.
        let p50 = h.quantile(0.5).unwrap();
        assert!((p50 - 51e-6).abs() < 1e-9, "{p50}");
        let p99 = h.quantile(0.99).unwrap();
        assert!((p99 - 100e-6).abs() < 1e-9, "{p99}");
        h.record(Duration::from_secs(1));
        assert_eq!(h.quantile(1.0), Some(1.0));
        h.record(Duration::from_secs(5));
        assert_eq!(h.quantile(1.0), Some(5.0));
    }

    /// Latency from a board frame's capture is tens of ms (half an
    /// ADS1115 read): above 20 ms the buckets are 1 ms, not one overflow
    /// whose quantiles all read as the max.
    #[test]
    fn quantiles_above_20_ms_are_to_the_millisecond() {
        let h = Histogram::default();
        for ms in [34, 34, 34, 85, 3000] {
            h.record(Duration::from_micros(ms * 1000 + 400));
        }
        let q = |p: f64| h.quantile(p).unwrap();
        assert!((q(0.5) - 0.035).abs() < 1e-12, "{}", q(0.5));
        assert!((q(0.8) - 0.086).abs() < 1e-12, "{}", q(0.8));
        assert!((q(1.0) - 3.0004).abs() < 1e-12, "{}", q(1.0));
        assert_eq!(bucket_of(Duration::from_micros(19_999)), FINE - 1);
        assert_eq!(bucket_of(Duration::from_millis(20)), FINE);
        assert_eq!(bucket_of(Duration::from_millis(1999)), BUCKETS - 1);
        assert_eq!(bucket_of(Duration::from_secs(2)), BUCKETS);
        assert_eq!(bucket_of(Duration::MAX), BUCKETS);
    }

    #[test]
    fn snapshot_difference_is_the_stretch_between() {
        let h = Histogram::default();
        for _ in 0..100 {
            h.record(Duration::from_micros(3));
        }
        let a = h.snapshot();
        for _ in 0..100 {
            h.record(Duration::from_micros(40));
        }
        let d = h.snapshot().since(&a);
        assert_eq!(d.count(), 100);
        assert!((d.quantile(0.5).unwrap() - 41e-6).abs() < 1e-12);
        assert!((a.quantile(0.99).unwrap() - 4e-6).abs() < 1e-12);
        assert_eq!(HistSnapshot(vec![]).quantile(0.5), None);
    }
}
