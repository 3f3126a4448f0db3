//! The station's fit itself: per-pose mean amplitudes of every beacon as
//! weighted residuals of the light equation (`model::light`'s
//! `predict_beacon`, the one light model), their Jacobian, the shared
//! Levenberg–Marquardt, the covariance with every parameter checked
//! determined, and the `[physical]` table the estimators take.
//!
//! Parameters, in order: each beacon's V1 and σ_b (rad), K_D, σ_R (rad),
//! ω and σ_h (rad) with scattering; the 24 free gains (the 25th is 25 − Σ
//! others); with a survey check of beacon d, d's position offset (m, D)
//! and axis offset (yaw, pitch, rad).

// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::frame::full_scale;
use lightpose_core::{Angle, ArrayGeometry, LightParams, Pose, Scattering, NDET};
use nalgebra::{DMatrix, DVector, SVector};

use super::{CalibError, StationFitOptions, StationFitter};
use crate::calibration::lm::levenberg_marquardt;
use crate::calibration::physical_fit::fisher::determined_named;
use crate::calibration::physical_fit::{gain_estimates, gains_of, noise_line, rms_per_channel};
use crate::calibration::station::{Station, SurveyedBeacon};
use crate::calibration::{ParamEstimate, PhysicalCalibration};
use crate::model::light::Placement;
use crate::model::light::{from_pose, predict_beacon, predict_beacon_with_grad, BeaconLight};
use crate::model::SensorModel;

type Counts = SVector<f64, NDET>;

/// One observation: a pose's mean amplitude of one beacon on one channel.
pub(super) struct Obs {
    pub group: usize,
    pub beacon: usize,
    pub k: usize,
    pub mean: f64,
    pub se: f64,
    /// The demodulator's variance of one frame's amplitude (counts²).
    var: f64,
    /// The mean's variance from that noise alone (`se` less the model's
    /// error).
    pub noise_var: f64,
}

/// The fit's data: per-pose means and the survey they are fitted against.
pub(super) struct Data {
    poses: Vec<Pose>,
    gts: Vec<f64>,
    pub obs: Vec<Obs>,
    pub survey: Vec<SurveyedBeacon>,
    bits: u8,
    v_ref: f64,
    geometry: ArrayGeometry,
    pub frames: u64,
}

/// A converged fit: its parameters, normalized residuals and covariance
/// (scaled by χ²/dof when that is above 1).
pub(super) struct Fitted {
    pub scat: bool,
    pub p: Vec<f64>,
    pub r: DVector<f64>,
    pub cov: DMatrix<f64>,
    /// Each observation's predicted amplitude's variance from `cov`
    /// (counts²): what the fitted parameters do not know there.
    pub pred_var: DVector<f64>,
    pub cost: f64,
    pub chi2_per_dof: f64,
}

/// Where the fit's parameters sit for `nb` beacons.
#[derive(Clone, Copy)]
pub(super) struct Layout {
    pub nb: usize,
    pub scat: bool,
}

impl Layout {
    pub fn v1(self, b: usize) -> usize {
        2 * b
    }
    pub fn sigma_b(self, b: usize) -> usize {
        2 * b + 1
    }
    pub fn k_d(self) -> usize {
        2 * self.nb
    }
    pub fn sigma_r(self) -> usize {
        2 * self.nb + 1
    }
    /// The light parameters (all positive): the first `np` of the vector.
    pub fn np(self) -> usize {
        2 * self.nb + if self.scat { 4 } else { 2 }
    }
    /// The first survey offset, when the survey is checked.
    pub fn diag(self) -> usize {
        self.np() + NDET - 1
    }
    /// Beacon b's five survey offsets start here.
    pub fn offsets(self, b: usize) -> usize {
        self.diag() + 5 * b
    }
}

/// Standard error of a mean of `n` amplitudes whose demodulator variance is
/// `var` each, with the amplitude model's relative error of the mean (it
/// does not average out over a pose's frames); the quantization floor
/// keeps a noise-free channel's weight finite.
fn standard_error(var: f64, n: f64, mean: f64, rel: f64) -> f64 {
    (var.max(1.0 / 12.0) / n + (rel * mean).powi(2)).sqrt()
}

