//! The settings of the estimators: the `[estimator]` table of a calibration
//! file (`[estimator.model]`, `[estimator.tracker]`), each with its defaults
//! and its validator.
//!
//! Why a file of its own: the calibration file carries these settings and
//! the estimators are built from them, so both must reach them; kept here,
//! apart from both, neither has to import the other to get them. A new
//! setting of an estimator goes into its table here, with its default and
//! its check in that table's `validate` (the tracker's table:
//! `settings/tracker.rs`, its checks: `settings/checks.rs`).

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use serde::{Deserialize, Serialize};

mod checks;
mod tracker;
pub use tracker::{
    Motion, TrackerConfig, PAPER_RATE_MAX_FRAMES, READING_CHECK_MAX_S, READING_CHECK_SLOT_S,
    WATER_CHECK_MAX_FRAMES,
};

pub use crate::model::daylight::DaylightConfig;

/// The `[estimator]` table: what the model-based estimators model for this
/// scene. Every key is optional. Scattering is not here: it is modelled
/// exactly when the physical calibration kept it (`omega`, `sigma_h_deg`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorSettings {
    /// `[estimator.model]`: the single-frame estimator.
    pub model: ModelConfig,
    /// `[estimator.tracker]`: the filter.
    pub tracker: TrackerConfig,
}

impl EstimatorSettings {
    /// These settings in water whose K_D is known only to `sigma_k_d` (1σ,
    /// m⁻¹) about the calibration's, as in a Monte Carlo that draws each
    /// run's water: a `k_d_sigma` left unset (the sweep's water) takes it,
    /// one set by the user stays.
    ///
    /// And whose temperature the frames report only to `sigma_temp_c` (1σ,
    /// °C, the same for a whole run): the tracker's `temp_sigma_c`, if
    /// unset, takes it.
    pub fn in_water_known_to(mut self, sigma_k_d: f64, sigma_temp_c: f64) -> Self {
        self.model.k_d_sigma.get_or_insert(sigma_k_d);
        self.tracker = self.tracker.in_water_known_to(sigma_k_d, sigma_temp_c);
        self
    }
}

/// Which pose coordinates one frame is asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Dof {
    /// x, y, z only; pitch and yaw are taken from the frame's attitude
    /// reading, or from the configured fixed values when it has none.
    Position,
    /// All five; the attitude reading, when present, is a prior with the
    /// sensor's σ. Without it one frame separates y from yaw and z from
    /// pitch poorly (MODEL.md), which the reported std will show.
    #[default]
    Full,
}

/// Settings of the model estimator (a TOML table with every key optional).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelConfig {
    pub dof: Dof,
    /// Attitude assumed by `dof = "position"` when a frame has no reading.
    pub fixed_pitch_deg: f64,
    pub fixed_yaw_deg: f64,
    /// Use `Frame.attitude` when present.
    pub use_attitude: bool,
    /// The attitude sensor's 1σ (MODEL.md defaults).
    pub attitude_sigma_pitch_deg: f64,
    pub attitude_sigma_yaw_deg: f64,
    /// Spec v3: the attitude sensor's roll 1σ (degrees; MODEL.md's 0.3°),
    /// for a frame whose attitude reading has roll (a frame's `std` has
    /// none for roll).
    pub attitude_sigma_roll_deg: f64,
    /// Spec v3: a frame without a roll reading is taken at roll 0 ± this
    /// (degrees, 1σ; a vehicle in waves rolls a few degrees, 5 is a fair
    /// figure), whose doubt goes into every other axis' σ and is reported
    /// as `std.roll`. Unset: roll is exactly 0 and not reported, as in
    /// spec v1/v2 (the default, so that v1/v2 logs give what they gave).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub roll_sigma_deg: Option<f64>,
    /// With `dof = "full"` and no attitude reading: a weak prior of
    /// pitch = yaw = 0 with this σ (degrees), for vehicles known to keep
    /// roughly facing the beacon. Absent: no prior at all.
    pub attitude_envelope_deg: Option<f64>,
    /// Range of x for which an estimate is `ok` (the calibrated range).
    pub x_range: [f64; 2],
    /// How far the solver may search, as multiples of that range's ends.
    pub search_margin: f64,
    /// Lateral offset limit as a fraction of x, and attitude limit.
    pub max_lateral_ratio: f64,
    pub max_angle_deg: f64,
    pub max_iter: usize,
    /// More channels at full scale than this gives `saturated`.
    pub max_saturated: usize,
    /// The brightest channel must stand this many σ above its offset, or
    /// the frame is `no_light`.
    pub min_signal_sigma: f64,
    /// χ² per degree of freedom above which the fit is `diverged`; below
    /// it, a χ²/dof above 1 inflates the reported std by its square root.
    pub max_reduced_chi2: f64,
    /// Warm start only across gaps shorter than this (seconds).
    pub max_gap_s: f64,
    /// 1σ by which the water's K_D may differ from the calibrated value,
    /// m⁻¹. K_D is not fitted per frame, so its doubt is added to the
    /// reported x std ("consider" covariance); 0 means K_D is known
    /// exactly. Unset: the calibration's own standard error of K_D, i.e.
    /// the water of the sweep; in other water say how far it may be off
    /// (MODEL.md's Monte Carlo spread is 0.015, which `lightpose
    /// montecarlo` and `bench` tell the estimator).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_d_sigma: Option<f64>,
    /// `[estimator.model.daylight]`: the vehicle works by day with a steady
    /// beacon, so the counts carry the sun's light (see
    /// [`DaylightConfig`]); left out, none is modelled (v1/v2). Frames of
    /// a blinking beacon (amplitudes) ignore it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub daylight: Option<DaylightConfig>,
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig {
            dof: Dof::Full,
            fixed_pitch_deg: 0.0,
            fixed_yaw_deg: 0.0,
            use_attitude: true,
            attitude_sigma_pitch_deg: 0.3,
            attitude_sigma_yaw_deg: 1.5,
            attitude_sigma_roll_deg: 0.3,
            roll_sigma_deg: None,
            attitude_envelope_deg: None,
            x_range: [3.0, 12.0],
            search_margin: 2.0,
            max_lateral_ratio: 0.7,
            max_angle_deg: 60.0,
            max_iter: 40,
            max_saturated: 4,
            min_signal_sigma: 6.0,
            max_reduced_chi2: 100.0,
            max_gap_s: 2.0,
            k_d_sigma: None,
            daylight: None,
        }
    }
}

