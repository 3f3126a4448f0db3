//! A docking station as surveyed (FORMATS.md "station file") and as
//! calibrated (the calibration file's `[station]` table).
//!
//! Why here: `lightpose calibrate --station` reads the survey, the fit
//! (`station_fit`) adds each beacon's brightness and beam width, and the
//! calibration file carries the result to the daemon and every estimator,
//! which take it as `BeaconLight`s ([`StationCalibration::beacon_lights`]):
//! the surveyed placement, the fitted light. The survey is never changed
//! by the fit; what the fit says of it is in each beacon's `survey_check`.

// `!(a > b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::nonminimal_bool)]

use lightpose_core::modulation::{check_beacons, BeaconFreq};
use lightpose_core::textfile::{parse_toml, read_text, TextError};
use lightpose_core::textpos::{line_of_key, line_of_key_nth};
use lightpose_core::{Angle, MAX_BEACONS};
use serde::{Deserialize, Serialize};
use std::path::Path;

use super::ParamEstimate;
use crate::model::light::{BeaconLight, Placement};

/// How far from D's origin a surveyed beacon may stand (a scene's bound).
const MAX_POSITION_M: f64 = 1e3;

/// One beacon as a survey gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurveyedBeacon {
    pub id: String,
    /// c_b in D, m.
    pub position_m: [f64; 3],
    #[serde(default)]
    pub axis_yaw_deg: f64,
    #[serde(default)]
    pub axis_pitch_deg: f64,
    pub mod_hz: f64,
}

impl SurveyedBeacon {
    /// Where the beacon stands and points, as the light equation takes it.
    pub fn placement(&self) -> Placement {
        Placement::new(
            self.position_m,
            Angle::from_deg(self.axis_yaw_deg),
            Angle::from_deg(self.axis_pitch_deg),
        )
    }
}

/// A station file: its name and its beacons, in the file's order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Station {
    pub name: String,
    pub beacons: Vec<SurveyedBeacon>,
}

/// Why a station file was refused: one line naming `file:line: key`.
#[derive(Debug, thiserror::Error)]
pub enum StationError {
    #[error(transparent)]
    Text(#[from] TextError),
    #[error("{file}:{line}: {key}: {msg}")]
    Invalid {
        file: String,
        line: usize,
        key: String,
        msg: String,
    },
}

/// A refusal within the station: which beacon (None: the top level), key,
/// why.
type Refusal = (Option<usize>, &'static str, String);

impl Station {
    /// Read and check a station file.
    pub fn load(path: &Path) -> Result<Station, StationError> {
        let text = read_text(path)?;
        Station::parse(&text, &path.display().to_string())
    }

    /// Parse and check station text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Station, StationError> {
        let s: Station = parse_toml(text, file)?;
        s.check().map_err(|r| Station::locate(text, file, r))?;
        Ok(s)
    }

    /// A refusal at its line of `text`.
    fn locate(text: &str, file: &str, (nth, key, msg): Refusal) -> StationError {
        let (line, key) = match nth {
            None => (line_of_key(text, "", key), key.to_string()),
            Some(n) => (
                line_of_key_nth(text, "beacons", n, key),
                format!("[[beacons]] #{} {key}", n + 1),
            ),
        };
        StationError::Invalid {
            file: file.to_string(),
            line,
            key,
            msg,
        }
    }

    /// Every value that parses but cannot be a station: a name, 1 to
    /// `MAX_BEACONS` beacons with distinct non-empty ids, finite positions
    /// and axes within their ranges, and frequencies that can be told
    /// apart (each blinking, none shared; MODEL.md's rules with an ADC are
    /// [`Station::check_frequencies`]).
    pub fn check(&self) -> Result<(), Refusal> {
        if self.name.trim().is_empty() {
            return Err((None, "name", "must be a non-empty string".into()));
        }
        if self.beacons.is_empty() || self.beacons.len() > MAX_BEACONS {
            return Err((
                None,
                "beacons",
                format!(
                    "{} beacons: a station has 1 to {MAX_BEACONS}",
                    self.beacons.len()
                ),
            ));
        }
        for (i, b) in self.beacons.iter().enumerate() {
            let bad = |key, msg: String| Err((Some(i), key, msg));
            if b.id.trim().is_empty() {
                return bad("id", "every beacon needs an id (a non-empty string)".into());
            }
            if let Some(j) = self.beacons[..i].iter().position(|o| o.id == b.id) {
                return bad("id", format!("{:?} is also beacon #{}'s", b.id, j + 1));
            }
            if !b.position_m.iter().all(|v| v.abs() <= MAX_POSITION_M) {
                return bad(
                    "position_m",
                    format!("must be [x, y, z], each finite within ±{MAX_POSITION_M} m"),
                );
            }
            if !(b.axis_yaw_deg.abs() <= 180.0) {
                return bad(
                    "axis_yaw_deg",
                    format!("{} must be -180..180°", b.axis_yaw_deg),
                );
            }
            if !(b.axis_pitch_deg.abs() <= 90.0) {
                return bad(
                    "axis_pitch_deg",
                    format!("{} must be -90..90°", b.axis_pitch_deg),
                );
            }
            if !(b.mod_hz > 0.0 && b.mod_hz <= 1e6) {
                return bad(
                    "mod_hz",
                    format!(
                        "{} Hz: a station's beacon blinks (more than 0, at most 1e6 Hz), \
                         so that the array sees each apart",
                        b.mod_hz
                    ),
                );
            }
            if let Some(j) = self.beacons[..i].iter().position(|o| o.mod_hz == b.mod_hz) {
                return bad(
                    "mod_hz",
                    format!("{} Hz is also beacon #{}'s", b.mod_hz, j + 1),
                );
            }
        }
        Ok(())
    }

    /// MODEL.md's frequency rules (core's `check_beacons`, the scene's own
    /// check) for frames of `rate_hz` sampled at `sample_hz`: the error
    /// names the station's beacon and the line of its `mod_hz` in `text`.
    pub fn check_frequencies(
        &self,
        rate_hz: f64,
        sample_hz: f64,
        text: &str,
        file: &str,
    ) -> Result<(), StationError> {
        let freqs: Vec<BeaconFreq> = self
            .beacons
            .iter()
            .map(|b| BeaconFreq {
                id: &b.id,
                mod_hz: b.mod_hz,
            })
            .collect();
        let Err(e) = check_beacons(rate_hz, sample_hz, &freqs) else {
            return Ok(());
        };
        let msg = format!("{e} (frames of {rate_hz} Hz sampled at {sample_hz} Hz)");
        let named = e
            .beacon()
            .and_then(|id| self.beacons.iter().position(|b| b.id == id));
        Err(Station::locate(text, file, (named, "mod_hz", msg)))
    }
}

/// What the fit says of one beacon's survey: its residuals, and the offset
/// of its position and axis that would explain them best, with their σ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurveyCheck {
    /// χ² of the beacon's observations over their number, in the fit with
    /// the survey as it is, and that number.
    pub chi2_per_n: f64,
    pub n: usize,
    /// Position offset (D, m) and axis offset (yaw, pitch, degrees) fitted
    /// as a diagnostic with everything else; absent when the sweeps could
    /// not determine it (`note` says why).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_offset_m: Option<[ParamEstimate; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis_offset_deg: Option<[ParamEstimate; 2]>,
    /// Whether any offset is beyond 3σ: the survey looks off.
    pub suspect: bool,
    /// The report in words.
    pub note: String,
}

