//! Choosing an estimator by name, so that replay, the daemon, the Monte
//! Carlo and the trade table accept the same `--estimator` words and get the
//! same object.
//!
//! What a model-based estimator models comes from the calibration, so that
//! an effect the scene does not have costs nothing per frame: scattering is
//! computed only when `[physical]` kept ω and σ_h; which DOF are free and
//! whether K_D is estimated come from `[estimator.model]` and
//! `[estimator.tracker]` (defaults when absent); an own-sensor reading
//! (attitude, depth, DVL) is used exactly when a frame carries one.

use crate::calibration::{Calibration, PhysicalCalibration};
use crate::model::{ModelEstimator, Tracker, WaterBank, WaterWatch};
use crate::paper::MomentsEstimator;
use lightpose_core::Estimator;

/// Names `build_estimator` accepts.
pub const NAMES: &[&str] = &["auto", "moments", "model", "tracker"];

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BuildError {
    #[error("unknown estimator \"{name}\" (known: {known})")]
    Unknown { name: String, known: String },
    #[error(
        "estimator \"{name}\" needs a [physical] table in the calibration \
         (re-run `lightpose calibrate` on sweeps that determine the light model)"
    )]
    NoPhysical { name: String },
    #[error("estimator \"{name}\": {msg}")]
    Config { name: String, msg: String },
}

/// The name "auto" resolves to for this calibration: the tracker when a
/// light model is calibrated, else the paper's moments estimator. No
/// per-frame switch: the tracker fuses whatever own-sensor readings a frame
/// carries (attitude, depth, DVL), and without them leans on the paper's
/// range of the same calibration; it is the best of the three either way
/// and the only one with a std on every field (docs/estimators.md, "Without
/// own sensors").
pub fn auto_choice(cal: &Calibration) -> &'static str {
    if cal.physical.is_some() {
        "tracker"
    } else {
        "moments"
    }
}

fn physical<'a>(cal: &'a Calibration, name: &str) -> Result<&'a PhysicalCalibration, BuildError> {
    cal.physical.as_ref().ok_or_else(|| BuildError::NoPhysical {
        name: name.to_string(),
    })
}

/// The estimator called `name` for calibration `cal` ("auto": see
/// [`auto_choice`]). Its `name()` says which one it is.
pub fn build_estimator(name: &str, cal: &Calibration) -> Result<Box<dyn Estimator>, BuildError> {
    let resolved = if name == "auto" {
        auto_choice(cal)
    } else {
        name
    };
    let settings = cal.estimator.clone().unwrap_or_default();
    let config = |msg: String| BuildError::Config {
        name: resolved.to_string(),
        msg,
    };
    match resolved {
        "moments" => Ok(Box::new(MomentsEstimator::new(cal))),
        "model" if cal.station().is_some() => Err(config(
            "the model estimator reads one beacon's image; a station's calibration runs the tracker (estimator = \"tracker\" or \"auto\")"
                .to_string(),
        )),
        "model" => {
            let m = physical(cal, resolved)?.sensor_model();
            let e = ModelEstimator::new(m, settings.model).map_err(|e| config(e.to_string()))?;
            Ok(Box::new(e))
        }
        "tracker" => {
            let m = physical(cal, resolved)?.sensor_model();
            let mut e = Tracker::new(m, settings.tracker)
                .map_err(|e| config(e.to_string()))?
                .with_paper(cal);
            // Spec v3: a station's calibration runs the tracker on every
            // beacon's image, its estimates named by the station.
            if let Some(st) = cal.station() {
                let ids: Vec<String> = st.beacons.iter().map(|b| b.id.clone()).collect();
                e = e
                    .with_station(st.beacon_lights())
                    .with_station_names(lightpose_core::StationNames::interned(&st.name, &ids));
            }
            if WaterBank::wanted(&e) {
                let bank = WaterBank::new(&e).map_err(|e| config(e.to_string()))?;
                return Ok(Box::new(bank));
            }
            if WaterWatch::wanted(&e) {
                let watch = WaterWatch::new(e).map_err(|e| config(e.to_string()))?;
                return Ok(Box::new(watch));
            }
            Ok(Box::new(e))
        }
        _ => Err(BuildError::Unknown {
            name: name.to_string(),
            known: NAMES.join(", "),
        }),
    }
}

