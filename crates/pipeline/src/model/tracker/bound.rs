//! A bound for a tracker: the posterior Cramér–Rao bound along a known
//! track, with the tracker's own motion model as the prior that ties one
//! frame to the next.
//!
//! Why: one frame's bound (`model::crb`) has no velocity in it, so it says
//! nothing of what a DVL, or simply following the vehicle, is worth; the
//! trade table's DVL rows need a bound that pools frames. This is the
//! recursive bound of Tichavský et al. (1998) for additive Gaussian noise,
//! with the transition and measurement Jacobians taken along the true
//! track: P⁻ = F·P·Fᵀ + Q, then each measurement's information added (the
//! covariance form of J⁺ = (F·J⁻¹·Fᵀ + Q)⁻¹ + Hᵀ·R⁻¹·H). It bounds any
//! unbiased estimator that believes the tracker's motion model (its Q) and
//! the given priors; a vehicle that moves more smoothly than Q allows can
//! be tracked better than this. The state is the tracker's plus the common
//! gain of an unknown water temperature (as in the single-frame bound);
//! K_D is an unknown constant with its prior, whether or not a tracker
//! estimates it. Spec v3: a tracker on a station (`with_station`) has roll
//! as a state; each frame adds every beacon's image, and an attitude
//! reading's roll when it has one.

// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::{BodyVec, Pose, NDET};
use nalgebra::{SMatrix, SVector};

use super::state::{Ms, State, Vs, KD, NS, ROLL, VEL};
use super::Tracker;
use crate::model::bound_light::{channels, station_channels, BoundChannel, BoundLight};
use crate::model::light::{from_pose, PoseVec};

/// The bound's state: the tracker's and the common gain.
const NB: usize = NS + 1;
const GAIN: usize = NS;
type Mb = SMatrix<f64, NB, NB>;

/// One frame of the true track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackPoint {
    pub t: f64,
    pub pose: Pose,
    /// Velocity over the ground in the body frame (what a DVL reads).
    pub velocity: BodyVec,
}

/// What is known and measured besides the counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackBoundScene {
    /// True water temperature (the frames' g_T).
    pub temp_c: f64,
    /// 1σ of K_D about the calibration (None: known).
    pub sigma_k_d: Option<f64>,
    /// 1σ of the temperature the frames report (None: known).
    pub sigma_temp_c: Option<f64>,
    /// 1σ of the own sensors' readings: attitude (pitch, yaw, rad), depth
    /// (m), DVL (m/s per component); None for a sensor the vehicle lacks.
    pub attitude: Option<(f64, f64)>,
    /// Spec v3: the attitude reading's roll, 1σ rad (read by a station's
    /// tracker only: one beacon's takes roll as known).
    pub roll: Option<f64>,
    pub depth: Option<f64>,
    pub dvl: Option<f64>,
    /// Spec v3: counts or a blinking beacon's amplitudes, and the sun
    /// (`bound_light`); the default is v1/v2's.
    pub light: BoundLight,
}

/// Lower bounds (1σ) at one frame; angles in degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackBound {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    pub surge: f64,
    /// Spec v3: a station's roll, degrees; 0 for one beacon (known).
    pub roll_deg: f64,
}

/// The measurement update in information form, P⁺ = (P⁻¹ + Hᵀ·R⁻¹·H)⁻¹,
/// each inverse scaled to a unit diagonal. The covariance form P − K·H·P
/// subtracted numbers of the vague prior's size (1e6 m²) to leave a few
/// cm²: within 7 m of the beacon its rounding left x's bound at 0 (an
/// audit: 0.000 against one frame's 0.146 m). States with no variance
/// (K_D or the temperature known) stay known.
fn inform<const M: usize>(p: &mut Mb, h: &SMatrix<f64, M, NB>, r: &SVector<f64, M>) {
    let known: [bool; NB] = std::array::from_fn(|i| !(p[(i, i)] > 0.0));
    let drop_known = |m: &mut Mb, diag: f64| {
        for i in (0..NB).filter(|i| known[*i]) {
            m.row_mut(i).fill(0.0);
            m.column_mut(i).fill(0.0);
            m[(i, i)] = diag;
        }
    };
    let mut prior = *p;
    drop_known(&mut prior, 1.0);
    let mut info = h.transpose() * SMatrix::<f64, M, M>::from_diagonal(&r.map(|v| 1.0 / v)) * h;
    drop_known(&mut info, 0.0);
    let Some(post) = spd_inverse(&prior).and_then(|j| spd_inverse(&(j + info))) else {
        // Not positive definite after rounding: the frame adds nothing
        // rather than a covariance that is not one.
        return;
    };
    let mut post = (post + post.transpose()) * 0.5;
    drop_known(&mut post, 0.0);
    *p = post;
}

