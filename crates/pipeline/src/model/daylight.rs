//! Daylight on a steady beacon's counts (spec v3, MODEL.md "Daylight"):
//! the sun's light through the water adds to every channel, brighter on
//! the upward-facing rows, and flickers as waves focus it. A blinking
//! beacon's demodulated amplitudes leave it out; a steady beacon's counts
//! cannot, so a fit of them must model it or read it as the beacon's.
//!
//! Why this shape: over the dome the ambient is S·e^(−K_D·h_k)·a(u_k)·F_k
//! with a(u) = (1 − ρ)(1 + u)²/4 + ρ and u_k = (R_BV n_k)_z. A detector
//! sits r·u_k above the dome's centre, so e^(−K_D·h_k) is the centre's
//! times e^(K_D·r·u_k) (4 % between the top and bottom rows in harbour
//! water: 80 counts of 12 bits under 2 V of sun, far above the noise, so
//! it is in the shape). S, the centre's depth and the flicker common to
//! every detector are not known frame by frame:
//! together they are one unknown level L ≥ 0 per frame (volts on an
//! upward-facing detector), a nuisance parameter that the single-frame
//! fit profiles out (variable projection) and the tracker marginalizes in
//! each update. The flicker each detector sees of its own (MODEL.md's
//! `spatial` share) is a noise: 1σ `flicker` × the channel's ambient.

use lightpose_core::{Angle, Attitude, NDET};
use serde::{Deserialize, Serialize};

use super::SensorModel;

/// `[estimator.model.daylight]`, `[estimator.tracker.daylight]`: the
/// vehicle works by day with a steady beacon, and the counts carry the
/// ambient. Left out (the default): no ambient is modelled, as in v1/v2.
/// Demodulated frames (a blinking beacon) never use it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DaylightConfig {
    /// ρ, the share of the ambient that comes from below (MODEL.md 0.02).
    pub upwelling: f64,
    /// 1σ of each channel's own flicker relative to its ambient:
    /// σ_f·e^(−h/h_f)·√spatial at the working depth (0.3·e^(−4/3)·√0.3
    /// ≈ 0.045 for MODEL.md's defaults at 4 m).
    pub flicker: f64,
    /// Largest σ of x, y or z (m) of a pose still called `ok`; a fit whose
    /// ambient leaves the beacon's light too little to fix the position
    /// says `daylight`.
    pub max_sigma_m: f64,
    /// Largest share of the brightest channel's light that may be ambient
    /// for an `ok` pose: above it the beacon is a small difference of two
    /// large numbers and the shape model's error, not the noise, decides.
    pub max_ambient_share: f64,
}

impl Default for DaylightConfig {
    fn default() -> Self {
        DaylightConfig {
            upwelling: 0.02,
            flicker: 0.045,
            max_sigma_m: 0.5,
            max_ambient_share: 0.9,
        }
    }
}

impl DaylightConfig {
    /// Refuse numbers no daylight has, naming the key.
    pub fn validate(&self) -> Result<(), String> {
        let within = |name: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(format!("daylight {name} = {v} must be in [{lo}, {hi}]"))
            }
        };
        within("upwelling", self.upwelling, 0.0, 1.0)?;
        within("flicker", self.flicker, 0.0, 1.0)?;
        within("max_sigma_m", self.max_sigma_m, 1e-3, 100.0)?;
        within("max_ambient_share", self.max_ambient_share, 0.0, 1.0)
    }
}

/// a(u) of MODEL.md: the ambient's angular shape, 1 facing up.
#[inline]
pub fn shape_of(u: f64, rho: f64) -> f64 {
    let v = 1.0 + u.clamp(-1.0, 1.0);
    (1.0 - rho) * v * v / 4.0 + rho
}

