//! What one frame's channels tell a bound (spec v3): a count of one
//! sample, or a blinking beacon's demodulated amplitude of N samples, with
//! or without daylight on top.
//!
//! Why one place: the single-frame bound (`crb`) and the tracker's bound
//! (`tracker::bound`) both sum each channel's gradient over its variance;
//! they differ in their parameters, not in what a channel measures. Three
//! cases, as the estimators read them (`measurement`, `daylight`):
//!
//! - **Counts of a steady beacon** (v1/v2): σ² from the noise model at the
//!   beacon's light; a channel at 0 or full scale is censored and left out.
//!   Bit for bit the bound of before.
//! - **Counts of a steady beacon by day**: the ambient L·b_k adds its shot
//!   noise and each channel's own flicker (a noise, 1σ `flicker` × the
//!   channel's ambient); its level L (the sun, the centre's depth and the
//!   flicker common to every detector) is unknown each frame, a nuisance
//!   without a prior. It is eliminated here (the Schur complement: each
//!   gradient loses its part along b in the noise's metric), so what is
//!   left is what the light tells about the pose beside an unknown sun;
//!   the shape b_k turns with the attitude, which the gradients keep.
//! - **Amplitudes of a blinking beacon**: the on level minus the off level
//!   over N samples, N/2 each: σ² = (2/N)·(σ²_on + σ²_off), each from the
//!   noise model at that level (the ambient's shot noise included, the
//!   flicker below the demodulator's band not: it rejects it ≥ 60 dB).
//!   The white-noise limit: the demodulator's own search for phase and
//!   flicker costs it up to 1.2× that variance (docs/demodulator.md), and
//!   its model error (`measurement::AMPLITUDE_MODEL_REL`) is no noise of
//!   the light's, so neither is in a lower bound. A channel whose on level
//!   clips is left out, as the demodulator flags it.

// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::NDET;

use super::daylight::counts_per_level;
#[cfg(test)]
use super::light::predict_with_grad_rolled;
use super::light::{predict_beacon, predict_beacon_with_grad, BeaconLight, PoseVec};
use super::SensorModel;

/// Parameters a channel's gradient is taken over: x, y, z, θ, ψ, K_D, the
/// common gain, roll.
pub const NG: usize = 8;

/// The sun in a bound's scene (MODEL.md "Daylight", its mean: the flicker
/// common to all detectors is in the unknown level).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundDaylight {
    /// S, volts an upward-facing detector reads below the surface.
    pub surface_v: f64,
    /// Depth of B's origin below the surface, m.
    pub origin_depth_m: f64,
    /// ρ.
    pub upwelling: f64,
    /// 1σ of each detector's own flicker relative to its ambient, at the
    /// surface (σ_f·√spatial); it falls with depth as e^(−h/h_f).
    pub own_flicker: f64,
    /// h_f, m.
    pub flicker_depth_m: f64,
}

/// How a scene's frames carry the light: the default is v1/v2's (counts
/// of a steady beacon, no daylight).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BoundLight {
    /// Samples per channel of a frame of a blinking beacon (its amplitudes
    /// are read); `None`: a steady beacon's counts.
    pub blink_samples: Option<u32>,
    pub daylight: Option<BoundDaylight>,
}

/// One channel of one frame: whether it informs, its variance (counts²)
/// and its gradient over [`NG`] parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundChannel {
    pub used: bool,
    pub var: f64,
    pub grad: [f64; NG],
}

impl Default for BoundChannel {
    fn default() -> Self {
        BoundChannel {
            used: false,
            var: 1.0,
            grad: [0.0; NG],
        }
    }
}

/// The frame at pose `q`, roll `roll` (rad), `k_d` and temperature gain
/// `gt`, channel by channel: see the module's three cases.
pub fn channels(
    m: &SensorModel,
    light: &BoundLight,
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> [BoundChannel; NDET] {
    channels_of(m, light, None, &[0.0; NDET], q, roll, k_d, gt)
}

/// A station's frame (spec v3, several blinking beacons): one image of
/// amplitudes per beacon, each channel's gradient that beacon's light's.
/// Each beacon's amplitude also pays the shot noise of the others' light
/// (on half the time, so half their level on both of its halves), and a
/// channel whose samples clip with every beacon on is left out.
pub fn station_channels(
    m: &SensorModel,
    light: &BoundLight,
    beacons: &[BeaconLight],
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> Vec<[BoundChannel; NDET]> {
    let volts: Vec<[f64; NDET]> = beacons
        .iter()
        .map(|b| {
            let (_, irr) = predict_beacon(m, Some(b), q, roll, k_d, gt);
            std::array::from_fn(|k| irr[k] * m.gain[k] * gt)
        })
        .collect();
    beacons
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let others: [f64; NDET] = std::array::from_fn(|k| {
                volts
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, v)| v[k])
                    .sum()
            });
            channels_of(m, light, Some(b), &others, q, roll, k_d, gt)
        })
        .collect()
}

