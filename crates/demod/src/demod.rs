//! The per-frame work: a frame's samples into FORMATS.md's demodulated
//! frame. docs/demodulator.md gives the method and its measured figures.

// Channels, beacons and matrix rows are indices into several arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::basis::{degree_for, Basis};
use crate::config::{ValidConfig, MAX_BEACONS};
use crate::track::{wrap, Track};
use lightpose_core::samples::{Burst, Demodulated};
use lightpose_core::NDET;

/// Variance floor of one sample, counts²: the ADC's own rounding (1/12 of
/// a count²) is there whatever the light, so no channel's noise is less.
const QUANT_VAR: f64 = 1.0 / 12.0;

/// Cells of the phase search narrower than this (cycles) are rounding's,
/// not the samples': they are skipped.
const MIN_CELL: f64 = 1e-9;

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
    tracks: Vec<Track>,
    locks: Vec<Lock>,
    /// The samples less their slow part, channel-major, NDET × N.
    xs: Vec<f64>,
    /// Each channel's mean and Σ x⊥².
    mean: [f64; NDET],
    energy: [f64; NDET],
    /// Each channel's noise variance in the last frame (None: no frame yet).
    noise: [Option<f64>; NDET],
    /// The templates of one channel, MAX_BEACONS × N, ±1/2.
    u: Vec<f64>,
    coef: Vec<f64>,
    events: Vec<(f64, u32)>,
    /// The slow polynomials by sample, N × D (the search flips one sample
    /// at a time), and each channel's Lᵀu in the search, NDET × D.
    cols: Vec<f64>,
    lu: Vec<f64>,
    /// Sample times from the frame's first: i / sample_hz.
    dt: Vec<f64>,
    frame_phase: [f64; MAX_BEACONS],
    frame_freq: [f64; MAX_BEACONS],
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
        let mut cols = vec![0.0; n * d];
        for j in 0..d {
            for (i, v) in basis.row(j).iter().enumerate() {
                cols[i * d + j] = *v;
            }
        }
        Demodulator {
            cols,
            lu: vec![0.0; NDET * d],
            basis,
            tracks,
            locks,
            xs: vec![0.0; NDET * n],
            mean: [0.0; NDET],
            energy: [0.0; NDET],
            noise: [None; NDET],
            u: vec![0.0; MAX_BEACONS * n],
            coef: vec![0.0; d],
            // At most two crossings of a half cycle per sample in a search
            // window of at most one cycle.
            events: Vec::with_capacity(2 * NDET * n),
            dt: (0..n).map(|i| i as f64 / cfg.sample_hz).collect(),
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
        assert_eq!(
            out.light.n_beacons,
            self.cfg.beacons.len(),
            "out from Demodulator::output"
        );

        // Clipped counts, and each channel less its slow part.
        let sqrt_n = (n as f64).sqrt();
        for k in 0..NDET {
            let raw = &samples[k * n..(k + 1) * n];
            out.light.clipped[k] = raw.iter().filter(|&&v| v == 0 || v == full).count() as u32;
            let x = &mut self.xs[k * n..(k + 1) * n];
            x.iter_mut().zip(raw).for_each(|(x, &v)| *x = f64::from(v));
            self.basis.remove(x, &mut self.coef);
            self.mean[k] = self.coef[0] / sqrt_n;
            self.energy[k] = x.iter().map(|v| v * v).sum();
        }
        // The phase search's weights: 1/σ², none for a clipped channel, so
        // that it spoils no other channel's amplitude through the phase.
        let mut w = [0.0; NDET];
        for k in 0..NDET {
            if out.light.clipped[k] == 0 {
                let var = self.noise[k].unwrap_or(self.energy[k] / n as f64);
                w[k] = 1.0 / var.max(QUANT_VAR);
            }
        }
        let used = w.iter().filter(|&&v| v > 0.0).count();

        for b in 0..self.cfg.beacons.len() {
            let m = self.cfg.beacons[b].half_period;
            let pred = self.tracks[b].predict(t);
            let locked = self.tracks[b].locked();
            let half = if locked {
                (6.0 * pred.var.sqrt() + 1.0 / (2 * m) as f64).min(0.5)
            } else {
                0.5
            };
            let var_prior = if locked && half < 0.5 {
                pred.var
            } else {
                f64::INFINITY
            };
            // The frequency too: an edge that crosses a sample instant in
            // the middle of a frame (every 1/(sample_hz·δ) s) is placed
            // only by a frequency off nominal in the right direction.
            let sf = self.tracks[b].freq_std().max(1e-12);
            let mut best = Cell::default();
            let mut freq = pred.freq;
            if used > 0 {
                best.ll = f64::NEG_INFINITY;
                for step in FREQ_STEPS {
                    let f = pred.freq + step * sf;
                    let mut cell = self.search(&w, f, pred.phase, half, var_prior);
                    cell.ll -= 0.5 * step * step;
                    if cell.ll > best.ll {
                        best = cell;
                        freq = f;
                    }
                }
            }
            let detected = used > 0 && best.score > detection_threshold(used);
            let phase = if detected {
                let cell = best.hi - best.lo;
                let phase = (pred.phase + 0.5 * (best.lo + best.hi)).rem_euclid(1.0);
                let var = cell * cell / 12.0
                    + 1.0 / (4.0 * std::f64::consts::PI.powi(2) * best.score.max(1.0));
                self.tracks[b].update(phase, var);
                phase
            } else {
                pred.phase
            };
            self.frame_phase[b] = phase;
            self.frame_freq[b] = if detected { freq } else { pred.freq };
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

        self.fit(out, full);
        Ok(())
    }

    /// The phase offset Δ in [−half, half] from `center` that best explains
    /// every unclipped channel at once: each channel's amplitude is free but
    /// not negative, so the likelihood gained is Σ_k w_k·max(c_k, 0)²/(2n)
    /// with c_k = u_k(Δ)·x⊥_k, less the prediction's (Δ²/2var). The
    /// templates u_k(Δ) change only where a sample crosses an edge of the
    /// wave: the search walks those crossings in order, one sample's change
    /// at a time, so no phase is missed however narrow its cell.
    fn search(&mut self, w: &[f64; NDET], freq: f64, center: f64, half: f64, var: f64) -> Cell {
        let n = self.cfg.n;
        let d = self.basis.len();
        let mut c = [0.0; NDET];
        let mut events = std::mem::take(&mut self.events);
        events.clear();
        for (k, ck) in c.iter_mut().enumerate() {
            if w[k] == 0.0 {
                continue;
            }
            let lu = &mut self.lu[k * d..(k + 1) * d];
            lu.iter_mut().for_each(|v| *v = 0.0);
            let x = &self.xs[k * n..(k + 1) * n];
            for (i, &xi) in x.iter().enumerate() {
                let p = center + freq * (self.dt[i] + k as f64 * self.cfg.channel_skew_s);
                let mut h = (2.0 * (p - half)).floor();
                let col = &self.cols[i * d..(i + 1) * d];
                let u = if (h as i64) & 1 == 0 {
                    *ck += xi;
                    0.5
                } else {
                    -0.5
                };
                lu.iter_mut().zip(col).for_each(|(a, b)| *a += u * b);
                for _ in 0..2 {
                    let dd = 0.5 * (h + 1.0) - p;
                    if dd > half {
                        break;
                    }
                    h += 1.0;
                    let on = (h as i64) & 1 == 0;
                    events.push((dd, (((k * n + i) as u32) << 1) | on as u32));
                }
            }
        }
        events.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        // The likelihood gained by channel k: its amplitude's fit,
        // c²/|u⊥|², |u⊥|² = N/4 − |Lᵀu|² (exact: with the norm taken as
        // N/4 a pattern that spoils the frame's ends would score higher).
        let quarter = n as f64 / 4.0;
        let mut norm = [quarter; NDET];
        for k in 0..NDET {
            if w[k] > 0.0 {
                let lu = &self.lu[k * d..(k + 1) * d];
                norm[k] = quarter - lu.iter().map(|v| v * v).sum::<f64>();
            }
        }
        let term = |k: usize, c: f64, norm: f64| {
            if norm > 0.0 {
                w[k] * c.max(0.0).powi(2) / norm
            } else {
                0.0
            }
        };
        let mut sum: f64 = (0..NDET).map(|k| term(k, c[k], norm[k])).sum();
        let score_at = |lo: f64, hi: f64, sum: f64| {
            let d = 0.0f64.clamp(lo, hi);
            let prior = if var.is_finite() {
                d * d / (2.0 * var)
            } else {
                0.0
            };
            0.5 * sum - prior
        };
        let mut best = Cell {
            lo: -half,
            hi: half,
            score: 0.0,
            ll: f64::NEG_INFINITY,
        };
        let mut lo = -half;
        for &(at, code) in events.iter().chain(std::iter::once(&(half, u32::MAX))) {
            if at - lo > MIN_CELL {
                let ll = score_at(lo, at, sum);
                if ll > best.ll {
                    best = Cell {
                        lo,
                        hi: at,
                        score: sum,
                        ll,
                    };
                }
                lo = at;
            }
            if code == u32::MAX {
                break;
            }
            let idx = (code >> 1) as usize;
            let (k, i) = (idx / n, idx % n);
            let before = term(k, c[k], norm[k]);
            let sign = if code & 1 == 1 { 1.0 } else { -1.0 };
            c[k] += sign * self.xs[idx];
            let lu = &mut self.lu[k * d..(k + 1) * d];
            let col = &self.cols[i * d..(i + 1) * d];
            let mut sq = 0.0;
            for (a, b) in lu.iter_mut().zip(col) {
                *a += sign * b;
                sq += *a * *a;
            }
            norm[k] = quarter - sq;
            sum += term(k, c[k], norm[k]) - before;
        }
        self.events = events;
        best
    }

    /// Per channel, the least-squares fit of the slow polynomials and every
    /// beacon's square wave at the phase found: the amplitudes, their σ from
    /// what the fit leaves, and the level with every beacon off.
    fn fit(&mut self, out: &mut Demodulated, full: u16) {
        let nb = self.cfg.beacons.len();
        let dof = (self.cfg.n - self.basis.len() - nb) as f64;
        let (phases, freqs) = (self.frame_phase, self.frame_freq);
        let mut first = [0.0; NDET];
        for (k, v) in first.iter_mut().enumerate() {
            *v = self.fit_channel(k, &phases, &freqs, out, full);
        }
        // Without a last frame, the channels' median: one board's noise.
        let mut sorted = first;
        sorted.sort_unstable_by(f64::total_cmp);
        let median = sorted[NDET / 2];
        for k in 0..NDET {
            let mut noise = first[k];
            // Six σ of the residual variance's own spread over the last
            // frame's.
            let prev = self.noise[k].unwrap_or(median);
            if out.light.clipped[k] == 0
                && noise > prev * (1.0 + 6.0 * (2.0 / dof).sqrt()) + QUANT_VAR
            {
                // The common phase leaves far more than this channel's noise:
                // an edge crossed one of its sample instants within the
                // frame where the common phase and frequency do not put it
                // (the channels' skew spreads the crossings over frames, and
                // their places depend on a drift not learnt yet). The
                // channel's own best phase within a sample of the common one,
                // kept only when it fits better.
                let (mut ph, mut fr) = (phases, freqs);
                let mut w = [0.0; NDET];
                w[k] = 1.0;
                for b in 0..nb {
                    let m = self.cfg.beacons[b].half_period;
                    let wide = self.cfg.max_drift * self.cfg.beacons[b].mod_hz;
                    let sf = self.tracks[b].freq_std().max(1e-12);
                    let mut best = (f64::NEG_INFINITY, phases[b], freqs[b]);
                    for f in [0.0, -1.5 * sf, 1.5 * sf, -wide, wide] {
                        let f = freqs[b] + f;
                        let cell =
                            self.search(&w, f, phases[b], 1.0 / (2 * m) as f64, f64::INFINITY);
                        if cell.ll > best.0 {
                            best = (cell.ll, phases[b] + 0.5 * (cell.lo + cell.hi), f);
                        }
                    }
                    ph[b] = best.1.rem_euclid(1.0);
                    fr[b] = best.2;
                }
                let mut kept = ([0.0; MAX_BEACONS], [0.0; MAX_BEACONS], out.light.ambient[k]);
                let nb = out.light.n_beacons;
                for (b, bo) in out.light.beacons[..nb].iter().enumerate() {
                    kept.0[b] = bo.amplitude[k];
                    kept.1[b] = bo.std[k];
                }
                let again = self.fit_channel(k, &ph, &fr, out, full);
                if again < noise {
                    noise = again;
                } else {
                    for (b, bo) in out.light.beacons[..nb].iter_mut().enumerate() {
                        bo.amplitude[k] = kept.0[b];
                        bo.std[k] = kept.1[b];
                    }
                    out.light.ambient[k] = kept.2;
                }
            }
            self.noise[k] = Some(noise);
        }
    }

    /// Channel k's fit at the beacons' phases and frequencies given; its
    /// noise variance.
    fn fit_channel(
        &mut self,
        k: usize,
        phases: &[f64; MAX_BEACONS],
        freqs: &[f64; MAX_BEACONS],
        out: &mut Demodulated,
        full: u16,
    ) -> f64 {
        let n = self.cfg.n;
        let nb = self.cfg.beacons.len();
        let d = self.basis.len();
        let dof = (n - d - nb) as f64;
        {
            let mut rhs = [0.0; MAX_BEACONS];
            let mut mean_u = [0.0; MAX_BEACONS];
            let mut g = [[0.0; MAX_BEACONS]; MAX_BEACONS];
            let x = &self.xs[k * n..(k + 1) * n];
            for b in 0..nb {
                let (phase, freq) = (phases[b], freqs[b]);
                let skew = k as f64 * self.cfg.channel_skew_s;
                let u = &mut self.u[b * n..(b + 1) * n];
                for (i, ui) in u.iter_mut().enumerate() {
                    let p = phase + freq * (self.dt[i] + skew);
                    *ui = if ((2.0 * p).floor() as i64) & 1 == 0 {
                        0.5
                    } else {
                        -0.5
                    };
                }
                rhs[b] = u.iter().zip(x).map(|(a, c)| a * c).sum();
                mean_u[b] = u.iter().sum::<f64>() / n as f64;
            }
            // G = UᵀU − (LᵀU)ᵀ(LᵀU): the templates' Gram matrix once the
            // slow part is out.
            for b in 0..nb {
                let ub = &self.u[b * n..(b + 1) * n];
                for c in 0..=b {
                    let uc = &self.u[c * n..(c + 1) * n];
                    g[b][c] = ub.iter().zip(uc).map(|(a, c)| a * c).sum();
                }
            }
            for j in 0..d {
                let p = self.basis.row(j);
                let mut lu = [0.0; MAX_BEACONS];
                for (b, l) in lu.iter_mut().enumerate().take(nb) {
                    *l = p
                        .iter()
                        .zip(&self.u[b * n..(b + 1) * n])
                        .map(|(a, c)| a * c)
                        .sum();
                }
                for b in 0..nb {
                    for c in 0..=b {
                        g[b][c] -= lu[b] * lu[c];
                    }
                }
            }
            let solved = Cholesky::new(&g, nb);
            let noise;
            match solved {
                Some(ch) => {
                    let a = ch.solve(&rhs, nb);
                    let fitted: f64 = (0..nb).map(|b| a[b] * rhs[b]).sum();
                    noise = ((self.energy[k] - fitted) / dof).max(QUANT_VAR);
                    let mut off = self.mean[k];
                    for b in 0..nb {
                        let mut std = (noise * ch.inverse_diag(b, nb)).sqrt();
                        if out.light.clipped[k] > 0 {
                            std = std.max(f64::from(full));
                        }
                        out.light.beacons[b].amplitude[k] = a[b];
                        out.light.beacons[b].std[k] = std;
                        off -= a[b] * (mean_u[b] + 0.5);
                    }
                    out.light.ambient[k] = off;
                }
                None => {
                    // Not reached with whole periods (G ≈ N/4 · I); kept so
                    // that no frame can panic here.
                    noise = (self.energy[k] / dof).max(QUANT_VAR);
                    let nb = out.light.n_beacons;
                    for bo in out.light.beacons[..nb].iter_mut() {
                        bo.amplitude[k] = 0.0;
                        bo.std[k] = f64::from(full);
                    }
                    out.light.ambient[k] = self.mean[k];
                }
            }
            noise
        }
    }
}

