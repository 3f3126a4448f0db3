//! The vehicle's own sensors in the tracker (spec v2): attitude (pitch,
//! yaw), depth (the depth sensor's z in B) and DVL velocity (body frame).
//!
//! Each reading is checked on its own before it is used — numbers finite,
//! its own `std` (if it gives one) positive, its value one a vehicle that
//! sees the beacon can have — then fused as a linear(ized) Kalman update
//! with an innovation gate. A reading that fails is refused with its
//! reason and changes nothing; the frame's counts still update the pose.
//! Noise: the reading's own `std`, else the tracker's setting (whose
//! default is MODEL.md's sensor).
//!
//! Measurement models (state in `state.rs`):
//! - attitude: (θ, ψ), the yaw innovation wrapped to ±π;
//! - depth: z + (R_BV·lever)_z = z + l_f·sin θ − l_d·cos θ, the lever arm
//!   from the dome centre to the sensor in V (docs/spec-notes.md); rolled
//!   by φ, z + l_f·sin θ − (l_r·sin φ + l_d·cos φ)·cos θ;
//! - velocity: the body model's (u, v, w) directly; with the world model
//!   R_BVᵀ·v, linearized in θ, ψ and v.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::model::normal::erfc;
use lightpose_core::{AttitudeReading, Frame, ReadingUse, Refusal, NDET};
use nalgebra::{SMatrix, SVector};

use super::counts::commit;
use super::state::{k_d_of, Ms, State, DOFF, KD, NS, POFF, VEL};
use super::Tracker;
use crate::model::measurement::Measurement;
use crate::model::solver::Censoring;
use crate::settings::{Motion, TrackerConfig};

/// A reading that passed the checks: its values and 1σ per component.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Checked<const M: usize> {
    pub z: SVector<f64, M>,
    pub sigma: SVector<f64, M>,
}

/// The paper's range of one frame as the tracker reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PaperReading {
    /// As a reading of x: the law's residual and the counts' noise.
    pub range: Checked<1>,
    /// The counts' noise alone through the law, m (1σ).
    pub noise: f64,
    pub t: f64,
    /// What the law reads off the light model's own frame at the state,
    /// minus the state's x: its bias where the filter puts the vehicle.
    pub model_bias: Option<f64>,
}

/// What the paper range's change may move: x and the three velocities
/// (see `Tracker::update_paper_rate`).
const RATE_MOVES: [bool; NS] = {
    let mut m = [false; NS];
    m[0] = true;
    m[VEL] = true;
    m[VEL + 1] = true;
    m[VEL + 2] = true;
    m
};

/// A reading before the gate: nothing to do, or ready to fuse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Pending<const M: usize> {
    /// Absent, ignored by the settings, or refused by a check: the verdict.
    Done(ReadingUse),
    Ready(Checked<M>),
}

impl<const M: usize> Pending<M> {
    pub fn ready(&self) -> Option<&Checked<M>> {
        match self {
            Pending::Ready(c) => Some(c),
            Pending::Done(_) => None,
        }
    }

    /// Held back as at odds with the light, if it was ready to fuse.
    fn refused_by_light(&self) -> Pending<M> {
        match self {
            Pending::Ready(_) => Pending::Done(ReadingUse::Refused(Refusal::Light)),
            done => *done,
        }
    }

    /// The verdict if the reading, when ready, was fused as it is.
    pub fn if_fused(&self) -> ReadingUse {
        match self {
            Pending::Ready(_) => ReadingUse::Used,
            Pending::Done(u) => *u,
        }
    }
}

/// A frame's three readings, checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct FrameReadings {
    pub attitude: Pending<2>,
    pub depth: Pending<1>,
    pub velocity: Pending<3>,
}

impl FrameReadings {
    /// The same readings for a start from the light alone: the depth
    /// (and the attitude, with `attitude`) refused as at odds with the
    /// light; the gate judges them once the light has a track.
    ///
    /// Only a reading ready to fuse is refused: one absent or already
    /// refused keeps its verdict (an audit: a frame without a depth was
    /// counted `refused_light` on such a start).
    pub fn for_light_alone(&self, attitude: bool) -> FrameReadings {
        FrameReadings {
            attitude: if attitude {
                self.attitude.refused_by_light()
            } else {
                self.attitude
            },
            depth: self.depth.refused_by_light(),
            velocity: self.velocity,
        }
    }
}

