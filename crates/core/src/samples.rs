//! Spec v3's two new kinds of frame (FORMATS.md): a BURST, the raw samples
//! of one frame as the ADC took them, and a demodulated frame, what a
//! demodulator made of them (per beacon an amplitude and its 1σ in every
//! channel; per channel the ambient level and the samples clipped). Both
//! live here, beside [`Frame`](crate::Frame), so that the simulator, the
//! log readers and writers and the demodulator share one definition. Each
//! is made once and refilled frame after frame: a burst's samples sit in
//! one buffer that keeps its capacity, and a demodulated frame holds at
//! most [`MAX_BEACONS`] beacons in fixed arrays.

use crate::{AttitudeReading, DepthReading, Truth, VelocityReading, NDET};

/// Most beacons a log or a scene may name: a fixed bound keeps a
/// demodulated frame free of the heap (MODEL.md's rules admit six at
/// N = 640).
pub const MAX_BEACONS: usize = 8;

/// Most samples of one channel in one frame: a BURST line of 25 × 4096
/// counts is about 0.5 MB, far past any real board's frame.
pub const MAX_SAMPLES_PER_FRAME: usize = 4096;

/// A beacon a demodulator looks for, as a log's header names it.
#[derive(Debug, Clone, PartialEq)]
pub struct BeaconInfo {
    pub id: String,
    /// Hz; 0 is steady.
    pub mod_hz: f64,
}

/// The raw samples of one frame (FORMATS.md `BURST`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Burst {
    pub seq: u64,
    /// Time of the frame's first sample: sample i of channel k was taken at
    /// t + i / sample_hz + k · channel_skew_s.
    pub t: f64,
    pub adc_bits: u8,
    /// Samples per channel, N.
    n: usize,
    /// Channel-major: sample i of channel k at `k * n + i`.
    samples: Vec<u16>,
    pub temp_c: Option<f64>,
    /// At the frame's middle, t + (N − 1) / (2 · sample_hz).
    pub truth: Option<Truth>,
    pub attitude: Option<AttitudeReading>,
    pub depth: Option<DepthReading>,
    pub velocity: Option<VelocityReading>,
}

impl Burst {
    /// An empty burst of `n` samples per channel (all 0).
    pub fn new(n: usize) -> Self {
        let mut b = Burst::default();
        b.resize(n);
        b
    }

    /// `from` into `self`, the buffer reused when it has the size (a
    /// derived `clone_from` would allocate a new one each frame).
    pub fn copy_from(&mut self, from: &Burst) {
        if self.n() != from.n() {
            self.resize(from.n());
        }
        self.samples_mut().copy_from_slice(from.samples());
        self.seq = from.seq;
        self.t = from.t;
        self.adc_bits = from.adc_bits;
        self.temp_c = from.temp_c;
        self.truth = from.truth;
        self.attitude = from.attitude;
        self.depth = from.depth;
        self.velocity = from.velocity;
    }

    /// Samples per channel.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Make room for `n` samples per channel; the buffer keeps its
    /// capacity, so a reused burst allocates only when N grows.
    pub fn resize(&mut self, n: usize) {
        self.n = n;
        self.samples.clear();
        self.samples.resize(n * NDET, 0);
    }

    /// Channel k's samples in time order.
    pub fn channel(&self, k: usize) -> &[u16] {
        &self.samples[k * self.n..(k + 1) * self.n]
    }
    pub fn channel_mut(&mut self, k: usize) -> &mut [u16] {
        &mut self.samples[k * self.n..(k + 1) * self.n]
    }
    /// All samples, channel-major.
    pub fn samples(&self) -> &[u16] {
        &self.samples
    }
    pub fn samples_mut(&mut self) -> &mut [u16] {
        &mut self.samples
    }
    /// Swap in a buffer of `n` samples per channel (channel-major), taking
    /// the old one out: a reader fills a buffer and hands it over without
    /// copying.
    pub(crate) fn swap_samples(&mut self, n: usize, buf: &mut Vec<u16>) {
        debug_assert_eq!(buf.len(), n * NDET);
        self.n = n;
        std::mem::swap(&mut self.samples, buf);
    }
}

/// One beacon of a demodulated frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BeaconAmplitude {
    /// Its place in the log header's `beacons` (or 0, the one steady
    /// beacon "beacon", when the header names none).
    pub beacon: u8,
    /// On level minus off level of its square wave in each channel, counts
    /// (may be slightly negative through noise).
    pub amplitude: [f64; NDET],
    /// 1σ of each amplitude, counts.
    pub std: [f64; NDET],
}

/// What a demodulator made of one frame's samples, apart from the frame's
/// own fields: each beacon's amplitude image with its 1σ, the ambient and
/// the clipped counts (FORMATS.md). The estimators read it from
/// [`crate::Frame::amplitudes`], the logs from [`Demodulated::light`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Amplitudes {
    /// How many of `beacons` are in use.
    pub n_beacons: usize,
    pub beacons: [BeaconAmplitude; MAX_BEACONS],
    /// Mean counts of what does not blink (daylight and dark offset).
    pub ambient: [f64; NDET],
    /// Samples of the frame at 0 or full scale, per channel.
    pub clipped: [u32; NDET],
}

