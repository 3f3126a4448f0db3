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

/// ADC resolution, reference, frame rate and (spec v3) sample rate and
/// channel skew.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Adc {
    pub bits: u8,
    pub v_ref: f64,
    pub rate_hz: f64,
    /// Samples per second of every channel: a whole multiple N of
    /// `rate_hz` (N = 1 in v1/v2).
    pub sample_hz: f64,
    /// Time between two consecutive channels' conversions, s.
    pub channel_skew_s: f64,
}

impl Adc {
    /// Samples of each channel per frame, N.
    pub fn samples_per_frame(&self) -> usize {
        lightpose_core::modulation::whole(self.sample_hz / self.rate_hz).map_or(1, |n| n as usize)
    }
}

/// A beacon's own clock (spec v3): a square wave s(t) = 1 while
/// frac(f·(1 + δ)·t + phase/360) < 0.5, dark during `off_s`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Blink {
    /// Hz; 0 is steady (v1/v2).
    pub mod_hz: f64,
    pub phase_deg: f64,
    pub drift_ppm: f64,
    /// Times [t0, t1) when the beacon is dark.
    pub off_s: Vec<(f64, f64)>,
}

impl Blink {
    /// s(t): whether the beacon is lit at `t` (MODEL.md).
    #[inline]
    pub fn on(&self, t: f64) -> bool {
        if self.off_s.iter().any(|&(a, b)| a <= t && t < b) {
            return false;
        }
        if self.mod_hz <= 0.0 {
            return true;
        }
        let cycles = self.mod_hz * (1.0 + self.drift_ppm * 1e-6) * t + self.phase_deg / 360.0;
        cycles - cycles.floor() < 0.5
    }
}

/// One beacon of a station (`[[beacons]]`, spec v3), in the station's
/// frame D.
#[derive(Debug, Clone, PartialEq)]
pub struct Beacon {
    pub id: String,
    /// V·m².
    pub v1: f64,
    pub sigma_b: Angle,
    pub blink: Blink,
    /// c_b in D, m.
    pub position_m: [f64; 3],
    pub axis_yaw: Angle,
    pub axis_pitch: Angle,
}

impl Beacon {
    /// Its optical axis in D: (cos θa·cos ψa, cos θa·sin ψa, sin θa).
    pub fn axis(&self) -> [f64; 3] {
        let (sp, cp) = self.axis_pitch.sin_cos();
        let (sy, cy) = self.axis_yaw.sin_cos();
        [cp * cy, cp * sy, sp]
    }
}

/// A listed flicker component: a · sin(2π f t + φ), common to every
/// detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flicker {
    pub hz: f64,
    pub amplitude: f64,
    pub phase_deg: f64,
}

/// The sun's light through the water (`[daylight]`, spec v3).
#[derive(Debug, Clone, PartialEq)]
pub struct Daylight {
    /// S, volts before the gain.
    pub surface_v: f64,
    pub origin_depth_m: f64,
    /// ρ.
    pub upwelling: f64,
    /// h_f, m.
    pub flicker_depth_m: f64,
    pub flicker: Vec<Flicker>,
    /// σ_f of the random part (0: none).
    pub random_std: f64,
    pub random_min_hz: f64,
    pub random_max_hz: f64,
    pub random_components: usize,
    pub spatial: f64,
}

impl Default for Daylight {
    /// MODEL.md's defaults, no listed component.
    fn default() -> Self {
        Daylight {
            surface_v: 1.0,
            origin_depth_m: 5.0,
            upwelling: 0.02,
            flicker_depth_m: 3.0,
            flicker: Vec::new(),
            random_std: 0.3,
            random_min_hz: 0.5,
            random_max_hz: 10.0,
            random_components: 8,
            spatial: 0.3,
        }
    }
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
    /// Spec v3: given, the sensor reports roll (else only when the
    /// trajectory has a roll column, with MODEL.md's 0.3°).
    pub sigma_roll: Option<Angle>,
}

/// MODEL.md's roll noise where the scene gives none.
pub const DEFAULT_SIGMA_ROLL_DEG: f64 = 0.3;