/// The inverse of a symmetric positive definite matrix whose diagonal
/// spans many orders of magnitude (metres², radians², K_D, gain), by
/// Cholesky on its unit-diagonal scaling.
fn spd_inverse(a: &Mb) -> Option<Mb> {
    if !(0..NB).all(|i| a[(i, i)] > 0.0 && a[(i, i)].is_finite()) {
        return None;
    }
    let d = SVector::<f64, NB>::from_fn(|i, _| 1.0 / a[(i, i)].sqrt());
    let scaled = Mb::from_fn(|i, j| a[(i, j)] * d[i] * d[j]);
    let inv = scaled.cholesky()?.inverse();
    Some(Mb::from_fn(|i, j| inv[(i, j)] * d[i] * d[j]))
}

impl Tracker {
    /// The tracker's transition over `dt` about state `x`: its Jacobian by
    /// central differences of the prediction, and its process noise (the
    /// prediction of a zero covariance). `attitude`: the frames carry an
    /// attitude reading, so the tracker steps as after one it fused (the
    /// sideslip's `side_tau_with_attitude_s`).
    fn transition(&self, x: &Vs, dt: f64, attitude: bool) -> (Ms, Ms) {
        let mut s = State::new(*x, Ms::zeros(), 0.0);
        s.attitude_fused = attitude;
        s.roll_free = !self.station.is_empty();
        let at = s;
        self.predict(&mut s, dt);
        let q = s.p;
        let mut f = Ms::zeros();
        for j in 0..NS {
            let h = 1e-6 * (1.0 + x[j].abs());
            let mut a = at;
            let mut b = a;
            a.x[j] += h;
            b.x[j] -= h;
            self.predict(&mut a, dt);
            self.predict(&mut b, dt);
            f.set_column(j, &((a.x - b.x) / (2.0 * h)));
        }
        (f, q)
    }

    /// The tracker's state at a point of the true track. The bound's K_D
    /// coordinate is K_D itself, not the tracker's ln K_D: its prior is the
    /// Monte Carlo's draw, Gaussian in K_D, and the transition leaves it
    /// alone either way.
    fn true_state(&self, p: &TrackPoint) -> Vs {
        let mut x = Vs::zeros();
        let q = from_pose(&p.pose);
        for i in 0..5 {
            x[i] = q[i];
        }
        for a in 0..3 {
            x[VEL + a] = p.velocity.0[a];
        }
        x[KD] = self.model.light.k_d;
        if !self.station.is_empty() {
            x[ROLL] = p.pose.roll.rad();
        }
        x
    }

    /// Add one frame's information: the light (uncensored channels of
    /// the true image, `bound_light`) and the own sensors' readings.
    /// Spec v3: the light is the true pose's, rolled by `roll` (rad; taken
    /// as known, as its reading gives it to the tracker to 0.3°).
    fn inform_frame(&self, p: &mut Mb, x: &Vs, roll: f64, sc: &TrackBoundScene) {
        let m = &self.model;
        let gt = lightpose_core::light::temperature_gain(sc.temp_c);
        let q = PoseVec::from_fn(|i, _| x[i]);
        let station = !self.station.is_empty();
        let images: Vec<[BoundChannel; NDET]> = if station {
            station_channels(m, &sc.light, &self.station, &q, x[ROLL], x[KD], gt)
        } else {
            vec![channels(m, &sc.light, &q, roll, x[KD], gt)]
        };
        for ch in &images {
            let mut h = SMatrix::<f64, NDET, NB>::zeros();
            let mut r = SVector::<f64, NDET>::from_element(1.0);
            for (k, c) in ch.iter().enumerate().filter(|(_, c)| c.used) {
                for j in 0..5 {
                    h[(k, j)] = c.grad[j];
                }
                h[(k, KD)] = c.grad[5];
                h[(k, GAIN)] = c.grad[6];
                if station {
                    h[(k, ROLL)] = c.grad[7];
                }
                r[k] = c.var;
            }
            inform(p, &h, &r);
        }
        if let Some(sr) = sc.roll.filter(|_| station) {
            let mut h = SMatrix::<f64, 1, NB>::zeros();
            h[(0, ROLL)] = 1.0;
            inform(p, &h, &SVector::<f64, 1>::new(sr * sr));
        }
        if let Some((sp, sy)) = sc.attitude {
            let mut h = SMatrix::<f64, 2, NB>::zeros();
            h[(0, 3)] = 1.0;
            h[(1, 4)] = 1.0;
            inform(p, &h, &SVector::<f64, 2>::new(sp * sp, sy * sy));
        }
        if let Some(sd) = sc.depth {
            let mut h = SMatrix::<f64, 1, NB>::zeros();
            h[(0, 2)] = 1.0;
            inform(p, &h, &SVector::<f64, 1>::new(sd * sd));
        }
        if let Some(sv) = sc.dvl {
            let mut h = SMatrix::<f64, 3, NB>::zeros();
            for a in 0..3 {
                h[(a, VEL + a)] = 1.0;
            }
            inform(p, &h, &SVector::<f64, 3>::from_element(sv * sv));
        }
    }

