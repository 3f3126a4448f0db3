//! The physical fit itself: the per-pose mean counts as weighted residuals
//! of the light equation (gains, offsets, and the dark log's offsets when
//! there is one), their Jacobian, Levenberg–Marquardt from MODEL.md's
//! defaults, and the `[physical]` table with standard errors, per-channel
//! residuals and the noise model.

// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::calibration::lm::{levenberg_marquardt, Lm};

use super::{
    fisher, CalibError, FitOptions, Group, ParamEstimate, PhysicalCalibration, PhysicalFitter,
};
use lightpose_core::frame::full_scale;
use lightpose_core::{Angle, ArrayGeometry, LightParams, Pose, Scattering, NDET};
use nalgebra::{DMatrix, DVector};

/// One observation: a pose group's mean count on one channel.
struct Obs {
    group: usize,
    k: usize,
    mean: f64,
    se: f64,
}

/// The fit's data: per-pose means, their standard errors and spreads.
pub(super) struct Data {
    poses: Vec<Pose>,
    gts: Vec<f64>,
    /// Per group: sample variance and mean per channel (for the noise fit).
    var: Vec<[f64; NDET]>,
    obs: Vec<Obs>,
    /// Dark: per channel mean count and its standard error.
    dark: Option<[(f64, f64); NDET]>,
    dark_var: Option<[f64; NDET]>,
    bits: u8,
    frames: u64,
    v_ref: f64,
}

/// Mean count and sample variance of channel `k` over a group's frames.
fn channel_stats(g: &Group, k: usize) -> (f64, f64) {
    let n = g.n as f64;
    let mean = g.sum[k] / n;
    let s2 = ((g.sumsq[k] - n * mean * mean) / (n - 1.0)).max(0.0);
    // Amplitudes carry their own variance (the demodulator's, checked
    // against their scatter): with the 3 frames a pose of a BURST sweep
    // the sample variance has 2 degrees of freedom, and weights that
    // noisy biased the fit (K_D 7σ off its std on the harbour sweep).
    if g.reported_var[k] > 0.0 {
        return (mean, g.reported_var[k] / n);
    }
    (mean, s2)
}

/// Standard error of the mean of `n` counts of sample variance `s2`; the
/// quantization floor keeps a noise-free channel's weight finite.
fn standard_error(s2: f64, n: f64) -> f64 {
    (s2.max(1.0 / 12.0) / n).sqrt()
}

/// How tightly an amplitude sweep's offsets are held at 0, counts: far
/// below any pose mean's standard error, far above round-off.
const AMPLITUDE_OFFSET_SE: f64 = 1e-3;

impl Data {
    /// The per-pose means of the groups with at least `o.min_samples`
    /// frames (clipped channels left out), and the dark log's.
    pub(super) fn build(
        fitter: &PhysicalFitter,
        o: &FitOptions,
        bits: u8,
    ) -> Result<Data, CalibError> {
        let mut poses = Vec::new();
        let mut gts = Vec::new();
        let mut var = Vec::new();
        let mut obs = Vec::new();
        for g in fitter.groups.iter().filter(|g| g.n >= o.min_samples) {
            let n = g.n as f64;
            let gi = poses.len();
            let mut v = [0.0; NDET];
            for k in 0..NDET {
                let (mean, s2) = channel_stats(g, k);
                v[k] = s2;
                if g.clipped[k] {
                    continue;
                }
                obs.push(Obs {
                    group: gi,
                    k,
                    mean,
                    se: standard_error(s2, n),
                });
            }
            poses.push(g.pose);
            gts.push(g.gt_sum / n);
            var.push(v);
        }
        if poses.is_empty() {
            let frames: u64 = fitter.groups.iter().map(|g| g.n).sum();
            return Err(match frames {
                0 => CalibError::NoTruth,
                n => CalibError::NoRepeatedPose(o.min_samples, n),
            });
        }
        let (dark, dark_var) = match &fitter.dark {
            Some(g) if g.n >= o.min_samples => {
                let n = g.n as f64;
                let mut d = [(0.0, 0.0); NDET];
                let mut dv = [0.0; NDET];
                for k in 0..NDET {
                    let (mean, s2) = channel_stats(g, k);
                    d[k] = (mean, standard_error(s2, n));
                    dv[k] = s2;
                }
                (Some(d), Some(dv))
            }
            // Amplitudes have no dark offset: the on level minus the off
            // level of a beacon that is off is 0 exactly, so the offsets
            // are held at 0 (a tight prior, in the place of a dark log's).
            _ if fitter.amplitudes == Some(true) => {
                (Some([(0.0, AMPLITUDE_OFFSET_SE); NDET]), None)
            }
            _ => (None, None),
        };
        Ok(Data {
            poses,
            gts,
            var,
            obs,
            dark,
            dark_var,
            bits,
            frames: fitter.frames,
            v_ref: o.v_ref,
        })
    }

