//! One frame's fit of the whole pose (x, y, z, pitch, yaw and roll) to a
//! docking station's images (spec v3, MODEL.md "Several beacons").
//!
//! Why a fit of its own: with one beacon roll is invisible and y, z trade
//! against yaw, pitch along ridges, so the estimators consider roll rather
//! than fit it (`light`). A station's beacons, seen apart by their
//! frequencies, each give an image of amplitudes; two that the vehicle
//! does not see in line make roll observable, three give the whole pose
//! from one frame. The fit is weighted Levenberg–Marquardt over the six
//! coordinates on every seen beacon's image, with the demodulator's σ and
//! each beacon's model error (`BeaconLight::model_rel`), and
//! the vehicle's own readings (attitude, depth) as priors when it has
//! them. Nothing is allocated: the normal equations are 6 × 6.
//!
//! A beacon whose image carries no signal (off, failed, occluded or out of
//! the field of view) is left out rather than read as "the vehicle looks
//! away from it": a dark image of a beacon that is off would pull the pose.
//! With fewer than two beacons seen, roll comes from the attitude reading
//! or the roll prior, as for one beacon.

// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]
// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use lightpose_core::{Amplitudes, BeaconAmplitude, NDET};
use nalgebra::{SMatrix, SVector};

use super::light::{predict_beacon, predict_beacon_with_grad, BeaconLight, PoseVec};
use super::SensorModel;

/// The fit's coordinates: x, y, z (m), θ, ψ, φ (rad).
pub type Pose6 = SVector<f64, 6>;
type Mat6 = SMatrix<f64, 6, 6>;

/// Signal-to-noise (Σ a²/σ² over an image) below which a beacon counts as
/// not seen. Noise alone makes a χ² of 25 degrees of freedom (25 ± 7, and
/// a little more where the demodulator's phase search locks onto noise):
/// 36 let a beacon that was off count as seen in 3 frames of 60; 100 is
/// far beyond noise (p < 1e-15) and a 10σ image.
pub const SEEN_SNR2: f64 = 100.0;

/// What the vehicle's own sensors say, each with its 1σ.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StationPriors {
    /// (θ, ψ, φ) in radians and their 1σ, in D.
    pub attitude: Option<([f64; 3], [f64; 3])>,
    /// z of the dome's centre in D and its 1σ, m.
    pub depth: Option<(f64, f64)>,
    /// Roll's 1σ about 0 when fewer than two beacons are seen and no
    /// attitude reading gives it (radians).
    pub roll_sigma: f64,
}

/// One frame's fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StationFit {
    pub pose: Pose6,
    /// Covariance of `pose` at the solution.
    pub cov: Mat6,
    /// Σ r²/σ² over the channels used, and how many were used.
    pub chi2: f64,
    pub channels: usize,
    /// Bit b: the station's beacon b was seen and fitted.
    pub seen: u32,
    pub iterations: usize,
}

impl StationFit {
    /// How many of the station's beacons were seen.
    pub fn beacons_seen(&self) -> u32 {
        self.seen.count_ones()
    }

    /// 1σ of coordinate `i` (order of [`Pose6`]).
    pub fn std(&self, i: usize) -> f64 {
        self.cov[(i, i)].max(0.0).sqrt()
    }
}

/// Which of `station`'s beacons the frame's images see (bit b for beacon b).
pub fn seen_beacons(station: &[BeaconLight], amps: &Amplitudes) -> u32 {
    let mut seen = 0u32;
    for img in amps.beacons() {
        let b = usize::from(img.beacon);
        if b >= station.len() || b >= 32 {
            continue;
        }
        if image_snr2(amps, img) >= SEEN_SNR2 {
            seen |= 1 << b;
        }
    }
    seen
}

/// Σ a²/σ² over an image's usable channels (none clipped, a σ, a finite
/// amplitude): what [`seen_beacons`] compares with [`SEEN_SNR2`], and the
/// per-beacon SNR an estimate reports.
pub fn image_snr2(amps: &Amplitudes, img: &BeaconAmplitude) -> f64 {
    (0..NDET)
        .filter(|&k| amps.clipped[k] == 0 && img.std[k] > 0.0 && img.amplitude[k].is_finite())
        .map(|k| (img.amplitude[k] / img.std[k]).powi(2))
        .sum()
}

/// The normal equations at `p`: H = Σ w·j·jᵀ, g = Σ w·j·r, and the cost
/// Σ w·r² (priors included).
struct Normal {
    h: Mat6,
    g: Pose6,
    cost: f64,
    channels: usize,
}

fn split(p: &Pose6) -> (PoseVec, f64) {
    (PoseVec::new(p[0], p[1], p[2], p[3], p[4]), p[5])
}

