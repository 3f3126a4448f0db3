//! The own sensors' offsets as states the light estimates: the depth
//! sensor's (`DOFF`, m) and the attitude sensor's pitch (`POFF`, rad).
//!
//! A sensor off by a constant (a beacon depth surveyed roughly, an AHRS
//! mounted a degree askew of the dome) goes whole into the pose when its
//! readings are believed. Told how far off one may be
//! (`depth_offset_sigma_m`, `pitch_offset_sigma_deg`), the tracker holds
//! its offset as a state with that prior: the reading's model is the
//! coordinate plus the offset. What tells the offset from the coordinate is
//! the light: the spot's elevation gives z at a known pitch and pitch at a
//! known z, and a depth offset moves the elevation as b/x with range where
//! a pitch offset does not, so with both told the range's change tells
//! them apart (docs/estimators.md, "Sensor offsets"). Untold, an offset is
//! held at 0, a consider state of variance [`HELD_VAR`] that nothing moves
//! and no reported σ feels, until the reading check calls depth or pitch
//! while both readings come (`which_offset`).
//!
//! Each offset is about its sensor, not the pose: what the last state knew
//! of it is kept across restarts and starts the next state.

use super::readings::FrameReadings;
use super::state::{Ms, State, Vs, DOFF, POFF};
use super::Tracker;
use crate::settings::TrackerConfig;

/// An offset the tracker can estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Offset {
    /// The depth sensor's, m: the depth reads z + it.
    Depth,
    /// The attitude sensor's pitch, rad: it reads θ + it.
    Pitch,
}

impl Offset {
    pub const ALL: [Offset; 2] = [Offset::Depth, Offset::Pitch];

    /// Its index in the state.
    pub fn index(self) -> usize {
        match self {
            Offset::Depth => DOFF,
            Offset::Pitch => POFF,
        }
    }

    /// The pose coordinate its reading measures with it: z, θ.
    pub fn coordinate(self) -> usize {
        match self {
            Offset::Depth => 2,
            Offset::Pitch => 3,
        }
    }

    /// Its sensor's place in a frame's readings (attitude, depth,
    /// velocity: `State::gated`'s order).
    pub fn reading(self) -> usize {
        match self {
            Offset::Pitch => 0,
            Offset::Depth => 1,
        }
    }

    /// Its setting's prior 1σ (state units; 0: not told).
    pub fn setting(self, cfg: &TrackerConfig) -> f64 {
        match self {
            Offset::Depth => cfg.depth_offset_sigma_m,
            Offset::Pitch => cfg.pitch_offset_sigma_deg.to_radians(),
        }
    }

    /// The prior 1σ it is woken with when the reading check calls (state
    /// units; 0: never).
    pub fn called(self, cfg: &TrackerConfig) -> f64 {
        match self {
            Offset::Depth => cfg.called_depth_offset_sigma_m,
            Offset::Pitch => cfg.called_pitch_offset_sigma_deg.to_radians(),
        }
    }

    /// Its random walk's density (state units² per s).
    pub fn walk(self, cfg: &TrackerConfig) -> f64 {
        match self {
            Offset::Depth => cfg.depth_offset_walk_psd,
            // A mounting is fixed.
            Offset::Pitch => 0.0,
        }
    }

    /// Its component's bit in `Agreement::suspect` (CHECKED's order).
    pub fn suspect_bit(self) -> u8 {
        match self {
            Offset::Pitch => 1 << 0,
            Offset::Depth => 1 << 2,
        }
    }
}

/// The variance an offset not estimated is held at, as a consider state
/// (state units²: (1 µm)², (1 µrad)²): small enough to move no σ the
/// tracker reports (P's relative change under 1e-8), large enough for f64
/// to carry the state's covariance with it, which is the state's
/// sensitivity to the offset times this.
pub(super) const HELD_VAR: f64 = 1e-12;

/// One offset as the filter last knew it: mean, variance and when. Before
/// any state, the setting's prior.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Memory {
    mean: f64,
    var: f64,
    t: Option<f64>,
}

/// Both offsets: what the last state knew, the prior of the start being
/// made, and the 1σ each was woken with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Offsets {
    mem: [Memory; 2],
    prior: [(f64, f64); 2],
    woken: [f64; 2],
}

impl Offsets {
    pub fn new(cfg: &TrackerConfig) -> Self {
        Offsets {
            mem: Offset::ALL.map(|o| Memory {
                mean: 0.0,
                var: o.setting(cfg).powi(2),
                t: None,
            }),
            prior: [(0.0, 0.0); 2],
            woken: [0.0; 2],
        }
    }