/// One beacon's channels (`None`: the model's own beacon at D's origin),
/// `others_v` the other beacons' light at the ADC (volts, all on).
#[allow(clippy::too_many_arguments)]
fn channels_of(
    m: &SensorModel,
    light: &BoundLight,
    beacon: Option<&BeaconLight>,
    others_v: &[f64; NDET],
    q: &PoseVec,
    roll: f64,
    k_d: f64,
    gt: f64,
) -> [BoundChannel; NDET] {
    let (pred, irr, jac, jr) = predict_beacon_with_grad(m, beacon, q, roll, k_d, gt);
    let fs = m.full_scale();
    let cpv = m.counts_per_volt();
    let amb = light.daylight.map(|d| Sun::at(m, &d, q, roll, k_d, gt));
    let mut out = [BoundChannel::default(); NDET];
    for k in 0..NDET {
        let beacon_v = irr[k] * m.gain[k] * gt;
        // The ambient's counts on channel k (0 without daylight).
        let a = amb.as_ref().map_or(0.0, |s| s.level * s.b[k]);
        let c = &mut out[k];
        let mut g = [0.0; NG];
        for j in 0..6 {
            g[j] = jac[(k, j)];
        }
        // In the order the bound has always multiplied it (v2 bit for bit).
        g[6] = m.gain[k] * gt * irr[k] * cpv;
        g[7] = jr[k];
        match light.blink_samples {
            Some(n) => {
                // The on level's samples must not clip; the off level is
                // the dark offset plus the ambient.
                let on = pred[k] + a;
                let others = others_v[k];
                c.used = on + others * cpv < fs - 0.5 && pred[k] - g[6] + a > 0.5;
                let on_var = m.count_variance(beacon_v + a / cpv + 0.5 * others);
                let off_var = m.count_variance(a / cpv + 0.5 * others);
                c.var = 2.0 / f64::from(n.max(2)) * (on_var + off_var);
            }
            None => {
                let z = pred[k] + a;
                c.used = z > 0.5 && z < fs - 0.5;
                c.var = m.count_variance(beacon_v + a / cpv);
                if let Some(s) = &amb {
                    let f = s.own_flicker * a;
                    c.var += f * f;
                    for (gj, dj) in g.iter_mut().zip(&s.d[k]) {
                        *gj += s.level * dj;
                    }
                    // The common gain scales the sun's light too.
                    g[6] += a;
                }
            }
        }
        c.grad = g;
    }
    if let (None, Some(s)) = (light.blink_samples, &amb) {
        s.eliminate_level(&mut out);
    }
    out
}

/// The sun at one pose: its counts per volt of level on each channel, the
/// level, and how b turns with the attitude and K_D.
struct Sun {
    b: [f64; NDET],
    level: f64,
    /// ∂b_k over the [`NG`] parameters (θ, ψ, K_D, roll; 0 elsewhere).
    d: [[f64; NG]; NDET],
    /// Relative 1σ of each channel's own flicker at this depth.
    own_flicker: f64,
}

impl Sun {
    fn at(m: &SensorModel, d: &BoundDaylight, q: &PoseVec, roll: f64, k_d: f64, gt: f64) -> Sun {
        let rho = d.upwelling;
        let mut mk = m.clone();
        mk.light.k_d = k_d;
        let b = counts_per_level(&mk, rho, q[3], q[4], roll, gt);
        // The detector's depth is the centre's less r·u_k, which b holds.
        let h = (d.origin_depth_m - q[2]).max(0.0);
        let level = d.surface_v * (-k_d * h).exp();
        let own_flicker = d.own_flicker * (-h / d.flicker_depth_m.max(1e-9)).exp();
        let mut dd = [[0.0; NG]; NDET];
        // Central differences: b is smooth and cheap, and the bound is off
        // the frame path.
        let step = 1e-6;
        let mut put = |j: usize, plus: [f64; NDET], minus: [f64; NDET], h: f64| {
            for k in 0..NDET {
                dd[k][j] = (plus[k] - minus[k]) / (2.0 * h);
            }
        };
        let (t, p) = (q[3], q[4]);
        put(
            3,
            counts_per_level(&mk, rho, t + step, p, roll, gt),
            counts_per_level(&mk, rho, t - step, p, roll, gt),
            step,
        );
        put(
            4,
            counts_per_level(&mk, rho, t, p + step, roll, gt),
            counts_per_level(&mk, rho, t, p - step, roll, gt),
            step,
        );
        put(
            7,
            counts_per_level(&mk, rho, t, p, roll + step, gt),
            counts_per_level(&mk, rho, t, p, roll - step, gt),
            step,
        );
        let hk = 1e-7;
        let (mut up, mut down) = (mk.clone(), mk.clone());
        up.light.k_d = k_d + hk;
        down.light.k_d = k_d - hk;
        put(
            5,
            counts_per_level(&up, rho, t, p, roll, gt),
            counts_per_level(&down, rho, t, p, roll, gt),
            hk,
        );
        Sun {
            b,
            level,
            d: dd,
            own_flicker,
        }
    }

