//! Spec v3 on the frame thread: a source that samples faster than its
//! frames gives bursts, and each is demodulated here (lightpose-demod's
//! one demodulator) into a frame with each beacon's amplitudes, which the
//! estimator reads. The demodulator is set up from the source's
//! [`Sampling`] the way a log reader sets one up from a log's header
//! (`lightpose_demod::demodulator_for`), so that a live run and its
//! recording are demodulated alike. Every buffer is made here, once: a
//! frame allocates nothing.

use lightpose_core::samples::{Burst, Demodulated};
use lightpose_core::{Frame, LogHeader};
use lightpose_demod::{ConfigError, Demodulator};
use lightpose_hal::{Sampling, SourceError, Text};

use crate::stats::{BeaconLock, DemodStatus};

/// The recording header's spec v3 fields for `sampling`, as FORMATS.md
/// has them (`sample_hz`, `channel_skew_s`, `beacons`).
pub fn header_fields(h: &mut LogHeader, sampling: &Sampling) {
    h.sample_hz = Some(sampling.sample_hz);
    h.channel_skew_s = Some(sampling.channel_skew_s);
    h.beacons = sampling.beacons.clone();
}

/// The demodulator for a source sampling as `sampling` says, its frames
/// at `rate_hz`; refused as a log of that header would be.
pub fn demodulator(sampling: &Sampling, rate_hz: f64) -> Result<Demodulator, ConfigError> {
    let mut h = LogHeader::new(16, rate_hz);
    header_fields(&mut h, sampling);
    match lightpose_demod::demodulator_for(&h)? {
        Some(d) => Ok(d),
        // N = 1 at this rate: the sampling says more, so the rates differ.
        None => Err(ConfigError::Range {
            key: "sample_hz",
            value: sampling.sample_hz,
            range: "more than rate_hz",
        }),
    }
}

/// The demodulator at work, with its burst and its output.
pub struct Demod {
    pub demod: Demodulator,
    /// The source fills it; it stays until the next frame (a recorder of
    /// raw samples takes it from here).
    pub burst: Burst,
    out: Box<Demodulated>,
    /// The last take was a burst (not a frame the source demodulated or
    /// counted itself).
    fresh: bool,
    /// Frames demodulated, and refused.
    frames: u64,
    refused: u64,
    /// Clipped samples over the run, and in the last frame.
    clipped_total: u64,
    clipped_last: u64,
}

impl Demod {
    pub fn new(demod: Demodulator) -> Demod {
        let out = Box::new(demod.output());
        let burst = Burst::new(demod.samples_per_channel());
        Demod {
            demod,
            burst,
            out,
            fresh: false,
            frames: 0,
            refused: 0,
            clipped_total: 0,
            clipped_last: 0,
        }
    }

    /// The burst the source gave, demodulated into a frame for the
    /// estimator; a burst the demodulator refuses is the source's bad data
    /// (counted as a failed frame, its words inline: no allocation).
    pub fn frame(&mut self) -> Result<Frame, SourceError> {
        self.fresh = true;
        if let Err(e) = self.demod.demodulate_burst(&self.burst, &mut self.out) {
            self.refused += 1;
            return Err(SourceError::BadData {
                place: Text::from_static("demodulator"),
                msg: Text::format(format_args!("frame {}: {e}", self.burst.seq)),
            });
        }
        self.frames += 1;
        let clipped: u64 = self.out.light.clipped.iter().map(|&c| u64::from(c)).sum();
        self.clipped_last = clipped;
        self.clipped_total += clipped;
        Ok(self.out.to_frame())
    }

    /// Before each take: no burst yet.
    pub fn taking(&mut self) {
        self.fresh = false;
    }

    /// The burst the frame just taken was demodulated from, if it was.
    pub fn last_burst(&self) -> Option<&Burst> {
        self.fresh.then_some(&self.burst)
    }