/// Whether `estimator`, built from `cal`, can read frames of an
/// `adc_bits` ADC: the light model of the model-based ones is one ADC's
/// (a frame of another is `bad_frame`, every one of them), the paper's
/// method reads any. Checked where a source's resolution is known before
/// its first frame (replay's log header, the daemon's backend), so that a
/// 12-bit log against a 10-bit calibration is one line at the start, not
/// a replay of nothing but `bad_frame`.
pub fn reads_frames_of(
    estimator: &dyn Estimator,
    cal: &Calibration,
    adc_bits: u8,
) -> Result<(), String> {
    match &cal.physical {
        Some(p) if estimator.name() != "moments" && p.adc_bits != adc_bits => Err(format!(
            "frames of a {adc_bits}-bit ADC, and the calibration's light model is of a {}-bit one: \
             the {} estimator would call every frame bad_frame (calibrate from this board's \
             sweeps, or use the moments estimator)",
            p.adc_bits,
            estimator.name()
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::file::tests::{sample, sample_physical};
    use crate::settings::EstimatorSettings;
    use lightpose_core::Angle;

    #[test]
    fn only_the_model_based_need_the_calibrations_adc() {
        let mut cal = sample();
        cal.physical = Some(sample_physical());
        let bits = cal.scene.adc_bits;
        for n in ["moments", "model", "tracker"] {
            let e = build_estimator(n, &cal).unwrap();
            assert!(reads_frames_of(e.as_ref(), &cal, bits).is_ok());
            let other = reads_frames_of(e.as_ref(), &cal, 12);
            assert_eq!(other.is_ok(), n == "moments", "{n}: {other:?}");
        }
    }

    #[test]
    fn every_name_builds_the_estimator_it_names() {
        let mut cal = sample();
        cal.physical = Some(sample_physical());
        for n in ["moments", "model", "tracker"] {
            assert_eq!(build_estimator(n, &cal).unwrap().name(), n);
        }
        let e = build_estimator("kalman", &cal).err().unwrap().to_string();
        assert_eq!(
            e,
            "unknown estimator \"kalman\" (known: auto, moments, model, tracker)"
        );
    }

    #[test]
    fn auto_is_the_tracker_with_a_light_model_else_moments() {
        let mut cal = sample();
        assert_eq!(auto_choice(&cal), "moments");
        assert_eq!(build_estimator("auto", &cal).unwrap().name(), "moments");
        cal.physical = Some(sample_physical());
        assert_eq!(auto_choice(&cal), "tracker");
        assert_eq!(build_estimator("auto", &cal).unwrap().name(), "tracker");
    }

    /// A dome as big as the search's farthest range (radius 5 m, within
    /// the bounds a scene keeps, and ranges out to 4 m) is refused when the
    /// estimator is built, not by a panic at the first frame's start.
    #[test]
    fn a_dome_too_big_to_search_around_is_refused() {
        let mut cal = sample();
        let mut p = sample_physical();
        p.radius_m = 5.0;
        cal.physical = Some(p);
        let mut settings = EstimatorSettings::default();
        settings.model.x_range = [1.0, 4.0];
        settings.tracker.x_range = [1.0, 4.0];
        cal.estimator = Some(settings);
        assert!(cal.check().is_ok());
        for n in ["model", "tracker"] {
            let e = build_estimator(n, &cal).err().unwrap().to_string();
            assert!(e.contains("leaves nothing to search"), "{e}");
        }
    }

    #[test]
    fn model_estimators_need_a_light_model() {
        let cal = sample();
        for n in ["model", "tracker"] {
            let e = build_estimator(n, &cal).err().unwrap();
            assert_eq!(e, BuildError::NoPhysical { name: n.into() });
            assert!(e.to_string().contains("[physical]"), "{e}");
        }
    }

    #[test]
    fn estimator_settings_reach_the_estimator() {
        let mut cal = sample();
        cal.physical = Some(sample_physical());
        let mut s = EstimatorSettings::default();
        s.model.max_iter = 0;
        cal.estimator = Some(s);
        let e = build_estimator("model", &cal).err().unwrap().to_string();
        assert!(e.contains("max_iter must be at least 1"), "{e}");
        // The tracker's own settings are still the defaults: it builds.
        assert_eq!(build_estimator("tracker", &cal).unwrap().name(), "tracker");
    }

    /// K_D's doubt: unset, the calibration's own standard error (the water
    /// of the sweep); a Monte Carlo's drawn water fills in its spread
    /// where the user set none; a user's setting stays.
    #[test]
    fn k_d_doubt_is_the_calibrations_unless_the_water_is_said_to_differ() {
        use crate::model::testutil::{synth_frame, Rng};
        let mut cal = sample();
        cal.physical = Some(sample_physical());
        let model = cal.physical.as_ref().unwrap().sensor_model();
        assert_eq!(model.k_d_sigma, 0.0007);
        let pose = lightpose_core::Pose::new(8.0, 0.1, 0.2, Angle::ZERO, Angle::ZERO);
        let sig = Some((0.3f64.to_radians(), 1.5f64.to_radians()));
        let frame = synth_frame(&model, &pose, 0, 0.0, sig, &mut Rng::new(4));
        let sx = |cal: &Calibration| {
            let mut e = build_estimator("model", cal).unwrap();
            e.estimate(&frame).std.x.unwrap()
        };
        let in_sweep_water = sx(&cal);
        let drawn = cal.in_water_known_to(0.015, 3.0);
        let in_other_water = sx(&drawn);
        // x·δK_D/(K_D + 2/x) at 8 m: 0.0007 → 0.016 m, 0.015 → 0.35 m.
        assert!(in_sweep_water < 0.2, "{in_sweep_water}");
        assert!(in_other_water > 0.3, "{in_other_water}");
        let st = drawn.estimator.unwrap();
        assert_eq!(
            (st.model.k_d_sigma, st.tracker.k_d_sigma),
            (Some(0.015), Some(0.015))
        );
        assert_eq!(st.tracker.temp_sigma_c, Some(3.0));
        let mut mine = EstimatorSettings::default();
        mine.tracker.k_d_sigma = Some(0.002);
        mine.tracker.temp_sigma_c = Some(0.5);
        cal.estimator = Some(mine);
        let st = cal.in_water_known_to(0.015, 3.0).estimator.unwrap();
        assert_eq!(
            (st.model.k_d_sigma, st.tracker.k_d_sigma),
            (Some(0.015), Some(0.002))
        );
        assert_eq!(st.tracker.temp_sigma_c, Some(0.5));
        // Unset, it stays out of a written file (and reads back unset).
        let text = toml::to_string(&EstimatorSettings::default()).unwrap();
        assert!(!text.contains("k_d_sigma"), "{text}");
    }

    /// Estimating K_D needs a prior: from a model that gives none, the
    /// setting must say it, in one clear line.
    #[test]
    fn estimating_k_d_without_any_doubt_is_refused_clearly() {
        let mut cal = sample();
        let mut physical = sample_physical();
        physical.k_d.std = 0.0;
        cal.physical = Some(physical);
        let mut s = EstimatorSettings::default();
        s.tracker.estimate_k_d = true;
        cal.estimator = Some(s.clone());
        let e = build_estimator("tracker", &cal).err().unwrap().to_string();
        assert!(e.contains("estimate_k_d needs k_d_sigma"), "{e}");
        s.tracker.k_d_sigma = Some(0.01);
        cal.estimator = Some(s);
        assert_eq!(build_estimator("tracker", &cal).unwrap().name(), "tracker");
    }
}