/// Each channel's count per volt of ambient level at pitch θ, yaw ψ and
/// roll φ (radians): g_k·g_T·(counts/V)·a(u_k)·e^(K_D·r·u_k), the level
/// being the light an upward-facing detector at the dome's centre reads.
pub fn counts_per_level(
    m: &SensorModel,
    rho: f64,
    theta: f64,
    psi: f64,
    roll: f64,
    gt: f64,
) -> [f64; NDET] {
    let att = Attitude::new(Angle::from_rad(theta), Angle::from_rad(psi))
        .with_roll(Angle::from_rad(roll));
    let cpv = m.counts_per_volt();
    let kr = m.light.k_d * m.geometry.radius_m;
    let mut b = [0.0; NDET];
    for (k, bk) in b.iter_mut().enumerate() {
        let u = att.to_beam(&m.geometry.normal(k)).0[2];
        *bk = m.gain[k] * gt * cpv * shape_of(u, rho) * (kr * u).exp();
    }
    b
}

/// What one frame's fit makes of the ambient: where the tracker and the
/// solver meet it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ambient {
    /// Counts per volt of level per channel ([`counts_per_level`]).
    pub b: [f64; NDET],
    /// Relative 1σ of each channel's own flicker.
    pub flicker: f64,
}

impl Ambient {
    /// The level (volts, ≥ 0) that best explains `z − pred` on the
    /// channels `used`, each weighted by `w` (1/σ): weighted least squares
    /// of one non-negative number.
    #[inline]
    pub fn level(
        &self,
        z: &[f64; NDET],
        pred: &[f64],
        w: &[f64; NDET],
        used: &[bool; NDET],
    ) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for k in 0..NDET {
            if used[k] {
                let w2 = w[k] * w[k];
                num += w2 * self.b[k] * (z[k] - pred[k]);
                den += w2 * self.b[k] * self.b[k];
            }
        }
        if den > 0.0 && num > 0.0 {
            num / den
        } else {
            0.0
        }
    }

    /// Variance (counts²) the flicker adds to channel k at level `l`.
    #[inline]
    pub fn flicker_variance(&self, k: usize, l: f64) -> f64 {
        let a = self.flicker * l * self.b[k];
        a * a
    }

    /// The ambient's light on channel k at level `l`, volts after the gain
    /// (for the shot noise: the noise model's argument).
    #[inline]
    pub fn volts(&self, m: &SensorModel, k: usize, l: f64) -> f64 {
        l * self.b[k] / m.counts_per_volt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shape_is_one_facing_up_and_rho_facing_down() {
        assert!((shape_of(1.0, 0.02) - 1.0).abs() < 1e-15);
        assert!((shape_of(-1.0, 0.02) - 0.02).abs() < 1e-15);
        assert!((shape_of(0.0, 0.02) - (0.98 * 0.25 + 0.02)).abs() < 1e-15);
        // Level: the upper rows face up when pitched up; the dome's centre
        // looks forward (u = 0) at attitude 0.
        let m = SensorModel::default();
        let b = counts_per_level(&m, 0.02, 0.0, 0.0, 0.0, 1.0);
        let centre = b[12] / m.counts_per_volt();
        assert!((centre - shape_of(0.0, 0.02)).abs() < 1e-12, "{centre}");
        assert!(b[2] > b[12] && b[12] > b[22], "{b:?}");
    }

    #[test]
    fn the_level_is_the_weighted_least_squares_one_and_never_negative() {
        let m = SensorModel::default();
        let a = Ambient {
            b: counts_per_level(&m, 0.02, 0.1, -0.05, 0.03, 1.0),
            flicker: 0.05,
        };
        let pred = [100.0; NDET];
        let mut z = [0.0; NDET];
        for k in 0..NDET {
            z[k] = pred[k] + 1.7 * a.b[k];
        }
        let w = [0.3; NDET];
        let l = a.level(&z, &pred, &w, &[true; NDET]);
        assert!((l - 1.7).abs() < 1e-12, "{l}");
        let dim = [50.0; NDET];
        assert_eq!(a.level(&dim, &pred, &w, &[true; NDET]), 0.0);
        assert_eq!(a.level(&z, &pred, &w, &[false; NDET]), 0.0);
    }
}
