//! The per-frame work: a frame's samples into FORMATS.md's demodulated
//! frame. docs/demodulator.md gives the method and its measured figures.

// Channels, beacons and matrix rows are indices into several arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::basis::{degree_for, Basis};
use crate::config::{ValidConfig, MAX_BEACONS};
use crate::posterior::SpreadSum;
use crate::runs::{on_runs, turns};
use crate::scan::{Cell, Scan, Signal, Window};
use crate::track::{wrap, Track};
use lightpose_core::samples::{Burst, Demodulated};
use lightpose_core::NDET;

mod amplitudes;

/// Variance floor of one sample, counts²: the ADC's own rounding (1/12 of
/// a count²) is there whatever the light, so no channel's noise is less.
const QUANT_VAR: f64 = 1.0 / 12.0;

/// What the demodulator knows of a beacon's clock after a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lock {
    /// The beacon was found in the frame (its light stood out of the noise).
    pub detected: bool,
    /// The phase is being tracked (found in this frame or one before).
    pub locked: bool,
    /// Phase at the frame's first sample, cycles in [0, 1): on where
    /// frac(phase + freq·(τ − t)) < 1/2.
    pub phase: f64,
    pub freq_hz: f64,
    pub phase_std: f64,
    pub freq_std_hz: f64,
    /// The matched filter's Σ_k c_k² / (σ_k² n) at the phase chosen: the
    /// frame's signal-to-noise ratio for the beacon (≈ 12.5 without it).
    pub detection: f64,
}

/// A frame the demodulator cannot take, naming what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("frame has {got} samples: want {expected} (25 channels × {n})")]
    Length {
        expected: usize,
        got: usize,
        n: usize,
    },
    #[error("adc_bits = {bits}: must be 1..=16")]
    Bits { bits: u8 },
    #[error("channel {channel} sample {sample}: count {value} above full scale {max}")]
    Count {
        channel: usize,
        sample: usize,
        value: u16,
        max: u16,
    },
    #[error("frame time t = {t}: not a finite number")]
    Time { t: f64 },
}

/// Turns each frame's samples into a [`Demodulated`]; made once, with
/// every buffer it needs, so that a frame allocates nothing.
#[derive(Debug, Clone)]
pub struct Demodulator {
    cfg: ValidConfig,
    basis: Basis,
    scan: Scan,
    tracks: Vec<Track>,
    locks: Vec<Lock>,
    /// The samples less their slow part, channel-major, NDET × N, and
    /// their prefix sums, NDET × (N + 1).
    xs: Vec<f64>,
    xs_sum: Vec<f64>,
    /// One channel's samples less the other beacons' fitted light (the
    /// search of one beacon of several), its prefix sums, and the slow part
    /// of that light (Σ_c a_c Lᵀu_c), NDET × D.
    ys: Vec<f64>,
    ys_sum: Vec<f64>,
    corr: Vec<f64>,
    /// Each channel's mean and Σ x⊥².
    mean: [f64; NDET],
    energy: [f64; NDET],
    /// Each channel's noise variance in the last frame (None: no frame yet).
    noise: [Option<f64>; NDET],
    coef: Vec<f64>,
    /// Lᵀu of each beacon's template in each channel at the last fit,
    /// NDET × MAX_BEACONS × D.
    fit_lu: Vec<f64>,
    /// Each beacon's turns in the channel being fitted.
    turns: Vec<Vec<u32>>,
    choices: [Choice; MAX_BEACONS],
    frame_phase: [f64; MAX_BEACONS],
    frame_freq: [f64; MAX_BEACONS],
}

/// A beacon's search in a frame: where it looked and what it found.
#[derive(Debug, Clone, Copy, Default)]
struct Choice {
    pred_phase: f64,
    pred_freq: f64,
    /// The window's half-width, and the prior's variance in it.
    half: f64,
    var_prior: f64,
    cell: Cell,
    freq: f64,
}

impl Choice {
    /// The phase at the frame's first sample: the best cell's centre.
    fn phase(&self) -> f64 {
        (self.pred_phase + 0.5 * (self.cell.lo + self.cell.hi)).rem_euclid(1.0)
    }
}