    /// The prior 1σ `o` is estimated with: its setting's, else the one it
    /// was woken with; 0 while it is held at 0.
    pub fn sigma(&self, o: Offset, cfg: &TrackerConfig) -> f64 {
        let told = o.setting(cfg);
        if told > 0.0 {
            told
        } else {
            self.woken[o as usize]
        }
    }

    /// Whether `o` is estimated.
    pub fn told(&self, o: Offset, cfg: &TrackerConfig) -> bool {
        self.sigma(o, cfg) > 0.0
    }

    /// `o` estimated from now on with prior 1σ `sigma` (the reading check
    /// called it: `which_offset`).
    pub fn wake(&mut self, o: Offset, sigma: f64) {
        self.woken[o as usize] = sigma;
    }

    /// Set the priors of a start at time `t`: each variance grown by its
    /// walk since it was known, capped at the setting's prior (also after
    /// time went back); 0 and 0 for an offset not told.
    pub fn start_at(&mut self, t: f64, cfg: &TrackerConfig) {
        for (k, o) in Offset::ALL.into_iter().enumerate() {
            let full = self.sigma(o, cfg).powi(2);
            let m = self.mem[k];
            self.prior[k] = match m.t {
                Some(t0) if t >= t0 => (m.mean, (m.var + o.walk(cfg) * (t - t0)).min(full)),
                Some(_) => (m.mean, full),
                None => (0.0, full),
            };
            if !(self.prior[k].1 > HELD_VAR) {
                self.prior[k].1 = HELD_VAR;
            }
        }
    }

    /// The prior (mean, variance) of `o` for the start being made.
    pub fn prior(&self, o: Offset) -> (f64, f64) {
        self.prior[o as usize]
    }

    /// Remember what state `s` knows of the told offsets.
    pub fn keep(&mut self, s: &State, cfg: &TrackerConfig) {
        for (k, o) in Offset::ALL.into_iter().enumerate() {
            if self.told(o, cfg) {
                let i = o.index();
                self.mem[k] = Memory {
                    mean: s.x[i],
                    var: s.p[(i, i)],
                    t: Some(s.t),
                };
            }
        }
    }

    /// `o`'s memory back to the setting's doubt (its mean kept): a start
    /// takes it as weakly as it took the first.
    pub fn doubt(&mut self, o: Offset, cfg: &TrackerConfig) {
        let full = self.sigma(o, cfg).powi(2);
        let m = &mut self.mem[o as usize];
        m.var = m.var.max(full);
    }

    /// `o` and its 1σ while it is estimated and a state has known it.
    pub fn report(&self, o: Offset, cfg: &TrackerConfig) -> Option<(f64, f64)> {
        let m = self.mem[o as usize];
        (self.told(o, cfg) && m.t.is_some()).then(|| (m.mean, m.var.max(0.0).sqrt()))
    }
}

impl Tracker {
    /// The told offsets in a start's state, and what the start fit's use
    /// of their readings ties to them. The fit took each reading less the
    /// offset's mean as a prior on its coordinate c with the offset's
    /// variance V added to the reading's, R = σ² + V, so every component's
    /// error holds −K·e_b with K_i = P_fit[i, c]/R (that prior's gain in
    /// the fit): the covariance −K·V, the mean left where it was. `p_fit`
    /// is the fit's own covariance, before a poor fit's widening: with the
    /// widened one the joint covariance is not positive semi-definite once
    /// the widening passes 1 + σ²/V (a review found it at 1.2 with the
    /// light weak on z), while with the fit's own the widened block stays
    /// ≥ the ties. Both at once are exact too: each prior is on its own
    /// coordinate, the offsets' errors are independent, and the Schur
    /// complement is P_fit·(A + Σ_c σ_c²/R_c²·e_c·e_cᵀ)·P_fit ≥ 0 (A the
    /// fit's other information).
    pub(super) fn start_offsets(&self, x: &mut Vs, p: &mut Ms, p_fit: &Ms, r: &FrameReadings) {
        for o in Offset::ALL {
            let (mean, var) = self.offsets.prior(o);
            if !(var > 0.0) {
                continue;
            }
            let i = o.index();
            x[i] = mean;
            p[(i, i)] = var;
            let sigma = match o {
                Offset::Depth => r.depth.ready().map(|d| d.sigma[0]),
                Offset::Pitch => r.attitude.ready().map(|a| a.sigma[0]),
            };
            let Some(sigma) = sigma else {
                continue;
            };
            let rr = sigma * sigma + var;
            let c = o.coordinate();
            for j in 0..5 {
                let v = -p_fit[(j, c)] * var / rr;
                p[(j, i)] = v;
                p[(i, j)] = v;
            }
        }
    }
}