impl Data {
    /// The per-pose means of the groups with at least `o.min_samples`
    /// frames (clipped channels left out).
    pub fn build(
        fitter: &StationFitter,
        station: &Station,
        o: &StationFitOptions,
        bits: u8,
    ) -> Result<Data, CalibError> {
        let (mut poses, mut gts, mut obs) = (Vec::new(), Vec::new(), Vec::new());
        for g in fitter.groups.iter().filter(|g| g.n >= o.min_samples) {
            let gi = poses.len();
            for (b, img) in g.images.iter().enumerate() {
                for k in 0..NDET {
                    if img.clipped[k] || img.n[k] < o.min_samples {
                        continue;
                    }
                    let n = img.n[k] as f64;
                    let (mean, var) = (img.sum[k] / n, img.var[k] / n);
                    obs.push(Obs {
                        group: gi,
                        beacon: b,
                        k,
                        mean,
                        se: standard_error(var, n, mean, o.model_rel),
                        var,
                        noise_var: standard_error(var, n, mean, 0.0).powi(2),
                    });
                }
            }
            poses.push(g.pose);
            gts.push(g.gt_sum / g.n as f64);
        }
        if poses.is_empty() {
            let frames: u64 = fitter.groups.iter().map(|g| g.n).sum();
            return Err(match frames {
                0 => CalibError::NoTruth,
                n => CalibError::NoRepeatedPose(o.min_samples, n),
            });
        }
        Ok(Data {
            poses,
            gts,
            obs,
            survey: station.beacons.clone(),
            bits,
            v_ref: o.v_ref,
            geometry: o.geometry,
            frames: fitter.frames,
        })
    }

    pub fn layout(&self, scat: bool) -> Layout {
        Layout {
            nb: self.survey.len(),
            scat,
        }
    }

    pub fn poses(&self) -> usize {
        self.poses.len()
    }

    fn cpv(&self) -> f64 {
        full_scale(self.bits) as f64 / self.v_ref
    }

    /// The array and water at `p` (offsets 0: amplitudes have none).
    fn model(&self, p: &[f64], l: Layout) -> SensorModel {
        SensorModel {
            light: LightParams {
                v1: p[l.v1(0)],
                sigma_b: Angle::from_rad(p[l.sigma_b(0)]),
                sigma_r: Angle::from_rad(p[l.sigma_r()]),
                k_d: p[l.k_d()],
                scattering: l.scat.then(|| Scattering {
                    omega: p[l.sigma_r() + 1],
                    sigma_h: Angle::from_rad(p[l.sigma_r() + 2]),
                }),
            },
            geometry: self.geometry,
            gain: gains_of(p, l.np()),
            offset_v: [0.0; NDET],
            v_ref: self.v_ref,
            adc_bits: self.bits,
            sigma_e_v: 0.0,
            kappa_v: 0.0,
            k_d_sigma: 0.0,
        }
    }

    /// Beacon `b` at `p`: its surveyed placement, moved by the offsets at
    /// its offsets at `p[l.offsets(b)..]` when the survey is checked.
    fn beacon(&self, p: &[f64], l: Layout, b: usize, diag: bool) -> BeaconLight {
        let s = &self.survey[b];
        let place = if diag {
            let d = &p[l.offsets(b)..l.offsets(b) + 5];
            let c = s.position_m;
            Placement::new(
                [c[0] + d[0], c[1] + d[1], c[2] + d[2]],
                Angle::from_rad(s.axis_yaw_deg.to_radians() + d[3]),
                Angle::from_rad(s.axis_pitch_deg.to_radians() + d[4]),
            )
        } else {
            s.placement()
        };
        BeaconLight {
            v1: p[l.v1(b)],
            sigma_b: Angle::from_rad(p[l.sigma_b(b)]),
            place,
            // The fit weighs its means by `StationFitOptions::model_rel`.
            model_rel: 0.0,
        }
    }