    /// The prior before the first frame: nothing on the pose (a vague
    /// 1 km / 1 rad), the start-up doubt of the rates, and the priors of
    /// K_D and of the common gain.
    fn bound_prior(&self, sc: &TrackBoundScene) -> Mb {
        let c = &self.cfg;
        let mut p = Mb::zeros();
        for i in 0..3 {
            p[(i, i)] = 1e6;
        }
        for i in 3..5 {
            p[(i, i)] = 1.0;
        }
        p[(VEL, VEL)] = c.init_velocity_sigma.powi(2);
        p[(VEL + 1, VEL + 1)] = c.side_sigma.powi(2);
        p[(VEL + 2, VEL + 2)] = c.side_sigma.powi(2);
        for i in 8..10 {
            p[(i, i)] = c.init_rate_sigma_deg.to_radians().powi(2);
        }
        p[(KD, KD)] = sc.sigma_k_d.unwrap_or(0.0).powi(2);
        let sg = sc.sigma_temp_c.map_or(0.0, |s| {
            s * lightpose_core::light::temperature_gain_slope(sc.temp_c)
        });
        p[(GAIN, GAIN)] = sg * sg;
        // A station's roll starts at the tracker's prior; one beacon's is
        // known (0 variance: left out of every update).
        if !self.station.is_empty() {
            p[(ROLL, ROLL)] = self.station_roll_prior().powi(2);
        }
        p
    }