    fn nphys(scat: bool) -> usize {
        if scat {
            6
        } else {
            4
        }
    }

    fn nparams(scat: bool) -> usize {
        Self::nphys(scat) + (NDET - 1) + NDET
    }

    fn nrows(&self) -> usize {
        self.obs.len() + if self.dark.is_some() { NDET } else { 0 }
    }

    pub(super) fn dof(&self, scat: bool) -> usize {
        self.nrows().saturating_sub(Self::nparams(scat)).max(1)
    }

    fn light(p: &[f64], scat: bool) -> LightParams {
        LightParams {
            v1: p[0],
            sigma_b: Angle::from_rad(p[1]),
            sigma_r: Angle::from_rad(p[2]),
            k_d: p[3],
            scattering: scat.then(|| Scattering {
                omega: p[4],
                sigma_h: Angle::from_rad(p[5]),
            }),
        }
    }

    /// E for every pose and channel with physical parameters `p`.
    fn irradiance(&self, p: &[f64], scat: bool, geom: &ArrayGeometry) -> Vec<[f64; NDET]> {
        let l = Self::light(p, scat);
        self.poses
            .iter()
            .map(|pose| {
                let mut e = [0.0; NDET];
                l.irradiance(geom, pose, &mut e);
                e
            })
            .collect()
    }

    fn gains(p: &[f64], np: usize) -> [f64; NDET] {
        gains_of(p, np)
    }

    /// ∂E/∂(each light parameter) for every pose and channel: central
    /// differences, relative steps (the light equation itself is checked
    /// analytically elsewhere; these columns are smooth and well scaled).
    fn irradiance_slopes(
        &self,
        p: &[f64],
        scat: bool,
        geom: &ArrayGeometry,
    ) -> Vec<Vec<[f64; NDET]>> {
        let np = Self::nphys(scat);
        let mut de: Vec<Vec<[f64; NDET]>> = Vec::with_capacity(np);
        for a in 0..np {
            let h = 1e-5 * p[a].abs().max(1e-3);
            let mut pp = p.to_vec();
            let mut pm = p.to_vec();
            pp[a] += h;
            pm[a] -= h;
            let ep = self.irradiance(&pp, scat, geom);
            let em = self.irradiance(&pm, scat, geom);
            de.push(
                ep.iter()
                    .zip(&em)
                    .map(|(a1, b1)| {
                        let mut out = [0.0; NDET];
                        for k in 0..NDET {
                            out[k] = (a1[k] - b1[k]) / (2.0 * h);
                        }
                        out
                    })
                    .collect(),
            );
        }
        de
    }