impl Demodulator {
    pub fn new(cfg: ValidConfig) -> Self {
        let n = cfg.n;
        let degree = degree_for(cfg.flicker_max_hz, n as f64 / cfg.sample_hz)
            .min(n.saturating_sub(cfg.beacons.len() + 2).max(1) - 1);
        let basis = Basis::new(n, degree);
        let tracks = cfg
            .beacons
            .iter()
            .map(|b| Track::new(b.mod_hz, cfg.max_drift))
            .collect();
        let locks = cfg
            .beacons
            .iter()
            .map(|b| Lock {
                detected: false,
                locked: false,
                phase: 0.0,
                freq_hz: b.mod_hz,
                phase_std: f64::INFINITY,
                freq_std_hz: b.mod_hz * cfg.max_drift,
                detection: 0.0,
            })
            .collect();
        let d = basis.len();
        Demodulator {
            scan: Scan::new(&basis, n),
            basis,
            tracks,
            locks,
            xs: vec![0.0; NDET * n],
            xs_sum: vec![0.0; NDET * (n + 1)],
            ys: vec![0.0; NDET * n],
            ys_sum: vec![0.0; NDET * (n + 1)],
            corr: vec![0.0; NDET * d],
            mean: [0.0; NDET],
            energy: [0.0; NDET],
            noise: [None; NDET],
            coef: vec![0.0; d],
            fit_lu: vec![0.0; NDET * MAX_BEACONS * d],
            turns: (0..MAX_BEACONS)
                .map(|_| Vec::with_capacity(n + 2))
                .collect(),
            choices: [Choice::default(); MAX_BEACONS],
            frame_phase: [0.0; MAX_BEACONS],
            frame_freq: [0.0; MAX_BEACONS],
            cfg,
        }
    }

    pub fn config(&self) -> &ValidConfig {
        &self.cfg
    }

    /// N: the samples per channel a frame must have.
    pub fn samples_per_channel(&self) -> usize {
        self.cfg.n
    }

    /// The number of slow polynomials removed (degree + 1).
    pub fn slow_terms(&self) -> usize {
        self.basis.len()
    }

    /// A demodulated frame (lightpose-core's, the one every log reader and
    /// writer takes) with one entry per beacon, in the configuration's
    /// order (`beacon` its index there, as in a log header's `beacons`),
    /// for [`Demodulator::demodulate`] to fill.
    pub fn output(&self) -> Demodulated {
        let mut out = Demodulated::default();
        out.light.n_beacons = self.cfg.beacons.len();
        for (b, slot) in out.light.beacons[..out.light.n_beacons]
            .iter_mut()
            .enumerate()
        {
            slot.beacon = b as u8;
        }
        out
    }

    /// Demodulates a BURST (lightpose-core's) into `out`, with the frame's
    /// own fields: its seq, its time (the middle of its samples, MODEL.md),
    /// its ADC and the readings it carries. `sample_hz` is the
    /// configuration's.
    pub fn demodulate_burst(
        &mut self,
        burst: &Burst,
        out: &mut Demodulated,
    ) -> Result<(), FrameError> {
        self.demodulate(burst.samples(), burst.t, burst.adc_bits, out)?;
        out.frame_of(burst, self.cfg.sample_hz);
        Ok(())
    }

    /// Beacon `b`'s clock after the last frame.
    pub fn lock(&self, b: usize) -> Lock {
        self.locks[b]
    }

    /// Forget every beacon's phase and the channels' noise (a new log, a
    /// source reopened).
    pub fn reset(&mut self) {
        self.tracks.iter_mut().for_each(Track::reset);
        self.noise = [None; NDET];
    }

    /// Demodulates one frame: `samples` channel-major (channel k's N
    /// samples at `k·N..(k+1)·N`, index k as in a frame), `t` the time of
    /// its first sample (channel 0's), `adc_bits` its ADC's resolution.
    /// `out` must come from [`Demodulator::output`]. On an error nothing of
    /// `out` or of the tracks has changed.
    pub fn demodulate(
        &mut self,
        samples: &[u16],
        t: f64,
        adc_bits: u8,
        out: &mut Demodulated,
    ) -> Result<(), FrameError> {
        let full = self.check(samples, t, adc_bits)?;
        assert_eq!(
            out.light.n_beacons,
            self.cfg.beacons.len(),
            "out from Demodulator::output"
        );
        self.slow_part_out(samples, full, out);
        let w = self.weights(out);
        let used = w.iter().filter(|&&v| v > 0.0).count();
        let nb = self.cfg.beacons.len();
        for b in 0..nb {
            self.predict(b, t);
            if used > 0 {
                self.search_beacon(b, &w, false);
            }
        }
        if nb > 1 && used > 0 {
            self.search_on_residuals(&w, used, out, full);
        }
        for b in 0..nb {
            self.commit(b, used);
        }
        self.fit(out, full);
        Ok(())
    }

    /// The frame's own checks; its ADC's full scale.
    fn check(&self, samples: &[u16], t: f64, adc_bits: u8) -> Result<u16, FrameError> {
        let n = self.cfg.n;
        if samples.len() != NDET * n {
            return Err(FrameError::Length {
                expected: NDET * n,
                got: samples.len(),
                n,
            });
        }
        if !(1..=16).contains(&adc_bits) {
            return Err(FrameError::Bits { bits: adc_bits });
        }
        if !t.is_finite() {
            return Err(FrameError::Time { t });
        }
        let full = ((1u32 << adc_bits) - 1) as u16;
        if let Some(at) = samples.iter().position(|&v| v > full) {
            return Err(FrameError::Count {
                channel: at / n,
                sample: at % n,
                value: samples[at],
                max: full,
            });
        }
        Ok(full)
    }