/// Add `m`'s images of the seen beacons (and the priors) at `p`.
fn normal<const GRAD: bool>(
    m: &SensorModel,
    station: &[BeaconLight],
    amps: &Amplitudes,
    seen: u32,
    gt: f64,
    priors: &StationPriors,
    p: &Pose6,
) -> Normal {
    let (q, roll) = split(p);
    let cpv = m.counts_per_volt();
    let k_d = m.light.k_d;
    let mut n = Normal {
        h: Mat6::zeros(),
        g: Pose6::zeros(),
        cost: 0.0,
        channels: 0,
    };
    for img in amps.beacons() {
        let b = usize::from(img.beacon);
        if b >= 32 || seen & (1 << b) == 0 {
            continue;
        }
        let beacon = &station[b];
        let (pred, jac, jr) = if GRAD {
            let (c, _, j, jr) = predict_beacon_with_grad(m, Some(beacon), &q, roll, k_d, gt);
            (c, Some(j), Some(jr))
        } else {
            (
                predict_beacon(m, Some(beacon), &q, roll, k_d, gt).0,
                None,
                None,
            )
        };
        for k in 0..NDET {
            let (a, s) = (img.amplitude[k], img.std[k]);
            if amps.clipped[k] != 0 || !(s > 0.0) || !a.is_finite() {
                continue;
            }
            // The prediction's amplitude: the count less the dark level.
            let model = pred[k] - m.offset_v[k] * cpv;
            let e = beacon.model_rel * model;
            let w = 1.0 / (s * s + e * e);
            let r = a - model;
            n.cost += w * r * r;
            n.channels += 1;
            if let (Some(j), Some(jr)) = (&jac, &jr) {
                let row = Pose6::new(j[(k, 0)], j[(k, 1)], j[(k, 2)], j[(k, 3)], j[(k, 4)], jr[k]);
                n.h += w * row * row.transpose();
                n.g += w * r * row;
            }
        }
    }
    let mut prior = |i: usize, value: f64, sigma: f64| {
        if sigma > 0.0 && sigma.is_finite() && value.is_finite() {
            let w = 1.0 / (sigma * sigma);
            let r = value - p[i];
            n.cost += w * r * r;
            n.h[(i, i)] += w;
            n.g[i] += w * r;
        }
    };
    if let Some((v, s)) = priors.attitude {
        for i in 0..3 {
            prior(3 + i, v[i], s[i]);
        }
    } else if seen.count_ones() < 2 {
        prior(5, 0.0, priors.roll_sigma);
    }
    if let Some((z, s)) = priors.depth {
        prior(2, z, s);
    }
    n
}

/// Invert a 6 × 6 information matrix scaled to a unit diagonal (its
/// columns differ by orders of magnitude: metres and radians).
fn invert(h: &Mat6) -> Option<Mat6> {
    let d = Pose6::from_fn(|i, _| {
        let v = h[(i, i)];
        if v > 0.0 {
            1.0 / v.sqrt()
        } else {
            1.0
        }
    });
    let scaled = Mat6::from_fn(|i, j| h[(i, j)] * d[i] * d[j]);
    let inv = scaled.cholesky()?.inverse();
    Some(Mat6::from_fn(|i, j| inv[(i, j)] * d[i] * d[j]))
}

/// Fit the frame's images from `start`. `None` when no beacon is seen or
/// the information is singular (a pose the frame cannot tell).
pub fn fit_station(
    m: &SensorModel,
    station: &[BeaconLight],
    amps: &Amplitudes,
    gt: f64,
    start: Pose6,
    priors: &StationPriors,
) -> Option<StationFit> {
    let seen = seen_beacons(station, amps);
    if seen == 0 {
        return None;
    }
    let mut p = start;
    let mut n = normal::<true>(m, station, amps, seen, gt, priors, &p);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    for _ in 0..50 {
        iterations += 1;
        let mut damped = n.h;
        for i in 0..6 {
            damped[(i, i)] += lambda * n.h[(i, i)].max(1e-12);
        }
        let Some(step) = invert(&damped).map(|c| c * n.g) else {
            lambda *= 10.0;
            continue;
        };
        let trial = p + step;
        // Keep the dome out of the beacons' plane and the angles sane.
        if !(trial[0] > 0.3) || trial.iter().skip(3).any(|a| !(a.abs() < 1.4)) {
            lambda *= 10.0;
            continue;
        }
        let cost = normal::<false>(m, station, amps, seen, gt, priors, &trial).cost;
        if cost < n.cost {
            p = trial;
            lambda = (lambda * 0.3).max(1e-9);
            let done = (n.cost - cost) <= 1e-10 * n.cost.max(1.0);
            n = normal::<true>(m, station, amps, seen, gt, priors, &p);
            if done {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    let cov = invert(&n.h)?;
    Some(StationFit {
        pose: p,
        cov,
        chi2: n.cost,
        channels: n.channels,
        seen,
        iterations,
    })
}