impl Default for Amplitudes {
    fn default() -> Self {
        Amplitudes {
            n_beacons: 0,
            beacons: [BeaconAmplitude::default(); MAX_BEACONS],
            ambient: [0.0; NDET],
            clipped: [0; NDET],
        }
    }
}

impl Amplitudes {
    /// The beacons in use.
    pub fn beacons(&self) -> &[BeaconAmplitude] {
        &self.beacons[..self.n_beacons.min(MAX_BEACONS)]
    }

    /// The beacon whose place in the header's `beacons` is `index`.
    pub fn beacon(&self, index: u8) -> Option<&BeaconAmplitude> {
        self.beacons().iter().find(|b| b.beacon == index)
    }

    /// What a steady reading of channel k averaged over the frame would
    /// have been: the ambient plus half of each beacon's amplitude (a
    /// square wave is on half the time), in counts. What a frame's
    /// `counts` show for a demodulated frame (images, the 5 × 5 view).
    pub fn mean_level(&self, k: usize) -> f64 {
        self.ambient[k]
            + self
                .beacons()
                .iter()
                .map(|b| 0.5 * b.amplitude[k])
                .sum::<f64>()
    }
}

/// What a demodulator made of a frame's samples (FORMATS.md: a FRAME with
/// `beacons`, `ambient` and `clipped` in place of `counts`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Demodulated {
    pub seq: u64,
    /// The frame's middle.
    pub t: f64,
    pub adc_bits: u8,
    pub light: Amplitudes,
    pub temp_c: Option<f64>,
    pub truth: Option<Truth>,
    pub attitude: Option<AttitudeReading>,
    pub depth: Option<DepthReading>,
    pub velocity: Option<VelocityReading>,
}

impl Default for Demodulated {
    fn default() -> Self {
        Demodulated {
            seq: 0,
            t: 0.0,
            adc_bits: 10,
            light: Amplitudes::default(),
            temp_c: None,
            truth: None,
            attitude: None,
            depth: None,
            velocity: None,
        }
    }
}

impl Demodulated {
    /// The frame fields of what `burst` was demodulated into: its seq, its
    /// ADC, its readings and truth, and its time, the middle of its
    /// samples (MODEL.md) at `sample_hz`.
    pub fn frame_of(&mut self, burst: &Burst, sample_hz: f64) {
        self.seq = burst.seq;
        self.t = burst.t + (burst.n() as f64 - 1.0) / (2.0 * sample_hz);
        self.adc_bits = burst.adc_bits;
        self.temp_c = burst.temp_c;
        self.truth = burst.truth;
        self.attitude = burst.attitude;
        self.depth = burst.depth;
        self.velocity = burst.velocity;
    }

    /// The beacons in use.
    pub fn beacons(&self) -> &[BeaconAmplitude] {
        self.light.beacons()
    }

    /// The frame an estimator reads: its amplitudes in
    /// [`crate::Frame::amplitudes`], and as `counts` each channel's mean
    /// level ([`Amplitudes::mean_level`], rounded and clamped to the
    /// ADC's range) for what shows counts.
    pub fn to_frame(&self) -> crate::Frame {
        let full = crate::frame::full_scale(self.adc_bits) as f64;
        let mut counts = [0u16; NDET];
        for (k, c) in counts.iter_mut().enumerate() {
            let v = self.light.mean_level(k).round();
            // NaN and below 0 read 0 (as an ADC clamps); above, full scale.
            *c = if v >= full {
                full as u16
            } else if v > 0.0 {
                v as u16
            } else {
                0
            };
        }
        crate::Frame {
            seq: self.seq,
            t: self.t,
            adc_bits: self.adc_bits,
            counts,
            temp_c: self.temp_c,
            truth: self.truth,
            attitude: self.attitude,
            depth: self.depth,
            velocity: self.velocity,
            amplitudes: Some(self.light),
        }
    }
}

/// One frame of a log, of whichever kind the log holds. A frame is held
/// by value, as everywhere (fixed size, never on the heap).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Record<'a> {
    /// Counts (spec v1/v2).
    Frame(crate::Frame),
    /// Raw samples (spec v3).
    Burst(&'a Burst),
    /// Demodulated (spec v3).
    Demodulated(&'a Demodulated),
}

/// The kinds of frame line, as a log that mixes them names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordKind {
    Frame,
    Burst,
    Demodulated,
}

impl RecordKind {
    pub fn describe(self) -> &'static str {
        match self {
            RecordKind::Frame => "FRAME line of counts",
            RecordKind::Burst => "BURST line (raw samples)",
            RecordKind::Demodulated => "demodulated FRAME line (beacons)",
        }
    }
}

impl Record<'_> {
    pub fn kind(&self) -> RecordKind {
        match self {
            Record::Frame(_) => RecordKind::Frame,
            Record::Burst(_) => RecordKind::Burst,
            Record::Demodulated(_) => RecordKind::Demodulated,
        }
    }
    pub fn seq(&self) -> u64 {
        match self {
            Record::Frame(f) => f.seq,
            Record::Burst(b) => b.seq,
            Record::Demodulated(d) => d.seq,
        }
    }
}