    /// Predicted amplitude of every (pose, beacon), index g·nb + b; only
    /// beacon `only` when given (the others left 0).
    fn predict(&self, p: &[f64], l: Layout, diag: bool, only: Option<usize>) -> Vec<Counts> {
        let m = self.model(p, l);
        let mut out = vec![Counts::zeros(); self.poses.len() * l.nb];
        for (g, pose) in self.poses.iter().enumerate() {
            for b in (0..l.nb).filter(|b| only.is_none_or(|o| o == *b)) {
                let bl = self.beacon(p, l, b, diag);
                let q = from_pose(pose);
                let k_d = p[l.k_d()];
                out[g * l.nb + b] =
                    predict_beacon(&m, Some(&bl), &q, pose.roll.rad(), k_d, self.gts[g]).0;
            }
        }
        out
    }

    /// The parameters differentiated numerically: every σ_b, σ_R, the
    /// scattering term's, and the checked beacon's axis; each with the
    /// beacon it alone moves (None: all).
    fn numeric_columns(&self, l: Layout, diag: bool) -> Vec<(usize, Option<usize>)> {
        let mut v: Vec<(usize, Option<usize>)> =
            (0..l.nb).map(|b| (l.sigma_b(b), Some(b))).collect();
        v.extend((l.sigma_r()..l.np()).map(|a| (a, None)));
        if diag {
            for b in 0..l.nb {
                v.extend([(l.offsets(b) + 3, Some(b)), (l.offsets(b) + 4, Some(b))]);
            }
        }
        v
    }

    /// Normalized residuals and (optionally) the Jacobian.
    fn eval(
        &self,
        p: &[f64],
        l: Layout,
        diag: bool,
        jac: Option<&mut DMatrix<f64>>,
    ) -> DVector<f64> {
        let mut r = DVector::zeros(self.obs.len());
        let Some(j) = jac else {
            let pred = self.predict(p, l, diag, None);
            for (i, ob) in self.obs.iter().enumerate() {
                r[i] = (pred[ob.group * l.nb + ob.beacon][ob.k] - ob.mean) / ob.se;
            }
            return r;
        };
        j.fill(0.0);
        let m = self.model(p, l);
        let nb = l.nb;
        // Analytic: the amplitude, ∂/∂K_D and ∂/∂(x, y, z) of the dome.
        let mut pred = vec![Counts::zeros(); self.poses.len() * nb];
        let mut grad = vec![[Counts::zeros(); 4]; self.poses.len() * nb];
        for (g, pose) in self.poses.iter().enumerate() {
            for b in 0..nb {
                let bl = self.beacon(p, l, b, diag);
                let (c, _, jp, _) = predict_beacon_with_grad(
                    &m,
                    Some(&bl),
                    &from_pose(pose),
                    pose.roll.rad(),
                    p[l.k_d()],
                    self.gts[g],
                );
                pred[g * nb + b] = c;
                grad[g * nb + b] = [5, 0, 1, 2].map(|c| jp.column(c).clone_owned());
            }
        }
        let numeric: Vec<(usize, Vec<Counts>)> = self
            .numeric_columns(l, diag)
            .into_iter()
            .map(|(a, only)| {
                let h = 1e-5 * p[a].abs().max(1e-3);
                let (mut pp, mut pm) = (p.to_vec(), p.to_vec());
                pp[a] += h;
                pm[a] -= h;
                let (up, down) = (
                    self.predict(&pp, l, diag, only),
                    self.predict(&pm, l, diag, only),
                );
                let d = up
                    .iter()
                    .zip(&down)
                    .map(|(u, w)| (u - w) / (2.0 * h))
                    .collect();
                (a, d)
            })
            .collect();
        let gains = gains_of(p, l.np());
        for (i, ob) in self.obs.iter().enumerate() {
            let at = ob.group * nb + ob.beacon;
            let c = pred[at][ob.k];
            r[i] = (c - ob.mean) / ob.se;
            let s = 1.0 / ob.se;
            j[(i, l.v1(ob.beacon))] = c / p[l.v1(ob.beacon)] * s;
            j[(i, l.k_d())] = grad[at][0][ob.k] * s;
            for (a, d) in &numeric {
                j[(i, *a)] = d[at][ob.k] * s;
            }
            let el = c / gains[ob.k] * s;
            if ob.k < NDET - 1 {
                j[(i, l.np() + ob.k)] += el;
            } else {
                for q in 0..NDET - 1 {
                    j[(i, l.np() + q)] -= el;
                }
            }
            if diag {
                // p_k − c_b: moving the beacon is moving the dome back.
                for a in 0..3 {
                    j[(i, l.offsets(ob.beacon) + a)] = -grad[at][1 + a][ob.k] * s;
                }
            }
        }
        r
    }

