//! The scene file's raw shape and the bounds each of its numbers must keep
//! (finite always, and within what physics or the ADC allows): its own
//! module because, with every number bounded, it outgrew `scene.rs`. The bounds are
//! generous on purpose: they refuse nonsense (negative, NaN, inf, 1e300),
//! they do not judge realism.

use super::{
    Adc, AttitudeNoise, Beacon, Blink, Daylight, DepthNoise, DvlNoise, Flicker, McSpread, Noise,
    Scene, SceneError,
};
use lightpose_core::bounds::{
    shown, Within, MAX_GAIN, MAX_K_D, MAX_K_D_DOUBT, MAX_OMEGA, MAX_RADIUS_M, MAX_SPACING_DEG,
    MAX_TEMP_DOUBT_C, MAX_V1_PER_V_REF, MAX_V_REF, MIN_V_REF, WIDTH_DEG,
};
use lightpose_core::modulation::{check_beacons, BeaconFreq};
use lightpose_core::textfile::parse_toml;
use lightpose_core::textpos::{line_of_key, line_of_key_nth};
use lightpose_core::MAX_BEACONS;
use lightpose_core::{Angle, ArrayGeometry, LightParams, Scattering, COLS, NDET, ROWS};
use serde::Deserialize;
use std::fmt;

mod sea;
use sea::{check_frequencies, RawDaylight, RawStationBeacon};

/// Water temperature, °C: liquid water with margin (inside `WATER_TEMP_C`, so frames stay usable).
const TEMP_C: (f64, f64) = (-5.0, 60.0);
/// A temperature noise or spread, °C: no wider than the whole allowed temperature range.
const MAX_SIGMA_TEMP_C: f64 = TEMP_C.1 - TEMP_C.0;
/// An attitude 1σ, degrees: beyond 180° the angle is unknown anyway.
const MAX_SIGMA_ANGLE_DEG: f64 = 180.0;
/// A depth sensor's 1σ, m: ten times the beacon's whole optical range (~10 m).
const MAX_SIGMA_DEPTH_M: f64 = 100.0;
/// A DVL's 1σ, m/s: several times the fastest vehicle's speed.
const MAX_SIGMA_DVL_MPS: f64 = 10.0;
/// A phase, degrees: one turn either way.
const PHASE_DEG: Within = Within::closed(-360.0, 360.0, "°");
/// A beacon clock's offset, ppm: a hundred times a poor crystal's.
const MAX_DRIFT_PPM: f64 = 1e4;
/// A beacon's position in D, m: far past the beacon's optical range.
const MAX_POSITION_M: f64 = 1e3;
/// Most random flicker sinusoids of each kind.
const MAX_RANDOM_COMPONENTS: i64 = 1000;

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
    /// Spec v3: a station's beacons, instead of `[beacon]`.
    beacons: Option<Vec<RawStationBeacon>>,
    daylight: Option<RawDaylight>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawBeacon {
    v1: Option<f64>,
    sigma_b_deg: Option<f64>,
    mod_hz: Option<f64>,
    phase_deg: Option<f64>,
    drift_ppm: Option<f64>,
    off_s: Option<Vec<Vec<f64>>>,
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
    sample_hz: Option<f64>,
    channel_skew_s: Option<f64>,
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
    sigma_roll_deg: Option<f64>,
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
    /// Within an array of tables (`[[beacons]]`, `[[daylight.flicker]]`):
    /// which of them, so that a key is found in its own table.
    nth: Option<usize>,
}