/// The verdict of a value check: finite values, a positive finite std
/// where the reading gives one, values within `limit`.
pub(crate) fn check<const M: usize>(
    z: [f64; M],
    own_std: Option<[f64; M]>,
    default_std: [f64; M],
    limit: [f64; M],
) -> Pending<M> {
    if !z.iter().all(|v| v.is_finite()) {
        return Pending::Done(ReadingUse::Refused(Refusal::NotFinite));
    }
    let sigma = match own_std {
        Some(s) if s.iter().all(|v| v.is_finite() && *v > 0.0) => s,
        Some(_) => return Pending::Done(ReadingUse::Refused(Refusal::BadStd)),
        None => default_std,
    };
    if z.iter().zip(&limit).any(|(v, l)| !(v.abs() <= *l)) {
        return Pending::Done(ReadingUse::Refused(Refusal::Implausible));
    }
    Pending::Ready(Checked {
        z: SVector::from(z),
        sigma: SVector::from(sigma),
    })
}

/// An attitude reading's check (radians), its noise its own `std` or
/// `sigma_deg` (pitch, yaw): pitch beyond ±90° or yaw beyond ±180° is no
/// attitude at all. The tracker's and the single-frame fit's alike.
pub(crate) fn check_attitude(a: &AttitudeReading, sigma_deg: [f64; 2]) -> Pending<2> {
    check(
        [a.pitch.rad(), a.yaw.rad()],
        a.std.map(|s| [s.pitch.rad(), s.yaw.rad()]),
        sigma_deg.map(f64::to_radians),
        [
            std::f64::consts::FRAC_PI_2 * (1.0 - 1e-9),
            std::f64::consts::PI,
        ],
    )
}

impl FrameReadings {
    /// Check each of `frame`'s readings against `cfg`.
    pub fn check(frame: &Frame, cfg: &TrackerConfig) -> FrameReadings {
        let (absent, ignored) = (ReadingUse::Absent, ReadingUse::Ignored);
        let attitude = match frame.attitude {
            None => Pending::Done(absent),
            Some(_) if !cfg.use_attitude => Pending::Done(ignored),
            Some(a) => check_attitude(
                &a,
                [cfg.attitude_sigma_pitch_deg, cfg.attitude_sigma_yaw_deg],
            ),
        };
        let depth = match frame.depth {
            None => Pending::Done(absent),
            Some(_) if !cfg.use_depth => Pending::Done(ignored),
            Some(d) => check(
                [d.z],
                d.std.map(|s| [s]),
                [cfg.depth_sigma_m],
                [cfg.depth_limit_m],
            ),
        };
        let velocity = match frame.velocity {
            None => Pending::Done(absent),
            Some(_) if !cfg.use_velocity => Pending::Done(ignored),
            Some(v) => check(
                v.v.0,
                v.std.map(|s| s.0),
                [cfg.velocity_sigma_mps; 3],
                [cfg.velocity_limit_mps; 3],
            ),
        };
        FrameReadings {
            attitude,
            depth,
            velocity,
        }
    }
}

/// χ² survival function P(χ²_k > x) for k = 1, 2, 3.
fn chi2_survival(k: usize, x: f64) -> f64 {
    let h = (0.5 * x).max(0.0);
    match k {
        1 => erfc(h.sqrt()),
        2 => (-h).exp(),
        _ => erfc(h.sqrt()) + (2.0 * x.max(0.0) / std::f64::consts::PI).sqrt() * (-h).exp(),
    }
}