impl Default for AttitudeNoise {
    /// MODEL.md's attitude sensor (scene-example.toml): 0.3° pitch, 1.5° yaw.
    fn default() -> Self {
        AttitudeNoise {
            sigma_pitch: Angle::from_deg(0.3),
            sigma_yaw: Angle::from_deg(1.5),
            sigma_roll: None,
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
    /// The one `[beacon]`'s clock (its light is `light`; spec v3).
    pub blink: Blink,
    /// Spec v3 `[[beacons]]`: a station of beacons in D (then `light`'s
    /// v1 and σ_b are the first beacon's, and `blink` is unused); empty for
    /// one `[beacon]` at B's origin.
    pub beacons: Vec<Beacon>,
    /// Spec v3 `[daylight]`.
    pub daylight: Option<Daylight>,
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
                sample_hz: 5.0,
                channel_skew_s: 0.0,
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
            blink: Blink::default(),
            beacons: Vec::new(),
            daylight: None,
        }
    }
}

impl Scene {
    /// Whether the scene is spec v1/v2's: one steady beacon, one sample per
    /// frame, no daylight (the frames are v2's; no roll is read here, since
    /// roll comes from the trajectory).
    pub fn is_v2(&self) -> bool {
        self.beacons.is_empty()
            && self.blink == Blink::default()
            && self.adc.samples_per_frame() == 1
            && self.daylight.is_none()
    }

    /// A log header for this scene's frames: its ADC and rate, and (spec
    /// v3, when a frame has several samples) the sample rate, the channel
    /// skew and the beacons a demodulator looks for.
    pub fn log_header(&self) -> lightpose_core::LogHeader {
        let mut h = lightpose_core::LogHeader::new(self.adc.bits, self.adc.rate_hz);
        if self.adc.samples_per_frame() > 1 {
            h.sample_hz = Some(self.adc.sample_hz);
            h.channel_skew_s = (self.adc.channel_skew_s > 0.0).then_some(self.adc.channel_skew_s);
            h.beacons = self.beacon_infos();
        }
        h
    }

    /// The beacons as the log header names them (id, mod_hz): the station's,
    /// or the one `[beacon]` (id "beacon").
    pub fn beacon_infos(&self) -> Vec<lightpose_core::BeaconInfo> {
        if self.beacons.is_empty() {
            return vec![lightpose_core::BeaconInfo {
                id: lightpose_core::log::DEFAULT_BEACON_ID.into(),
                mod_hz: self.blink.mod_hz,
            }];
        }
        self.beacons
            .iter()
            .map(|b| lightpose_core::BeaconInfo {
                id: b.id.clone(),
                mod_hz: b.mod_hz(),
            })
            .collect()
    }
}