    /// Step 1: clipped counts, and each channel less its slow part (with
    /// its mean, its energy and its prefix sums).
    fn slow_part_out(&mut self, samples: &[u16], full: u16, out: &mut Demodulated) {
        let n = self.cfg.n;
        let sqrt_n = (n as f64).sqrt();
        for k in 0..NDET {
            let raw = &samples[k * n..(k + 1) * n];
            out.light.clipped[k] = raw.iter().filter(|&&v| v == 0 || v == full).count() as u32;
            let x = &mut self.xs[k * n..(k + 1) * n];
            x.iter_mut().zip(raw).for_each(|(x, &v)| *x = f64::from(v));
            self.basis.remove(x, &mut self.coef);
            self.mean[k] = self.coef[0] / sqrt_n;
            self.energy[k] = x.iter().map(|v| v * v).sum();
            prefix(x, &mut self.xs_sum[k * (n + 1)..(k + 1) * (n + 1)]);
        }
    }

    /// The phase search's weights: 1/σ², none for a clipped channel, so
    /// that it spoils no other channel's amplitude through the phase.
    fn weights(&self, out: &Demodulated) -> [f64; NDET] {
        let mut w = [0.0; NDET];
        for k in 0..NDET {
            if out.light.clipped[k] == 0 {
                let var = self.noise[k].unwrap_or(self.energy[k] / self.cfg.n as f64);
                w[k] = 1.0 / var.max(QUANT_VAR);
            }
        }
        w
    }

    /// Beacon b's prediction at the frame and the window searched about it
    /// (±6σ and a sample; the whole cycle before a lock).
    fn predict(&mut self, b: usize, t: f64) {
        let m = self.cfg.beacons[b].half_period;
        let pred = self.tracks[b].predict(t);
        let locked = self.tracks[b].locked();
        let half = if locked {
            (6.0 * pred.var.sqrt() + 1.0 / (2 * m) as f64).min(0.5)
        } else {
            0.5
        };
        self.choices[b] = Choice {
            pred_phase: pred.phase,
            pred_freq: pred.freq,
            half,
            var_prior: if locked && half < 0.5 {
                pred.var
            } else {
                f64::INFINITY
            },
            cell: Cell::default(),
            freq: pred.freq,
        };
    }

    /// Step 2: beacon b's best cell over the frequencies tried (the
    /// track's, ±1.5σ: an edge that crosses a sample instant in the middle
    /// of a frame, every 1/(sample_hz·δ) s, is placed only by a frequency
    /// off nominal in the right direction), on the samples (`residual`
    /// false) or on what the other beacons' fit leaves (`ys`, true).
    fn search_beacon(&mut self, b: usize, w: &[f64; NDET], residual: bool) {
        let ch = self.choices[b];
        let sf = self.tracks[b].freq_std().max(1e-12);
        let sig = if residual {
            Signal {
                x: &self.ys,
                sums: &self.ys_sum,
                corr: Some(&self.corr),
            }
        } else {
            Signal {
                x: &self.xs,
                sums: &self.xs_sum,
                corr: None,
            }
        };
        let mut best = (
            Cell {
                ll: f64::NEG_INFINITY,
                ..Cell::default()
            },
            ch.pred_freq,
        );
        // The phase's spread over the cells at every frequency tried: a
        // frequency off by 1.5σ moves the best cell by the edges it
        // places differently, and the track should know that it might.
        let mut spread = SpreadSum::new();
        for step in FREQ_STEPS {
            let freq = ch.pred_freq + step * sf;
            let win = Window {
                freq,
                center: ch.pred_phase,
                half: ch.half,
                var: ch.var_prior,
                sample_hz: self.cfg.sample_hz,
                skew_s: self.cfg.channel_skew_s,
            };
            let mut cell = self.scan.search(&sig, w, &win);
            cell.ll -= 0.5 * step * step;
            self.scan.spread_into(&mut spread, -0.5 * step * step);
            if cell.ll > best.0.ll {
                best = (cell, freq);
            }
        }
        best.0.spread = spread.finish();
        self.choices[b].cell = best.0;
        self.choices[b].freq = best.1;
    }

