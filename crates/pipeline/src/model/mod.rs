//! Model-based estimation: everything that inverts MODEL.md's light
//! equation rather than reading pose off image moments.
//!
//! - [`light`]: the light equation and its analytic derivatives with respect
//!   to pose and K_D, the one place the Jacobian is derived.
//! - [`SensorModel`]: light equation plus each channel's gain, offset, ADC
//!   and noise, i.e. what a count is expected to be and how much it scatters.
//! - [`solver`]: censored, weighted Levenberg–Marquardt on one frame.
//! - [`single_frame`]: the `"model"` estimator, each frame fitted on its own.
//! - [`tracker`]: the `"tracker"` estimator, a filter over pose and rates.
//! - [`crb`]: the Cramér–Rao bound, the best any estimator could do.
//! - [`station_fit`]: one frame's fit of the whole pose, roll too, to a
//!   docking station's images (spec v3, several beacons).
//!
//! Their settings are in [`crate::settings`]; the light model they run on
//! is fitted by `calibration::physical_fit`. A new model-based estimator
//! goes here, next to these.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

pub mod bound_light;
pub mod crb;
pub mod daylight;
pub(crate) mod findings;
pub mod frozen;
pub mod light;
pub mod measurement;
pub(crate) mod normal;
pub mod single_frame;
pub mod solver;
pub mod station_fit;
#[cfg(test)]
pub(crate) mod testutil;
pub mod tracker;

pub use light::{predict, predict_with_grad, PoseJacobian, NGRAD};
pub use measurement::Measurement;
pub use single_frame::ModelEstimator;
pub use solver::{solve, Censoring, LmResult, Prior, SolveOptions};
pub use tracker::{Tracker, WaterBank, WaterWatch};

use lightpose_core::frame::full_scale;
use lightpose_core::{ArrayGeometry, LightParams, NDET};

/// Everything needed to say what count a channel should read for a pose and
/// how noisy it is: the light equation, each channel's gain and offset, the
/// ADC and the noise model of MODEL.md.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorModel {
    pub light: LightParams,
    pub geometry: ArrayGeometry,
    /// g_k, relative responsivity of each channel (mean 1 after calibration).
    pub gain: [f64; NDET],
    /// o_k, dark offset of each channel in volts.
    pub offset_v: [f64; NDET],
    pub v_ref: f64,
    pub adc_bits: u8,
    /// σ_e, electronic noise in volts (1σ).
    pub sigma_e_v: f64,
    /// κ, shot-noise factor in volts: variance grows by κ·E.
    pub kappa_v: f64,
    /// 1σ of `light.k_d` as its source knows it, m⁻¹: a calibration's
    /// standard error of its fit (the water of the sweep), 0 for a model
    /// taken as exact (a scene's truth). The estimators' `k_d_sigma`
    /// defaults to it.
    pub k_d_sigma: f64,
}

impl Default for SensorModel {
    /// MODEL.md's default tank: unit gains, 0.15 V offsets, 10 bits over 5 V,
    /// σ_e = 0.05 V.
    fn default() -> Self {
        SensorModel {
            light: LightParams::default(),
            geometry: ArrayGeometry::paper(),
            gain: [1.0; NDET],
            offset_v: [0.15; NDET],
            v_ref: 5.0,
            adc_bits: 10,
            sigma_e_v: 0.05,
            kappa_v: 0.0,
            k_d_sigma: 0.0,
        }
    }
}

impl SensorModel {
    /// Largest count of the ADC.
    #[inline]
    pub fn full_scale(&self) -> f64 {
        full_scale(self.adc_bits) as f64
    }

    /// Counts per volt: (2^bits − 1)/V_ref.
    #[inline]
    pub fn counts_per_volt(&self) -> f64 {
        self.full_scale() / self.v_ref
    }

    /// Variance of channel k's count when its irradiance is `e` volts:
    /// (σ_e² + κ·E)·(counts/V)² plus the quantization LSB²/12. Never below
    /// the quantization floor, so every weight is finite.
    #[inline]
    pub fn count_variance(&self, e: f64) -> f64 {
        let cpv = self.counts_per_volt();
        let v = self.sigma_e_v * self.sigma_e_v + self.kappa_v * e.max(0.0);
        v * cpv * cpv + 1.0 / 12.0
    }

    /// Whether the model's numbers can be used at all (finite, positive
    /// where they must be); estimators refuse a model that is not.
    pub fn validate(&self) -> Result<(), String> {
        let l = &self.light;
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} = {v} must be a positive number"))
            }
        };
        pos("v1", l.v1)?;
        pos("sigma_b", l.sigma_b.rad())?;
        pos("sigma_r", l.sigma_r.rad())?;
        pos("v_ref", self.v_ref)?;
        pos("radius_m", self.geometry.radius_m)?;
        if !(l.k_d.is_finite() && l.k_d >= 0.0) {
            return Err(format!("k_d = {} must be a non-negative number", l.k_d));
        }
        if !(self.k_d_sigma.is_finite() && self.k_d_sigma >= 0.0) {
            return Err(format!(
                "k_d's std = {} must be a non-negative number",
                self.k_d_sigma
            ));
        }
        if let Some(s) = l.scattering {
            if !(s.omega.is_finite() && s.omega >= 0.0) {
                return Err(format!("omega = {} must be non-negative", s.omega));
            }
            pos("sigma_h", s.sigma_h.rad())?;
        }
        if !(1..=16).contains(&self.adc_bits) {
            return Err(format!("adc_bits = {} must be 1..16", self.adc_bits));
        }
        if !(self.sigma_e_v.is_finite() && self.sigma_e_v >= 0.0) {
            return Err(format!(
                "sigma_e_v = {} must be non-negative",
                self.sigma_e_v
            ));
        }
        if !(self.kappa_v.is_finite() && self.kappa_v >= 0.0) {
            return Err(format!("kappa_v = {} must be non-negative", self.kappa_v));
        }
        for k in 0..NDET {
            pos(&format!("gain[{k}]"), self.gain[k])?;
            if !self.offset_v[k].is_finite() {
                return Err(format!("offset_v[{k}] is not finite"));
            }
        }
        Ok(())
    }
}
