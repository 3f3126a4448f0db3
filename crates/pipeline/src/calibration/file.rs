//! The calibration file: every coefficient of the paper's pose equations,
//! how well each was fitted, the range of poses it is valid over, the scene
//! facts it assumed and the files it came from. It is the contract between
//! `lightpose calibrate` (which writes it) and every estimator, the daemon
//! and the Monte Carlo (which read it), so it is typed and checked on load:
//! unknown keys and impossible values are refused with file, line and key.
//!
//! The optional `[physical]` table holds the light model fitted from the
//! same sweeps ([`PhysicalCalibration`], `physical_fit.rs`), which the
//! model-based estimators and the Cramér–Rao bound run on; the optional
//! `[estimator]` table holds their settings ([`EstimatorSettings`],
//! `src/settings.rs`), so that what a scene requires (free DOF, K_D
//! estimation) travels with its calibration.

pub use super::feature::{Feature, Moment, Origin};
use super::physical_fit::PhysicalCalibration;
use super::station::StationCalibration;
use crate::model::light::BeaconLight;
use crate::settings::EstimatorSettings;
use lightpose_core::bounds::{Within, MAX_K_D, MAX_V1_PER_V_REF, MAX_V_REF, MIN_V_REF};
use lightpose_core::textfile::{parse_toml, read_text, TextError};
use lightpose_core::textpos::line_of_key;
use lightpose_core::NDET;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// `meta.format` of every calibration file.
pub const FORMAT: &str = "lightpose-calibration";
/// `meta.version` this code reads and writes.
pub const VERSION: u32 = 1;
/// Longest surge window the estimator holds (fixed so it never allocates).
pub const MAX_SURGE_WINDOW: usize = 64;

#[derive(Debug, thiserror::Error)]
pub enum CalError {
    // The I/O error is in the message, not chained as a source, so that a
    // one-line `{:#}` report does not say it twice.
    #[error("{file}: {err}")]
    Io { file: String, err: std::io::Error },
    /// Unreadable, too large, or TOML syntax, a wrong type, a missing or an
    /// unknown key.
    #[error(transparent)]
    Text(#[from] TextError),
    /// A value that parses but cannot be right.
    #[error("{file}:{line}: {key}: {msg}")]
    Invalid {
        file: String,
        line: usize,
        key: String,
        msg: String,
    },
    #[error("{file}: cannot serialize calibration: {msg}")]
    Serialize { file: String, msg: String },
    /// Something else given where a calibration goes (an intensity log,
    /// whose TOML error would only say `invalid key`).
    #[error("{file}: {what}, not a calibration (the TOML that `lightpose calibrate` writes)")]
    NotACalibration { file: String, what: &'static str },
}

/// What a file given as a calibration is instead, when its first line
/// says so: JSON (an opening brace, `\u{7b}`) where TOML should be.
fn not_a_calibration(text: &str) -> Option<&'static str> {
    let first = text.lines().map(str::trim).find(|l| !l.is_empty())?;
    if !first.starts_with('\u{7b}') {
        return None;
    }
    Some(if first.contains("\"lightpose-intensity\"") {
        "an intensity log (JSON Lines): calibrate from it with `lightpose calibrate --sweep`, or replay it with --log"
    } else {
        "JSON"
    })
}

/// Provenance of the calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Meta {
    pub format: String,
    pub version: u32,
    pub created_by: String,
    /// The sweep logs it was fitted from, as given on the command line.
    pub sweeps: Vec<String>,
    /// Where the dark offsets came from: a dark log's path, "sweep" (beacon-off
    /// frames inside the sweeps) or "nominal" (MODEL.md's 0.15 V, no dark data).
    pub dark_source: String,
    /// Frames that went into the fits, and log lines refused.
    pub frames: u64,
    pub bad_lines: u64,
}

/// The scene facts the fit assumed; replay converts counts with the same.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFacts {
    /// Resolution of the sweep logs (frames of other resolutions convert
    /// by their own; this is a record, not a restriction).
    pub adc_bits: u8,
    /// ADC reference, volts: counts → volts.
    pub v_ref: f64,
    /// Reference temperature of eq. 14 (g_T = 1 there).
    pub t_ref_c: f64,
    /// Water temperature assumed for frames that report none.
    pub default_temp_c: f64,
    pub rate_hz: f64,
}

/// Each channel's dark offset (volts), subtracted before anything else.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dark {
    pub offset_v: Vec<f64>,
    /// Each channel's noise (1σ, volts) when dark frames were available.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_v: Option<Vec<f64>>,
    #[serde(default)]
    pub frames: u64,
}

