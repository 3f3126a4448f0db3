//! Synthetic frames as MODEL.md makes them: per channel a level, daylight's
//! flicker, each beacon's square wave on its own clock (phase, drift), the
//! channels' skew, white noise, quantised and clamped per sample.

#![allow(dead_code)]

use lightpose_core::NDET;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

#[derive(Debug, Clone)]
pub struct Wave {
    pub mod_hz: f64,
    /// Phase at t = 0, cycles.
    pub phase: f64,
    /// δ: the beacon's clock runs at mod_hz · (1 + δ).
    pub drift: f64,
    /// Per channel, on level minus off level, counts.
    pub amplitude: [f64; NDET],
}

impl Wave {
    pub fn on(&self, t: f64) -> bool {
        (self.mod_hz * (1.0 + self.drift) * t + self.phase).rem_euclid(1.0) < 0.5
    }
}

/// A flicker component common to every channel: a·sin(2π f t + φ).
#[derive(Debug, Clone, Copy)]
pub struct Flicker {
    pub hz: f64,
    pub amplitude: f64,
    pub phase: f64,
}

#[derive(Debug, Clone)]
pub struct Scene {
    pub sample_hz: f64,
    pub rate_hz: f64,
    pub skew_s: f64,
    pub bits: u8,
    pub level: [f64; NDET],
    pub waves: Vec<Wave>,
    pub flicker: Vec<Flicker>,
    pub noise: f64,
    /// Channels forced to full scale for this share of their samples.
    pub clip: Option<(usize, f64)>,
    /// Time of frame 0's first sample.
    pub t0: f64,
}

impl Scene {
    pub fn n(&self) -> usize {
        (self.sample_hz / self.rate_hz).round() as usize
    }

    /// Frame j's first-sample time.
    pub fn t(&self, j: usize) -> f64 {
        self.t0 + j as f64 / self.rate_hz
    }

    pub fn full(&self) -> f64 {
        ((1u32 << self.bits) - 1) as f64
    }

    /// Frame j's samples, channel-major; `rng` draws the noise.
    pub fn frame(&self, j: usize, rng: &mut ChaCha8Rng) -> Vec<u16> {
        let n = self.n();
        let normal = Normal::new(0.0, self.noise.max(1e-300)).unwrap();
        let mut s = vec![0u16; NDET * n];
        for k in 0..NDET {
            for i in 0..n {
                let t = self.t(j) + i as f64 / self.sample_hz + k as f64 * self.skew_s;
                let mut v = self.level[k];
                for f in &self.flicker {
                    v += f.amplitude * (2.0 * std::f64::consts::PI * f.hz * t + f.phase).sin();
                }
                for w in &self.waves {
                    if w.on(t) {
                        v += w.amplitude[k];
                    }
                }
                if self.noise > 0.0 {
                    v += normal.sample(rng);
                }
                if let Some((ch, share)) = self.clip {
                    if ch == k && (i as f64) < share * n as f64 && i % 2 == 0 {
                        v = self.full() + 100.0;
                    }
                }
                s[k * n + i] = v.round().clamp(0.0, self.full()) as u16;
            }
        }
        s
    }
}

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// The white-noise limit of a square wave's amplitude (on minus off), N
/// samples, noise σ: 4σ²/N (the wave is ±A/2 about its mean on N samples,
/// Σ u² = N/4; phase known, level unknown: the least-squares fit's own
/// variance, which no unbiased estimator beats).
pub fn limit_var(sigma: f64, n: usize) -> f64 {
    4.0 * sigma * sigma / n as f64
}
