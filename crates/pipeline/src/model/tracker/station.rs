//! The tracker on a docking station's light (spec v3, issue 41 item 3):
//! each frame's images, one per beacon, update the one state beacon by
//! beacon, and roll is a state the light estimates.
//!
//! Why sequential 25-channel updates: the beacons' images are independent
//! measurements (the demodulator separates them by frequency, each with its
//! own σ), so one update per image is the joint update, costs a 25 × 25
//! factorization per beacon instead of one of 25·B, and lets a beacon the
//! gate refuses (a reflection, an image the model cannot explain) be left
//! out alone. A beacon whose image carries no signal (`seen_beacons`) is
//! left out that frame rather than read as "the vehicle looks away from
//! it"; losing or regaining one changes which updates run, never the
//! state's continuity (no restart on a change of the seen set).
//!
//! The mode follows from the beacons seen (`lightpose_core::StationMode`):
//! three or more give the whole pose, two make roll observable, one leaves
//! roll to the attitude reading or the roll prior (its variance bounded at
//! `roll_sigma_deg`, [`STATION_ROLL_PRIOR_DEG`] unset), none predicts only.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use std::sync::Arc;

use lightpose_core::{
    Amplitudes, BeaconAmplitude, Frame, ReadingUse, StationSeen, Status, MAX_BEACONS, NDET,
};
use nalgebra::{SMatrix, SVector};

use super::counts::commit;
use super::offsets::Offset;
use super::readings::FrameReadings;
use super::state::{k_d_of, Ms, State, Vs, KD, NS, ROLL};
use super::Tracker;
use crate::model::light::{predict_beacon_with_grad, BeaconLight, PoseVec};
use crate::model::station_fit::{fit_station, image_snr2, seen_beacons, Pose6, StationPriors};

/// Roll's 1σ about level (degrees) when fewer than two beacons are seen,
/// no attitude reading gives roll and `roll_sigma_deg` is unset: a vehicle
/// docking in a harbour rolls a few degrees.
pub const STATION_ROLL_PRIOR_DEG: f64 = 10.0;

/// Ranges the start fit tries (m, on the station's axis, at the reading's
/// attitude or level): one frame's fit, started on the wrong side of a
/// ridge, stays there, and the approach begins anywhere from the mouth to
/// beyond 8 m.
const START_RANGES_M: [f64; 4] = [1.5, 3.0, 6.0, 10.0];

type Zv = SVector<f64, NDET>;
type Hm = SMatrix<f64, NDET, NS>;
type Rm = SMatrix<f64, NDET, NDET>;

/// What one frame's images did to the state.
pub(super) struct StationUpdate {
    /// At least one seen beacon's image was fused.
    pub applied: bool,
}

impl Tracker {
    /// This tracker on a docking station's light: `station[b]` is the
    /// beacon whose image has `beacon == b` (the log header's order). A
    /// frame with amplitudes is then read beacon by beacon (`station`);
    /// frames of counts and an empty station are the single-beacon path.
    pub fn with_station(mut self, station: Vec<BeaconLight>) -> Self {
        self.station = Arc::from(station);
        self
    }

    /// The station's name and beacon ids, which its estimates carry
    /// (POSE's `frame` and `beacons_seen`).
    pub fn with_station_names(mut self, names: &'static lightpose_core::StationNames) -> Self {
        self.station_names = Some(names);
        self
    }

    /// The station's beacons (empty: one beacon).
    pub fn station(&self) -> &[BeaconLight] {
        &self.station
    }

