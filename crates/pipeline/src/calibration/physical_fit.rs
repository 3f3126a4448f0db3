//! Physical calibration: fit MODEL.md's light equation — V1, σ_b, σ_R, K_D,
//! and ω, σ_h when the water scatters — and each channel's gain and dark
//! offset, from truth-labelled sweeps (and an optional dark log).
//!
//! Why: the model estimator, the tracker and the Cramér–Rao bound all need
//! these numbers, with their uncertainty. Sweeps hold 200 frames per pose;
//! they are averaged per pose first (the truth pose groups them, streamed so
//! a sweep never sits in memory), and the fit runs on the per-pose means
//! weighted by their standard errors — a few hundred poses, not 61,600
//! frames. Gain and V1 are degenerate (only their product is seen), so the
//! mean gain is fixed to 1 by eliminating the last gain. A sweep that
//! cannot determine a parameter is refused with the parameter's name.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::frame::full_scale;
use lightpose_core::light::temperature_gain;
use lightpose_core::{Angle, ArrayGeometry, Frame, LightParams, Pose, Scattering, NDET};
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::model::SensorModel;

/// A fitted value and its standard error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamEstimate {
    pub value: f64,
    pub std: f64,
}

/// The light equation's parameters as fitted from sweeps (the calibration
/// file's optional `[physical]` table). Angles in degrees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicalCalibration {
    pub v1: ParamEstimate,
    pub sigma_b_deg: ParamEstimate,
    pub sigma_r_deg: ParamEstimate,
    pub k_d: ParamEstimate,
    /// Scattering, when the fit found (or was told) the water has it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub omega: Option<ParamEstimate>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_h_deg: Option<ParamEstimate>,
    /// Per channel, row-major; mean gain is 1 by construction.
    pub gain: Vec<ParamEstimate>,
    pub offset_v: Vec<ParamEstimate>,
    /// Noise model fitted to the spread within each pose.
    pub sigma_e_v: f64,
    pub kappa_v: f64,
    /// The ADC and dome this was fitted for.
    pub v_ref: f64,
    pub adc_bits: u8,
    pub spacing_deg: f64,
    pub radius_m: f64,
    /// Per channel: RMS of the residuals of the per-pose means, in counts
    /// and in units of their standard errors.
    pub residual_rms_counts: Vec<f64>,
    pub residual_rms_normalized: Vec<f64>,
    /// χ² per degree of freedom of the whole fit.
    pub chi2_per_dof: f64,
    /// Poses (groups) and frames used.
    pub poses: usize,
    pub frames: u64,
}

impl PhysicalCalibration {
    /// The sensor model the estimators run on.
    pub fn sensor_model(&self) -> SensorModel {
        let scattering = match (self.omega, self.sigma_h_deg) {
            (Some(o), Some(h)) => Some(Scattering {
                omega: o.value,
                sigma_h: Angle::from_deg(h.value),
            }),
            _ => None,
        };
        let mut gain = [1.0; NDET];
        let mut offset_v = [0.0; NDET];
        for k in 0..NDET {
            gain[k] = self.gain.get(k).map_or(1.0, |g| g.value);
            offset_v[k] = self.offset_v.get(k).map_or(0.0, |o| o.value);
        }
        SensorModel {
            light: LightParams {
                v1: self.v1.value,
                sigma_b: Angle::from_deg(self.sigma_b_deg.value),
                sigma_r: Angle::from_deg(self.sigma_r_deg.value),
                k_d: self.k_d.value,
                scattering,
            },
            geometry: ArrayGeometry::new(Angle::from_deg(self.spacing_deg), self.radius_m),
            gain,
            offset_v,
            v_ref: self.v_ref,
            adc_bits: self.adc_bits,
            sigma_e_v: self.sigma_e_v,
            kappa_v: self.kappa_v,
        }
    }

    /// Check a loaded table: 25 channels, finite, positive where needed.
    pub fn validate(&self) -> Result<(), String> {
        if self.gain.len() != NDET || self.offset_v.len() != NDET {
            return Err(format!("gain and offset_v must have {NDET} entries"));
        }
        self.sensor_model().validate()
    }
}