    /// Several beacons: each searched again on the samples less the
    /// others' light as the first searches and a joint fit give it, so that
    /// no beacon's light (nor its share in the slow polynomials, which the
    /// templates do not cancel) moves another's cell.
    fn search_on_residuals(
        &mut self,
        w: &[f64; NDET],
        used: usize,
        out: &mut Demodulated,
        full: u16,
    ) {
        let nb = self.cfg.beacons.len();
        let threshold = detection_threshold(used);
        let (mut phases, mut freqs) = ([0.0; MAX_BEACONS], [0.0; MAX_BEACONS]);
        for b in 0..nb {
            let ch = &self.choices[b];
            let found = ch.cell.score > threshold;
            phases[b] = if found { ch.phase() } else { ch.pred_phase };
            freqs[b] = if found { ch.freq } else { ch.pred_freq };
        }
        for k in 0..NDET {
            self.fit_channel(k, &phases, &freqs, out, full);
        }
        for b in 0..nb {
            for k in 0..NDET {
                if w[k] > 0.0 {
                    self.residual(k, b, &phases, &freqs, out);
                }
            }
            self.search_beacon(b, w, true);
        }
    }

    /// Channel k's samples (slow part out) less every beacon's fitted light
    /// but b's, into `ys`, with its prefix sums and `corr` (the slow part
    /// of the light taken out, which x⊥ does not hold: added back in the
    /// search through Lᵀu).
    fn residual(
        &mut self,
        k: usize,
        b: usize,
        phases: &[f64; MAX_BEACONS],
        freqs: &[f64; MAX_BEACONS],
        out: &Demodulated,
    ) {
        let n = self.cfg.n;
        let d = self.basis.len();
        let y = &mut self.ys[k * n..(k + 1) * n];
        y.copy_from_slice(&self.xs[k * n..(k + 1) * n]);
        let corr = &mut self.corr[k * d..(k + 1) * d];
        corr.iter_mut().for_each(|v| *v = 0.0);
        for c in 0..self.cfg.beacons.len() {
            let a = out.light.beacons[c].amplitude[k];
            if c == b || a == 0.0 {
                continue;
            }
            let p0 = phases[c] + freqs[c] * k as f64 * self.cfg.channel_skew_s;
            let turns_c = &mut self.turns[c];
            let first_on = turns(p0, freqs[c] / self.cfg.sample_hz, n, turns_c);
            // u = on − 1/2: y −= a·u.
            y.iter_mut().for_each(|v| *v += 0.5 * a);
            for (s, e) in on_runs(first_on, turns_c, n) {
                y[s..e].iter_mut().for_each(|v| *v -= a);
            }
            let lu = &self.fit_lu[(k * MAX_BEACONS + c) * d..(k * MAX_BEACONS + c + 1) * d];
            corr.iter_mut().zip(lu).for_each(|(v, l)| *v += a * l);
        }
        prefix(y, &mut self.ys_sum[k * (n + 1)..(k + 1) * (n + 1)]);
    }

    /// Steps 3 and 4: beacon b detected or not, its track updated, its
    /// lock and the phase and frequency its fit uses.
    fn commit(&mut self, b: usize, used: usize) {
        let ch = self.choices[b];
        let best = if used > 0 { ch.cell } else { Cell::default() };
        let detected = used > 0 && best.score > detection_threshold(used);
        let phase = if detected {
            // The track takes the likelihood's mean and spread over the
            // window's cells (`posterior.rs`); the fit, the best cell's
            // template (the prior's pick).
            let s = best.spread;
            if s.var.is_finite() {
                self.tracks[b].update(ch.pred_phase + s.mean, s.var);
            }
            ch.phase()
        } else {
            ch.pred_phase
        };
        self.frame_phase[b] = phase;
        self.frame_freq[b] = if detected { ch.freq } else { ch.pred_freq };
        let tr = &self.tracks[b];
        self.locks[b] = Lock {
            detected,
            locked: tr.locked(),
            phase: if tr.locked() {
                wrap(tr.phase()).rem_euclid(1.0)
            } else {
                phase
            },
            freq_hz: tr.freq(),
            phase_std: tr.phase_std(),
            freq_std_hz: tr.freq_std(),
            detection: best.score,
        };
    }
}

/// `sums[i] = Σ_{i' < i} x[i']` (N + 1 values).
fn prefix(x: &[f64], sums: &mut [f64]) {
    let mut s = 0.0;
    sums[0] = 0.0;
    for (v, out) in x.iter().zip(&mut sums[1..]) {
        s += v;
        *out = s;
    }
}

/// The frequencies tried per frame, in σ of the track's frequency about
/// its prediction.
const FREQ_STEPS: [f64; 3] = [0.0, -1.5, 1.5];

/// A beacon is in a frame when its score stands well out of what noise
/// alone gives: each used channel adds max(z, 0)² with z ~ N(0, 1), mean
/// 1/2 and variance 5/4, and the search takes the best of some tens of
/// nearly independent phases; ten σ over the mean, and 10 more.
pub fn detection_threshold(channels: usize) -> f64 {
    let c = channels as f64;
    0.5 * c + 10.0 * (1.25 * c).sqrt() + 10.0
}