/// x from the peak: PD_max = a1 · exp(−b1 · x) (eqs. 2–3), fitted as a line
/// in ln PD_max.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeFit {
    /// volts
    pub a1: f64,
    /// 1/m
    pub b1: f64,
    pub r2: f64,
    /// Residual σ of ln PD_max: of every translation frame about the law
    /// (off-axis dimming included), whatever frames the law was fitted on.
    pub sigma_ln: f64,
    /// The same as metres of x (σ_ln / b1).
    pub sigma_m: f64,
    pub n: u64,
    /// Which frames the fit was taken from (a file without the key was
    /// fitted over the whole grid).
    #[serde(default)]
    pub basis: RangeBasis,
}

/// The frames the range law is fitted on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RangeBasis {
    /// On the beam axis, facing the beacon (y = z = 0, level): the paper's
    /// reading, and what its tank errors show.
    Axis,
    /// Every translation frame, off-axis ones included.
    #[default]
    Grid,
}

/// quantity = a · feature + b (eqs. 4–7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearFit {
    pub feature: Feature,
    pub a: f64,
    pub b: f64,
    pub r2: f64,
    /// Residual σ in the quantity's unit (metres or degrees).
    pub sigma: f64,
    pub n: u64,
}

impl LinearFit {
    #[inline]
    pub fn eval(&self, f: f64) -> f64 {
        self.a * f + self.b
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fits {
    pub x: RangeFit,
    /// degrees
    pub pitch: LinearFit,
    /// degrees
    pub yaw: LinearFit,
    /// metres
    pub y: LinearFit,
    /// metres
    pub z: LinearFit,
}

/// The poses the sweeps covered, [min, max].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Coverage {
    pub x_m: [f64; 2],
    pub y_m: [f64; 2],
    pub z_m: [f64; 2],
    pub pitch_deg: [f64; 2],
    pub yaw_deg: [f64; 2],
}

/// Thresholds of the status word and the surge smoothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Peak signal (volts, after offset and temperature) below which a
    /// frame has no light.
    pub no_light_v: f64,
    /// Samples of x the surge slope is fitted over (paper: 10).
    pub surge_window: usize,
    /// How far outside the covered range an estimate may go before its
    /// status says out_of_range.
    pub margin_x_m: f64,
    pub margin_yz_m: f64,
    pub margin_angle_deg: f64,
    /// A gap longer than this between usable frames restarts y, z and surge.
    pub max_gap_s: f64,
}

/// A value that parses but cannot be right: (table, key, why).
pub type Refusal = (&'static str, &'static str, String);

fn finite(t: &'static str, k: &'static str, v: f64) -> Result<(), Refusal> {
    if v.is_finite() {
        Ok(())
    } else {
        Err((t, k, format!("{v} is not a finite number")))
    }
}

fn positive(t: &'static str, k: &'static str, v: f64) -> Result<(), Refusal> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err((t, k, format!("{v} must be a positive number")))
    }
}

impl Meta {
    /// `[meta]`: this format, this version.
    fn check(&self) -> Result<(), Refusal> {
        if self.format != FORMAT {
            return Err((
                "meta",
                "format",
                format!(
                    "\"{}\" is not \"{FORMAT}\"",
                    lightpose_core::textfile::excerpt(&self.format, 40)
                ),
            ));
        }
        if self.version != VERSION {
            return Err((
                "meta",
                "version",
                format!("{} is not supported (only {VERSION})", self.version),
            ));
        }
        Ok(())
    }
}

impl SceneFacts {
    /// `[scene]`: an ADC, a rate, and eq. 14's reference temperature of
    /// this build.
    fn check(&self) -> Result<(), Refusal> {
        if !(1..=16).contains(&self.adc_bits) {
            return Err((
                "scene",
                "adc_bits",
                format!("{} must be 1..16", self.adc_bits),
            ));
        }
        let v_ref = Within::closed(MIN_V_REF, MAX_V_REF, " V").check(self.v_ref);
        v_ref.map_err(|m| ("scene", "v_ref", m))?;
        positive("scene", "rate_hz", self.rate_hz)?;
        finite("scene", "t_ref_c", self.t_ref_c)?;
        if (self.t_ref_c - lightpose_core::light::T_REF_C).abs() > 1e-9 {
            return Err((
                "scene",
                "t_ref_c",
                format!(
                    "{} differs from the {} °C that eq. 14 is referred to in this build",
                    self.t_ref_c,
                    lightpose_core::light::T_REF_C
                ),
            ));
        }
        let water = lightpose_core::light::WATER_TEMP_C;
        if !water.contains(&self.default_temp_c) {
            return Err((
                "scene",
                "default_temp_c",
                format!(
                    "{} °C is not a water temperature ({}..{} °C)",
                    self.default_temp_c,
                    water.start(),
                    water.end()
                ),
            ));
        }
        Ok(())
    }
}

