//! The scene file: the beacon, the water, the array, the ADC, the noise, the
//! Monte Carlo spreads and the vehicle's sensors (attitude, depth, DVL), with exactly the keys of
//! `scene-example.toml`. A table that is left out turns its effect off
//! (scattering, noise, attitude sensor); a key left out of a present table
//! takes MODEL.md's default. Unknown keys, wrong types and impossible values
//! are refused with the file, the line and the key.

use lightpose_core::textfile::{parse_toml, read_text, TextError};
use lightpose_core::textpos::line_of_key;
use lightpose_core::{Angle, ArrayGeometry, LightParams, Scattering, COLS, NDET, ROWS};
use serde::Deserialize;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// Unreadable, too large, or not TOML of the scene's shape.
    #[error(transparent)]
    Text(#[from] TextError),
    #[error("{file}:{line}: {msg}")]
    Invalid {
        file: String,
        line: usize,
        msg: String,
    },
}

/// ADC resolution, reference and frame rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Adc {
    pub bits: u8,
    pub v_ref: f64,
    pub rate_hz: f64,
}

/// Per-sample noise; absent means a noise-free scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Electronic noise, 1σ, volts.
    pub sigma_e_v: f64,
    /// Signal shot-noise factor, volts (variance κ·E).
    pub kappa_v: f64,
    /// Noise of the reported temperature, °C.
    pub sigma_temp_c: f64,
}

/// Spread across Monte Carlo realizations (paper Table 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McSpread {
    pub sigma_temp_c: f64,
    pub sigma_k_d: f64,
}

/// The vehicle's attitude sensor noise (1σ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeNoise {
    pub sigma_pitch: Angle,
    pub sigma_yaw: Angle,
}

impl Default for AttitudeNoise {
    /// MODEL.md's attitude sensor (scene-example.toml): 0.3° pitch, 1.5° yaw.
    fn default() -> Self {
        AttitudeNoise {
            sigma_pitch: Angle::from_deg(0.3),
            sigma_yaw: Angle::from_deg(1.5),
        }
    }
}

/// The vehicle's depth sensor noise (1σ, metres; spec v2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthNoise {
    pub sigma_m: f64,
}

impl Default for DepthNoise {
    /// MODEL.md's depth sensor: 0.02 m.
    fn default() -> Self {
        DepthNoise { sigma_m: 0.02 }
    }
}

/// The vehicle's DVL noise (1σ per body component, m/s; spec v2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvlNoise {
    pub sigma_mps: f64,
}

impl Default for DvlNoise {
    /// MODEL.md's DVL: 0.02 m/s.
    fn default() -> Self {
        DvlNoise { sigma_mps: 0.02 }
    }
}

/// A validated scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    pub light: LightParams,
    pub geometry: ArrayGeometry,
    /// True water temperature, °C.
    pub temp_c: f64,
    pub gain: [f64; NDET],
    pub offset_v: [f64; NDET],
    pub adc: Adc,
    pub noise: Option<Noise>,
    pub montecarlo: McSpread,
    pub attitude: Option<AttitudeNoise>,
    pub depth: Option<DepthNoise>,
    pub dvl: Option<DvlNoise>,
}