    /// Where the main fit starts: MODEL.md's defaults for the shapes, each
    /// V1 scaled to its own images.
    fn start(&self, l: Layout) -> Vec<f64> {
        let def = LightParams::default();
        let mut p = vec![0.0; l.diag()];
        for b in 0..l.nb {
            p[l.v1(b)] = 1.0;
            p[l.sigma_b(b)] = def.sigma_b.rad();
        }
        p[l.k_d()] = def.k_d;
        p[l.sigma_r()] = def.sigma_r.rad();
        if l.scat {
            p[l.sigma_r() + 1] = 0.5;
            p[l.sigma_r() + 2] = 20f64.to_radians();
        }
        for k in 0..NDET - 1 {
            p[l.np() + k] = 1.0;
        }
        let pred = self.predict(&p, l, false, None);
        let (mut num, mut den) = (vec![0.0; l.nb], vec![0.0; l.nb]);
        for ob in &self.obs {
            let c = pred[ob.group * l.nb + ob.beacon][ob.k];
            num[ob.beacon] += c * ob.mean / (ob.se * ob.se);
            den[ob.beacon] += c * c / (ob.se * ob.se);
        }
        for b in 0..l.nb {
            if num[b] > 0.0 && den[b] > 0.0 {
                p[l.v1(b)] = num[b] / den[b];
            }
        }
        p
    }

    /// The name of parameter `i` in a refusal.
    fn name(&self, l: Layout, i: usize) -> String {
        let id = |b: usize| &self.survey[b].id;
        let shared = ["k_d", "sigma_r", "omega", "sigma_h"];
        let offsets = ["x", "y", "z", "axis_yaw", "axis_pitch"];
        match i {
            i if i < 2 * l.nb => {
                format!(
                    "beacon {}'s {}",
                    id(i / 2),
                    if i % 2 == 0 { "v1" } else { "sigma_b" }
                )
            }
            i if i < l.np() => shared[i - 2 * l.nb].to_string(),
            i if i < l.diag() => format!("gain[{}]", i - l.np()),
            i => format!(
                "beacon {}'s survey offset {}",
                id(((i - l.diag()) / 5).min(l.nb - 1)),
                offsets[(i - l.diag()) % 5]
            ),
        }
    }