    /// The bound at every point of `track` (in time order).
    pub fn track_bound(&self, track: &[TrackPoint], sc: &TrackBoundScene) -> Vec<TrackBound> {
        let mut p = self.bound_prior(sc);
        let mut out = Vec::with_capacity(track.len());
        let mut last: Option<(f64, Vs)> = None;
        for pt in track {
            let x = self.true_state(pt);
            if let Some((t0, x0)) = last {
                let (f, q) = self.transition(&x0, pt.t - t0, sc.attitude.is_some());
                let mut fb = Mb::identity();
                let mut qb = Mb::zeros();
                for i in 0..NS {
                    for j in 0..NS {
                        fb[(i, j)] = f[(i, j)];
                        qb[(i, j)] = q[(i, j)];
                    }
                }
                let pn = fb * p * fb.transpose() + qb;
                p = (pn + pn.transpose()) * 0.5;
            }
            self.inform_frame(&mut p, &x, pt.pose.roll.rad(), sc);
            last = Some((pt.t, x));
            let sd = |i: usize| p[(i, i)].max(0.0).sqrt();
            out.push(TrackBound {
                x: sd(0),
                y: sd(1),
                z: sd(2),
                pitch_deg: sd(3).to_degrees(),
                yaw_deg: sd(4).to_degrees(),
                surge: sd(VEL),
                roll_deg: sd(ROLL).to_degrees(),
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::SensorModel;
    use crate::settings::TrackerConfig;
    use lightpose_core::Angle;

    fn approach() -> Vec<TrackPoint> {
        (0..41)
            .map(|i| {
                let t = i as f64 * 0.2;
                TrackPoint {
                    t,
                    pose: Pose::new(8.5 - 0.5 * t, 0.1, 0.2, Angle::from_deg(2.0), Angle::ZERO),
                    velocity: BodyVec([0.5, 0.0, 0.0]),
                }
            })
            .collect()
    }

    /// Information only adds: every sensor narrows the bound; the DVL
    /// narrows surge most, depth z; and pooling frames beats one frame.
    #[test]
    fn every_sensor_narrows_the_bound_and_frames_pool() {
        let tr = Tracker::new(SensorModel::default(), TrackerConfig::default()).unwrap();
        let base = TrackBoundScene {
            temp_c: 20.0,
            sigma_k_d: Some(0.015),
            sigma_temp_c: Some(3.0),
            attitude: Some((0.3f64.to_radians(), 1.5f64.to_radians())),
            roll: None,
            depth: None,
            dvl: None,
            light: BoundLight::default(),
        };
        let track = approach();
        let att = tr.track_bound(&track, &base);
        let all = tr.track_bound(
            &track,
            &TrackBoundScene {
                depth: Some(0.02),
                dvl: Some(0.02),
                ..base
            },
        );
        for (a, b) in att.iter().zip(&all) {
            assert!(b.x <= a.x * 1.0001 && b.z <= a.z * 1.0001, "{a:?} {b:?}");
            assert!(b.surge <= a.surge * 1.0001, "{a:?} {b:?}");
        }
        let end = all.last().unwrap();
        assert!(end.z < 0.02 && end.surge < 0.02, "{end:?}");
        // Later frames know more than the first.
        assert!(att[40].y < att[0].y && att[40].surge < att[0].surge);
    }

    /// A vehicle holding still near the beacon: the first frame's bound is
    /// one frame's (a little under it, for the prior of the angles), never
    /// 0, and pooling frames only narrows it. The covariance form had
    /// rounded x's bound to 0 within 7 m.
    #[test]
    fn the_first_frame_s_bound_is_one_frame_s_at_any_range() {
        let model = SensorModel::default();
        let tr = Tracker::new(model.clone(), TrackerConfig::default()).unwrap();
        let sc = TrackBoundScene {
            temp_c: 20.0,
            sigma_k_d: Some(0.015),
            sigma_temp_c: Some(3.0),
            attitude: None,
            roll: None,
            depth: None,
            dvl: None,
            light: BoundLight::default(),
        };
        for x in [4.0, 5.0, 6.0, 7.0, 8.5] {
            let pose = Pose::new(x, 0.0, 0.0, Angle::ZERO, Angle::ZERO);
            let still: Vec<_> = (0..10)
                .map(|i| TrackPoint {
                    t: i as f64 * 0.2,
                    pose,
                    velocity: BodyVec([0.0; 3]),
                })
                .collect();
            let b = tr.track_bound(&still, &sc);
            let one = crate::model::crb::crb_along(
                &crate::model::crb::CrbScene::montecarlo(model.clone()),
                &[pose],
            )[0];
            let ratio = b[0].x / one.x;
            assert!(
                (0.8..=1.0001).contains(&ratio),
                "x = {x}: {:?} against {one:?}",
                b[0]
            );
            for w in b.windows(2) {
                assert!(w[1].x > 0.0 && w[1].x <= w[0].x * 1.0001, "x = {x}: {w:?}");
            }
        }
    }

    /// The bound believes the tracker's motion model as the tracker runs
    /// it: with attitude readings the sideslip's memory is
    /// `side_tau_with_attitude_s`, without them `side_tau_s`.
    #[test]
    fn the_bound_steps_as_the_tracker_does_with_and_without_the_attitude() {
        let short = TrackerConfig {
            side_tau_with_attitude_s: TrackerConfig::default().side_tau_s,
            ..TrackerConfig::default()
        };
        let scene = |attitude| TrackBoundScene {
            temp_c: 20.0,
            sigma_k_d: Some(0.015),
            sigma_temp_c: Some(3.0),
            attitude,
            roll: None,
            depth: Some(0.02),
            dvl: Some(0.02),
            light: BoundLight::default(),
        };
        let track = approach();
        let bound = |cfg: &TrackerConfig, att| {
            let tr = Tracker::new(SensorModel::default(), cfg.clone()).unwrap();
            *tr.track_bound(&track, &scene(att)).last().unwrap()
        };
        let ahrs = Some((0.3f64.to_radians(), 1.5f64.to_radians()));
        let (long, brief) = (bound(&TrackerConfig::default(), ahrs), bound(&short, ahrs));
        // A longer memory is more prior information on the sideslip.
        assert!(long.y < brief.y * 0.95, "{long:?} {brief:?}");
        assert!(long.z <= brief.z, "{long:?} {brief:?}");
        // Without attitude readings the setting is not used.
        assert_eq!(bound(&TrackerConfig::default(), None), bound(&short, None));
    }
}
