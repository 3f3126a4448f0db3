//! The phase search of one beacon (docs/demodulator.md, step 2): the
//! offset from a predicted phase that best explains every channel at once.
//! Its own module because it is the demodulator's inner loop: what depends
//! only on the configuration (the slow polynomials by sample and their
//! prefix sums) is made once here, and a search costs O(turns · D) to start
//! and O(D) per sample crossing an edge in the window.

// Channels and samples index several arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::basis::Basis;
use crate::posterior::{Spread, SpreadSum};
use crate::runs::{on_runs, turns};
use lightpose_core::NDET;

/// Cells of the phase search narrower than this (cycles) are rounding's,
/// not the samples': they are skipped.
const MIN_CELL: f64 = 1e-9;

/// The search's best phase cell, offsets from its centre, and its score.
#[derive(Debug, Clone, Copy)]
pub struct Cell {
    pub lo: f64,
    pub hi: f64,
    /// Σ_k w_k max(c_k, 0)² / |u⊥_k|² there.
    pub score: f64,
    /// The log-likelihood gained, less the priors'.
    pub ll: f64,
    /// The phase offset's mean and variance under the likelihood alone,
    /// over the window's cells at every frequency tried: what the track
    /// takes (`posterior.rs`; filled by the demodulator's search).
    pub spread: Spread,
}

impl Default for Cell {
    fn default() -> Self {
        Cell {
            lo: -0.5,
            hi: 0.5,
            score: 0.0,
            ll: 0.0,
            spread: Spread::default(),
        }
    }
}

/// What a search reads, per channel (channel-major): the samples with
/// their slow part out (and, searching one beacon of several, the others'
/// fitted light out too), their prefix sums (N + 1 a channel), and for the
/// latter the slow part of the others' light put back: v_k = Σ_c a_c Lᵀu_c
/// (D a channel), so that c_k = u⊥ᵀ(x⊥ − Σ_c a_c u_c⊥) = uᵀy + (Lᵀu)·v_k.
pub struct Signal<'a> {
    pub x: &'a [f64],
    pub sums: &'a [f64],
    pub corr: Option<&'a [f64]>,
}

/// Where a search looks: the beacon's frequency, the phase at the frame's
/// first sample it is centred on, the half-width of the window (cycles),
/// the prediction's variance (infinite: no prior), and the sampling.
#[derive(Debug, Clone, Copy)]
pub struct Window {
    pub freq: f64,
    pub center: f64,
    pub half: f64,
    pub var: f64,
    pub sample_hz: f64,
    pub skew_s: f64,
}

#[derive(Debug, Clone)]
pub struct Scan {
    n: usize,
    d: usize,
    /// The slow polynomials by sample, N × D (an event flips one sample).
    cols: Vec<f64>,
    /// Their prefix sums, (N + 1) × D: row i is Σ_{i' < i} of cols' rows.
    cum: Vec<f64>,
    /// Each channel's Lᵀu during a search, NDET × D.
    lu: Vec<f64>,
    events: Vec<(f64, u32)>,
    /// The events' sort keys (the offset in 2^32 steps of the window, then
    /// the event's index), and the radix sort's other buffer.
    keys: Vec<u64>,
    spare: Vec<u64>,
    turns: Vec<u32>,
    /// The window's cells at the last search: (lo, hi, score).
    cells: Vec<(f64, f64, f64)>,
}

impl Scan {
    pub fn new(basis: &Basis, n: usize) -> Self {
        let d = basis.len();
        let mut cols = vec![0.0; n * d];
        for j in 0..d {
            for (i, v) in basis.row(j).iter().enumerate() {
                cols[i * d + j] = *v;
            }
        }
        let mut cum = vec![0.0; (n + 1) * d];
        for i in 0..n {
            for j in 0..d {
                cum[(i + 1) * d + j] = cum[i * d + j] + cols[i * d + j];
            }
        }
        Scan {
            n,
            d,
            cols,
            cum,
            lu: vec![0.0; NDET * d],
            // At most two crossings of a half cycle per sample in a window
            // of at most one cycle.
            events: Vec::with_capacity(2 * NDET * n),
            keys: Vec::with_capacity(2 * NDET * n),
            spare: Vec::with_capacity(2 * NDET * n),
            turns: Vec::with_capacity(n + 2),
            cells: Vec::with_capacity(2 * NDET * n + 1),
        }
    }