impl Checker<'_> {
    fn err(&self, table: &str, key: &str, msg: impl fmt::Display) -> SceneError {
        let (line, shown) = match self.nth {
            None => (line_of_key(self.text, table, key), format!("[{table}]")),
            Some(n) => (
                line_of_key_nth(self.text, table, n, key),
                format!("[[{table}]] #{}", n + 1),
            ),
        };
        SceneError::Invalid {
            file: self.file.to_string(),
            line,
            msg: format!("{shown} {key}: {msg}"),
        }
    }

    /// The same checker within the `n`th of an array of tables.
    fn nth(&self, n: usize) -> Checker<'_> {
        Checker {
            file: self.file,
            text: self.text,
            nth: Some(n),
        }
    }

    /// `off_s`: pairs [t0, t1) of finite times, t0 < t1.
    fn off_s(&self, table: &str, v: Option<Vec<Vec<f64>>>) -> Result<Vec<(f64, f64)>, SceneError> {
        let mut out = Vec::new();
        for (i, pair) in v.unwrap_or_default().iter().enumerate() {
            match pair[..] {
                [a, b] if a.is_finite() && b.is_finite() && a < b => out.push((a, b)),
                _ => {
                    return Err(self.err(
                        table,
                        "off_s",
                        format!("entry {i} must be [t0, t1] with finite t0 < t1"),
                    ))
                }
            }
        }
        Ok(out)
    }

    /// A beacon's clock: mod_hz, phase_deg, drift_ppm, off_s.
    fn blink(
        &self,
        table: &str,
        mod_hz: Option<f64>,
        phase_deg: Option<f64>,
        drift_ppm: Option<f64>,
        off_s: Option<Vec<Vec<f64>>>,
    ) -> Result<Blink, SceneError> {
        Ok(Blink {
            mod_hz: self.num(
                table,
                "mod_hz",
                mod_hz,
                0.0,
                Within::closed(0.0, 1e6, " Hz"),
            )?,
            phase_deg: self.num(table, "phase_deg", phase_deg, 0.0, PHASE_DEG)?,
            drift_ppm: self.num(
                table,
                "drift_ppm",
                drift_ppm,
                0.0,
                Within::closed(-MAX_DRIFT_PPM, MAX_DRIFT_PPM, " ppm"),
            )?,
            off_s: self.off_s(table, off_s)?,
        })
    }

    /// Take `v` or the default, and require it `within` its bounds.
    fn num(
        &self,
        table: &str,
        key: &str,
        v: Option<f64>,
        default: f64,
        within: Within,
    ) -> Result<f64, SceneError> {
        match v {
            Some(x) => within.check(x).map_err(|m| self.err(table, key, m)),
            None if within.contains(default) => Ok(default),
            None => Err(self.err(
                table,
                key,
                format!("the default {default} is impossible here: must be {within}"),
            )),
        }
    }

    /// `[array]`'s per-channel `key`: one value for all, or one per channel.
    fn per_channel(
        &self,
        key: &str,
        v: Option<PerChannel>,
        default: f64,
        within: Within,
    ) -> Result<[f64; NDET], SceneError> {
        let mut out = [default; NDET];
        let given = v.is_some();
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
        match out.iter().enumerate().find(|(_, x)| !within.contains(**x)) {
            Some((k, x)) if given => Err(self.err(
                "array",
                key,
                format!(
                    "channel {k} = {} is impossible: must be {within}",
                    shown(*x)
                ),
            )),
            Some((_, x)) => Err(self.err(
                "array",
                key,
                format!("the default {x} is impossible here: must be {within}"),
            )),
            None => Ok(out),
        }
    }
}

/// V1 (V·m², up to `MAX_V1_PER_V_REF`·v_ref; 0 is the beacon off, as in
/// a dark sweep) and σ_b (degrees) of `table`.
fn beacon_light(
    c: &Checker,
    table: &str,
    v1: Option<f64>,
    sigma_b_deg: Option<f64>,
    v_ref: f64,
) -> Result<(f64, f64), SceneError> {
    let v1_max = Within::closed(0.0, MAX_V1_PER_V_REF * v_ref, " V·m²").why("1e6 × [adc] v_ref");
    let v1 = c.num(table, "v1", v1, LightParams::default().v1, v1_max)?;
    let sigma_b = c.num(table, "sigma_b_deg", sigma_b_deg, 12.0, WIDTH_DEG)?;
    Ok((v1, sigma_b))
}

impl RawBeacon {
    /// `[beacon]`: V1 and σ_b, and (spec v3) its clock.
    fn validate(self, c: &Checker, v_ref: f64) -> Result<(f64, f64, Blink), SceneError> {
        let (v1, sigma_b) = beacon_light(c, "beacon", self.v1, self.sigma_b_deg, v_ref)?;
        let blink = c.blink(
            "beacon",
            self.mod_hz,
            self.phase_deg,
            self.drift_ppm,
            self.off_s,
        )?;
        Ok((v1, sigma_b, blink))
    }
}

impl RawWater {
    /// `[water]`: K_D (1/m) and the true temperature (°C).
    fn validate(self, c: &Checker) -> Result<(f64, f64), SceneError> {
        let k_d = c.num(
            "water",
            "k_d",
            self.k_d,
            0.09,
            Within::closed(0.0, MAX_K_D, " m⁻¹"),
        )?;
        let temp_c = c.num(
            "water",
            "temp_c",
            self.temp_c,
            20.0,
            Within::closed(TEMP_C.0, TEMP_C.1, " °C").why("liquid water"),
        )?;
        Ok((k_d, temp_c))
    }
}