/// The search's best phase cell, offsets from its centre, and its score.
#[derive(Debug, Clone, Copy)]
struct Cell {
    lo: f64,
    hi: f64,
    /// Σ_k w_k max(c_k, 0)² / n there.
    score: f64,
    /// The log-likelihood gained, less the priors'.
    ll: f64,
}

impl Default for Cell {
    fn default() -> Self {
        Cell {
            lo: -0.5,
            hi: 0.5,
            score: 0.0,
            ll: 0.0,
        }
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

/// Cholesky factor of a small symmetric positive definite matrix (the
/// lower triangle of `g` is read).
struct Cholesky {
    l: [[f64; MAX_BEACONS]; MAX_BEACONS],
}

impl Cholesky {
    fn new(g: &[[f64; MAX_BEACONS]; MAX_BEACONS], nb: usize) -> Option<Self> {
        let mut l = [[0.0; MAX_BEACONS]; MAX_BEACONS];
        for i in 0..nb {
            for j in 0..=i {
                let mut s = g[i][j];
                for q in 0..j {
                    s -= l[i][q] * l[j][q];
                }
                if i == j {
                    if !s.is_finite() || s <= 0.0 {
                        return None;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        Some(Cholesky { l })
    }

    fn solve(&self, b: &[f64; MAX_BEACONS], nb: usize) -> [f64; MAX_BEACONS] {
        let l = &self.l;
        let mut y = [0.0; MAX_BEACONS];
        for i in 0..nb {
            let mut s = b[i];
            for q in 0..i {
                s -= l[i][q] * y[q];
            }
            y[i] = s / l[i][i];
        }
        let mut x = [0.0; MAX_BEACONS];
        for i in (0..nb).rev() {
            let mut s = y[i];
            for q in i + 1..nb {
                s -= l[q][i] * x[q];
            }
            x[i] = s / l[i][i];
        }
        x
    }

    /// (G⁻¹)_bb.
    fn inverse_diag(&self, b: usize, nb: usize) -> f64 {
        let mut e = [0.0; MAX_BEACONS];
        e[b] = 1.0;
        self.solve(&e, nb)[b]
    }
}