    /// Fit the station (with the scattering term when `scat`); with `diag`
    /// = p, also every beacon's survey offsets, from the fit `p`: jointly,
    /// so that one beacon's survey error is not read into another's.
    pub fn fit(
        &self,
        scat: bool,
        diag: Option<&[f64]>,
        o: &StationFitOptions,
    ) -> Result<Fitted, CalibError> {
        let l = self.layout(scat);
        let start = match diag {
            None => self.start(l),
            Some(p) => {
                let mut p = p.to_vec();
                p.extend(std::iter::repeat_n(0.0, 5 * l.nb));
                p
            }
        };
        let d = diag.is_some();
        let npar = start.len();
        if self.obs.len() <= npar {
            return Err(CalibError::TooFewPoses(self.poses.len(), npar));
        }
        let np = l.np();
        let positive = |p: &[f64]| p[..np].iter().all(|v| *v > 0.0 && v.is_finite());
        let lm = levenberg_marquardt(start, self.obs.len(), o.max_iter, positive, |p, jac| {
            self.eval(p, l, d, jac)
        });
        let h = lm.jac.transpose() * &lm.jac;
        let name = |i: usize| self.name(l, i);
        let mut cov = determined_named(&h, &lm.p, np, npar, &name)?;
        if !lm.converged {
            return Err(CalibError::NoConvergence(format!(
                "{} iterations, χ² = {:.1}",
                o.max_iter, lm.cost
            )));
        }
        let dof = (self.obs.len() - npar).max(1);
        let chi2_per_dof = lm.cost / dof as f64;
        // Honest errors when the model fits worse than the noise says.
        if chi2_per_dof > 1.0 {
            cov *= chi2_per_dof;
        }
        // J·C·Jᵀ's diagonal, J's rows in units of each observation's σ.
        let jc = &lm.jac * &cov;
        let pred_var = DVector::from_iterator(
            self.obs.len(),
            self.obs
                .iter()
                .enumerate()
                .map(|(i, ob)| jc.row(i).dot(&lm.jac.row(i)) * ob.se * ob.se),
        );
        Ok(Fitted {
            scat,
            p: lm.p,
            r: lm.r,
            cov,
            pred_var,
            cost: lm.cost,
            chi2_per_dof,
        })
    }

    /// Parameter `i` of `f` with its standard error, times `scale`.
    pub fn estimate(f: &Fitted, i: usize, scale: f64) -> ParamEstimate {
        ParamEstimate {
            value: f.p[i] * scale,
            std: f.cov[(i, i)].max(0.0).sqrt() * scale,
        }
    }

    /// The `[physical]` table of the fit: the water's and the array's
    /// parameters, the first beacon's V1 and σ_b (the sensor model's own
    /// beacon; the station's are in `[station]`), offsets 0 (amplitudes
    /// have none), the noise line of the demodulator's variances, and the
    /// per-channel residuals over every beacon.
    pub fn physical_of(&self, f: &Fitted, o: &StationFitOptions) -> PhysicalCalibration {
        let l = self.layout(f.scat);
        let deg = 180.0 / std::f64::consts::PI;
        let est = |i: usize, s: f64| Data::estimate(f, i, s);
        let g = gains_of(&f.p, l.np());
        let pred = self.predict(&f.p, l, false, None);
        let cpv = self.cpv();
        let (mut ss_c, mut ss_n, mut cnt) = ([0.0; NDET], [0.0; NDET], [0usize; NDET]);
        for (i, ob) in self.obs.iter().enumerate() {
            let c = pred[ob.group * l.nb + ob.beacon][ob.k];
            ss_c[ob.k] += (c - ob.mean).powi(2);
            ss_n[ob.k] += f.r[i] * f.r[i];
            cnt[ob.k] += 1;
        }
        let points = self
            .obs
            .iter()
            .map(|ob| (pred[ob.group * l.nb + ob.beacon][ob.k] / cpv, ob.var));
        let (sigma_e_v, kappa_v) = noise_line(points, std::iter::empty(), cpv);
        let zero = ParamEstimate {
            value: 0.0,
            std: 0.0,
        };
        PhysicalCalibration {
            v1: est(l.v1(0), 1.0),
            sigma_b_deg: est(l.sigma_b(0), deg),
            sigma_r_deg: est(l.sigma_r(), deg),
            k_d: est(l.k_d(), 1.0),
            omega: f.scat.then(|| est(l.sigma_r() + 1, 1.0)),
            sigma_h_deg: f.scat.then(|| est(l.sigma_r() + 2, deg)),
            gain: gain_estimates(&g, &f.cov, l.np()),
            offset_v: vec![zero; NDET],
            sigma_e_v,
            kappa_v,
            v_ref: self.v_ref,
            adc_bits: self.bits,
            spacing_deg: o.geometry.spacing.deg(),
            radius_m: o.geometry.radius_m,
            residual_rms_counts: rms_per_channel(&ss_c, &cnt),
            residual_rms_normalized: rms_per_channel(&ss_n, &cnt),
            chi2_per_dof: f.chi2_per_dof,
            poses: self.poses.len(),
            frames: self.frames,
        }
    }
}