    /// `frame`'s images when this tracker reads it as a station's.
    pub(super) fn station_amps<'a>(&self, frame: &'a Frame) -> Option<&'a Amplitudes> {
        frame
            .amplitudes
            .as_ref()
            .filter(|_| !self.station.is_empty())
    }

    /// Which beacons `amps` shows, and each image's SNR.
    pub(super) fn station_seen(&self, amps: &Amplitudes) -> StationSeen {
        let mut out = StationSeen {
            station: u8::try_from(self.station.len()).unwrap_or(u8::MAX),
            names: self.station_names,
            seen: seen_beacons(&self.station, amps),
            snr2: [0.0; MAX_BEACONS],
        };
        for img in amps.beacons() {
            let b = usize::from(img.beacon);
            if b < MAX_BEACONS && b < self.station.len() {
                out.snr2[b] = image_snr2(amps, img) as f32;
            }
        }
        out
    }

    /// Roll's 1σ (rad) when the light leaves it to a prior.
    pub(super) fn station_roll_prior(&self) -> f64 {
        self.cfg
            .roll_sigma_deg
            .unwrap_or(STATION_ROLL_PRIOR_DEG)
            .to_radians()
    }

    /// Update `s` with each seen beacon's image in turn (the counts' gate
    /// per image: a refused one is left out alone).
    pub(super) fn update_station(
        &self,
        s: &mut State,
        amps: &Amplitudes,
        gt: f64,
        seen: u32,
    ) -> StationUpdate {
        let (mut chi2, mut n, mut ll, mut applied) = (0.0, 0usize, 0.0, false);
        for img in amps.beacons() {
            let b = usize::from(img.beacon);
            if b >= 32 || seen & (1 << b) == 0 {
                continue;
            }
            let Some(beacon) = self.station.get(b) else {
                continue;
            };
            if let Some(u) = self.update_beacon(s, beacon, img, &amps.clipped, gt) {
                chi2 += u.0;
                n += u.1;
                ll += u.2;
                applied = true;
            }
        }
        if applied {
            s.counts_nis = Some(chi2 / n.max(1) as f64);
            s.counts_ll = Some(ll);
        }
        StationUpdate { applied }
    }

    /// One beacon's image as a 25-channel EKF update through
    /// `predict_beacon_with_grad` (the roll column from the gradient):
    /// (χ², channels, ln-likelihood) when fused, None when the gate or the
    /// numbers refused it (the state untouched).
    fn update_beacon(
        &self,
        s: &mut State,
        b: &BeaconLight,
        img: &BeaconAmplitude,
        clipped: &[u32; NDET],
        gt: f64,
    ) -> Option<(f64, usize, f64)> {
        let m = &self.model;
        let q = PoseVec::from_fn(|i, _| s.x[i]);
        let k_d = k_d_of(&s.x);
        let (pred, _, jac, jr) = predict_beacon_with_grad(m, Some(b), &q, s.x[ROLL], k_d, gt);
        let cpv = m.counts_per_volt();
        let frozen = self.init.frozen_mask();
        let (mut h, mut y, mut r) = (Hm::zeros(), Zv::zeros(), Rm::identity());
        let mut n_used = 0usize;
        for k in 0..NDET {
            let (a, sd) = (img.amplitude[k], img.std[k]);
            let usable = clipped[k] == 0
                && frozen & (1 << k) == 0
                && a.is_finite()
                && sd.is_finite()
                && sd > 0.0;
            if !usable {
                continue;
            }
            // The prediction's amplitude: the count less the dark level,
            // with the light model's own error beside the demodulator's σ.
            let model = pred[k] - m.offset_v[k] * cpv;
            let e = b.model_rel * model;
            r[(k, k)] = sd * sd + e * e;
            y[k] = a - model;
            for j in 0..5 {
                h[(k, j)] = jac[(k, j)];
            }
            h[(k, KD)] = jac[(k, 5)] * k_d;
            h[(k, ROLL)] = jr[k];
            n_used += 1;
        }
        if n_used == 0 {
            return None;
        }
        let hp = h * s.p;
        let sm = hp * h.transpose() + r;
        let ch = sm.cholesky()?;
        let chi2 = y.dot(&ch.solve(&y));
        if !(chi2 / n_used as f64 <= self.cfg.nis_gate) {
            return None;
        }
        let log_det: f64 = (0..NDET).map(|k| 2.0 * ch.l()[(k, k)].ln()).sum();
        // K = P·Hᵀ·S⁻¹ = (S⁻¹·H·P)ᵀ: a solve, not an inverse.
        let mut k = ch.solve(&hp).transpose();
        s.consider(&mut k);
        let xn = s.x + k * y;
        let ikh = Ms::identity() - k * h;
        // K·R·Kᵀ with R diagonal: K's columns scaled, not a 25 × 25 product.
        let mut kr = k;
        for c in 0..NDET {
            kr.column_mut(c).scale_mut(r[(c, c)]);
        }
        let pn = ikh * s.p * ikh.transpose() + kr * k.transpose();
        commit(s, xn, pn).then_some((chi2, n_used, -0.5 * (chi2 + log_det)))
    }

    /// Fuse a fused attitude reading's roll into the roll state (`ok` on
    /// the gate like any reading), and when neither it nor two beacons
    /// pin roll, hold roll's variance at the prior's (a bound, as
    /// `bound_unmeasured_attitude` holds pitch and yaw).
    pub(super) fn station_roll_readings(&self, s: &mut State, frame: &Frame, attitude_used: bool) {
        let reading = frame
            .attitude
            .filter(|_| attitude_used)
            .and_then(|a| a.roll)
            .map(|r| r.rad())
            .filter(|r| r.is_finite());
        let sd = self.cfg.attitude_sigma_roll_deg.to_radians();
        if let Some(r) = reading {
            // A roll the gate refuses leaves roll to the light.
            super::readings::fuse_scalar(s, ROLL, r, sd, self.gate[0]);
            return;
        }
        if s.station_seen.count() >= 2 {
            return;
        }
        let b2 = self.station_roll_prior().powi(2);
        let v = s.p[(ROLL, ROLL)];
        if v > b2 {
            // 1/b² = 1/v + 1/r: the reading's variance r that takes v to b².
            let r = b2 * v / (v - b2);
            super::readings::fuse_scalar(s, ROLL, 0.0, r.sqrt(), f64::INFINITY);
        }
    }

    /// The station's start: one frame's 6-DOF fit (`fit_station`) with the
    /// readings as priors, from the ranges [`START_RANGES_M`] tried in
    /// turn (the best fit kept).
    pub(super) fn start_station(
        &self,
        frame: &Frame,
        r: &FrameReadings,
        amps: &Amplitudes,
    ) -> Result<(State, [ReadingUse; 3]), Status> {
        let seen = self.station_seen(amps);
        if seen.seen == 0 {
            return Err(Status::NoLight);
        }
        let gt = super::gain_of(frame);
        let priors = self.station_priors(frame, r, seen.count());
        let att = priors.attitude.map_or([0.0; 3], |(v, _)| v);
        let fit = START_RANGES_M
            .iter()
            .filter_map(|&x0| {
                let z0 = priors.depth.map_or(0.0, |(z, _)| z);
                let start = Pose6::new(x0, 0.0, z0, att[0], att[1], att[2]);
                fit_station(&self.model, &self.station, amps, gt, start, &priors)
            })
            .min_by(|a, b| a.chi2.total_cmp(&b.chi2))
            .ok_or(Status::Diverged)?;
        let red = fit.chi2 / (fit.channels.saturating_sub(6).max(1)) as f64;
        if !(red <= self.init.config().max_reduced_chi2) {
            return Err(Status::Diverged);
        }
        let at = |i: usize| if i == 5 { ROLL } else { i };
        let mut x = Vs::zeros();
        let mut p_fit = Ms::zeros();
        for i in 0..6 {
            x[at(i)] = fit.pose[i];
            for j in 0..6 {
                p_fit[(at(i), at(j))] = fit.cov[(i, j)];
            }
        }
        let mut s = self.started_state(frame, r, x, p_fit, red, None, None)?;
        s.roll_free = true;
        s.station_seen = seen;
        Ok((s, super::start::uses_of(r)))
    }

    /// The start fit's priors: the attitude reading (less the pitch
    /// offset's mean; roll its own when it has one, else the prior while
    /// fewer than two beacons are seen), the depth reading as the dome's z.
    fn station_priors(&self, frame: &Frame, r: &FrameReadings, seen: u32) -> StationPriors {
        let prior = self.station_roll_prior();
        let roll = frame
            .attitude
            .and_then(|a| a.roll)
            .map(|r| r.rad())
            .filter(|r| r.is_finite());
        let attitude = r.attitude.ready().map(|a| {
            let (offset, var) = self.offsets.prior(Offset::Pitch);
            let sr = match roll {
                Some(_) => self.cfg.attitude_sigma_roll_deg.to_radians(),
                None if seen < 2 => prior,
                None => f64::INFINITY,
            };
            (
                [a.z[0] - offset, a.z[1], roll.unwrap_or(0.0)],
                [(a.sigma[0].powi(2) + var).sqrt(), a.sigma[1], sr],
            )
        });
        let depth = r.depth.ready().map(|d| {
            let (offset, var) = self.offsets.prior(Offset::Depth);
            let pitch = attitude.map_or(0.0, |(v, _)| v[0]);
            let z = self.dome_z_of_depth(d.z[0] - offset, pitch);
            (z, (d.sigma[0].powi(2) + var).sqrt())
        });
        StationPriors {
            attitude,
            depth,
            roll_sigma: prior,
        }
    }
}