impl Dark {
    /// `[dark]`: one finite offset per channel, noise ≥ 0 where given.
    fn check(&self) -> Result<(), Refusal> {
        if self.offset_v.len() != NDET {
            return Err((
                "dark",
                "offset_v",
                format!("has {} values, expected {NDET}", self.offset_v.len()),
            ));
        }
        if let Some(v) = self.offset_v.iter().find(|v| !v.is_finite()) {
            return Err(("dark", "offset_v", format!("{v} is not a finite number")));
        }
        if let Some(sig) = &self.sigma_v {
            if sig.len() != NDET || sig.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err((
                    "dark",
                    "sigma_v",
                    format!("must be {NDET} non-negative numbers"),
                ));
            }
        }
        Ok(())
    }
}

impl Fits {
    /// `[fits.*]`: a falling range law, finite lines, and for each quantity
    /// the kind of moment the paper's equation takes (a ratio for the
    /// angles, a first moment for y and z).
    fn check(&self) -> Result<(), Refusal> {
        let x = &self.x;
        // Beyond these no light reads as a range (a b1 of 1e300 made every
        // range the law's a1 alone, and those poses `ok`).
        let a1 = Within::above(0.0, MAX_V1_PER_V_REF * MAX_V_REF, " V");
        a1.check(x.a1).map_err(|m| ("fits.x", "a1", m))?;
        let b1 = Within::above(0.0, MAX_K_D, " m⁻¹").why("the murkiest water's K_D");
        b1.check(x.b1).map_err(|m| ("fits.x", "b1", m))?;
        finite("fits.x", "r2", x.r2)?;
        // A residual's σ goes into every pose's std: 0 or less would
        // publish a certainty no fit has.
        positive("fits.x", "sigma_ln", x.sigma_ln)?;
        positive("fits.x", "sigma_m", x.sigma_m)?;
        let lines = [
            ("fits.pitch", &self.pitch, false),
            ("fits.yaw", &self.yaw, false),
            ("fits.y", &self.y, true),
            ("fits.z", &self.z, true),
        ];
        for (t, f, _) in lines {
            finite(t, "a", f.a)?;
            finite(t, "b", f.b)?;
            finite(t, "r2", f.r2)?;
            positive(t, "sigma", f.sigma)?;
        }
        for (t, f, first) in lines {
            if matches!(f.feature.moment, Moment::M10 | Moment::M01) != first {
                let want = if first {
                    "must be a first moment (m10 or m01)"
                } else {
                    "must be a moment ratio (m12/m22 or m21/m22)"
                };
                return Err((t, "feature", want.into()));
            }
        }
        Ok(())
    }
}

impl Coverage {
    /// `[coverage]`: each a finite [min, max].
    fn check(&self) -> Result<(), Refusal> {
        for (k, r) in [
            ("x_m", self.x_m),
            ("y_m", self.y_m),
            ("z_m", self.z_m),
            ("pitch_deg", self.pitch_deg),
            ("yaw_deg", self.yaw_deg),
        ] {
            if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1]) {
                return Err((
                    "coverage",
                    k,
                    format!("[{}, {}] is not a range", r[0], r[1]),
                ));
            }
        }
        Ok(())
    }
}

impl Limits {
    /// `[limits]`: a positive threshold and gap, a window the estimator
    /// holds, margins ≥ 0.
    fn check(&self) -> Result<(), Refusal> {
        positive("limits", "no_light_v", self.no_light_v)?;
        if !(2..=MAX_SURGE_WINDOW).contains(&self.surge_window) {
            return Err((
                "limits",
                "surge_window",
                format!("{} must be 2..{MAX_SURGE_WINDOW}", self.surge_window),
            ));
        }
        for (k, v) in [
            ("margin_x_m", self.margin_x_m),
            ("margin_yz_m", self.margin_yz_m),
            ("margin_angle_deg", self.margin_angle_deg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(("limits", k, format!("{v} must be ≥ 0")));
            }
        }
        positive("limits", "max_gap_s", self.max_gap_s)
    }
}