impl Beacon {
    pub fn mod_hz(&self) -> f64 {
        self.blink.mod_hz
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
    const EXAMPLE_V3: &str = include_str!("../../../../shared/spec/scene-example-v3.toml");
    const DOCK: &str = include_str!("../../../../shared/spec/dock-example.toml");

    /// Every key of spec v3 at its default is the v2 example plus roll
    /// noise and a daylight table.
    #[test]
    fn the_v3_example_is_the_v2_example_with_roll_noise_and_daylight() {
        let v2 = Scene::parse(EXAMPLE, "scene-example.toml").unwrap();
        let v3 = Scene::parse(EXAMPLE_V3, "scene-example-v3.toml").unwrap();
        assert!(v2.is_v2());
        let d = v3.daylight.clone().expect("a daylight table");
        assert_eq!(
            d.flicker,
            vec![Flicker {
                hz: 1.7,
                amplitude: 0.1,
                phase_deg: 0.0
            }]
        );
        assert_eq!((d.random_components, d.random_std), (8, 0.3));
        let want = Scene {
            attitude: Some(AttitudeNoise {
                sigma_roll: Some(Angle::from_deg(0.3)),
                ..v2.attitude.unwrap()
            }),
            daylight: Some(d),
            ..v2
        };
        assert_eq!(v3, want);
    }

    #[test]
    fn the_dock_example_is_a_station_of_four() {
        let s = Scene::parse(DOCK, "dock-example.toml").unwrap();
        let ids: Vec<&str> = s.beacons.iter().map(|b| b.id.as_str()).collect();
        assert_eq!(ids, ["top", "starboard", "bottom", "port"]);
        assert_eq!(s.adc.samples_per_frame(), 400);
        assert_eq!(s.adc.channel_skew_s, 4e-6);
        let port = &s.beacons[3];
        assert_eq!((port.mod_hz(), port.position_m), (500.0, [0.0, -0.5, 0.0]));
        let a = port.axis();
        assert!((a[1] - (-5f64).to_radians().sin()).abs() < 1e-15 && a[2] == 0.0);
        assert_eq!(s.light.v1, 4.0);
        assert!(!s.is_v2());
        assert_eq!(s.beacon_infos().len(), 4);
    }

    #[test]
    fn bad_v3_scenes_name_the_line_and_the_beacons() {
        let e = refused("[beacon]\nv1 = 1\n\n[[beacons]]\nid = \"a\"\nmod_hz = 200\n");
        assert!(
            e.starts_with("bad.toml:5: [[beacons]] #1 id: a scene has one [beacon]"),
            "{e}"
        );
        let two = |f2: &str| {
            format!("[adc]\nrate_hz = 10\nsample_hz = 4800\n\n[[beacons]]\nid = \"a\"\nmod_hz = 200\n\n[[beacons]]\nid = \"b\"\n{f2}\n")
        };
        let e = refused(&two("mod_hz = 600"));
        assert!(e.starts_with("bad.toml:7: [[beacons]] #1 mod_hz: beacons \"a\" (200 Hz) and \"b\" (600 Hz) stand in the ratio 1 : 3"), "{e}");
        let e = refused(&two("mod_hz = 0"));
        assert!(
            e.starts_with("bad.toml:11: [[beacons]] #2 mod_hz: beacon \"b\" is steady"),
            "{e}"
        );
        let e = refused(&two("mod_hz = 320"));
        assert!(e.starts_with("bad.toml:11: [[beacons]] #2 mod_hz: beacon \"b\": mod_hz = 320 gives 15 samples per period"), "{e}");
        assert!(Scene::parse(&two("mod_hz = 150"), "ok.toml").is_ok());
        let e = refused(&two("mod_hz = 150\ncolour = 1"));
        assert!(e.starts_with("bad.toml:12:") && e.contains("colour"), "{e}");
        let e = refused("[adc]\nrate_hz = 10\nsample_hz = 4800\n\n[[beacons]]\nid = \"a\"\nmod_hz = 200\n\n[[beacons]]\nid = \"a\"\nmod_hz = 150\n");
        assert!(
            e.starts_with("bad.toml:10: [[beacons]] #2 id: \"a\" repeats"),
            "{e}"
        );
        let e = refused(&two("mod_hz = 150\nposition_m = [1, 2]"));
        assert!(
            e.starts_with("bad.toml:12: [[beacons]] #2 position_m"),
            "{e}"
        );
        let e = refused("[adc]\nrate_hz = 10\nsample_hz = 4000\n");
        assert!(
            e.starts_with("bad.toml:3: [adc] sample_hz:") && e.contains("no beacon blinks"),
            "{e}"
        );
        let e = refused("[adc]\nrate_hz = 10\nsample_hz = 4005\n\n[beacon]\nmod_hz = 200\n");
        assert!(
            e.starts_with("bad.toml:3: [adc] sample_hz:") && e.contains("whole multiple"),
            "{e}"
        );
        let e = refused("[beacon]\noff_s = [[3.0, 1.0]]\n");
        assert!(e.starts_with("bad.toml:2: [beacon] off_s: entry 0"), "{e}");
        let e = refused("[daylight]\nspatial = 2\n");
        assert!(e.starts_with("bad.toml:2: [daylight] spatial"), "{e}");
        let e = refused(
            "[daylight]\n\n[[daylight.flicker]]\nhz = 1\n\n[[daylight.flicker]]\nhz = -1\n",
        );
        assert!(
            e.starts_with("bad.toml:7: [[daylight.flicker]] #2 hz"),
            "{e}"
        );
        let e = refused("[daylight]\n\n[[daylight.flicker]]\nhz = 1\nwave = 3\n");
        assert!(e.starts_with("bad.toml:5:") && e.contains("wave"), "{e}");
        let e = refused("[attitude]\nsigma_roll_deg = -1\n");
        assert!(
            e.starts_with("bad.toml:2: [attitude] sigma_roll_deg"),
            "{e}"
        );
    }

    #[test]
    fn example_scene_is_the_default_tank_plus_the_vehicle_sensors() {
        let s = Scene::parse(EXAMPLE, "scene-example.toml").unwrap();
        let want = Scene {
            attitude: Some(AttitudeNoise {
                sigma_pitch: Angle::from_deg(0.3),
                sigma_yaw: Angle::from_deg(1.5),
                sigma_roll: None,
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