impl RawScattering {
    /// `[scattering]`: ω and σ_h.
    fn validate(self, c: &Checker) -> Result<Scattering, SceneError> {
        let omega = Within::closed(0.0, MAX_OMEGA, "");
        Ok(Scattering {
            omega: c.num("scattering", "omega", self.omega, 0.5, omega)?,
            sigma_h: Angle::from_deg(c.num(
                "scattering",
                "sigma_h_deg",
                self.sigma_h_deg,
                20.0,
                WIDTH_DEG,
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
    /// per-channel gains and dark offsets (an offset is a reading of the ADC,
    /// so within [0, v_ref]).
    fn validate(self, c: &Checker, v_ref: f64) -> Result<ArrayTable, SceneError> {
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
        let spacing =
            Within::above(0.0, MAX_SPACING_DEG, "°").why("so the dome stays a hemisphere");
        let spacing = c.num("array", "spacing_deg", self.spacing_deg, 15.0, spacing)?;
        let radius = Within::above(0.0, MAX_RADIUS_M, " m");
        let radius = c.num("array", "radius_m", self.radius_m, 0.229, radius)?;
        let sigma_r_deg = c.num("array", "sigma_r_deg", self.sigma_r_deg, 18.0, WIDTH_DEG)?;
        let gain = c.per_channel("gain", self.gain, 1.0, Within::above(0.0, MAX_GAIN, ""))?;
        let offset = Within::closed(0.0, v_ref, " V").why("0..[adc] v_ref");
        let offset_v = c.per_channel("offset_v", self.offset_v, 0.15, offset)?;
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
        let v_ref = Within::closed(MIN_V_REF, MAX_V_REF, " V");
        let v_ref = c.num("adc", "v_ref", self.v_ref, 5.0, v_ref)?;
        let rate = Within::above(0.0, 1e6, " Hz");
        let rate_hz = c.num("adc", "rate_hz", self.rate_hz, 5.0, rate)?;
        // Whether it is a whole multiple of the rate is MODEL.md's
        // frequency rules' to say (with the beacons, in `parse`).
        let sample = Within::above(0.0, 1e7, " Hz");
        let sample_hz = c.num("adc", "sample_hz", self.sample_hz, rate_hz, sample)?;
        let skew = Within::closed(0.0, 1.0 / rate_hz, " s").why("up to a frame period");
        let channel_skew_s = c.num("adc", "channel_skew_s", self.channel_skew_s, 0.0, skew)?;
        Ok(Adc {
            bits,
            v_ref,
            rate_hz,
            sample_hz,
            channel_skew_s,
        })
    }
}

impl RawNoise {
    /// `[noise]`: electronic and shot noise (neither larger than the whole
    /// ADC range: κ ≤ v_ref keeps a full-scale signal's shot noise within
    /// it), and the reported temperature's.
    fn validate(self, c: &Checker, v_ref: f64) -> Result<Noise, SceneError> {
        let volts = Within::closed(0.0, v_ref, " V").why("the whole ADC range, [adc] v_ref");
        let temp = Within::closed(0.0, MAX_SIGMA_TEMP_C, " °C");
        Ok(Noise {
            sigma_e_v: c.num("noise", "sigma_e_v", self.sigma_e_v, 0.05, volts)?,
            kappa_v: c.num("noise", "kappa_v", self.kappa_v, 0.0, volts)?,
            sigma_temp_c: c.num("noise", "sigma_temp_c", self.sigma_temp_c, 0.1, temp)?,
        })
    }
}

impl RawMc {
    /// `[montecarlo]`: the spreads drawn per realization.
    fn validate(self, c: &Checker) -> Result<McSpread, SceneError> {
        // The estimators' own limits for these doubts, which a Monte Carlo
        // hands them: a scene that passed here had failed there, naming
        // the estimator's setting instead of this table.
        let temp = Within::closed(0.0, MAX_TEMP_DOUBT_C, " °C");
        let k_d = Within::closed(0.0, MAX_K_D_DOUBT, " m⁻¹");
        Ok(McSpread {
            sigma_temp_c: c.num("montecarlo", "sigma_temp_c", self.sigma_temp_c, 3.0, temp)?,
            sigma_k_d: c.num("montecarlo", "sigma_k_d", self.sigma_k_d, 0.015, k_d)?,
        })
    }
}

impl RawAttitude {
    /// `[attitude]`: the attitude sensor's noise (defaults: MODEL.md's).
    fn validate(self, c: &Checker) -> Result<AttitudeNoise, SceneError> {
        let d = AttitudeNoise::default();
        let deg = Within::closed(0.0, MAX_SIGMA_ANGLE_DEG, "°");
        let n = |key, v, default: Angle| c.num("attitude", key, v, default.deg(), deg);
        Ok(AttitudeNoise {
            sigma_pitch: Angle::from_deg(n(
                "sigma_pitch_deg",
                self.sigma_pitch_deg,
                d.sigma_pitch,
            )?),
            sigma_yaw: Angle::from_deg(n("sigma_yaw_deg", self.sigma_yaw_deg, d.sigma_yaw)?),
            sigma_roll: self
                .sigma_roll_deg
                .map(|v| c.num("attitude", "sigma_roll_deg", Some(v), 0.0, deg))
                .transpose()?
                .map(Angle::from_deg),
        })
    }
}

impl RawDepth {
    /// `[depth]`: the depth sensor's noise.
    fn validate(self, c: &Checker) -> Result<DepthNoise, SceneError> {
        let m = Within::closed(0.0, MAX_SIGMA_DEPTH_M, " m");
        let default = DepthNoise::default().sigma_m;
        Ok(DepthNoise {
            sigma_m: c.num("depth", "sigma_m", self.sigma_m, default, m)?,
        })
    }
}

impl RawDvl {
    /// `[dvl]`: the DVL's noise.
    fn validate(self, c: &Checker) -> Result<DvlNoise, SceneError> {
        let mps = Within::closed(0.0, MAX_SIGMA_DVL_MPS, " m/s");
        let default = DvlNoise::default().sigma_mps;
        Ok(DvlNoise {
            sigma_mps: c.num("dvl", "sigma_mps", self.sigma_mps, default, mps)?,
        })
    }
}

/// Parse and validate a scene from TOML text; `file` names it in errors.
/// `[adc]` is checked first, since the offsets, the noise and V1 are bounded
/// by its reference; then each table by its own validator. A table left out
/// takes its defaults, or turns its effect off.
pub(super) fn parse(text: &str, file: &str) -> Result<Scene, SceneError> {
    let raw: RawScene = parse_toml(text, file)?;
    let c = Checker {
        file,
        text,
        nth: None,
    };
    let adc = raw.adc.unwrap_or_default().validate(&c)?;
    if raw.beacon.is_some() && raw.beacons.is_some() {
        return Err(c.nth(0).err(
            "beacons",
            "id",
            "a scene has one [beacon] or a station of [[beacons]], not both",
        ));
    }
    let beacons = match raw.beacons {
        None => Vec::new(),
        Some(list) => {
            if list.is_empty() || list.len() > MAX_BEACONS {
                return Err(c.err("beacons", "id", format!("1 to {MAX_BEACONS} beacons")));
            }
            let mut out: Vec<Beacon> = Vec::with_capacity(list.len());
            for (i, b) in list.into_iter().enumerate() {
                let b = b.validate(&c.nth(i), adc.v_ref)?;
                if out.iter().any(|o| o.id == b.id) {
                    return Err(c
                        .nth(i)
                        .err("beacons", "id", format!("\"{}\" repeats", b.id)));
                }
                out.push(b);
            }
            out
        }
    };
    let (v1, sigma_b, blink) = match beacons.first() {
        // A station: `light` carries its first beacon's (for the v2 code
        // that reads one V1); each beacon's own is in `beacons`.
        Some(b) => (b.v1, b.sigma_b.deg(), Blink::default()),
        None => raw.beacon.unwrap_or_default().validate(&c, adc.v_ref)?,
    };
    check_frequencies(&c, &adc, &blink, &beacons)?;
    let daylight = raw
        .daylight
        .map(|d| d.validate(&c, adc.v_ref))
        .transpose()?;
    let (k_d, temp_c) = raw.water.unwrap_or_default().validate(&c)?;
    let scattering = raw.scattering.map(|s| s.validate(&c)).transpose()?;
    let array = raw.array.unwrap_or_default().validate(&c, adc.v_ref)?;
    let noise = raw.noise.map(|n| n.validate(&c, adc.v_ref)).transpose()?;
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
        blink,
        beacons,
        daylight,
    })
}