/// A typed calibration (see the module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    pub meta: Meta,
    pub scene: SceneFacts,
    pub dark: Dark,
    pub fits: Fits,
    pub coverage: Coverage,
    pub limits: Limits,
    /// R² of every candidate feature for each quantity: the evidence for
    /// the features that `fits` chose.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub selection: BTreeMap<String, BTreeMap<String, f64>>,
    /// Light-model parameters for the model-based estimators; absent when
    /// the sweeps could not determine them (the moments part still works).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physical: Option<PhysicalCalibration>,
    /// Settings of the model-based estimators; absent means their defaults.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimator: Option<EstimatorSettings>,
    /// Spec v3: the docking station this was calibrated against
    /// (`lightpose calibrate --station`); absent for one beacon, so that a
    /// v2 file reads and writes as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub station: Option<StationCalibration>,
}

impl Calibration {
    /// This calibration used in water whose K_D is known only to
    /// `sigma_k_d` about its own, and whose temperature the frames report
    /// only to `sigma_temp_c` (see `EstimatorSettings::in_water_known_to`).
    pub fn in_water_known_to(&self, sigma_k_d: f64, sigma_temp_c: f64) -> Calibration {
        let mut c = self.clone();
        let settings = c.estimator.take().unwrap_or_default();
        c.estimator = Some(settings.in_water_known_to(sigma_k_d, sigma_temp_c));
        c
    }

    /// Read, parse and check a calibration file.
    pub fn load(path: &Path) -> Result<Calibration, CalError> {
        let text = read_text(path)?;
        Calibration::parse(&text, &path.display().to_string())
    }

