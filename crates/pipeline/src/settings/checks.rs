//! The checks of the tracker's settings (`TrackerConfig::validate`): each
//! value in its range, with a message that names the setting. Apart from
//! the table itself so that the table reads as the list of settings.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::{
    num, ModelError, TrackerConfig, MAX_K_D_DOUBT, MAX_TEMP_DOUBT_C, PAPER_RATE_MAX_FRAMES,
    READING_CHECK_MAX_S, WATER_CHECK_MAX_FRAMES,
};

/// The smallest start-up 1σ taken (m/s, °/s, °): a thousandth of a unit
/// is already a start that knows more than any sensor.
const INIT_SIGMA_MIN: f64 = 1e-3;

impl TrackerConfig {
    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::Config(m));
        if let Some(d) = &self.daylight {
            d.validate().map_err(ModelError::Config)?;
        }
        super::roll_sigma_ok(self.roll_sigma_deg).map_err(ModelError::Config)?;
        for (name, v) in [
            ("accel_psd", self.accel_psd),
            ("ang_accel_psd_deg", self.ang_accel_psd_deg),
            ("k_d_walk_psd", self.k_d_walk_psd),
            ("init_velocity_sigma", self.init_velocity_sigma),
            ("init_rate_sigma_deg", self.init_rate_sigma_deg),
            ("init_attitude_sigma_deg", self.init_attitude_sigma_deg),
            ("attitude_sigma_pitch_deg", self.attitude_sigma_pitch_deg),
            ("attitude_sigma_yaw_deg", self.attitude_sigma_yaw_deg),
            ("attitude_sigma_roll_deg", self.attitude_sigma_roll_deg),
            ("roll_walk_psd_deg", self.roll_walk_psd_deg),
            ("nis_gate", self.nis_gate),
            ("max_gap_s", self.max_gap_s),
            ("side_sigma", self.side_sigma),
            ("side_tau_s", self.side_tau_s),
            ("side_tau_with_attitude_s", self.side_tau_with_attitude_s),
            ("depth_sigma_m", self.depth_sigma_m),
            ("velocity_sigma_mps", self.velocity_sigma_mps),
            ("depth_limit_m", self.depth_limit_m),
            ("velocity_limit_mps", self.velocity_limit_mps),
            ("paper_range_sigma_scale", self.paper_range_sigma_scale),
            ("paper_rate_drift_mps", self.paper_rate_drift_mps),
            ("surge_max_sigma", self.surge_max_sigma),
            ("water_check_doubt", self.water_check_doubt),
            ("reading_check_limit", self.reading_check_limit),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("tracker {name} = {} must be positive", num(v)));
            }
        }
        self.validate_water()?;
        self.validate_start()?;
        let [lo, hi] = self.x_range;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo) {
            return bad(format!(
                "tracker x_range = [{}, {}] must be 0 < lo < hi",
                num(lo),
                num(hi)
            ));
        }
        if self.update_iterations == 0 {
            return bad("tracker update_iterations must be at least 1".into());
        }
        if !(self.reading_gate_p > 0.0 && self.reading_gate_p < 0.5) {
            return bad(format!(
                "tracker reading_gate_p = {} must be in (0, 0.5)",
                num(self.reading_gate_p)
            ));
        }
        if self.reading_gate_restart == 0 {
            return bad("tracker reading_gate_restart must be at least 1".into());
        }
        if !(1..=PAPER_RATE_MAX_FRAMES).contains(&self.paper_rate_frames) {
            return bad(format!(
                "tracker paper_rate_frames = {} must be 1 to {PAPER_RATE_MAX_FRAMES}",
                self.paper_rate_frames
            ));
        }
        if !(0.0..=READING_CHECK_MAX_S).contains(&self.reading_check_s) {
            return bad(format!(
                "tracker reading_check_s = {} must be 0 (off) to {READING_CHECK_MAX_S}",
                num(self.reading_check_s)
            ));
        }
        self.validate_sensor_models()
    }

    /// The start-up's doubts (part of `validate`).
    fn validate_start(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::Config(m));
        // The start-up's doubts past what any vehicle does (or so small
        // that the covariance underflows) made every pose `diverged`,
        // without a word (an audit: 1e300 and 1e-300).
        for (name, v, hi, unit) in [
            ("init_velocity_sigma", self.init_velocity_sigma, 10.0, "m/s"),
            (
                "init_rate_sigma_deg",
                self.init_rate_sigma_deg,
                1000.0,
                "°/s",
            ),
            (
                "init_attitude_sigma_deg",
                self.init_attitude_sigma_deg,
                90.0,
                "°",
            ),
        ] {
            if !(INIT_SIGMA_MIN..=hi).contains(&v) {
                return bad(format!(
                    "tracker {name} = {} must be {INIT_SIGMA_MIN} to {hi} {unit}",
                    num(v)
                ));
            }
        }
        if let Some(v) = self.init_lateral_sigma_deg {
            if !(v.is_finite() && v > 0.0 && v < 80.0) {
                return bad(format!(
                    "tracker init_lateral_sigma_deg = {} must be in (0, 80)",
                    num(v)
                ));
            }
        }
        Ok(())
    }

    /// The water's settings: K_D's doubt, the temperature's, and the water
    /// check's (part of `validate`).
    fn validate_water(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::Config(m));
        // A doubt of K_D past any water's own K_D (a harbour's is about 1
        // m⁻¹) is no doubt but a mistake, and the water bank's members at
        // e^(±3σ/K_D) overflowed: the error then named k_d_sigma = 0.
        if self.water_check_doubt > MAX_K_D_DOUBT {
            return bad(format!(
                "tracker water_check_doubt = {} must be at most {MAX_K_D_DOUBT} m⁻¹",
                num(self.water_check_doubt)
            ));
        }
        // 0 means "K_D known exactly", possible only when it is not
        // estimated (the filter's prior on it must be positive).
        if let Some(v) = self.k_d_sigma {
            if !(v.is_finite() && (0.0..=MAX_K_D_DOUBT).contains(&v))
                || (self.estimate_k_d && v == 0.0)
            {
                return bad(format!(
                    "tracker k_d_sigma = {} must be 0 to {MAX_K_D_DOUBT} m⁻¹ (above 0 with \
                     estimate_k_d)",
                    num(v)
                ));
            }
        }
        if let Some(v) = self.temp_sigma_c {
            if !(v.is_finite() && (0.0..=MAX_TEMP_DOUBT_C).contains(&v)) {
                return bad(format!(
                    "tracker temp_sigma_c = {} must be in [0, {MAX_TEMP_DOUBT_C}] °C",
                    num(v)
                ));
            }
        }
        if self.water_check_frames > WATER_CHECK_MAX_FRAMES {
            return bad(format!(
                "tracker water_check_frames = {} must be 0 (off) to {WATER_CHECK_MAX_FRAMES}",
                self.water_check_frames
            ));
        }
        if !(self.water_check_nis.is_finite() && self.water_check_nis > 1.0) {
            return bad(format!(
                "tracker water_check_nis = {} must be above 1 (its median in the calibrated water)",
                self.water_check_nis
            ));
        }
        Ok(())
    }

    /// The own sensors' lever arm and offsets (part of `validate`).
    fn validate_sensor_models(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::Config(m));
        if let Some(v) = self.depth_lever_arm_m.iter().find(|v| !(v.abs() <= 10.0)) {
            return bad(format!(
                "tracker depth_lever_arm_m has {}: each must be within ±10 m (a sensor \
                 on the vehicle)",
                num(*v)
            ));
        }
        // The offsets' priors, told or for when the reading check calls.
        for (name, v, hi, unit) in [
            (
                "depth_offset_sigma_m",
                self.depth_offset_sigma_m,
                100.0,
                " m",
            ),
            (
                "called_depth_offset_sigma_m",
                self.called_depth_offset_sigma_m,
                100.0,
                " m",
            ),
            (
                "pitch_offset_sigma_deg",
                self.pitch_offset_sigma_deg,
                30.0,
                "°",
            ),
            (
                "called_pitch_offset_sigma_deg",
                self.called_pitch_offset_sigma_deg,
                30.0,
                "°",
            ),
        ] {
            if !(0.0..=hi).contains(&v) {
                return bad(format!(
                    "tracker {name} = {} must be 0 (off) to {hi}{unit}",
                    num(v)
                ));
            }
        }
        // Under 1° the bound would pin pitch and yaw as a reading does
        // (at 1e-9° every pose had them at 0 ± 1e-9°, pitch's ±2σ covering
        // 5 % of frames).
        let v = self.unmeasured_attitude_sigma_deg;
        if !(v == 0.0 || (1.0..=90.0).contains(&v)) {
            return bad(format!(
                "tracker unmeasured_attitude_sigma_deg = {} must be 0 (off) or 1 to 90°",
                num(v)
            ));
        }
        // An offset that wanders a metre in a second is a broken sensor, not
        // an offset; at 1e300 the report printed its σ with 130 digits.
        if !(0.0..=1.0).contains(&self.depth_offset_walk_psd) {
            return bad(format!(
                "tracker depth_offset_walk_psd = {} must be 0 to 1 m²/s",
                num(self.depth_offset_walk_psd)
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::{num, ModelConfig, TrackerConfig};

    fn tracker(f: impl FnOnce(&mut TrackerConfig)) -> Result<(), String> {
        let mut c = TrackerConfig::default();
        f(&mut c);
        c.validate().map_err(|e| e.to_string())
    }

    fn model(f: impl FnOnce(&mut ModelConfig)) -> Result<(), String> {
        let mut c = ModelConfig::default();
        f(&mut c);
        c.validate().map_err(|e| e.to_string())
    }

    /// Spec v3's roll settings, in both estimators: a prior σ a vehicle's
    /// roll can have, a reading's σ positive; each refused by its name.
    #[test]
    fn roll_settings_are_refused_by_their_own_name() {
        for v in [0.0, -1.0, 46.0, f64::NAN, f64::INFINITY] {
            let e = tracker(|c| c.roll_sigma_deg = Some(v)).unwrap_err();
            assert!(
                e.contains("roll_sigma_deg = ") && e.contains("at most 45°"),
                "{e}"
            );
            let e = model(|c| c.roll_sigma_deg = Some(v)).unwrap_err();
            assert!(e.contains("roll_sigma_deg = "), "{e}");
        }
        for v in [0.0, -0.3, f64::NAN] {
            let e = tracker(|c| c.attitude_sigma_roll_deg = v).unwrap_err();
            assert!(e.contains("attitude_sigma_roll_deg"), "{e}");
            let e = model(|c| c.attitude_sigma_roll_deg = v).unwrap_err();
            assert!(e.contains("attitude_sigma_roll_deg"), "{e}");
        }
        tracker(|c| c.roll_sigma_deg = Some(5.0)).unwrap();
        model(|c| c.roll_sigma_deg = Some(45.0)).unwrap();
    }

    /// Values an audit found accepted that made every pose wrong or the
    /// error name another setting: each is refused naming its own setting,
    /// and huge or tiny values show in exponent form.
    #[test]
    fn extreme_settings_are_refused_by_their_own_name() {
        for v in [1e-9, 0.5, 90.5, f64::NAN] {
            let e = tracker(|c| c.unmeasured_attitude_sigma_deg = v).unwrap_err();
            assert!(e.contains("unmeasured_attitude_sigma_deg"), "{e}");
        }
        for v in [0.0, 1.0, 15.0, 90.0] {
            tracker(|c| c.unmeasured_attitude_sigma_deg = v).unwrap();
        }
        let e = tracker(|c| c.k_d_sigma = Some(1e200)).unwrap_err();
        assert!(e.contains("k_d_sigma = 1e200"), "{e}");
        let e = tracker(|c| c.water_check_doubt = 1e200).unwrap_err();
        assert!(e.contains("water_check_doubt = 1e200"), "{e}");
        tracker(|c| c.k_d_sigma = Some(10.0)).unwrap();
        let e = tracker(|c| c.depth_lever_arm_m = [0.0, 0.0, 1e300]).unwrap_err();
        assert!(e.contains("depth_lever_arm_m has 1e300"), "{e}");
        tracker(|c| c.depth_lever_arm_m = [0.3, -0.1, 0.2]).unwrap();
        let e = tracker(|c| c.called_depth_offset_sigma_m = f64::NAN).unwrap_err();
        assert!(
            e.contains("called_depth_offset_sigma_m = NaN must be 0"),
            "{e}"
        );
        let e = tracker(|c| c.called_pitch_offset_sigma_deg = 45.0).unwrap_err();
        assert!(
            e.contains("called_pitch_offset_sigma_deg = 45 must be 0"),
            "{e}"
        );
        tracker(|c| {
            c.called_depth_offset_sigma_m = 0.0;
            c.called_pitch_offset_sigma_deg = 30.0;
        })
        .unwrap();
        let e = tracker(|c| c.depth_offset_walk_psd = 1e300).unwrap_err();
        assert!(e.contains("depth_offset_walk_psd = 1e300 must be"), "{e}");
        let e = tracker(|c| c.init_velocity_sigma = 1e300).unwrap_err();
        assert!(e.contains("init_velocity_sigma = 1e300 must be"), "{e}");
        let e = tracker(|c| c.init_rate_sigma_deg = 1e-300).unwrap_err();
        assert!(e.contains("init_rate_sigma_deg = 1e-300 must be"), "{e}");
        for v in [1e-300, 90.5, f64::NAN] {
            let e = tracker(|c| c.init_attitude_sigma_deg = v).unwrap_err();
            assert!(e.contains("init_attitude_sigma_deg"), "{e}");
        }
        tracker(|c| {
            c.init_velocity_sigma = 10.0;
            c.init_rate_sigma_deg = 0.001;
            c.init_attitude_sigma_deg = 90.0;
        })
        .unwrap();
        let e = tracker(|c| c.accel_psd = -1e-300).unwrap_err();
        assert!(e.contains("accel_psd = -1e-300 must"), "{e}");
        for v in [f64::NAN, f64::INFINITY, -1.0] {
            let e = model(|c| c.min_signal_sigma = v).unwrap_err();
            assert!(e.contains("min_signal_sigma"), "{e}");
        }
        let e = model(|c| c.fixed_pitch_deg = 370.0).unwrap_err();
        assert!(e.contains("fixed_pitch_deg = 370"), "{e}");
        model(|c| c.fixed_yaw_deg = -180.0).unwrap();
        let e = model(|c| c.x_range = [2e-300, 1e-300]).unwrap_err();
        assert!(e.len() < 80, "{e}");
        assert_eq!(
            [num(0.005), num(1e-300), num(2.5e12), num(0.0)],
            ["0.005", "1e-300", "2.5e12", "0"]
        );
    }
}