/// One beacon of a calibrated station: the survey as given, the fitted
/// brightness and beam width with their standard errors, and the check of
/// its survey.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibratedBeacon {
    pub id: String,
    pub position_m: [f64; 3],
    pub axis_yaw_deg: f64,
    pub axis_pitch_deg: f64,
    pub mod_hz: f64,
    pub v1: ParamEstimate,
    pub sigma_b_deg: ParamEstimate,
    pub survey_check: SurveyCheck,
    /// The relative model error of this beacon's images that the fit's
    /// residuals allow (`station_fit::model_error`), which the estimators
    /// add beside the demodulator's σ. A calibration written before it
    /// was measured reads as the fixed 2 %
    /// (`measurement::AMPLITUDE_MODEL_REL`).
    #[serde(default = "unmeasured_model_rel")]
    pub model_rel: f64,
}

fn unmeasured_model_rel() -> f64 {
    crate::model::measurement::AMPLITUDE_MODEL_REL
}

/// The calibration file's `[station]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StationCalibration {
    pub name: String,
    pub beacons: Vec<CalibratedBeacon>,
    /// χ² per degree of freedom of the whole fit, poses and frames used.
    pub chi2_per_dof: f64,
    pub poses: usize,
    pub frames: u64,
}

impl StationCalibration {
    /// The station as surveyed (what the fit took).
    pub fn survey(&self) -> Station {
        Station {
            name: self.name.clone(),
            beacons: self
                .beacons
                .iter()
                .map(|b| SurveyedBeacon {
                    id: b.id.clone(),
                    position_m: b.position_m,
                    axis_yaw_deg: b.axis_yaw_deg,
                    axis_pitch_deg: b.axis_pitch_deg,
                    mod_hz: b.mod_hz,
                })
                .collect(),
        }
    }

    /// Every beacon as the light equation sees it, in the station's order:
    /// the surveyed placement, the fitted V1 and σ_b (what the station's
    /// estimators take as `&[BeaconLight]`).
    pub fn beacon_lights(&self) -> Vec<BeaconLight> {
        let survey = self.survey();
        self.beacons
            .iter()
            .zip(&survey.beacons)
            .map(|(b, s)| BeaconLight {
                v1: b.v1.value,
                sigma_b: Angle::from_deg(b.sigma_b_deg.value),
                place: s.placement(),
                model_rel: b.model_rel,
            })
            .collect()
    }

    /// A loaded table: the survey's checks, and fitted values that a light
    /// equation can take (V1 > 0, σ_b a width, σ finite ≥ 0, a model
    /// error in [0, 1]); (key, why).
    pub fn check(&self) -> Result<(), (String, String)> {
        self.survey().check().map_err(|(nth, k, m)| match nth {
            Some(i) => (format!("beacons #{} {k}", i + 1), m),
            None => (k.to_string(), m),
        })?;
        for (i, b) in self.beacons.iter().enumerate() {
            let key = |k: &str| format!("beacons #{} {k}", i + 1);
            let ok = |e: &ParamEstimate| e.std.is_finite() && e.std >= 0.0;
            if !(b.v1.value > 0.0 && b.v1.value.is_finite()) || !ok(&b.v1) {
                return Err((key("v1"), format!("{:?} is not a brightness ± σ", b.v1)));
            }
            let w = lightpose_core::bounds::WIDTH_DEG;
            if w.check(b.sigma_b_deg.value).is_err() || !ok(&b.sigma_b_deg) {
                return Err((
                    key("sigma_b_deg"),
                    format!("{:?} is not a beam width ± σ", b.sigma_b_deg),
                ));
            }
            if !(0.0..=1.0).contains(&b.model_rel) {
                return Err((
                    key("model_rel"),
                    format!("{} is not a relative error in [0, 1]", b.model_rel),
                ));
            }
        }
        Ok(())
    }
}