    /// Parse and check calibration text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Calibration, CalError> {
        if let Some(what) = not_a_calibration(text) {
            return Err(CalError::NotACalibration {
                file: file.to_string(),
                what,
            });
        }
        let cal: Calibration = parse_toml(text, file)?;
        cal.check().map_err(|(table, key, msg)| CalError::Invalid {
            file: file.to_string(),
            line: line_of_key(text, table, key),
            key: if table.is_empty() {
                key.to_string()
            } else if key.is_empty() {
                table.to_string()
            } else {
                format!("{table}.{key}")
            },
            msg,
        })?;
        Ok(cal)
    }

    /// The TOML text of this calibration.
    pub fn to_toml(&self) -> Result<String, String> {
        toml::to_string(self).map_err(|e| e.to_string())
    }

    /// Write the calibration (checked first, so that what is written loads).
    pub fn save(&self, path: &Path) -> Result<(), CalError> {
        let file = path.display().to_string();
        self.check()
            .map_err(|(table, key, msg)| CalError::Invalid {
                file: file.clone(),
                line: 0,
                key: format!("{table}.{key}"),
                msg,
            })?;
        let mut text = String::from(
            "# lightpose calibration: coefficients of the paper's pose equations\n\
             # (eqs. 2-7), fitted by `lightpose calibrate`. See docs/pipeline.md.\n\n",
        );
        text.push_str(&self.to_toml().map_err(|msg| CalError::Serialize {
            file: file.clone(),
            msg,
        })?);
        std::fs::write(path, text).map_err(|err| CalError::Io { file, err })
    }

    /// Volts that this calibration's ADC can read: the dark offsets and
    /// the no-light threshold within ±`scene.v_ref`.
    fn fits_this_adc(&self) -> Result<(), Refusal> {
        let v_ref = self.scene.v_ref;
        if let Some(v) = self.dark.offset_v.iter().find(|v| v.abs() > v_ref) {
            return Err((
                "dark",
                "offset_v",
                format!("{v} V is beyond the ADC's ±{v_ref} V (scene.v_ref)"),
            ));
        }
        if self.limits.no_light_v > v_ref {
            return Err((
                "limits",
                "no_light_v",
                format!(
                    "{} V is beyond the ADC's {v_ref} V (scene.v_ref): no frame could have light",
                    self.limits.no_light_v
                ),
            ));
        }
        Ok(())
    }

    /// The light model was fitted on this calibration's ADC, and every
    /// standard error is a σ (finite, ≥ 0).
    fn physical_fits_this_adc(&self, p: &PhysicalCalibration) -> Result<(), Refusal> {
        if p.adc_bits != self.scene.adc_bits {
            return Err((
                "physical",
                "adc_bits",
                format!(
                    "{} differs from scene.adc_bits {}: the light model is of another ADC",
                    p.adc_bits, self.scene.adc_bits
                ),
            ));
        }
        if p.v_ref != self.scene.v_ref {
            return Err((
                "physical",
                "v_ref",
                format!(
                    "{} differs from scene.v_ref {}: the light model is of another ADC",
                    p.v_ref, self.scene.v_ref
                ),
            ));
        }
        let mut named = vec![
            ("v1", &p.v1),
            ("sigma_b_deg", &p.sigma_b_deg),
            ("sigma_r_deg", &p.sigma_r_deg),
            ("k_d", &p.k_d),
        ];
        named.extend(p.omega.as_ref().map(|e| ("omega", e)));
        named.extend(p.sigma_h_deg.as_ref().map(|e| ("sigma_h_deg", e)));
        named.extend(p.gain.iter().map(|e| ("gain", e)));
        named.extend(p.offset_v.iter().map(|e| ("offset_v", e)));
        match named
            .iter()
            .find(|(_, e)| !(e.std.is_finite() && e.std >= 0.0))
        {
            Some((k, e)) => Err((
                "physical",
                k,
                format!("std {} must be a non-negative number", e.std),
            )),
            None => Ok(()),
        }
    }

    /// Every value that parses but cannot be right, as (table, key, why):
    /// each table by its own check, in the file's order.
    pub fn check(&self) -> Result<(), Refusal> {
        self.meta.check()?;
        self.scene.check()?;
        self.dark.check()?;
        self.fits.check()?;
        self.coverage.check()?;
        self.limits.check()?;
        self.fits_this_adc()?;
        if let Some(p) = &self.physical {
            p.validate().map_err(|(k, m)| ("physical", k, m))?;
            self.physical_fits_this_adc(p)?;
        }
        if let Some(st) = &self.station {
            st.check()
                .map_err(|(k, m)| ("station", "beacons", format!("{k}: {m}")))?;
        }
        if let Some(e) = &self.estimator {
            e.model
                .validate()
                .map_err(|m| ("estimator", "model", m.to_string()))?;
            e.tracker
                .validate()
                .map_err(|m| ("estimator", "tracker", m.to_string()))?;
        }
        Ok(())
    }

    /// The station this calibration carries (spec v3), if any.
    pub fn station(&self) -> Option<&StationCalibration> {
        self.station.as_ref()
    }

    /// The station's beacons as the light equation sees them (surveyed
    /// placement, fitted V1 and σ_b), what the station's estimators take;
    /// empty for one beacon (the sensor model's own, at D's origin).
    pub fn beacon_lights(&self) -> Vec<BeaconLight> {
        self.station
            .as_ref()
            .map_or_else(Vec::new, StationCalibration::beacon_lights)
    }

    /// Dark offsets as a fixed array (checked to have NDET values).
    pub fn dark_offsets(&self) -> [f64; NDET] {
        let mut o = [0.0; NDET];
        for (d, s) in o.iter_mut().zip(&self.dark.offset_v) {
            *d = *s;
        }
        o
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A plausible calibration for tests (not a fit of anything).
    pub(crate) fn sample() -> Calibration {
        let lin = |feature: &str, a: f64, b: f64| LinearFit {
            feature: Feature::try_from(feature.to_string()).unwrap(),
            a,
            b,
            r2: 0.99,
            sigma: 0.1,
            n: 100,
        };
        Calibration {
            meta: Meta {
                format: FORMAT.into(),
                version: VERSION,
                created_by: "test".into(),
                sweeps: vec!["sweep.jsonl".into()],
                dark_source: "nominal".into(),
                frames: 100,
                bad_lines: 0,
            },
            scene: SceneFacts {
                adc_bits: 10,
                v_ref: 5.0,
                t_ref_c: 20.0,
                default_temp_c: 20.0,
                rate_hz: 5.0,
            },
            dark: Dark {
                offset_v: vec![0.15; NDET],
                sigma_v: None,
                frames: 0,
            },
            fits: Fits {
                x: RangeFit {
                    a1: 33.0,
                    b1: 0.44,
                    r2: 0.99,
                    sigma_ln: 0.02,
                    basis: RangeBasis::Axis,
                    sigma_m: 0.07,
                    n: 100,
                },
                pitch: lin("m21/m22@peak", -20.0, 0.0),
                yaw: lin("m12/m22@peak", -20.0, 0.0),
                y: lin("m10@centre", -0.5, 0.0),
                z: lin("m01@centre", 0.5, 0.0),
            },
            coverage: Coverage {
                x_m: [4.5, 8.5],
                y_m: [-0.6, 0.6],
                z_m: [0.0, 0.8],
                pitch_deg: [-15.0, 15.0],
                yaw_deg: [-15.0, 15.0],
            },
            limits: Limits {
                no_light_v: 0.25,
                surge_window: 10,
                margin_x_m: 0.5,
                margin_yz_m: 0.2,
                margin_angle_deg: 5.0,
                max_gap_s: 2.0,
            },
            selection: BTreeMap::new(),
            physical: None,
            estimator: None,
            station: None,
        }
    }

    #[test]
    fn save_load_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cal.toml");
        let mut c = sample();
        c.selection
            .entry("pitch".into())
            .or_default()
            .insert("m21/m22@peak".into(), 0.98);
        c.save(&p).unwrap();
        let back = Calibration::load(&p).unwrap();
        assert_eq!(back, c);
    }

    #[test]
    fn unknown_key_is_named_with_its_line() {
        let text = sample()
            .to_toml()
            .unwrap()
            .replace("[limits]\n", "[limits]\nbogus = 3\n");
        let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
        let line = text.lines().position(|l| l.starts_with("bogus")).unwrap() + 1;
        assert!(e.starts_with(&format!("c.toml:{line}: ")), "{e}");
        assert!(e.contains("bogus"), "{e}");
    }

    #[test]
    fn impossible_value_is_named_with_key_and_line() {
        let text = sample()
            .to_toml()
            .unwrap()
            .replace("b1 = 0.44", "b1 = -0.44");
        let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
        let line = text.lines().position(|l| l.starts_with("b1 =")).unwrap() + 1;
        assert_eq!(
            e,
            format!(
                "c.toml:{line}: fits.x.b1: -0.44 is impossible: must be in (0, 100] m⁻¹ (the murkiest water's K_D)"
            )
        );
    }

    /// An audit's calibrations that loaded and then panicked the first
    /// frame's start (a dome of radius 13 m, a spacing of NaN) or gave
    /// garbage as `ok` poses (b1 = 1e300): each refused, naming its key.
    #[test]
    fn a_light_model_no_scene_could_hold_is_refused_naming_its_key() {
        let base = sample();
        let mut c = base.clone();
        c.physical = Some(sample_physical());
        let good = c.to_toml().unwrap();
        Calibration::parse(&good, "c.toml").expect("the sample loads");
        for (from, to, key) in [
            ("radius_m = 0.229", "radius_m = 13.0", "physical.radius_m"),
            (
                "spacing_deg = 15.0",
                "spacing_deg = nan",
                "physical.spacing_deg",
            ),
            (
                "spacing_deg = 15.0",
                "spacing_deg = -1.0",
                "physical.spacing_deg",
            ),
            (
                "sigma_e_v = 0.05",
                "sigma_e_v = 1e300",
                "physical.sigma_e_v",
            ),
            ("b1 = 0.44", "b1 = 1e300", "fits.x.b1"),
        ] {
            assert_eq!(good.matches(from).count(), 1, "{from}");
            let text = good.replace(from, to);
            let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
            let line = text.lines().position(|l| l.starts_with(to)).unwrap() + 1;
            assert!(
                e.starts_with(&format!("c.toml:{line}: {key}: ")),
                "{to}: {e}"
            );
            assert!(e.contains("is impossible: must be in"), "{e}");
        }
        // A table's value (`[physical.v1]`) is named by its table.
        let mut p = sample_physical();
        p.v1.value = 1e300;
        c.physical = Some(p);
        let e = Calibration::parse(&c.to_toml().unwrap(), "c.toml").unwrap_err();
        assert!(
            e.to_string().contains("physical.v1: 1e300 is impossible"),
            "{e}"
        );
    }

    #[test]
    fn missing_key_and_bad_feature_are_refused() {
        let e = refusal_with("surge_window = 10\n", "");
        assert!(e.contains("surge_window"), "{e}");
        let e = refusal_with("m10@centre", "m11@centre");
        assert!(e.contains("unknown moment \"m11\""), "{e}");
    }

    /// The refusal of the sample calibration with `from` written as `to`.
    fn refusal_with(from: &str, to: &str) -> String {
        let text = sample().to_toml().unwrap().replace(from, to);
        Calibration::parse(&text, "c.toml").unwrap_err().to_string()
    }

    #[test]
    fn a_wrong_format_is_quoted_on_one_line_and_bounded() {
        // Found by the fuzz target: the whole value was quoted, newlines
        // and all.
        let wrong = format!("lig{}\\n/cu0ve{}", "R".repeat(300), "R".repeat(300));
        let e = refusal_with("\"lightpose-calibration\"", &format!("\"{wrong}\""));
        assert!(e.starts_with("c.toml:") && e.contains("meta.format"), "{e}");
        assert!(!e.contains('\n') && e.chars().count() < 200, "{e}");
    }

    #[test]
    fn a_default_temperature_no_water_has_is_refused() {
        for t in ["100.0", "-20.0"] {
            let e = refusal_with("default_temp_c = 20.0", &format!("default_temp_c = {t}"));
            assert!(e.contains("c.toml") && e.contains("default_temp_c"), "{e}");
            assert!(e.contains("not a water temperature (-10..60 °C)"), "{e}");
        }
    }

    /// A physical table as the fitter writes it: V1 135, K_D 0.09, unit
    /// gains, 0.15 V offsets, no scattering.
    pub(crate) fn sample_physical() -> PhysicalCalibration {
        let pe = |value: f64, std: f64| crate::calibration::ParamEstimate { value, std };
        PhysicalCalibration {
            v1: pe(135.0, 0.3),
            sigma_b_deg: pe(12.0, 0.01),
            sigma_r_deg: pe(18.0, 0.02),
            k_d: pe(0.09, 0.0007),
            omega: None,
            sigma_h_deg: None,
            gain: vec![pe(1.0, 0.001); NDET],
            offset_v: vec![pe(0.15, 0.001); NDET],
            sigma_e_v: 0.05,
            kappa_v: 0.0,
            v_ref: 5.0,
            adc_bits: 10,
            spacing_deg: 15.0,
            radius_m: 0.229,
            residual_rms_counts: vec![1.0; NDET],
            residual_rms_normalized: vec![1.0; NDET],
            chi2_per_dof: 1.05,
            poses: 100,
            frames: 20000,
        }
    }

    #[test]
    fn physical_and_estimator_tables_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cal.toml");
        let mut c = sample();
        c.physical = Some(sample_physical());
        let mut settings = EstimatorSettings::default();
        settings.model.dof = crate::settings::Dof::Position;
        settings.tracker.estimate_k_d = true;
        c.estimator = Some(settings);
        c.save(&p).unwrap();
        let back = Calibration::load(&p).unwrap();
        assert_eq!(back, c);
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(
            text.contains("[physical.v1]") || text.contains("[physical]"),
            "{text}"
        );
        assert!(text.contains("estimate_k_d = true"), "{text}");
    }

    #[test]
    fn a_bad_physical_table_is_refused_with_its_table() {
        let mut c = sample();
        let mut p = sample_physical();
        p.gain.pop();
        c.physical = Some(p);
        let text = c.to_toml().unwrap();
        let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
        assert!(
            e.contains("physical.gain: has 24 entries, expected 25"),
            "{e}"
        );
        // A partial table (the old raw form) is refused, naming the key.
        let mut text = sample().to_toml().unwrap();
        text.push_str("\n[physical]\nv1 = 135.0\n");
        let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
        assert!(e.contains("c.toml:"), "{e}");
    }

    /// Values that parse but that no fit or ADC gives: a residual σ of 0
    /// or less (published as a pose's std), volts beyond the ADC, a light
    /// model of another ADC, a negative standard error.
    #[test]
    fn values_no_fit_or_adc_gives_are_refused_by_key() {
        for (from, to, want) in [
            ("sigma_m = 0.07", "sigma_m = -0.6", "fits.x.sigma_m"),
            ("sigma_m = 0.07", "sigma_m = 0.0", "fits.x.sigma_m"),
            ("sigma_ln = 0.02", "sigma_ln = 0.0", "fits.x.sigma_ln"),
            ("offset_v = [0.15,", "offset_v = [1e9,", "dark.offset_v"),
        ] {
            let e = refusal_with(from, to);
            assert!(
                e.starts_with("c.toml:") && e.contains(want),
                "{from} → {to}: {e}"
            );
        }
        let mut c = sample();
        let no_light = c.scene.v_ref * 2.0;
        c.limits.no_light_v = no_light;
        let e = Calibration::parse(&c.to_toml().unwrap(), "c.toml").unwrap_err();
        assert!(e.to_string().contains("limits.no_light_v"), "{e}");
        let with = |f: &dyn Fn(&mut PhysicalCalibration)| {
            let mut c = sample();
            let mut p = sample_physical();
            f(&mut p);
            c.physical = Some(p);
            Calibration::parse(&c.to_toml().unwrap(), "c.toml").map_err(|e| e.to_string())
        };
        assert!(with(&|_| {}).is_ok());
        let e = with(&|p| p.adc_bits = 12).unwrap_err();
        assert!(
            e.contains("physical.adc_bits") && e.contains("another ADC"),
            "{e}"
        );
        let e = with(&|p| p.v_ref = 3.3).unwrap_err();
        assert!(e.contains("physical.v_ref"), "{e}");
        let e = with(&|p| p.v1.std = -1.0).unwrap_err();
        assert!(
            e.contains("physical.v1") && e.contains("non-negative"),
            "{e}"
        );
        let e = with(&|p| p.gain[3].std = f64::NAN).unwrap_err();
        assert!(e.contains("physical.gain"), "{e}");
    }

    #[test]
    fn a_bad_estimator_setting_is_refused() {
        let mut text = sample().to_toml().unwrap();
        text.push_str("\n[estimator.tracker]\nupdate_iterations = 0\n");
        let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
        assert!(e.contains("estimator.tracker"), "{e}");
        assert!(e.contains("update_iterations must be at least 1"), "{e}");
    }

    #[test]
    fn a_temperature_doubt_is_read_and_checked() {
        let mut text = sample().to_toml().unwrap();
        text.push_str("\n[estimator.tracker]\ntemp_sigma_c = 0.5\n");
        let c = Calibration::parse(&text, "c.toml").unwrap();
        let st = c.estimator.unwrap();
        assert_eq!(st.tracker.temp_sigma_c, Some(0.5));
        for bad in ["-1.0", "nan", "80.0"] {
            let mut text = sample().to_toml().unwrap();
            text.push_str(&format!("\n[estimator.tracker]\ntemp_sigma_c = {bad}\n"));
            let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
            assert!(
                e.contains("temp_sigma_c") && e.contains("c.toml"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn the_water_reading_and_depth_offset_settings_are_read_and_checked() {
        let mut text = sample().to_toml().unwrap();
        text.push_str("\n[estimator.tracker]\nwater_check_frames = 0\nreading_check_s = 8.0\nreading_check_limit = 1.5\ndepth_offset_sigma_m = 0.3\n");
        let c = Calibration::parse(&text, "c.toml").unwrap();
        let t = c.estimator.unwrap().tracker;
        assert_eq!(t.water_check_frames, 0);
        assert_eq!(
            (t.depth_offset_sigma_m, t.depth_offset_walk_psd),
            (0.3, 1e-6)
        );
        assert_eq!((t.reading_check_s, t.reading_check_limit), (8.0, 1.5));
        for (key, bad, says) in [
            ("water_check_frames", "65", "0 (off) to 64"),
            ("reading_check_s", "13.0", "0 (off) to 12.8"),
            ("reading_check_s", "-1.0", "0 (off) to 12.8"),
            ("reading_check_limit", "0.0", "must be positive"),
            ("reading_check_limit", "nan", "must be positive"),
            ("water_check_nis", "1.0", "must be above 1"),
            ("water_check_nis", "nan", "must be above 1"),
            ("water_check_doubt", "-0.3", "must be positive"),
            ("depth_offset_sigma_m", "-0.1", "0 (off) to 100 m"),
            ("depth_offset_sigma_m", "nan", "0 (off) to 100 m"),
            ("pitch_offset_sigma_deg", "31.0", "0 (off) to 30°"),
            ("pitch_offset_sigma_deg", "nan", "0 (off) to 30°"),
            ("depth_offset_walk_psd", "-1e-6", "must be 0 to 1 m²/s"),
            ("depth_offset_walk_psd", "inf", "must be 0 to 1 m²/s"),
        ] {
            let mut text = sample().to_toml().unwrap();
            text.push_str(&format!("\n[estimator.tracker]\n{key} = {bad}\n"));
            let e = Calibration::parse(&text, "c.toml").unwrap_err().to_string();
            assert!(
                e.contains(key) && e.contains(says) && e.contains("c.toml"),
                "{key} = {bad}: {e}"
            );
        }
    }

    #[test]
    fn features_round_trip_as_words() {
        for f in Feature::RATIOS.iter().chain(Feature::FIRST.iter()) {
            assert_eq!(Feature::try_from(f.to_string()), Ok(*f));
        }
    }
}