    /// Row i of the polynomials' prefix sums (D values).
    pub fn cum(&self, i: usize) -> &[f64] {
        &self.cum[i * self.d..(i + 1) * self.d]
    }

    /// The phase offset Δ in (−half, half] from `win.center` that best
    /// explains every channel of weight w_k > 0 at once: each channel's
    /// amplitude is free but not negative, so the likelihood gained is
    /// Σ_k w_k·max(c_k, 0)²/(2|u⊥_k|²), less the prediction's Δ²/2var. The
    /// templates change only where a sample crosses an edge of the wave:
    /// the search walks those crossings in order, one sample at a time, so
    /// no phase is missed however narrow its cell.
    pub fn search(&mut self, sig: &Signal<'_>, w: &[f64; NDET], win: &Window) -> Cell {
        let n = self.n;
        let g = win.freq / win.sample_hz;
        let mut state = State {
            c: [0.0; NDET],
            dot: [0.0; NDET],
            norm: [n as f64 / 4.0; NDET],
        };
        self.events.clear();
        for k in 0..NDET {
            if w[k] == 0.0 {
                continue;
            }
            let p0 = win.center + win.freq * k as f64 * win.skew_s;
            self.start(k, sig, p0 - win.half, g, &mut state);
            self.list_events(k, p0, g, win.half);
        }
        self.order(win.half);
        self.walk(sig, w, win, &mut state)
    }

    /// Channel k's template at the window's start: c_k = uᵀx⊥ (with the
    /// correction), Lᵀu and |u⊥|² = N/4 − |Lᵀu|² (exact: with N/4 a pattern
    /// that spoils the frame's ends, where the polynomials are large, would
    /// score higher), from the runs of the wave and prefix sums.
    fn start(&mut self, k: usize, sig: &Signal<'_>, p_start: f64, g: f64, st: &mut State) {
        let (n, d) = (self.n, self.d);
        let first_on = turns(p_start, g, n, &mut self.turns);
        let sums = &sig.sums[k * (n + 1)..(k + 1) * (n + 1)];
        let lu = &mut self.lu[k * d..(k + 1) * d];
        let total = &self.cum[n * d..(n + 1) * d];
        lu.iter_mut().zip(total).for_each(|(l, t)| *l = -0.5 * t);
        let mut raw = 0.0;
        for (a, b) in on_runs(first_on, &self.turns, n) {
            raw += sums[b] - sums[a];
            let (ca, cb) = (&self.cum[a * d..(a + 1) * d], &self.cum[b * d..(b + 1) * d]);
            for j in 0..d {
                lu[j] += cb[j] - ca[j];
            }
        }
        let sq: f64 = lu.iter().map(|v| v * v).sum();
        let dot = match sig.corr {
            Some(v) => lu
                .iter()
                .zip(&v[k * d..(k + 1) * d])
                .map(|(a, b)| a * b)
                .sum(),
            None => 0.0,
        };
        st.c[k] = raw - 0.5 * sums[n] + dot;
        st.dot[k] = dot;
        st.norm[k] = n as f64 / 4.0 - sq;
    }

    /// Channel k's crossings in the window: for each edge (half cycle) b/2
    /// near it, the samples whose phase p_i lies within `half` of it cross
    /// it at Δ = b/2 − p_i, turning on when b is even.
    fn list_events(&mut self, k: usize, p0: f64, g: f64, half: f64) {
        let n = self.n;
        let last = p0 + g * (n - 1) as f64;
        let mut b = (2.0 * (p0 - half)).floor() + 1.0;
        let top = (2.0 * (last + half)).floor();
        while b <= top {
            let edge = 0.5 * b;
            // A sample of margin each side; the test below decides.
            let lo = ((edge - half - p0) / g).floor().max(0.0) as usize;
            let hi = (((edge + half - p0) / g).ceil() + 1.0).clamp(0.0, n as f64) as usize;
            let on = (b as i64) & 1 == 0;
            for i in lo..hi {
                let dd = edge - (p0 + g * i as f64);
                if dd > -half && dd <= half {
                    self.events
                        .push((dd, (((k * n + i) as u32) << 1) | on as u32));
                }
            }
            b += 1.0;
        }
    }