    /// The demodulator's state for STATUS into `into`, its buffers reused
    /// when it has them (each beacon's id is written once).
    pub fn report(&self, into: &mut Option<DemodStatus>) {
        let cfg = self.demod.config();
        let s = into.get_or_insert_with(|| DemodStatus {
            sample_hz: cfg.sample_hz,
            samples_per_frame: cfg.n,
            channel_skew_s: cfg.channel_skew_s,
            beacons: cfg
                .beacons
                .iter()
                .map(|b| BeaconLock {
                    id: b.id.clone(),
                    mod_hz: b.mod_hz,
                    ..BeaconLock::default()
                })
                .collect(),
            ..DemodStatus::default()
        });
        s.frames = self.frames;
        s.refused = self.refused;
        s.clipped_total = self.clipped_total;
        s.clipped_last = self.clipped_last;
        for (b, slot) in s.beacons.iter_mut().enumerate() {
            let lock = self.demod.lock(b);
            slot.locked = lock.locked;
            slot.detected = lock.detected;
            slot.freq_hz = lock.freq_hz;
            slot.detection = lock.detection;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::samples::BeaconInfo;

    fn sampling(mod_hz: f64, skew: f64) -> Sampling {
        Sampling {
            sample_hz: 2000.0,
            samples_per_frame: 400,
            channel_skew_s: skew,
            beacons: vec![BeaconInfo {
                id: "beacon".into(),
                mod_hz,
            }],
        }
    }

    /// The demodulator a source's sampling asks for is the one a log of
    /// that header gets; what it cannot take (a steady beacon sampled
    /// fast, a frequency off MODEL.md's grid, a skew past the frame) is
    /// refused, as `--check-config` then says at the backend's key.
    #[test]
    fn a_sampling_is_demodulated_as_its_header_would_be() {
        let d = demodulator(&sampling(250.0, 2e-5), 5.0).expect("valid");
        assert_eq!(d.samples_per_channel(), 400);
        assert_eq!(d.config().channel_skew_s, 2e-5);
        let mut h = LogHeader::new(10, 5.0);
        header_fields(&mut h, &sampling(250.0, 2e-5));
        assert_eq!(h.samples_per_frame(), 400);
        assert_eq!(h.beacons[0].mod_hz, 250.0);
        for (mod_hz, skew) in [(0.0, 0.0), (300.0, 0.0), (250.0, 0.01)] {
            assert!(
                demodulator(&sampling(mod_hz, skew), 5.0).is_err(),
                "{mod_hz} Hz, skew {skew} s"
            );
        }
        // The frame rate differs from the sampling's: N = 1.
        assert!(demodulator(&sampling(250.0, 0.0), 2000.0).is_err());
    }

    /// A burst is demodulated into a frame with the beacon's amplitudes;
    /// one with a count above full scale is the source's bad data, counted.
    #[test]
    fn bursts_become_frames_with_amplitudes_and_bad_ones_are_counted() {
        let mut d = Demod::new(demodulator(&sampling(250.0, 0.0), 5.0).expect("valid"));
        d.burst.adc_bits = 10;
        for k in 0..lightpose_core::NDET {
            for (i, c) in d.burst.channel_mut(k).iter_mut().enumerate() {
                // 250 Hz at 2 kHz: on for 4 samples, off for 4.
                *c = if (i / 4) % 2 == 0 { 300 } else { 100 };
            }
        }
        let f = d.frame().expect("a frame");
        let a = f.amplitudes.expect("amplitudes");
        assert_eq!(a.n_beacons, 1);
        assert!(
            (a.beacons[0].amplitude[0] - 200.0).abs() < 1.0,
            "{}",
            a.beacons[0].amplitude[0]
        );
        assert!(d.last_burst().is_some());
        d.burst.channel_mut(3)[5] = 1024;
        assert!(matches!(d.frame(), Err(SourceError::BadData { .. })));
        let mut s = None;
        d.report(&mut s);
        let s = s.expect("a report");
        assert_eq!((s.frames, s.refused), (1, 1));
        assert_eq!(s.beacons[0].id, "beacon");
        assert!(s.beacons[0].locked, "{s:?}");
    }
}