impl Default for Scene {
    /// The paper's tank with every effect of `scene-example.toml` on
    /// (scattering and noise; no attitude sensor).
    fn default() -> Self {
        Scene {
            light: LightParams::default(),
            geometry: ArrayGeometry::paper(),
            temp_c: 20.0,
            gain: [1.0; NDET],
            offset_v: [0.15; NDET],
            adc: Adc {
                bits: 10,
                v_ref: 5.0,
                rate_hz: 5.0,
            },
            noise: Some(Noise {
                sigma_e_v: 0.05,
                kappa_v: 0.0,
                sigma_temp_c: 0.1,
            }),
            montecarlo: McSpread {
                sigma_temp_c: 3.0,
                sigma_k_d: 0.015,
            },
            attitude: None,
            depth: None,
            dvl: None,
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawScene {
    beacon: Option<RawBeacon>,
    water: Option<RawWater>,
    scattering: Option<RawScattering>,
    array: Option<RawArray>,
    adc: Option<RawAdc>,
    noise: Option<RawNoise>,
    montecarlo: Option<RawMc>,
    attitude: Option<RawAttitude>,
    depth: Option<RawDepth>,
    dvl: Option<RawDvl>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawBeacon {
    v1: Option<f64>,
    sigma_b_deg: Option<f64>,
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawWater {
    k_d: Option<f64>,
    temp_c: Option<f64>,
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawScattering {
    omega: Option<f64>,
    sigma_h_deg: Option<f64>,
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawArray {
    rows: Option<i64>,
    cols: Option<i64>,
    spacing_deg: Option<f64>,
    radius_m: Option<f64>,
    sigma_r_deg: Option<f64>,
    gain: Option<PerChannel>,
    offset_v: Option<PerChannel>,
}
#[derive(Deserialize)]
#[serde(untagged)]
enum PerChannel {
    One(f64),
    List(Vec<f64>),
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawAdc {
    bits: Option<i64>,
    v_ref: Option<f64>,
    rate_hz: Option<f64>,
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawNoise {
    sigma_e_v: Option<f64>,
    kappa_v: Option<f64>,
    sigma_temp_c: Option<f64>,
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawMc {
    sigma_temp_c: Option<f64>,
    sigma_k_d: Option<f64>,
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawAttitude {
    sigma_pitch_deg: Option<f64>,
    sigma_yaw_deg: Option<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawDepth {
    sigma_m: Option<f64>,
}
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawDvl {
    sigma_mps: Option<f64>,
}

struct Checker<'a> {
    file: &'a str,
    text: &'a str,
}

impl Checker<'_> {
    fn err(&self, table: &str, key: &str, msg: impl std::fmt::Display) -> SceneError {
        SceneError::Invalid {
            file: self.file.to_string(),
            line: line_of_key(self.text, table, key),
            msg: format!("[{table}] {key}: {msg}"),
        }
    }

    /// Take `v` or the default, and require `ok(v)`.
    fn num(
        &self,
        table: &str,
        key: &str,
        v: Option<f64>,
        default: f64,
        ok: fn(f64) -> bool,
        what: &str,
    ) -> Result<f64, SceneError> {
        let x = v.unwrap_or(default);
        if x.is_finite() && ok(x) {
            Ok(x)
        } else {
            Err(self.err(table, key, format!("{x} is impossible: must be {what}")))
        }
    }

    fn per_channel(
        &self,
        key: &str,
        v: Option<PerChannel>,
        default: f64,
        ok: fn(f64) -> bool,
        what: &str,
    ) -> Result<[f64; NDET], SceneError> {
        let mut out = [default; NDET];
        match v {
            None => {}
            Some(PerChannel::One(x)) => out = [x; NDET],
            Some(PerChannel::List(list)) => {
                if list.len() != NDET {
                    return Err(self.err(
                        "array",
                        key,
                        format!(
                            "list has {} values, expected rows·cols = {NDET}",
                            list.len()
                        ),
                    ));
                }
                out.copy_from_slice(&list);
            }
        }
        if let Some((k, x)) = out
            .iter()
            .enumerate()
            .find(|(_, x)| !(x.is_finite() && ok(**x)))
        {
            return Err(self.err(
                "array",
                key,
                format!("channel {k} = {x} is impossible: must be {what}"),
            ));
        }
        Ok(out)
    }
}

fn positive(x: f64) -> bool {
    x > 0.0
}
fn non_negative(x: f64) -> bool {
    x >= 0.0
}
fn below_right_angle(x: f64) -> bool {
    x > 0.0 && x < 90.0
}

impl RawBeacon {
    /// `[beacon]`: V1 (volts) and σ_b (degrees).
    fn validate(self, c: &Checker) -> Result<(f64, f64), SceneError> {
        let v1 = c.num(
            "beacon",
            "v1",
            self.v1,
            LightParams::default().v1,
            non_negative,
            "≥ 0",
        )?;
        let sigma_b = c.num(
            "beacon",
            "sigma_b_deg",
            self.sigma_b_deg,
            12.0,
            below_right_angle,
            "in (0, 90)",
        )?;
        Ok((v1, sigma_b))
    }
}

impl RawWater {
    /// `[water]`: K_D (1/m) and the true temperature (°C).
    fn validate(self, c: &Checker) -> Result<(f64, f64), SceneError> {
        let k_d = c.num("water", "k_d", self.k_d, 0.09, non_negative, "≥ 0")?;
        let temp_c = c.num(
            "water",
            "temp_c",
            self.temp_c,
            20.0,
            |t| (-5.0..=60.0).contains(&t),
            "in −5..60 °C",
        )?;
        Ok((k_d, temp_c))
    }
}

impl RawScattering {
    /// `[scattering]`: ω and σ_h.
    fn validate(self, c: &Checker) -> Result<Scattering, SceneError> {
        Ok(Scattering {
            omega: c.num("scattering", "omega", self.omega, 0.5, non_negative, "≥ 0")?,
            sigma_h: Angle::from_deg(c.num(
                "scattering",
                "sigma_h_deg",
                self.sigma_h_deg,
                20.0,
                below_right_angle,
                "in (0, 90)",
            )?),
        })
    }
}

/// What `[array]` gives: the dome, the detectors' acceptance σ_R (degrees)
/// and each channel's gain and dark offset.
struct ArrayTable {
    geometry: ArrayGeometry,
    sigma_r_deg: f64,
    gain: [f64; NDET],
    offset_v: [f64; NDET],
}

impl RawArray {
    /// `[array]`: a 5 × 5 dome, its spacing and radius, σ_R, and the
    /// per-channel gains and offsets (one value for all, or one per channel).
    fn validate(self, c: &Checker) -> Result<ArrayTable, SceneError> {
        for (key, v, want) in [("rows", self.rows, ROWS), ("cols", self.cols, COLS)] {
            if let Some(n) = v {
                if n != want as i64 {
                    return Err(c.err(
                        "array",
                        key,
                        format!("{n}: only a {ROWS} × {COLS} array is supported"),
                    ));
                }
            }
        }
        let spacing = c.num(
            "array",
            "spacing_deg",
            self.spacing_deg,
            15.0,
            |x| x > 0.0 && x <= 22.5,
            "in (0, 22.5] so the dome stays a hemisphere",
        )?;
        let radius = c.num("array", "radius_m", self.radius_m, 0.229, positive, "> 0")?;
        let sigma_r_deg = c.num(
            "array",
            "sigma_r_deg",
            self.sigma_r_deg,
            18.0,
            below_right_angle,
            "in (0, 90)",
        )?;
        let gain = c.per_channel("gain", self.gain, 1.0, positive, "> 0")?;
        let offset_v = c.per_channel(
            "offset_v",
            self.offset_v,
            0.15,
            |x| x.abs() < 1e3,
            "a voltage",
        )?;
        Ok(ArrayTable {
            geometry: ArrayGeometry::new(Angle::from_deg(spacing), radius),
            sigma_r_deg,
            gain,
            offset_v,
        })
    }
}

impl RawAdc {
    /// `[adc]`: resolution, reference and frame rate.
    fn validate(self, c: &Checker) -> Result<Adc, SceneError> {
        let bits = match self.bits {
            None => 10,
            Some(n @ 1..=16) => n as u8,
            Some(n) => {
                return Err(c.err("adc", "bits", format!("{n} is impossible: must be 1..16")))
            }
        };
        let v_ref = c.num("adc", "v_ref", self.v_ref, 5.0, positive, "> 0")?;
        let rate_hz = c.num(
            "adc",
            "rate_hz",
            self.rate_hz,
            5.0,
            |x| x > 0.0 && x <= 1e6,
            "in (0, 1e6]",
        )?;
        Ok(Adc {
            bits,
            v_ref,
            rate_hz,
        })
    }
}

impl RawNoise {
    /// `[noise]`: electronic and shot noise, and the reported temperature's.
    fn validate(self, c: &Checker) -> Result<Noise, SceneError> {
        let n = |key, v, default| c.num("noise", key, v, default, non_negative, "≥ 0");
        Ok(Noise {
            sigma_e_v: n("sigma_e_v", self.sigma_e_v, 0.05)?,
            kappa_v: n("kappa_v", self.kappa_v, 0.0)?,
            sigma_temp_c: n("sigma_temp_c", self.sigma_temp_c, 0.1)?,
        })
    }
}

impl RawMc {
    /// `[montecarlo]`: the spreads drawn per realization.
    fn validate(self, c: &Checker) -> Result<McSpread, SceneError> {
        let n = |key, v, default| c.num("montecarlo", key, v, default, non_negative, "≥ 0");
        Ok(McSpread {
            sigma_temp_c: n("sigma_temp_c", self.sigma_temp_c, 3.0)?,
            sigma_k_d: n("sigma_k_d", self.sigma_k_d, 0.015)?,
        })
    }
}

impl RawAttitude {
    /// `[attitude]`: the attitude sensor's noise (defaults: MODEL.md's).
    fn validate(self, c: &Checker) -> Result<AttitudeNoise, SceneError> {
        let d = AttitudeNoise::default();
        let n = |key, v, default| c.num("attitude", key, v, default, non_negative, "≥ 0");
        Ok(AttitudeNoise {
            sigma_pitch: Angle::from_deg(n(
                "sigma_pitch_deg",
                self.sigma_pitch_deg,
                d.sigma_pitch.deg(),
            )?),
            sigma_yaw: Angle::from_deg(n("sigma_yaw_deg", self.sigma_yaw_deg, d.sigma_yaw.deg())?),
        })
    }
}

impl RawDepth {
    /// `[depth]`: the depth sensor's noise.
    fn validate(self, c: &Checker) -> Result<DepthNoise, SceneError> {
        Ok(DepthNoise {
            sigma_m: c.num(
                "depth",
                "sigma_m",
                self.sigma_m,
                DepthNoise::default().sigma_m,
                non_negative,
                "≥ 0",
            )?,
        })
    }
}

impl RawDvl {
    /// `[dvl]`: the DVL's noise.
    fn validate(self, c: &Checker) -> Result<DvlNoise, SceneError> {
        Ok(DvlNoise {
            sigma_mps: c.num(
                "dvl",
                "sigma_mps",
                self.sigma_mps,
                DvlNoise::default().sigma_mps,
                non_negative,
                "≥ 0",
            )?,
        })
    }
}

impl Scene {
    /// Read and validate a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = read_text(path)?;
        Scene::parse(&text, &path.display().to_string())
    }

    /// Parse and validate a scene from TOML text; `file` names it in errors.
    /// Each table is checked by its own validator, in the file's order; a
    /// table left out takes its defaults, or turns its effect off.
    pub fn parse(text: &str, file: &str) -> Result<Scene, SceneError> {
        let raw: RawScene = parse_toml(text, file)?;
        let c = Checker { file, text };
        let (v1, sigma_b) = raw.beacon.unwrap_or_default().validate(&c)?;
        let (k_d, temp_c) = raw.water.unwrap_or_default().validate(&c)?;
        let scattering = raw.scattering.map(|s| s.validate(&c)).transpose()?;
        let array = raw.array.unwrap_or_default().validate(&c)?;
        let adc = raw.adc.unwrap_or_default().validate(&c)?;
        let noise = raw.noise.map(|n| n.validate(&c)).transpose()?;
        let montecarlo = raw.montecarlo.unwrap_or_default().validate(&c)?;
        let attitude = raw.attitude.map(|a| a.validate(&c)).transpose()?;
        let depth = raw.depth.map(|d| d.validate(&c)).transpose()?;
        let dvl = raw.dvl.map(|d| d.validate(&c)).transpose()?;
        Ok(Scene {
            light: LightParams {
                v1,
                sigma_b: Angle::from_deg(sigma_b),
                sigma_r: Angle::from_deg(array.sigma_r_deg),
                k_d,
                scattering,
            },
            geometry: array.geometry,
            temp_c,
            gain: array.gain,
            offset_v: array.offset_v,
            adc,
            noise,
            montecarlo,
            attitude,
            depth,
            dvl,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = include_str!("../../../../shared/spec/scene-example.toml");

    #[test]
    fn example_scene_is_the_default_tank_plus_the_vehicle_sensors() {
        let s = Scene::parse(EXAMPLE, "scene-example.toml").unwrap();
        let want = Scene {
            attitude: Some(AttitudeNoise {
                sigma_pitch: Angle::from_deg(0.3),
                sigma_yaw: Angle::from_deg(1.5),
            }),
            depth: Some(DepthNoise { sigma_m: 0.02 }),
            dvl: Some(DvlNoise { sigma_mps: 0.02 }),
            ..Scene::default()
        };
        assert_eq!(s, want);
    }

    #[test]
    fn left_out_tables_turn_effects_off() {
        let s = Scene::parse("[water]\nk_d = 0.2\n", "h.toml").unwrap();
        assert!(s.light.scattering.is_none());
        assert!(s.noise.is_none());
        assert!(s.attitude.is_none());
        assert!(s.depth.is_none() && s.dvl.is_none());
        assert_eq!(s.light.k_d, 0.2);
        assert_eq!(s.light.v1, 135.0);
        // a present table with no keys takes the defaults
        let s = Scene::parse("[noise]\n", "n.toml").unwrap();
        assert_eq!(s.noise.unwrap().sigma_e_v, 0.05);
    }

    fn refused(text: &str) -> String {
        Scene::parse(text, "bad.toml").unwrap_err().to_string()
    }

    #[test]
    fn bad_scenes_name_file_line_and_key() {
        let e = refused("[water]\nk_d = -0.1\n");
        assert!(e.starts_with("bad.toml:2: [water] k_d"), "{e}");
        let e = refused("[adc]\nbits = 0\n");
        assert!(e.starts_with("bad.toml:2: [adc] bits"), "{e}");
        let e = refused("[beacon]\nv1 = 1\n\n[array]\ngain = [1.0, 2.0]\n");
        assert!(
            e.starts_with("bad.toml:5: [array] gain: list has 2 values"),
            "{e}"
        );
        let e = refused("[water]\nk_d = 0.1\ncolour = \"green\"\n");
        assert!(e.starts_with("bad.toml:3:") && e.contains("colour"), "{e}");
        let e = refused("[water]\nk_d = \"clear\"\n");
        assert!(e.starts_with("bad.toml:2:"), "{e}");
        let e = refused("[lamp]\nv1 = 3\n");
        assert!(e.starts_with("bad.toml:1:") && e.contains("lamp"), "{e}");
        let e = refused("[depth]\nsigma_m = -0.1\n");
        assert!(e.starts_with("bad.toml:2: [depth] sigma_m"), "{e}");
        let e = refused("[dvl]\nsigma = 0.1\n");
        assert!(e.starts_with("bad.toml:2:") && e.contains("sigma"), "{e}");
        let e = refused("[array]\nrows = 4\n");
        assert!(e.contains("rows") && e.contains("5 × 5"), "{e}");
        let e = refused("[array]\noffset_v = [0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, nan]\n");
        assert!(e.contains("channel 24"), "{e}");
        assert_eq!(e.lines().count(), 1, "error spans lines: {e}");
    }
}