    /// The events in order of their offsets, as `keys` (low 32 bits: the
    /// index into `events`). A radix sort on the offset quantised to 2^-32
    /// of the window (under 2.4e-10 cycles, below the narrowest cell kept,
    /// MIN_CELL): four passes of a byte, O(events), where a comparison sort
    /// of the tens of thousands of events of a whole-cycle window took a
    /// third of a frame's time.
    fn order(&mut self, half: f64) {
        let scale = 4_294_967_295.0 / (2.0 * half).max(f64::MIN_POSITIVE);
        self.keys.clear();
        for (e, &(at, _)) in self.events.iter().enumerate() {
            let q = ((at + half) * scale).clamp(0.0, 4_294_967_295.0) as u64;
            self.keys.push((q << 32) | e as u64);
        }
        self.spare.clear();
        self.spare.resize(self.keys.len(), 0);
        for pass in 0..4 {
            let shift = 32 + 8 * pass;
            let mut count = [0usize; 257];
            for &k in &self.keys {
                count[((k >> shift) & 0xff) as usize + 1] += 1;
            }
            for b in 0..256 {
                count[b + 1] += count[b];
            }
            for &k in &self.keys {
                let b = ((k >> shift) & 0xff) as usize;
                self.spare[count[b]] = k;
                count[b] += 1;
            }
            std::mem::swap(&mut self.keys, &mut self.spare);
        }
    }

    /// Walks the sorted crossings, scoring each cell between them; the best.
    fn walk(&mut self, sig: &Signal<'_>, w: &[f64; NDET], win: &Window, st: &mut State) -> Cell {
        let (n, d, half, var) = (self.n, self.d, win.half, win.var);
        let quarter = n as f64 / 4.0;
        let term = |k: usize, c: f64, norm: f64| {
            if w[k] > 0.0 && norm > 0.0 {
                w[k] * c.max(0.0).powi(2) / norm
            } else {
                0.0
            }
        };
        let mut sum: f64 = (0..NDET).map(|k| term(k, st.c[k], st.norm[k])).sum();
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
            spread: Spread::default(),
        };
        self.cells.clear();
        let mut lo = -half;
        let ordered = self
            .keys
            .iter()
            .map(|&key| self.events[(key & 0xffff_ffff) as usize]);
        for (at, code) in ordered.chain(std::iter::once((half, u32::MAX))) {
            if at - lo > MIN_CELL {
                let ll = score_at(lo, at, sum);
                self.cells.push((lo, at, sum));
                if ll > best.ll {
                    best = Cell {
                        lo,
                        hi: at,
                        score: sum,
                        ll,
                        spread: Spread::default(),
                    };
                }
                lo = at;
            }
            if code == u32::MAX {
                break;
            }
            let idx = (code >> 1) as usize;
            let (k, i) = (idx / n, idx % n);
            let before = term(k, st.c[k], st.norm[k]);
            let sign = if code & 1 == 1 { 1.0 } else { -1.0 };
            let lu = &mut self.lu[k * d..(k + 1) * d];
            let col = &self.cols[i * d..(i + 1) * d];
            let mut sq = 0.0;
            for (a, b) in lu.iter_mut().zip(col) {
                *a += sign * b;
                sq += *a * *a;
            }
            let dot = match sig.corr {
                Some(v) => lu
                    .iter()
                    .zip(&v[k * d..(k + 1) * d])
                    .map(|(a, b)| a * b)
                    .sum(),
                None => 0.0,
            };
            st.c[k] += sign * sig.x[idx] + dot - st.dot[k];
            st.dot[k] = dot;
            st.norm[k] = quarter - sq;
            sum += term(k, st.c[k], st.norm[k]) - before;
        }
        best
    }

    /// The cells of the last walk into `acc`, each at the samples'
    /// likelihood exp(score/2 + `ll`), flat within it (the prior left out:
    /// the track has it); cells below the most likely by more than 40
    /// (e^-40) left out, the most likely first (offsets are about it).
    pub fn spread_into(&self, acc: &mut SpreadSum, ll: f64) {
        let top = self
            .cells
            .iter()
            .map(|c| c.2)
            .fold(f64::NEG_INFINITY, f64::max);
        if let Some(&(lo, hi, _)) = self.cells.iter().find(|c| c.2 == top) {
            acc.add(lo, hi, 0.5 * top + ll);
        }
        for &(lo, hi, sum) in &self.cells {
            if sum != top && 0.5 * (sum - top) >= -40.0 {
                acc.add(lo, hi, 0.5 * sum + ll);
            }
        }
    }
}

/// Each channel's running c_k, its slow-part correction and |u⊥_k|².
struct State {
    c: [f64; NDET],
    dot: [f64; NDET],
    norm: [f64; NDET],
}