    /// Project the level's direction b out of every used channel's
    /// gradient in the noise's metric: g_j ← g_j − b·(bᵀR⁻¹g_j)/(bᵀR⁻¹b),
    /// so that Σ g gᵀ/σ² is the information with L profiled out.
    fn eliminate_level(&self, ch: &mut [BoundChannel; NDET]) {
        let mut bb = 0.0;
        let mut bg = [0.0; NG];
        for k in (0..NDET).filter(|&k| ch[k].used) {
            let w = 1.0 / ch[k].var;
            bb += self.b[k] * self.b[k] * w;
            for j in 0..NG {
                bg[j] += self.b[k] * ch[k].grad[j] * w;
            }
        }
        if !(bb > 0.0) {
            return;
        }
        for (c, b) in ch.iter_mut().zip(&self.b).filter(|(c, _)| c.used) {
            for j in 0..NG {
                c.grad[j] -= b * bg[j] / bb;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::light::from_pose;
    use lightpose_core::{Angle, Pose};

    fn pose() -> PoseVec {
        from_pose(&Pose::new(
            6.0,
            0.2,
            -0.3,
            Angle::from_deg(4.0),
            Angle::from_deg(-3.0),
        ))
    }

    fn model() -> SensorModel {
        SensorModel {
            adc_bits: 12,
            ..SensorModel::default()
        }
    }

    fn day() -> BoundDaylight {
        BoundDaylight {
            surface_v: 5.0,
            origin_depth_m: 4.0,
            upwelling: 0.02,
            own_flicker: 0.3 * 0.3f64.sqrt(),
            flicker_depth_m: 3.0,
        }
    }

    /// v1/v2: each channel is the noise model's count at the beacon's
    /// light, its gradient the light equation's.
    #[test]
    fn counts_of_a_steady_beacon_are_the_noise_model_s() {
        let m = model();
        let q = pose();
        let ch = channels(&m, &BoundLight::default(), &q, 0.0, m.light.k_d, 1.0);
        let (pred, irr, jac, _) = predict_with_grad_rolled(&m, &q, 0.0, m.light.k_d, 1.0);
        for k in 0..NDET {
            assert_eq!(ch[k].var, m.count_variance(irr[k] * m.gain[k]));
            assert_eq!(ch[k].grad[0], jac[(k, 0)]);
            assert_eq!(ch[k].used, pred[k] > 0.5 && pred[k] < m.full_scale() - 0.5);
        }
    }

    /// A blinking beacon over N samples: the white-noise limit
    /// (2/N)·(σ²_on + σ²_off); by day the ambient's shot noise raises it,
    /// and nothing of the sun enters the gradient.
    #[test]
    fn amplitudes_carry_the_white_noise_limit_and_only_the_sun_s_shot_noise() {
        let m = SensorModel {
            kappa_v: 1e-3,
            ..model()
        };
        let q = pose();
        let night = BoundLight {
            blink_samples: Some(100),
            daylight: None,
        };
        let steady = channels(&m, &BoundLight::default(), &q, 0.0, m.light.k_d, 1.0);
        let n = channels(&m, &night, &q, 0.0, m.light.k_d, 1.0);
        let d = channels(
            &m,
            &BoundLight {
                daylight: Some(day()),
                ..night
            },
            &q,
            0.0,
            m.light.k_d,
            1.0,
        );
        for k in (0..NDET).filter(|&k| n[k].used) {
            let dark = m.count_variance(0.0);
            let want = 2.0 / 100.0 * (steady[k].var + dark);
            assert!((n[k].var - want).abs() <= 1e-12 * want, "{k}");
            assert!(d[k].var > n[k].var, "{k}");
            assert_eq!(d[k].grad, n[k].grad, "{k}");
        }
    }

    /// A steady beacon by day: the level's direction is gone from every
    /// gradient (bᵀR⁻¹g = 0).
    #[test]
    fn a_steady_beacon_by_day_loses_the_level_s_direction() {
        let m = model();
        let q = pose();
        let light = BoundLight {
            blink_samples: None,
            daylight: Some(day()),
        };
        let ch = channels(&m, &light, &q, 0.01, m.light.k_d, 1.0);
        let b = counts_per_level(&m, 0.02, q[3], q[4], 0.01, 1.0);
        for j in 0..NG {
            let s: f64 = (0..NDET)
                .filter(|&k| ch[k].used)
                .map(|k| b[k] * ch[k].grad[j] / ch[k].var)
                .sum();
            let scale: f64 = (0..NDET)
                .filter(|&k| ch[k].used)
                .map(|k| (b[k] * ch[k].grad[j] / ch[k].var).abs())
                .sum();
            assert!(
                s.abs() <= 1e-9 * scale.max(1e-300),
                "param {j}: {s} of {scale}"
            );
        }
    }
}