/// Why a model-based estimator cannot be built: its sensor model or its
/// settings are unusable. Here because the settings' validators return it.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("sensor model: {0}")]
    Model(String),
    #[error("model estimator config: {0}")]
    Config(String),
}

pub use lightpose_core::bounds::{MAX_K_D_DOUBT, MAX_TEMP_DOUBT_C};

/// A setting's value as a message shows it: in full where that is short,
/// else in exponent form (1e-300 had printed 300 digits).
pub(crate) fn num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e9).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// `roll_sigma_deg`, when set, is a roll a vehicle can have: above 0 and
/// at most 45°.
pub(crate) fn roll_sigma_ok(v: Option<f64>) -> Result<(), String> {
    match v {
        Some(v) if !(v.is_finite() && v > 0.0 && v <= 45.0) => Err(format!(
            "roll_sigma_deg = {} must be above 0 and at most 45°",
            num(v)
        )),
        _ => Ok(()),
    }
}

/// A frame's roll as an estimator takes it: the reading's (with the
/// configured σ) when it has one, else 0 with `prior_sigma_deg` when that
/// is set; `None` (roll exactly 0, not reported: spec v1/v2) otherwise.
/// Radians: (roll, 1σ).
pub fn roll_of(
    frame: &lightpose_core::Frame,
    use_attitude: bool,
    reading_sigma_deg: f64,
    prior_sigma_deg: Option<f64>,
) -> Option<(f64, f64)> {
    let reading = frame
        .attitude
        .filter(|_| use_attitude)
        .and_then(|a| a.roll)
        .filter(|r| r.rad().is_finite());
    match (reading, prior_sigma_deg) {
        (Some(r), _) => Some((r.rad(), reading_sigma_deg.to_radians())),
        (None, Some(s)) => Some((0.0, s.to_radians())),
        (None, None) => None,
    }
}

impl ModelConfig {
    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::Config(m));
        if let Some(d) = &self.daylight {
            d.validate().map_err(ModelError::Config)?;
        }
        let [lo, hi] = self.x_range;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo) {
            return bad(format!(
                "x_range = [{}, {}] must be 0 < lo < hi",
                num(lo),
                num(hi)
            ));
        }
        for (name, v) in [
            ("attitude_sigma_pitch_deg", self.attitude_sigma_pitch_deg),
            ("attitude_sigma_yaw_deg", self.attitude_sigma_yaw_deg),
            ("attitude_sigma_roll_deg", self.attitude_sigma_roll_deg),
            ("search_margin", self.search_margin),
            ("max_lateral_ratio", self.max_lateral_ratio),
            ("max_angle_deg", self.max_angle_deg),
            ("max_reduced_chi2", self.max_reduced_chi2),
            ("max_gap_s", self.max_gap_s),
            ("min_signal_sigma", self.min_signal_sigma),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("{name} = {} must be positive", num(v)));
            }
        }
        if let Some(v) = self.k_d_sigma {
            if !(v.is_finite() && (0.0..=MAX_K_D_DOUBT).contains(&v)) {
                return bad(format!(
                    "k_d_sigma = {} must be 0 to {MAX_K_D_DOUBT} m⁻¹",
                    num(v)
                ));
            }
        }
        roll_sigma_ok(self.roll_sigma_deg).map_err(ModelError::Config)?;
        if let Some(v) = self.attitude_envelope_deg {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("attitude_envelope_deg = {v} must be positive"));
            }
        }
        // Angles as the poses give them (a pitch of 370° had diverged on
        // every frame without a word).
        if !(self.fixed_pitch_deg.abs() <= 90.0 && self.fixed_yaw_deg.abs() <= 180.0) {
            return bad(format!(
                "fixed_pitch_deg = {} must be within ±90° and fixed_yaw_deg = {} within ±180°",
                num(self.fixed_pitch_deg),
                num(self.fixed_yaw_deg)
            ));
        }
        if self.search_margin < 1.0 {
            return bad("search_margin must be at least 1".into());
        }
        if self.max_iter == 0 {
            return bad("max_iter must be at least 1".into());
        }
        Ok(())
    }
}