    /// Normalized residuals and (optionally) the Jacobian.
    fn eval(
        &self,
        p: &[f64],
        scat: bool,
        geom: &ArrayGeometry,
        jac: Option<&mut DMatrix<f64>>,
    ) -> DVector<f64> {
        let np = Self::nphys(scat);
        let cpv = full_scale(self.bits) as f64 / self.v_ref;
        let e = self.irradiance(p, scat, geom);
        let g = Self::gains(p, np);
        let off0 = np + NDET - 1;
        let mut r = DVector::zeros(self.nrows());
        for (i, ob) in self.obs.iter().enumerate() {
            let pred = (g[ob.k] * self.gts[ob.group] * e[ob.group][ob.k] + p[off0 + ob.k]) * cpv;
            r[i] = (pred - ob.mean) / ob.se;
        }
        let base = self.obs.len();
        if let Some(d) = &self.dark {
            for k in 0..NDET {
                r[base + k] = (p[off0 + k] * cpv - d[k].0) / d[k].1;
            }
        }
        if let Some(j) = jac {
            j.fill(0.0);
            let de = self.irradiance_slopes(p, scat, geom);
            for (i, ob) in self.obs.iter().enumerate() {
                let s = self.gts[ob.group] * cpv / ob.se;
                for a in 0..np {
                    j[(i, a)] = g[ob.k] * s * de[a][ob.group][ob.k];
                }
                let el = e[ob.group][ob.k] * s;
                // g_last = N − Σ others: each free gain also lowers it.
                if ob.k < NDET - 1 {
                    j[(i, np + ob.k)] += el;
                } else {
                    for q in 0..NDET - 1 {
                        j[(i, np + q)] -= el;
                    }
                }
                j[(i, off0 + ob.k)] = cpv / ob.se;
            }
            if let Some(d) = &self.dark {
                for k in 0..NDET {
                    j[(base + k, off0 + k)] = cpv / d[k].1;
                }
            }
        }
        r
    }

    /// Fit the light model (with the scattering term when `scat`) and say
    /// how well each parameter is determined.
    pub(super) fn fit(
        &self,
        scat: bool,
        o: &FitOptions,
    ) -> Result<PhysicalCalibration, CalibError> {
        let np = Self::nphys(scat);
        let npar = Self::nparams(scat);
        let ng = self.poses.len();
        if self.nrows() <= npar {
            return Err(CalibError::TooFewPoses(ng, npar));
        }
        let lm = self.levenberg_marquardt(self.start(scat, &o.geometry), scat, o);
        let h = lm.jac.transpose() * &lm.jac;
        if !lm.converged {
            // LM crawling without end is most often a flat valley: a
            // parameter the data cannot fix (ω → 0 in water that does not
            // scatter). Name it when the Fisher matrix shows it; otherwise
            // say the fit did not converge.
            fisher::determined(&h, &lm.p, np, npar)?;
            return Err(CalibError::NoConvergence(format!(
                "{} iterations, χ² = {:.1}",
                o.max_iter, lm.cost
            )));
        }
        let mut cov = fisher::determined(&h, &lm.p, np, npar)?;
        let dof = self.dof(scat);
        let chi2_per_dof = lm.cost / dof as f64;
        // Honest errors when the model fits worse than the noise says.
        if chi2_per_dof > 1.0 {
            cov *= chi2_per_dof;
        }
        Ok(self.table(scat, &o.geometry, &lm, &cov, chi2_per_dof))
    }

    /// Where the fit starts: MODEL.md's defaults for shape, offsets from the
    /// dark log or each channel's dimmest pose, V1 scaled to the brightest
    /// pose.
    fn start(&self, scat: bool, geom: &ArrayGeometry) -> Vec<f64> {
        let np = Self::nphys(scat);
        let npar = Self::nparams(scat);
        let cpv = full_scale(self.bits) as f64 / self.v_ref;
        let mut p = vec![0.0; npar];
        let def = LightParams::default();
        p[0] = def.v1;
        p[1] = def.sigma_b.rad();
        p[2] = def.sigma_r.rad();
        p[3] = def.k_d;
        if scat {
            p[4] = 0.5;
            p[5] = 20f64.to_radians();
        }
        for k in 0..NDET - 1 {
            p[np + k] = 1.0;
        }
        let off0 = np + NDET - 1;
        for k in 0..NDET {
            p[off0 + k] = match &self.dark {
                Some(d) => d[k].0 / cpv,
                None => {
                    self.obs
                        .iter()
                        .filter(|ob| ob.k == k)
                        .map(|ob| ob.mean)
                        .fold(f64::INFINITY, f64::min)
                        .min(1e6)
                        / cpv
                        * 0.9
                }
            };
        }
        let e = self.irradiance(&p, scat, geom);
        let (mut num, mut den) = (0.0, 0.0);
        for ob in &self.obs {
            let model = e[ob.group][ob.k] * self.gts[ob.group] * cpv;
            let seen = ob.mean - p[off0 + ob.k] * cpv;
            num += model * seen;
            den += model * model;
        }
        if den > 0.0 && num > 0.0 {
            p[0] *= num / den;
        }
        p
    }

