//! Spec v3's open-sea tables of a scene ("The open sea" in MODEL.md): a
//! docking station's `[[beacons]]`, `[daylight]` with its flicker, and the
//! frequency rules every blinking beacon must keep.

use super::*;

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct RawStationBeacon {
    id: Option<String>,
    v1: Option<f64>,
    sigma_b_deg: Option<f64>,
    mod_hz: Option<f64>,
    phase_deg: Option<f64>,
    drift_ppm: Option<f64>,
    off_s: Option<Vec<Vec<f64>>>,
    position_m: Option<Vec<f64>>,
    axis_yaw_deg: Option<f64>,
    axis_pitch_deg: Option<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDaylight {
    surface_v: Option<f64>,
    origin_depth_m: Option<f64>,
    upwelling: Option<f64>,
    flicker_depth_m: Option<f64>,
    random_std: Option<f64>,
    random_min_hz: Option<f64>,
    random_max_hz: Option<f64>,
    random_components: Option<i64>,
    spatial: Option<f64>,
    flicker: Option<Vec<RawFlicker>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFlicker {
    hz: Option<f64>,
    amplitude: Option<f64>,
    phase_deg: Option<f64>,
}

impl RawStationBeacon {
    /// One `[[beacons]]` table: its id, light, clock, position and axis.
    pub(super) fn validate(self, c: &Checker, v_ref: f64) -> Result<Beacon, SceneError> {
        let t = "beacons";
        let id = match self.id {
            Some(id) if !id.trim().is_empty() => id,
            _ => return Err(c.err(t, "id", "every beacon needs an id (a non-empty string)")),
        };
        let (v1, sigma_b) = beacon_light(c, t, self.v1, self.sigma_b_deg, v_ref)?;
        let blink = c.blink(t, self.mod_hz, self.phase_deg, self.drift_ppm, self.off_s)?;
        let position_m = match self.position_m.as_deref() {
            None => [0.0; 3],
            Some(&[x, y, z]) if [x, y, z].iter().all(|v| v.abs() <= MAX_POSITION_M) => [x, y, z],
            Some(_) => {
                return Err(c.err(
                    t,
                    "position_m",
                    format!("must be [x, y, z], each finite within ±{MAX_POSITION_M} m"),
                ))
            }
        };
        let axis_yaw = c.num(
            t,
            "axis_yaw_deg",
            self.axis_yaw_deg,
            0.0,
            Within::closed(-180.0, 180.0, "°"),
        )?;
        let axis_pitch = c.num(
            t,
            "axis_pitch_deg",
            self.axis_pitch_deg,
            0.0,
            Within::closed(-90.0, 90.0, "°"),
        )?;
        Ok(Beacon {
            id,
            v1,
            sigma_b: Angle::from_deg(sigma_b),
            blink,
            position_m,
            axis_yaw: Angle::from_deg(axis_yaw),
            axis_pitch: Angle::from_deg(axis_pitch),
        })
    }
}

impl RawDaylight {
    /// `[daylight]` and its `[[daylight.flicker]]` components.
    pub(super) fn validate(self, c: &Checker, v_ref: f64) -> Result<Daylight, SceneError> {
        let t = "daylight";
        let d = Daylight::default();
        let surface = Within::closed(0.0, MAX_V1_PER_V_REF * v_ref, " V").why("1e6 × [adc] v_ref");
        let depth = Within::closed(0.0, 1e4, " m");
        let unit = Within::closed(0.0, 1.0, "");
        let hz = Within::above(0.0, 1e6, " Hz");
        let random_min_hz = c.num(t, "random_min_hz", self.random_min_hz, d.random_min_hz, hz)?;
        let random_max_hz = c.num(
            t,
            "random_max_hz",
            self.random_max_hz,
            d.random_max_hz.max(random_min_hz),
            Within::closed(random_min_hz, 1e6, " Hz").why("random_min_hz and up"),
        )?;
        let random_components = match self.random_components {
            None => d.random_components,
            Some(n @ 0..=MAX_RANDOM_COMPONENTS) => n as usize,
            Some(n) => {
                return Err(c.err(
                    t,
                    "random_components",
                    format!("{n} is impossible: must be 0..{MAX_RANDOM_COMPONENTS}"),
                ))
            }
        };
        let mut flicker = Vec::new();
        for (i, f) in self.flicker.unwrap_or_default().into_iter().enumerate() {
            let c = c.nth(i);
            let ft = "daylight.flicker";
            flicker.push(Flicker {
                hz: c.num(ft, "hz", f.hz, 1.0, Within::closed(0.0, 1e6, " Hz"))?,
                amplitude: c.num(
                    ft,
                    "amplitude",
                    f.amplitude,
                    0.0,
                    Within::closed(0.0, 100.0, ""),
                )?,
                phase_deg: c.num(ft, "phase_deg", f.phase_deg, 0.0, PHASE_DEG)?,
            });
        }
        Ok(Daylight {
            surface_v: c.num(t, "surface_v", self.surface_v, d.surface_v, surface)?,
            origin_depth_m: c.num(
                t,
                "origin_depth_m",
                self.origin_depth_m,
                d.origin_depth_m,
                depth,
            )?,
            upwelling: c.num(t, "upwelling", self.upwelling, d.upwelling, unit)?,
            flicker_depth_m: c.num(
                t,
                "flicker_depth_m",
                self.flicker_depth_m,
                d.flicker_depth_m,
                Within::above(0.0, 1e4, " m"),
            )?,
            flicker,
            random_std: c.num(
                t,
                "random_std",
                self.random_std,
                d.random_std,
                Within::closed(0.0, 100.0, ""),
            )?,
            random_min_hz,
            random_max_hz,
            random_components,
            spatial: c.num(t, "spatial", self.spatial, d.spatial, unit)?,
        })
    }
}

/// MODEL.md's frequency rules on the scene's beacons (core's
/// `check_beacons`), the error at the line of the first beacon it names
/// (or of `[adc] sample_hz`).
pub(super) fn check_frequencies(
    c: &Checker,
    adc: &Adc,
    blink: &Blink,
    beacons: &[Beacon],
) -> Result<(), SceneError> {
    let one = [BeaconFreq {
        id: lightpose_core::log::DEFAULT_BEACON_ID,
        mod_hz: blink.mod_hz,
    }];
    let list: Vec<BeaconFreq> = beacons
        .iter()
        .map(|b| BeaconFreq {
            id: &b.id,
            mod_hz: b.mod_hz(),
        })
        .collect();
    let freqs = if beacons.is_empty() {
        &one[..]
    } else {
        &list[..]
    };
    let Err(e) = check_beacons(adc.rate_hz, adc.sample_hz, freqs) else {
        return Ok(());
    };
    let Some(id) = e.beacon() else {
        return Err(c.err("adc", "sample_hz", e));
    };
    match beacons.iter().position(|b| b.id == id) {
        Some(i) => Err(c.nth(i).err("beacons", "mod_hz", e)),
        None => Err(c.err("beacon", "mod_hz", e)),
    }
}