/// Whether to fit the scattering term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ScatterFit {
    Off,
    On,
    /// Fit both; keep scattering when it improves χ² by more than 25
    /// (two parameters, far beyond chance) and is determined.
    #[default]
    Auto,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    pub scattering: ScatterFit,
    pub v_ref: f64,
    pub geometry: ArrayGeometry,
    pub max_iter: usize,
    /// Poses with fewer frames than this are ignored (no standard error).
    pub min_samples: u64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            scattering: ScatterFit::Auto,
            v_ref: 5.0,
            geometry: ArrayGeometry::paper(),
            max_iter: 60,
            min_samples: 2,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    #[error("sweep has no frames with a truth pose")]
    NoTruth,
    #[error("frames differ in ADC resolution ({0} and {1} bits)")]
    MixedBits(u8, u8),
    #[error("only {0} usable poses; the fit has {1} parameters")]
    TooFewPoses(usize, usize),
    #[error("the sweeps cannot determine {parameter}: {reason}")]
    Undetermined { parameter: String, reason: String },
    #[error("the fit did not converge: {0}")]
    NoConvergence(String),
}

#[derive(Debug, Clone)]
struct Group {
    pose: Pose,
    n: u64,
    sum: [f64; NDET],
    sumsq: [f64; NDET],
    clipped: [bool; NDET],
    gt_sum: f64,
}

impl Group {
    fn new(pose: Pose) -> Self {
        Group {
            pose,
            n: 0,
            sum: [0.0; NDET],
            sumsq: [0.0; NDET],
            clipped: [false; NDET],
            gt_sum: 0.0,
        }
    }
}

/// Streams frames in, grouping consecutive frames of one truth pose.
#[derive(Debug, Clone, Default)]
pub struct PhysicalFitter {
    groups: Vec<Group>,
    dark: Option<Group>,
    bits: Option<u8>,
    frames: u64,
}

impl PhysicalFitter {
    pub fn new() -> Self {
        Self::default()
    }

    fn check_bits(&mut self, f: &Frame) -> Result<(), CalibError> {
        match self.bits {
            None => self.bits = Some(f.adc_bits),
            Some(b) if b != f.adc_bits => return Err(CalibError::MixedBits(b, f.adc_bits)),
            _ => {}
        }
        Ok(())
    }

    fn accumulate(g: &mut Group, f: &Frame) {
        let fs = full_scale(f.adc_bits);
        g.n += 1;
        g.gt_sum += f.temp_c.map_or(1.0, temperature_gain);
        for k in 0..NDET {
            let c = f.counts[k];
            if c == 0 || c >= fs {
                g.clipped[k] = true;
            }
            let c = c as f64;
            g.sum[k] += c;
            g.sumsq[k] += c * c;
        }
    }

    /// Add one sweep frame; frames without truth are skipped.
    pub fn add_frame(&mut self, f: &Frame) -> Result<(), CalibError> {
        let Some(truth) = f.truth else { return Ok(()) };
        self.check_bits(f)?;
        self.frames += 1;
        let same = self.groups.last().is_some_and(|g| g.pose == truth.pose);
        if !same {
            self.groups.push(Group::new(truth.pose));
        }
        if let Some(g) = self.groups.last_mut() {
            Self::accumulate(g, f);
        }
        Ok(())
    }

    /// Add one frame of a dark log (beacon off).
    pub fn add_dark(&mut self, f: &Frame) -> Result<(), CalibError> {
        self.check_bits(f)?;
        self.frames += 1;
        let g = self.dark.get_or_insert_with(|| Group::new(Pose::default()));
        Self::accumulate(g, f);
        Ok(())
    }

    /// Fit the light equation to everything added.
    pub fn fit(&self, o: &FitOptions) -> Result<PhysicalCalibration, CalibError> {
        let bits = self.bits.ok_or(CalibError::NoTruth)?;
        let data = Data::build(self, o, bits)?;
        match o.scattering {
            ScatterFit::Off => data.fit(false, o),
            ScatterFit::On => data.fit(true, o),
            ScatterFit::Auto => {
                let off = data.fit(false, o)?;
                match data.fit(true, o) {
                    Ok(on) => {
                        let dof_on = data.dof(true);
                        let dof_off = data.dof(false);
                        let chi_on = on.chi2_per_dof * dof_on as f64;
                        let chi_off = off.chi2_per_dof * dof_off as f64;
                        Ok(if chi_off - chi_on > 25.0 { on } else { off })
                    }
                    Err(_) => Ok(off),
                }
            }
        }
    }
}

/// One observation: a pose group's mean count on one channel.
struct Obs {
    group: usize,
    k: usize,
    mean: f64,
    se: f64,
}