    /// Levenberg–Marquardt from `p`, the light parameters kept positive.
    fn levenberg_marquardt(&self, p: Vec<f64>, scat: bool, o: &FitOptions) -> Lm {
        let np = Self::nphys(scat);
        let geom = &o.geometry;
        let positive = |p: &[f64]| p[..np].iter().all(|v| *v > 0.0 && v.is_finite());
        levenberg_marquardt(p, self.nrows(), o.max_iter, positive, |p, jac| {
            self.eval(p, scat, geom, jac)
        })
    }

    /// The `[physical]` table from a converged fit and its covariance:
    /// values and standard errors (angles in degrees), per-channel
    /// residuals, and the noise model.
    fn table(
        &self,
        scat: bool,
        geom: &ArrayGeometry,
        lm: &Lm,
        cov: &DMatrix<f64>,
        chi2_per_dof: f64,
    ) -> PhysicalCalibration {
        let np = Self::nphys(scat);
        let off0 = np + NDET - 1;
        let cpv = full_scale(self.bits) as f64 / self.v_ref;
        let p = &lm.p;
        let sd = |i: usize| cov[(i, i)].max(0.0).sqrt();
        let est = |i: usize, scale: f64| ParamEstimate {
            value: p[i] * scale,
            std: sd(i) * scale,
        };
        let g = Self::gains(p, np);
        let gain = gain_estimates(&g, cov, np);
        let offset_v = (0..NDET).map(|k| est(off0 + k, 1.0)).collect();
        let e = self.irradiance(p, scat, geom);
        let (residual_rms_counts, residual_rms_normalized) =
            self.residual_rms(&e, &g, p, &lm.r, off0, cpv);
        let (sigma_e_v, kappa_v) = self.noise_fit(&e, &g, p[off0..].as_ref(), cpv);
        let deg = |i: usize| est(i, 180.0 / std::f64::consts::PI);
        PhysicalCalibration {
            v1: est(0, 1.0),
            sigma_b_deg: deg(1),
            sigma_r_deg: deg(2),
            k_d: est(3, 1.0),
            omega: scat.then(|| est(4, 1.0)),
            sigma_h_deg: scat.then(|| deg(5)),
            gain,
            offset_v,
            sigma_e_v,
            kappa_v,
            v_ref: self.v_ref,
            adc_bits: self.bits,
            spacing_deg: geom.spacing.deg(),
            radius_m: geom.radius_m,
            residual_rms_counts,
            residual_rms_normalized,
            chi2_per_dof,
            poses: self.poses.len(),
            frames: self.frames,
        }
    }

    /// Per channel, the RMS of the per-pose means' residuals in counts and
    /// in units of their standard errors (`r`, the normalized residuals).
    fn residual_rms(
        &self,
        e: &[[f64; NDET]],
        g: &[f64; NDET],
        p: &[f64],
        r: &DVector<f64>,
        off0: usize,
        cpv: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut ss_c = [0.0; NDET];
        let mut ss_n = [0.0; NDET];
        let mut cnt = [0usize; NDET];
        for (i, ob) in self.obs.iter().enumerate() {
            let pred = (g[ob.k] * self.gts[ob.group] * e[ob.group][ob.k] + p[off0 + ob.k]) * cpv;
            ss_c[ob.k] += (pred - ob.mean).powi(2);
            ss_n[ob.k] += r[i] * r[i];
            cnt[ob.k] += 1;
        }
        (rms_per_channel(&ss_c, &cnt), rms_per_channel(&ss_n, &cnt))
    }