/// The χ² values with 1, 2 and 3 degrees of freedom that a consistent
/// reading exceeds with probability `p` (bisection on the survival
/// function).
pub(super) fn gate_thresholds(p: f64) -> [f64; 3] {
    [1, 2, 3].map(|k| {
        let (mut lo, mut hi) = (0.0f64, 2000.0f64);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if chi2_survival(k, mid) > p {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    })
}

/// A linear(ized) measurement of the state: prediction, Jacobian, and the
/// reading it is compared with.
struct Linear<const M: usize> {
    h: SVector<f64, M>,
    jac: SMatrix<f64, M, NS>,
}

/// Kalman update of `s` with reading `r` through `lin`; `wrap` marks
/// components that are angles (innovation wrapped to ±π). Refused (and `s`
/// untouched) when the innovation's χ² exceeds `gate`.
fn fuse<const M: usize>(
    s: &mut State,
    r: &Checked<M>,
    lin: &Linear<M>,
    wrap: [bool; M],
    gate: f64,
) -> ReadingUse {
    fuse_into(s, r, lin, wrap, gate, &[true; NS])
}

/// [`fuse`] of a reading of state component `i` alone (`value` ± `sd`,
/// an angle: the innovation wrapped). A station's roll (`station`).
pub(super) fn fuse_scalar(s: &mut State, i: usize, value: f64, sd: f64, gate: f64) -> ReadingUse {
    let mut jac = SMatrix::<f64, 1, NS>::zeros();
    jac[(0, i)] = 1.0;
    let lin = Linear {
        h: SVector::<f64, 1>::new(s.x[i]),
        jac,
    };
    let c = Checked {
        z: SVector::<f64, 1>::new(value),
        sigma: SVector::<f64, 1>::new(sd),
    };
    fuse(s, &c, &lin, [true], gate)
}

/// [`fuse`], and each component's normalized innovation ν_i/√S_ii
/// against `s` into `innov` (for the reading check, `agreement.rs`),
/// formed before the gate.
fn fuse_judged<const M: usize>(
    s: &mut State,
    r: &Checked<M>,
    lin: &Linear<M>,
    wrap: [bool; M],
    gate: f64,
    innov: &mut [Option<f64>],
) -> ReadingUse {
    fuse_with(s, r, lin, wrap, gate, &[true; NS], innov)
}

/// [`fuse`], moving only the state components marked in `moves` (the
/// Joseph form keeps P honest for the restricted gain).
fn fuse_into<const M: usize>(
    s: &mut State,
    r: &Checked<M>,
    lin: &Linear<M>,
    wrap: [bool; M],
    gate: f64,
    moves: &[bool; NS],
) -> ReadingUse {
    fuse_with(s, r, lin, wrap, gate, moves, &mut [])
}

/// [`fuse_into`], writing the first `innov.len()` components' normalized
/// innovations ν_i/√S_ii into `innov` (none for an empty slice).
fn fuse_with<const M: usize>(
    s: &mut State,
    r: &Checked<M>,
    lin: &Linear<M>,
    wrap: [bool; M],
    gate: f64,
    moves: &[bool; NS],
    innov: &mut [Option<f64>],
) -> ReadingUse {
    let mut y = r.z - lin.h;
    for (i, w) in wrap.iter().enumerate() {
        if *w {
            y[i] = (y[i] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
        }
    }
    let rm = SMatrix::<f64, M, M>::from_diagonal(&r.sigma.component_mul(&r.sigma));
    let sm = lin.jac * s.p * lin.jac.transpose() + rm;
    for (i, slot) in innov.iter_mut().enumerate().take(M) {
        *slot = Some(y[i] / sm[(i, i)].sqrt()).filter(|v| v.is_finite());
    }
    let Some(ch) = sm.cholesky() else {
        return ReadingUse::Refused(Refusal::Gate);
    };
    let nis = y.dot(&ch.solve(&y));
    if !(nis <= gate) {
        return ReadingUse::Refused(Refusal::Gate);
    }
    let mut k = s.p * lin.jac.transpose() * ch.inverse();
    s.consider(&mut k);
    for (i, m) in moves.iter().enumerate() {
        if !m {
            k.row_mut(i).fill(0.0);
        }
    }
    let ikh = Ms::identity() - k * lin.jac;
    let p = ikh * s.p * ikh.transpose() + k * rm * k.transpose();
    let x = s.x + k * y;
    let log_det: f64 = (0..M).map(|i| 2.0 * ch.l()[(i, i)].ln()).sum();
    if commit(s, x, p) {
        s.readings_ll -= 0.5 * (nis + log_det);
        ReadingUse::Used
    } else {
        ReadingUse::Refused(Refusal::Gate)
    }
}

impl Tracker {
    /// On a frame whose attitude no reading pinned: pitch and yaw are
    /// read as 0 (level, along the beam axis) with the variance that
    /// leaves each at `unmeasured_attitude_sigma_deg`² when its own is
    /// larger, and not at all when it is within (see the setting). A
    /// bound, not a reading that adds up: frame after frame it holds the
    /// σ at the setting, where the same reading each frame would shrink
    /// it without end.
    pub(super) fn bound_unmeasured_attitude(&self, s: &mut State) {
        let bound = self.cfg.unmeasured_attitude_sigma_deg.to_radians();
        if bound <= 0.0 {
            return;
        }
        let b2 = bound * bound;
        for i in [3, 4] {
            let v = s.p[(i, i)];
            if !(v > b2) {
                continue;
            }
            // 1/b² = 1/v + 1/r: the reading's variance r that takes v to b².
            let r = b2 * v / (v - b2);
            let mut jac = SMatrix::<f64, 1, NS>::zeros();
            jac[(0, i)] = 1.0;
            let lin = Linear {
                h: SVector::<f64, 1>::new(s.x[i]),
                jac,
            };
            let c = Checked {
                z: SVector::<f64, 1>::new(0.0),
                sigma: SVector::<f64, 1>::new(r.sqrt()),
            };
            fuse(s, &c, &lin, [true], f64::INFINITY);
        }
    }

    /// (θ, ψ) of the state as the attitude sensor reads them: its pitch
    /// offset added (0 with no doubt unless `pitch_offset_sigma_deg` asks
    /// for it).
    fn attitude_model(s: &State) -> Linear<2> {
        let mut jac = SMatrix::<f64, 2, NS>::zeros();
        jac[(0, 3)] = 1.0;
        jac[(0, POFF)] = 1.0;
        jac[(1, 4)] = 1.0;
        Linear {
            h: SVector::<f64, 2>::new(s.x[3] + s.x[POFF], s.x[4]),
            jac,
        }
    }

    /// The depth sensor's z: z + l_f·sin θ − l_d·cos θ, plus its offset
    /// (0 with no doubt unless `depth_offset_sigma_m` asks for it).
    fn depth_model(&self, s: &State) -> Linear<1> {
        let [lf, lr, ld] = self.cfg.depth_lever_arm_m;
        let (st, ct) = s.x[3].sin_cos();
        let mut jac = SMatrix::<f64, 1, NS>::zeros();
        jac[(0, 2)] = 1.0;
        jac[(0, DOFF)] = 1.0;
        let phi = s.roll_rad();
        if phi != 0.0 {
            // Rolled: R_BV's z row is (sθ, −sφ·cθ, −cφ·cθ), so the right
            // arm counts too.
            let (sr, cr) = phi.sin_cos();
            jac[(0, 3)] = lf * ct + (lr * sr + ld * cr) * st;
            let h = s.x[2] + lf * st - (lr * sr + ld * cr) * ct + s.x[DOFF];
            return Linear {
                h: SVector::<f64, 1>::new(h),
                jac,
            };
        }
        jac[(0, 3)] = lf * ct + ld * st;
        Linear {
            h: SVector::<f64, 1>::new(s.x[2] + lf * st - ld * ct + s.x[DOFF]),
            jac,
        }
    }

    /// The velocity in V (forward, right, down) that the DVL reads.
    fn velocity_model(&self, s: &State) -> Linear<3> {
        let mut jac = SMatrix::<f64, 3, NS>::zeros();
        match self.cfg.motion {
            Motion::Body => {
                for a in 0..3 {
                    jac[(a, VEL + a)] = 1.0;
                }
                Linear {
                    h: SVector::<f64, 3>::new(s.x[VEL], s.x[VEL + 1], s.x[VEL + 2]),
                    jac,
                }
            }
            Motion::World => {
                let (axes, [d_t, d_p]) = s.axes();
                let v = [s.x[VEL], s.x[VEL + 1], s.x[VEL + 2]];
                let dot = |a: &[f64; 3]| a[0] * v[0] + a[1] * v[1] + a[2] * v[2];
                let mut h = SVector::<f64, 3>::zeros();
                for a in 0..3 {
                    h[a] = dot(&axes[a]);
                    jac[(a, 3)] = dot(&d_t[a]);
                    jac[(a, 4)] = dot(&d_p[a]);
                    for j in 0..3 {
                        jac[(a, VEL + j)] = axes[a][j];
                    }
                }
                Linear { h, jac }
            }
        }
    }

    /// The paper's range of a frame (its on-axis law, eqs. 2–3: the
    /// frame's `law_reading`) as a reading of x, if configured.
    pub(super) fn paper_range(&self, law: Option<PaperReading>) -> Option<PaperReading> {
        law.filter(|_| self.cfg.paper_range)
    }

    /// The paper law's range of `frame` (light only: its brightest channel
    /// through the law), its channels classified as `kinds`: 1σ is the
    /// law's residual over the calibration grid (scaled, see
    /// `paper_range_sigma_scale`) and the counts' noise at the brightest
    /// channel through the law, σ_count/(peak·b1), in quadrature.
    ///
    /// None for counts by day (`daylight` set): the paper's moments read
    /// the sun's light as the beacon's, a range metres short under 2 V of
    /// it, and nothing in the law takes it out.
    pub(super) fn law_reading(&self, frame: &Frame, meas: &Measurement) -> Option<PaperReading> {
        if self.cfg.daylight.is_some() && !meas.is_amplitude() {
            return None;
        }
        let m = &self.model;
        let p = self.paper.as_ref()?;
        // The paper's moments read the whole image: a stuck channel, left
        // out of the fits, is read as its neighbours here.
        let z = Censoring::stand_in(m, meas);
        let cpv = m.counts_per_volt();
        let mut whole = *frame;
        match whole.amplitudes.as_mut().and_then(|a| {
            let n = a.n_beacons.min(a.beacons.len());
            a.beacons[..n]
                .iter_mut()
                .find(|b| b.beacon == crate::model::measurement::BEACON)
        }) {
            Some(b) => {
                for k in 0..NDET {
                    b.amplitude[k] = z[k] - m.offset_v[k] * cpv;
                }
            }
            None => whole.counts = z.map(|c| c as u16),
        }
        let frame = &whole;
        let x = p.est.range_of(frame)?;
        let (peak, k) = (0..NDET)
            .map(|k| (z[k] - m.offset_v[k] * cpv, k))
            .fold((f64::NEG_INFINITY, 0), |a, b| if b.0 > a.0 { b } else { a });
        let var = meas.variance(m, k, (peak / cpv / m.gain[k]).max(0.0));
        let noise = var.sqrt() / (peak.max(1.0) * p.b1.max(1e-3));
        let sigma = noise.hypot(p.bias(self.cfg.paper_range_sigma_scale));
        (sigma.is_finite() && sigma > 0.0).then(|| PaperReading {
            range: Checked {
                z: SVector::<f64, 1>::new(x),
                sigma: SVector::<f64, 1>::new(sigma),
            },
            noise,
            t: frame.t,
            model_bias: None,
        })
    }

    /// The paper law's bias at the state: its range read off the light
    /// model's own frame there (on the stack: nothing allocated), minus the
    /// state's x.
    pub(super) fn law_bias_at(&self, s: &State, frame: &Frame) -> Option<f64> {
        let m = &self.model;
        let q = crate::model::light::PoseVec::from_fn(|i, _| s.x[i]);
        let gt = super::gain_of(frame);
        let (pred, _) = crate::model::light::predict_rolled(m, &q, s.roll_rad(), k_d_of(&s.x), gt);
        let fs = m.full_scale();
        let mut f = Frame::new(
            frame.seq,
            frame.t,
            frame.adc_bits,
            [0; lightpose_core::NDET],
        );
        f.temp_c = frame.temp_c;
        for (c, p) in f.counts.iter_mut().zip(pred.iter()) {
            *c = p.round().clamp(0.0, fs) as u16;
        }
        let p = self.paper.as_ref()?;
        let x = p.est.range_of(&f)?;
        let b = x - s.x[0];
        b.is_finite().then_some(b)
    }

    /// Fuse the change of the paper's range over the last
    /// `paper_rate_frames` frames that had one as a measurement of ẋ (see
    /// `TrackerConfig::paper_rate`). It is read as the rate now, though it
    /// is the mean over its span (0.6 s at 5 Hz by default: a lag of 0.3 s,
    /// 0.02 m/s at the dock's 0.06 m/s²), and its ends' noise is taken as
    /// independent of what the state already holds of those ranges
    /// (through x, whose σ is the law's scaled residual, 2–10× the counts'
    /// noise). Only x and the velocities move: the bias's drift
    /// follows the off-axis geometry, and letting it move y, z, pitch and
    /// yaw widened their Monte Carlo spread by 17–29 % on the dive.
    pub(super) fn update_paper_rate(&self, s: &mut State, now: &PaperReading) -> ReadingUse {
        if !self.cfg.paper_rate {
            return ReadingUse::Absent;
        }
        let Some(prev) = s.paper_back(self.cfg.paper_rate_frames - 1) else {
            return ReadingUse::Absent;
        };
        let dt = now.t - prev.t;
        if !(dt > 1e-3 && dt <= self.cfg.max_gap_s) {
            return ReadingUse::Absent;
        }
        let mut rate = (now.range.z[0] - prev.range.z[0]) / dt;
        if let (Some(b1), Some(b0)) = (now.model_bias, prev.model_bias) {
            rate -= (b1 - b0) / dt;
        }
        let sigma = (now.noise.hypot(prev.noise) / dt).hypot(self.cfg.paper_rate_drift_mps);
        let c = Checked {
            z: SVector::<f64, 1>::new(rate),
            sigma: SVector::<f64, 1>::new(sigma),
        };
        fuse_into(
            s,
            &c,
            &self.x_rate_model(s),
            [false],
            self.gate[0],
            &RATE_MOVES,
        )
    }

    /// ẋ of the state as the paper range's change reads it: the velocity's
    /// component along B's x (the x row of the position's rate in
    /// `predict_body` / `predict_world`), scaled by the law's reading of
    /// the state's water (`paper_k_d_scale`).
    fn x_rate_model(&self, s: &State) -> Linear<1> {
        let mut jac = SMatrix::<f64, 1, NS>::zeros();
        let h = match self.cfg.motion {
            Motion::Body => {
                let (axes, [d_t, d_p]) = s.axes();
                let mut h = 0.0;
                for a in 0..3 {
                    let v = s.x[VEL + a];
                    h += v * axes[a][0];
                    jac[(0, VEL + a)] = axes[a][0];
                    jac[(0, 3)] += v * d_t[a][0];
                    jac[(0, 4)] += v * d_p[a][0];
                }
                h
            }
            Motion::World => {
                jac[(0, VEL)] = 1.0;
                s.x[VEL]
            }
        };
        // The law's range reads x·(1 + δ/b1), so its change ẋ·(1 + δ/b1).
        let (scale, per_k_d) = self.paper_k_d_scale(s);
        jac *= scale;
        jac[(0, KD)] = h * per_k_d;
        Linear {
            h: SVector::<f64, 1>::new(h * scale),
            jac,
        }
    }

    /// Fuse the paper's range as a measurement of x. The law was fitted
    /// in the calibration's water (K_D0): water with K_D0 + δ dims the
    /// peak by a further e^(−δ·x), which the law reads as range, so it
    /// reads x·(1 + δ/b1). That is its model, K_D's column and all, so that
    /// the range it pins holds K_D's doubt as the light's own range does.
    pub(super) fn update_paper_range(&self, s: &mut State, c: &Checked<1>) -> ReadingUse {
        let (scale, per_k_d) = self.paper_k_d_scale(s);
        let mut jac = SMatrix::<f64, 1, NS>::zeros();
        jac[(0, 0)] = scale;
        jac[(0, KD)] = s.x[0] * per_k_d;
        let lin = Linear {
            h: SVector::<f64, 1>::new(s.x[0] * scale),
            jac,
        };
        fuse(s, c, &lin, [false], self.gate[0])
    }

    /// How the paper's law scales a range (or its rate) in the state's
    /// water: 1 + (K_D − K_D0)/b1, and its slope in ln K_D, K_D/b1 (see
    /// `update_paper_range`); (1, 0) without the law.
    fn paper_k_d_scale(&self, s: &State) -> (f64, f64) {
        match &self.paper {
            Some(p) if p.b1 > 0.0 => {
                let k = k_d_of(&s.x);
                (1.0 + (k - p.k_d0) / p.b1, k / p.b1)
            }
            _ => (1.0, 0.0),
        }
    }

    /// Fuse the frame's checked readings into `s`, attitude first (it
    /// sharpens the other two's models): what became of each (attitude,
    /// depth, velocity), and each component's normalized innovation in
    /// [`lightpose_core::CHECKED`] order (`None`: no such reading).
    pub(super) fn update_readings(
        &self,
        s: &mut State,
        r: &FrameReadings,
    ) -> ([ReadingUse; 3], [Option<f64>; 6]) {
        let g = self.gate;
        let mut innov = [None; 6];
        let (att, rest) = innov.split_at_mut(2);
        let (dep, vel) = rest.split_at_mut(1);
        let attitude = match &r.attitude {
            Pending::Done(u) => *u,
            Pending::Ready(c) => {
                let lin = Self::attitude_model(s);
                fuse_judged(s, c, &lin, [false, true], g[1], att)
            }
        };
        let depth = match &r.depth {
            Pending::Done(u) => *u,
            Pending::Ready(c) => {
                let lin = self.depth_model(s);
                fuse_judged(s, c, &lin, [false], g[0], dep)
            }
        };
        let velocity = match &r.velocity {
            Pending::Done(u) => *u,
            Pending::Ready(c) => {
                let lin = self.velocity_model(s);
                fuse_judged(s, c, &lin, [false; 3], g[2], vel)
            }
        };
        ([attitude, depth, velocity], innov)
    }
}

#[cfg(test)]
mod tests {
    use super::super::state::Vs;
    use super::*;
    use crate::model::SensorModel;

    /// A state cruising at 0.4 m/s along the beam axis, a little off it.
    fn cruising() -> State {
        let mut x = Vs::zeros();
        // K_D 0.14 ± 0.01 (the state holds ln K_D).
        let (ln_k, sd_ln_k) = (0.14f64.ln(), 0.01 / 0.14);
        x.copy_from_slice(&[
            6.0, 0.1, 0.2, 0.05, 0.02, 0.4, 0.0, 0.0, 0.0, 0.0, ln_k, 0.0, 0.0, 0.0,
        ]);
        // The sensors' offsets and roll held at 0 with no doubt (the
        // default).
        let sd = [
            0.3, 0.2, 0.2, 0.1, 0.1, 0.15, 0.05, 0.05, 0.05, 0.05, sd_ln_k, 0.0, 0.0, 0.0,
        ];
        let p = Ms::from_diagonal(&Vs::from_iterator(sd.iter().map(|s| s * s)));
        State::new(x, p, 0.6)
    }

    fn reading(t: f64, range: f64) -> PaperReading {
        PaperReading {
            range: Checked {
                z: SVector::<f64, 1>::new(range),
                sigma: SVector::<f64, 1>::new(0.15),
            },
            noise: 0.01,
            t,
            model_bias: None,
        }
    }

    #[test]
    fn the_paper_range_s_change_pulls_surge_and_moves_only_x_and_velocity() {
        let tr = Tracker::new(SensorModel::default(), TrackerConfig::default()).unwrap();
        let mut s = cruising();
        // Nothing to difference against yet.
        let now = reading(0.6, 6.0 - 0.6 * 0.2);
        assert_eq!(tr.update_paper_rate(&mut s, &now), ReadingUse::Absent);
        // The ranges say 0.2 m/s closing (x falls), the state 0.4 m/s; the
        // span is the default three frames back (0.6 s), not the last frame
        // (whose range is off by 5 cm: it must not be the one used).
        for (t, r) in [(0.0, 6.0), (0.2, 5.96), (0.4, 5.97)] {
            s.push_paper(reading(t, r));
        }
        let before = s;
        assert_eq!(tr.update_paper_rate(&mut s, &now), ReadingUse::Used);
        let u = s.x[VEL];
        assert!(u < 0.4 && u > 0.2, "surge {u} not pulled toward 0.2");
        assert!(s.p[(VEL, VEL)] < before.p[(VEL, VEL)]);
        for i in 1..5 {
            assert_eq!(s.x[i], before.x[i], "component {i} moved");
            assert!(
                (s.p[(i, i)] - before.p[(i, i)]).abs() < 1e-15,
                "σ of {i} moved"
            );
        }
        // Less noise at the ends pulls harder.
        let mut quiet = before;
        let mut sharp = now;
        sharp.noise = 0.001;
        tr.update_paper_rate(&mut quiet, &sharp);
        assert!(quiet.x[VEL] < u, "{} vs {u}", quiet.x[VEL]);
    }

    #[test]
    fn no_paper_rate_across_a_gap_or_when_turned_off() {
        let mut s = cruising();
        for (t, r) in [(0.0, 6.0), (0.2, 5.96), (0.4, 5.92)] {
            s.push_paper(reading(t, r));
        }
        let tr = Tracker::new(SensorModel::default(), TrackerConfig::default()).unwrap();
        let late = reading(0.0 + TrackerConfig::default().max_gap_s + 0.1, 5.0);
        assert_eq!(
            tr.update_paper_rate(&mut s.clone(), &late),
            ReadingUse::Absent
        );
        let cfg = TrackerConfig {
            paper_rate: false,
            ..TrackerConfig::default()
        };
        let off = Tracker::new(SensorModel::default(), cfg).unwrap();
        let now = reading(0.6, 5.88);
        assert_eq!(off.update_paper_rate(&mut s, &now), ReadingUse::Absent);
        // The ring keeps the newest `PAPER_RATE_MAX_FRAMES`, newest first.
        for k in 0..10 {
            s.push_paper(reading(1.0 + k as f64, k as f64));
        }
        assert_eq!(s.paper_back(0).map(|p| p.t), Some(10.0));
        assert_eq!(s.paper_back(7).map(|p| p.t), Some(3.0));
    }

    #[test]
    fn paper_rate_settings_are_checked() {
        for frames in [0, crate::settings::PAPER_RATE_MAX_FRAMES + 1] {
            let cfg = TrackerConfig {
                paper_rate_frames: frames,
                ..TrackerConfig::default()
            };
            let e = cfg.validate().unwrap_err().to_string();
            assert!(e.contains("paper_rate_frames"), "{e}");
        }
        let cfg = TrackerConfig {
            paper_rate_drift_mps: -0.1,
            ..TrackerConfig::default()
        };
        assert!(cfg.validate().is_err());
    }

    #[test]
    fn gate_thresholds_are_the_chi2_quantiles() {
        // Tables: χ²(0.999) = 10.83, 13.82, 16.27; χ²(0.95) = 3.84, 5.99, 7.81.
        let g = gate_thresholds(1e-3);
        for (a, b) in g.iter().zip([10.828, 13.816, 16.266]) {
            assert!((a - b).abs() < 2e-3, "{g:?}");
        }
        let g = gate_thresholds(0.05);
        for (a, b) in g.iter().zip([3.841, 5.991, 7.815]) {
            assert!((a - b).abs() < 2e-3, "{g:?}");
        }
        let g = gate_thresholds(1e-6);
        for (a, b) in g.iter().zip([23.928, 27.631, 30.664]) {
            assert!((a - b).abs() < 2e-2, "{g:?}");
        }
    }

    #[test]
    fn a_start_from_the_light_alone_refuses_only_readings_it_had() {
        let depth = Pending::Ready(Checked {
            z: SVector::from([3.0]),
            sigma: SVector::from([0.02]),
        });
        let not_finite = Pending::Done(ReadingUse::Refused(Refusal::NotFinite));
        let r = FrameReadings {
            attitude: Pending::Done(ReadingUse::Absent),
            depth,
            velocity: Pending::Done(ReadingUse::Absent),
        };
        let alone = r.for_light_alone(true);
        assert_eq!(alone.attitude, Pending::Done(ReadingUse::Absent));
        assert_eq!(
            alone.depth,
            Pending::Done(ReadingUse::Refused(Refusal::Light))
        );
        assert_eq!(alone.velocity, r.velocity);
        let r = FrameReadings {
            attitude: not_finite,
            depth: Pending::Done(ReadingUse::Absent),
            ..r
        };
        let alone = r.for_light_alone(true);
        assert_eq!(alone.attitude, not_finite);
        assert_eq!(alone.depth, Pending::Done(ReadingUse::Absent));
    }

    /// The tracker with the shipped tank calibration's light model and
    /// paper's estimator.
    fn tank_tracker() -> Tracker {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/calibration/tank.toml");
        let cal = crate::calibration::Calibration::load(&path).expect("tank calibration");
        let m = cal.physical.as_ref().expect("light model").sensor_model();
        Tracker::new(m, TrackerConfig::default())
            .expect("tracker")
            .with_paper(&cal)
    }

    #[test]
    fn the_paper_range_pins_x_only_outside_k_d_s_doubt() {
        let tr = tank_tracker();
        let pinned = |sigma_k_d: f64| {
            let mut s = cruising();
            s.x[KD] = super::super::state::ln_k_d(tr.model.light.k_d);
            s.doubt_k_d(sigma_k_d);
            let c = Checked {
                z: SVector::<f64, 1>::new(s.x[0]),
                sigma: SVector::<f64, 1>::new(0.6),
            };
            assert_eq!(tr.update_paper_range(&mut s, &c), ReadingUse::Used);
            s.sd(0)
        };
        // The law reads water with K_D0 + δ as range x·(1 + δ/b1), as the
        // light's own range does: a doubt of ±0.3 m⁻¹ about 0.09 (in ln
        // K_D, +1σ at 0.39, −1σ at 0.021) is 2.2 m nearer and 1.3 m
        // farther at 6 m, which the reading must not take away; without a
        // doubt it pins x within its own σ.
        let (wide, none) = (pinned(0.3), pinned(0.0));
        assert!(wide > 1.5, "σx {wide} with K_D ± 0.3");
        assert!(none < 0.6, "σx {none} with K_D known");
        // Its model is the law's reading of the state's water.
        let mut s = cruising();
        let k = tr.model.light.k_d + 0.1;
        s.x[KD] = super::super::state::ln_k_d(k);
        let (scale, per) = tr.paper_k_d_scale(&s);
        let b1 = tr.paper.as_ref().expect("paper").b1;
        assert!((per - k / b1).abs() < 1e-12, "slope per ln K_D");
        assert!((scale - (1.0 + 0.1 / b1)).abs() < 1e-12);
    }

    #[test]
    fn the_paper_rate_takes_out_the_law_s_predicted_drift() {
        let tr = Tracker::new(SensorModel::default(), TrackerConfig::default()).unwrap();
        // The vehicle closes at 0.4 m/s (as the state says) while the law's
        // bias grows by 0.12 m over the 0.6 s span: the ranges fall at only
        // 0.2 m/s. Told that drift, the rate reads 0.4 and leaves surge;
        // not told, it pulls surge toward 0.2.
        let run = |told: bool| {
            let mut s = cruising();
            for (i, t) in [0.0, 0.2, 0.4, 0.6].into_iter().enumerate() {
                let bias = 0.2 * t;
                let mut r = reading(t, 6.0 - 0.4 * t + bias);
                r.model_bias = told.then_some(bias);
                if i < 3 {
                    s.push_paper(r);
                } else {
                    assert_eq!(tr.update_paper_rate(&mut s, &r), ReadingUse::Used);
                }
            }
            s.x[VEL]
        };
        let (told, not) = (run(true), run(false));
        // (The state's ẋ is 0.4·cos θ·cos ψ, a hair under 0.4.)
        assert!(
            (told - 0.4).abs() < 2e-3,
            "surge {told} moved though the rate agreed"
        );
        assert!(not < 0.39, "surge {not} not pulled by the drift");
    }
}
