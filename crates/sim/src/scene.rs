//! The scene file: the beacon, the water, the array, the ADC, the noise, the
//! Monte Carlo spreads and the vehicle's sensors (attitude, depth, DVL), with exactly the keys of
//! `scene-example.toml`. A table that is left out turns its effect off
//! (scattering, noise, attitude sensor); a key left out of a present table
//! takes MODEL.md's default. Unknown keys, wrong types and impossible values
//! (not finite, or outside what physics or the ADC allows) are refused with
//! the file, the line, the key and the bound.

use lightpose_core::textfile::{read_text, TextError};
use lightpose_core::{Angle, ArrayGeometry, LightParams, NDET};
use std::path::Path;

mod validate;

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

impl Scene {
    /// Read and validate a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = read_text(path)?;
        Scene::parse(&text, &path.display().to_string())
    }

    /// Parse and validate a scene from TOML text; `file` names it in errors.
    /// A table left out takes its defaults, or turns its effect off; every
    /// number must be finite and within its bounds (`scene/validate.rs`).
    pub fn parse(text: &str, file: &str) -> Result<Scene, SceneError> {
        validate::parse(text, file)
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