    /// σ_e and κ from the spread within each pose: var(count) − 1/12 =
    /// (σ_e² + κ·g·E)·cpv², a straight line in E fitted by least squares
    /// (unclipped channels only), non-negative.
    fn noise_fit(&self, e: &[[f64; NDET]], g: &[f64; NDET], _off: &[f64], cpv: f64) -> (f64, f64) {
        let points = self.obs.iter().map(|ob| {
            let x = g[ob.k] * self.gts[ob.group] * e[ob.group][ob.k];
            (x, self.var[ob.group][ob.k])
        });
        let dark = self.dark_var.iter().flatten().copied();
        noise_line(points, dark, cpv)
    }
}

/// σ_e and κ (volts) from (light after gain and g_T in volts, variance of
/// a count) points and a dark log's variances: var − 1/12 = (σ_e² + κ·x)·cpv²
/// fitted by least squares, κ ≥ 0 (shared by the physical fit of one
/// beacon and a station's).
/// Each channel's root mean square from its sum of squares `ss` over
/// `cnt` observations (0 for a channel with none).
pub(crate) fn rms_per_channel(ss: &[f64; NDET], cnt: &[usize; NDET]) -> Vec<f64> {
    (0..NDET)
        .map(|k| {
            if cnt[k] > 0 {
                (ss[k] / cnt[k] as f64).sqrt()
            } else {
                0.0
            }
        })
        .collect()
}

pub(crate) fn noise_line(
    points: impl Iterator<Item = (f64, f64)>,
    dark: impl Iterator<Item = f64>,
    cpv: f64,
) -> (f64, f64) {
    let (mut s1, mut sx, mut sxx, mut sy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut add = |x: f64, y: f64| {
        s1 += 1.0;
        sx += x;
        sxx += x * x;
        sy += y;
        sxy += x * y;
    };
    for (x, v) in points {
        add(x, (v - 1.0 / 12.0) / (cpv * cpv));
    }
    for v in dark {
        add(0.0, (v - 1.0 / 12.0) / (cpv * cpv));
    }
    let det = s1 * sxx - sx * sx;
    let (a, b) = if det.abs() > 1e-300 * s1.max(1.0) && det > 0.0 {
        ((sxx * sy - sx * sxy) / det, (s1 * sxy - sx * sy) / det)
    } else {
        (sy / s1.max(1.0), 0.0)
    };
    let (a, b) = if b < 0.0 {
        (sy / s1.max(1.0), 0.0)
    } else {
        (a, b)
    };
    (a.max(0.0).sqrt(), b.max(0.0))
}

/// The 25 gains from the 24 free ones at `p[np..]`: the last is N − Σ
/// others, so that the mean gain is 1 (gain and V1 are degenerate).
pub(crate) fn gains_of(p: &[f64], np: usize) -> [f64; NDET] {
    let mut g = [0.0; NDET];
    let mut s = 0.0;
    for k in 0..NDET - 1 {
        g[k] = p[np + k];
        s += g[k];
    }
    g[NDET - 1] = NDET as f64 - s;
    g
}

/// Every gain with its standard error; the last is N − Σ others, so its
/// variance is 1ᵀC1 over the free gains.
pub(crate) fn gain_estimates(g: &[f64; NDET], cov: &DMatrix<f64>, np: usize) -> Vec<ParamEstimate> {
    let sd = |i: usize| cov[(i, i)].max(0.0).sqrt();
    let mut gain = Vec::with_capacity(NDET);
    for k in 0..NDET - 1 {
        gain.push(ParamEstimate {
            value: g[k],
            std: sd(np + k),
        });
    }
    // Var(g_last) = Var(Σ others) = 1ᵀ C 1 over the free gains.
    let mut v_last = 0.0;
    for a in 0..NDET - 1 {
        for b in 0..NDET - 1 {
            v_last += cov[(np + a, np + b)];
        }
    }
    gain.push(ParamEstimate {
        value: g[NDET - 1],
        std: v_last.max(0.0).sqrt(),
    });
    gain
}