struct Data {
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

const PHYS_NAMES: [&str; 6] = ["v1", "sigma_b", "sigma_r", "k_d", "omega", "sigma_h"];

impl Data {
    fn build(fitter: &PhysicalFitter, o: &FitOptions, bits: u8) -> Result<Data, CalibError> {
        let mut poses = Vec::new();
        let mut gts = Vec::new();
        let mut var = Vec::new();
        let mut obs = Vec::new();
        for g in fitter.groups.iter().filter(|g| g.n >= o.min_samples) {
            let n = g.n as f64;
            let gi = poses.len();
            let mut v = [0.0; NDET];
            for k in 0..NDET {
                let mean = g.sum[k] / n;
                let s2 = ((g.sumsq[k] - n * mean * mean) / (n - 1.0)).max(0.0);
                v[k] = s2;
                if g.clipped[k] {
                    continue;
                }
                // The quantization floor keeps a noise-free channel's weight
                // finite.
                let se = (s2.max(1.0 / 12.0) / n).sqrt();
                obs.push(Obs {
                    group: gi,
                    k,
                    mean,
                    se,
                });
            }
            poses.push(g.pose);
            gts.push(g.gt_sum / n);
            var.push(v);
        }
        if poses.is_empty() {
            return Err(CalibError::NoTruth);
        }
        let (dark, dark_var) = match &fitter.dark {
            Some(g) if g.n >= o.min_samples => {
                let n = g.n as f64;
                let mut d = [(0.0, 0.0); NDET];
                let mut dv = [0.0; NDET];
                for k in 0..NDET {
                    let mean = g.sum[k] / n;
                    let s2 = ((g.sumsq[k] - n * mean * mean) / (n - 1.0)).max(0.0);
                    d[k] = (mean, (s2.max(1.0 / 12.0) / n).sqrt());
                    dv[k] = s2;
                }
                (Some(d), Some(dv))
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

    fn dof(&self, scat: bool) -> usize {
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
        let mut g = [0.0; NDET];
        let mut s = 0.0;
        for k in 0..NDET - 1 {
            g[k] = p[np + k];
            s += g[k];
        }
        g[NDET - 1] = NDET as f64 - s;
        g
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
            // Physical parameters: central differences of E, relative steps
            // (the light equation itself is checked analytically elsewhere;
            // these columns are smooth and well scaled).
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

    fn param_name(i: usize, np: usize) -> String {
        if i < np {
            PHYS_NAMES[i].to_string()
        } else if i < np + NDET - 1 {
            format!("gain[{}]", i - np)
        } else {
            format!("offset[{}]", i - np - (NDET - 1))
        }
    }

    /// Refuse a Fisher matrix that cannot determine every parameter,
    /// naming the parameter most involved in its weakest direction.
    fn check_determined(h: &DMatrix<f64>, np: usize) -> Result<DMatrix<f64>, CalibError> {
        let n = h.nrows();
        let mut d = DVector::zeros(n);
        for i in 0..n {
            let v = h[(i, i)];
            if !(v > 0.0 && v.is_finite()) {
                return Err(CalibError::Undetermined {
                    parameter: Self::param_name(i, np),
                    reason: "no data depends on it (zero Fisher column)".into(),
                });
            }
            d[i] = 1.0 / v.sqrt();
        }
        let hs = DMatrix::from_fn(n, n, |i, j| h[(i, j)] * d[i] * d[j]);
        let eig = SymmetricEigen::new(hs.clone());
        let (mut imin, mut lmin, mut lmax) = (0, f64::INFINITY, 0.0f64);
        for (i, l) in eig.eigenvalues.iter().enumerate() {
            if *l < lmin {
                lmin = *l;
                imin = i;
            }
            lmax = lmax.max(*l);
        }
        let cond = lmax / lmin.max(1e-300);
        if !(cond < 1e12) {
            let v = eig.eigenvectors.column(imin);
            let worst = (0..n)
                .max_by(|a, b| v[*a].abs().total_cmp(&v[*b].abs()))
                .unwrap_or(0);
            return Err(CalibError::Undetermined {
                parameter: Self::param_name(worst, np),
                reason: format!("singular or ill-conditioned Fisher matrix (condition {cond:.1e})"),
            });
        }
        let inv = hs
            .cholesky()
            .map(|c| c.inverse())
            .ok_or_else(|| CalibError::Undetermined {
                parameter: Self::param_name(imin, np),
                reason: "Fisher matrix is not positive definite".into(),
            })?;
        Ok(DMatrix::from_fn(n, n, |i, j| inv[(i, j)] * d[i] * d[j]))
    }

    /// The covariance at `p`, or which parameter the data leave undetermined.
    fn determined(
        h: &DMatrix<f64>,
        p: &[f64],
        np: usize,
        npar: usize,
    ) -> Result<DMatrix<f64>, CalibError> {
        let cov = Self::check_determined(h, np)?;
        // A parameter whose marginal variance is vastly above its variance
        // with the others held (variance inflation) is confounded with
        // them; one whose standard error exceeds its value is not measured.
        for i in 0..npar {
            let vif = cov[(i, i)] * h[(i, i)];
            if !(vif < 1e8) {
                return Err(CalibError::Undetermined {
                    parameter: Self::param_name(i, np),
                    reason: format!("ill-conditioned Fisher matrix (variance inflation {vif:.1e})"),
                });
            }
        }
        for i in 0..np {
            let se = cov[(i, i)].max(0.0).sqrt();
            if !(se < p[i].abs()) {
                return Err(CalibError::Undetermined {
                    parameter: Self::param_name(i, np),
                    reason: format!(
                        "standard error {se:.3e} exceeds the value {:.3e} (Fisher information too small)",
                        p[i]
                    ),
                });
            }
        }
        Ok(cov)
    }

    fn fit(&self, scat: bool, o: &FitOptions) -> Result<PhysicalCalibration, CalibError> {
        let np = Self::nphys(scat);
        let npar = Self::nparams(scat);
        let ng = self.poses.len();
        if self.nrows() <= npar {
            return Err(CalibError::TooFewPoses(ng, npar));
        }
        let cpv = full_scale(self.bits) as f64 / self.v_ref;
        let geom = &o.geometry;
        // Start: MODEL.md's defaults for shape, offsets from the dark log or
        // each channel's dimmest pose, V1 scaled to the brightest pose.
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
        {
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
        }
        let positive = |p: &[f64]| p[..np].iter().all(|v| *v > 0.0 && v.is_finite());
        let mut jac = DMatrix::zeros(self.nrows(), npar);
        let mut r = self.eval(&p, scat, geom, Some(&mut jac));
        let mut cost = r.norm_squared();
        let mut lambda = 1e-3;
        let mut converged = false;
        for _ in 0..o.max_iter {
            let h = jac.transpose() * &jac;
            let g = jac.transpose() * &r;
            let mut stepped = false;
            for _ in 0..15 {
                let mut a = h.clone();
                for i in 0..npar {
                    a[(i, i)] += lambda * h[(i, i)].max(1e-12);
                }
                let Some(ch) = a.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let delta = -ch.solve(&g);
                let pn: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
                if !positive(&pn) {
                    lambda *= 4.0;
                    continue;
                }
                let rn = self.eval(&pn, scat, geom, None);
                let cn = rn.norm_squared();
                if cn.is_finite() && cn <= cost {
                    let rel = (cost - cn) / cost.max(1e-300);
                    p = pn;
                    cost = cn;
                    lambda = (lambda / 3.0).max(1e-12);
                    stepped = true;
                    if rel < 1e-10 {
                        converged = true;
                    }
                    break;
                }
                lambda *= 4.0;
            }
            if !stepped {
                converged = true;
            }
            r = self.eval(&p, scat, geom, Some(&mut jac));
            if converged {
                break;
            }
        }
        let h = jac.transpose() * &jac;
        if !converged {
            // LM crawling without end is most often a flat valley: a
            // parameter the data cannot fix (ω → 0 in water that does not
            // scatter). Name it when the Fisher matrix shows it; otherwise
            // say the fit did not converge.
            Self::determined(&h, &p, np, npar)?;
            return Err(CalibError::NoConvergence(format!(
                "{} iterations, χ² = {cost:.1}",
                o.max_iter
            )));
        }
        let mut cov = Self::determined(&h, &p, np, npar)?;
        let dof = self.dof(scat);
        let chi2_per_dof = cost / dof as f64;
        // Honest errors when the model fits worse than the noise says.
        if chi2_per_dof > 1.0 {
            cov *= chi2_per_dof;
        }
        let sd = |i: usize| cov[(i, i)].max(0.0).sqrt();
        let est = |i: usize, scale: f64| ParamEstimate {
            value: p[i] * scale,
            std: sd(i) * scale,
        };
        let g = Self::gains(&p, np);
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
        let offset_v = (0..NDET).map(|k| est(off0 + k, 1.0)).collect();
        // Per-channel residuals.
        let e = self.irradiance(&p, scat, geom);
        let mut ss_c = [0.0; NDET];
        let mut ss_n = [0.0; NDET];
        let mut cnt = [0usize; NDET];
        for (i, ob) in self.obs.iter().enumerate() {
            let pred = (g[ob.k] * self.gts[ob.group] * e[ob.group][ob.k] + p[off0 + ob.k]) * cpv;
            ss_c[ob.k] += (pred - ob.mean).powi(2);
            ss_n[ob.k] += r[i] * r[i];
            cnt[ob.k] += 1;
        }
        let rms = |ss: &[f64; NDET]| -> Vec<f64> {
            (0..NDET)
                .map(|k| {
                    if cnt[k] > 0 {
                        (ss[k] / cnt[k] as f64).sqrt()
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        let (sigma_e_v, kappa_v) = self.noise_fit(&e, &g, p[off0..].as_ref(), cpv);
        let deg = |i: usize| est(i, 180.0 / std::f64::consts::PI);
        Ok(PhysicalCalibration {
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
            residual_rms_counts: rms(&ss_c),
            residual_rms_normalized: rms(&ss_n),
            chi2_per_dof,
            poses: self.poses.len(),
            frames: self.frames,
        })
    }

    /// σ_e and κ from the spread within each pose: var(count) − 1/12 =
    /// (σ_e² + κ·g·E)·cpv², a straight line in E fitted by least squares
    /// (unclipped channels only), non-negative.
    fn noise_fit(&self, e: &[[f64; NDET]], g: &[f64; NDET], _off: &[f64], cpv: f64) -> (f64, f64) {
        let (mut s1, mut sx, mut sxx, mut sy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut add = |x: f64, y: f64| {
            s1 += 1.0;
            sx += x;
            sxx += x * x;
            sy += y;
            sxy += x * y;
        };
        for ob in &self.obs {
            let x = g[ob.k] * self.gts[ob.group] * e[ob.group][ob.k];
            let y = (self.var[ob.group][ob.k] - 1.0 / 12.0) / (cpv * cpv);
            add(x, y);
        }
        if let Some(dv) = &self.dark_var {
            for v in dv {
                add(0.0, (v - 1.0 / 12.0) / (cpv * cpv));
            }
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
}

/// Fit from iterators of sweep frames and (optionally) dark frames.
pub fn fit_physical<'a>(
    sweeps: impl IntoIterator<Item = &'a Frame>,
    dark: Option<&mut dyn Iterator<Item = &'a Frame>>,
    o: &FitOptions,
) -> Result<PhysicalCalibration, CalibError> {
    let mut f = PhysicalFitter::new();
    for fr in sweeps {
        f.add_frame(fr)?;
    }
    if let Some(d) = dark {
        for fr in d {
            f.add_dark(fr)?;
        }
    }
    f.fit(o)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::testutil::{synth_frame, Rng};

    fn sweep_poses(xs: &[f64], orientation: bool) -> Vec<Pose> {
        let mut v = Vec::new();
        for &x in xs {
            for iy in -2..=2 {
                for iz in 0..=4 {
                    v.push(Pose::new(
                        x,
                        0.3 * iy as f64,
                        0.2 * iz as f64,
                        Angle::ZERO,
                        Angle::ZERO,
                    ));
                }
            }
            if orientation {
                for a in (-15..=15).step_by(3) {
                    let a = Angle::from_deg(a as f64);
                    v.push(Pose::new(x, 0.0, 0.0, a, Angle::ZERO));
                    v.push(Pose::new(x, 0.0, 0.0, Angle::ZERO, a));
                }
            }
        }
        v
    }

    fn truth_model() -> SensorModel {
        let mut m = SensorModel::default();
        for k in 0..NDET {
            m.gain[k] = 1.0 + 0.04 * ((k as f64) * 1.7).sin();
            m.offset_v[k] = 0.15 + 0.01 * ((k as f64) * 0.9).cos();
        }
        let mean: f64 = m.gain.iter().sum::<f64>() / NDET as f64;
        for g in m.gain.iter_mut() {
            *g /= mean;
        }
        m
    }

    fn feed(f: &mut PhysicalFitter, m: &SensorModel, poses: &[Pose], n: u64, rng: &mut Rng) {
        let mut seq = 0;
        for p in poses {
            for _ in 0..n {
                let fr = synth_frame(m, p, seq, seq as f64 * 0.2, None, rng);
                seq += 1;
                f.add_frame(&fr).unwrap();
            }
        }
    }

    #[test]
    fn recovers_light_parameters_gains_and_offsets() {
        let m = truth_model();
        let mut rng = Rng::new(5);
        let mut fitter = PhysicalFitter::new();
        feed(
            &mut fitter,
            &m,
            &sweep_poses(&[4.5, 5.5, 6.5, 7.5, 8.5], true),
            30,
            &mut rng,
        );
        let cal = fitter.fit(&FitOptions::default()).unwrap();
        eprintln!(
            "v1 {:?} σb {:?} σR {:?} K_D {:?} ω {:?} σh {:?} χ²/dof {:.3} σe {:.4}",
            cal.v1,
            cal.sigma_b_deg,
            cal.sigma_r_deg,
            cal.k_d,
            cal.omega,
            cal.sigma_h_deg,
            cal.chi2_per_dof,
            cal.sigma_e_v
        );
        let within = |e: &ParamEstimate, t: f64, name: &str| {
            assert!(e.std > 0.0 && e.std.is_finite(), "{name} {e:?}");
            assert!((e.value - t).abs() < 4.0 * e.std, "{name}: {e:?} vs {t}");
        };
        within(&cal.v1, 135.0, "v1");
        within(&cal.sigma_b_deg, 12.0, "sigma_b");
        within(&cal.sigma_r_deg, 18.0, "sigma_r");
        within(&cal.k_d, 0.09, "k_d");
        let omega = cal.omega.expect("scattering found");
        within(&omega, 0.5, "omega");
        within(&cal.sigma_h_deg.unwrap(), 20.0, "sigma_h");
        let mut outside = 0;
        for k in 0..NDET {
            if (cal.gain[k].value - m.gain[k]).abs() > 3.0 * cal.gain[k].std {
                outside += 1;
            }
            if (cal.offset_v[k].value - m.offset_v[k]).abs() > 3.0 * cal.offset_v[k].std {
                outside += 1;
            }
        }
        assert!(outside <= 2, "{outside} of 50 channel parameters beyond 3σ");
        assert!(
            (0.8..1.25).contains(&cal.chi2_per_dof),
            "{}",
            cal.chi2_per_dof
        );
        assert!((cal.sigma_e_v - 0.05).abs() < 0.003, "{}", cal.sigma_e_v);
        assert_eq!(cal.residual_rms_counts.len(), NDET);
        // The fitted model drives the estimator: round trip through TOML.
        let text = toml::to_string(&cal).unwrap();
        let back: PhysicalCalibration = toml::from_str(&text).unwrap();
        assert_eq!(back, cal);
        back.validate().unwrap();
    }

    #[test]
    fn single_distance_sweep_is_refused_naming_a_parameter() {
        // One range only: attenuation and source strength cannot be told
        // apart (nor scattering from either).
        let m = truth_model();
        let mut rng = Rng::new(9);
        let mut fitter = PhysicalFitter::new();
        feed(&mut fitter, &m, &sweep_poses(&[6.5], true), 10, &mut rng);
        let opts = FitOptions {
            scattering: ScatterFit::On,
            ..FitOptions::default()
        };
        match fitter.fit(&opts) {
            Err(CalibError::Undetermined { parameter, reason }) => {
                eprintln!("refused: {parameter}: {reason}");
                assert!(!parameter.is_empty() && reason.contains("Fisher"));
            }
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    #[test]
    fn dark_log_pins_offsets() {
        let mut m = truth_model();
        m.light.scattering = None;
        let mut rng = Rng::new(13);
        let mut fitter = PhysicalFitter::new();
        feed(
            &mut fitter,
            &m,
            &sweep_poses(&[4.5, 6.5, 8.5], true),
            20,
            &mut rng,
        );
        let mut dark_m = m.clone();
        dark_m.light.v1 = 0.0;
        let far = Pose::new(6.5, 0.0, 0.0, Angle::ZERO, Angle::ZERO);
        for i in 0..400 {
            let mut fr = synth_frame(&dark_m, &far, i, 0.0, None, &mut rng);
            fr.truth = None;
            fitter.add_dark(&fr).unwrap();
        }
        let cal = fitter
            .fit(&FitOptions {
                scattering: ScatterFit::Auto,
                ..FitOptions::default()
            })
            .unwrap();
        assert!(cal.omega.is_none(), "no scattering in this water: {cal:?}");
        for k in 0..NDET {
            let o = cal.offset_v[k];
            assert!((o.value - m.offset_v[k]).abs() < 4.0 * o.std, "{k}: {o:?}");
            assert!(o.std < 0.002);
        }
    }
}
