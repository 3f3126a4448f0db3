//! Physical calibration: fit MODEL.md's light equation — V1, σ_b, σ_R, K_D,
//! and ω, σ_h when the water scatters — and each channel's gain and dark
//! offset, from truth-labelled sweeps (and an optional dark log).
//!
//! Why: the model estimator, the tracker and the Cramér–Rao bound all need
//! these numbers, with their uncertainty. Sweeps hold 200 frames per pose;
//! they are averaged per pose first (the truth pose groups them, streamed so
//! a sweep never sits in memory), and the fit runs on the per-pose means
//! weighted by their standard errors — a few hundred poses, not 61,600
//! frames. Gain and V1 are degenerate (only their product is seen), so the
//! mean gain is fixed to 1 by eliminating the last gain. A sweep that
//! cannot determine a parameter is refused with the parameter's name.

use lightpose_core::bounds::{
    Within, MAX_GAIN, MAX_K_D, MAX_OMEGA, MAX_RADIUS_M, MAX_SPACING_DEG, MAX_V1_PER_V_REF,
    MAX_V_REF, MIN_V_REF, WIDTH_DEG,
};
use lightpose_core::frame::full_scale;
use lightpose_core::light::temperature_gain;
use lightpose_core::{Angle, ArrayGeometry, Frame, LightParams, Pose, Scattering, NDET};
use serde::{Deserialize, Serialize};

use crate::model::SensorModel;
use problem::Data;

pub(crate) mod fisher;
mod problem;
pub(crate) use problem::{gain_estimates, gains_of, noise_line, rms_per_channel};

/// A fitted value and its standard error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamEstimate {
    pub value: f64,
    pub std: f64,
}

/// The light equation's parameters as fitted from sweeps (the calibration
/// file's optional `[physical]` table). Angles in degrees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicalCalibration {
    pub v1: ParamEstimate,
    pub sigma_b_deg: ParamEstimate,
    pub sigma_r_deg: ParamEstimate,
    pub k_d: ParamEstimate,
    /// Scattering, when the fit found (or was told) the water has it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub omega: Option<ParamEstimate>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_h_deg: Option<ParamEstimate>,
    /// Per channel, row-major; mean gain is 1 by construction.
    pub gain: Vec<ParamEstimate>,
    pub offset_v: Vec<ParamEstimate>,
    /// Noise model fitted to the spread within each pose.
    pub sigma_e_v: f64,
    pub kappa_v: f64,
    /// The ADC and dome this was fitted for.
    pub v_ref: f64,
    pub adc_bits: u8,
    pub spacing_deg: f64,
    pub radius_m: f64,
    /// Per channel: RMS of the residuals of the per-pose means, in counts
    /// and in units of their standard errors.
    pub residual_rms_counts: Vec<f64>,
    pub residual_rms_normalized: Vec<f64>,
    /// χ² per degree of freedom of the whole fit.
    pub chi2_per_dof: f64,
    /// Poses (groups) and frames used.
    pub poses: usize,
    pub frames: u64,
}

impl PhysicalCalibration {
    /// The sensor model the estimators run on.
    pub fn sensor_model(&self) -> SensorModel {
        let scattering = match (self.omega, self.sigma_h_deg) {
            (Some(o), Some(h)) => Some(Scattering {
                omega: o.value,
                sigma_h: Angle::from_deg(h.value),
            }),
            _ => None,
        };
        let mut gain = [1.0; NDET];
        let mut offset_v = [0.0; NDET];
        for k in 0..NDET {
            gain[k] = self.gain.get(k).map_or(1.0, |g| g.value);
            offset_v[k] = self.offset_v.get(k).map_or(0.0, |o| o.value);
        }
        SensorModel {
            light: LightParams {
                v1: self.v1.value,
                sigma_b: Angle::from_deg(self.sigma_b_deg.value),
                sigma_r: Angle::from_deg(self.sigma_r_deg.value),
                k_d: self.k_d.value,
                scattering,
            },
            geometry: ArrayGeometry::new(Angle::from_deg(self.spacing_deg), self.radius_m),
            gain,
            offset_v,
            v_ref: self.v_ref,
            adc_bits: self.adc_bits,
            sigma_e_v: self.sigma_e_v,
            kappa_v: self.kappa_v,
            k_d_sigma: self.k_d.std,
        }
    }

    /// Check a loaded table: 25 channels, and each number within the
    /// bounds a scene's must keep (`lightpose_core::bounds`); the key and
    /// why. An audit's dome of radius 13 m loaded, and the first frame's
    /// start panicked (the search's nearest range beyond its farthest).
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        for (k, list) in [("gain", &self.gain), ("offset_v", &self.offset_v)] {
            if list.len() != NDET {
                return Err((k, format!("has {} entries, expected {NDET}", list.len())));
            }
        }
        let v_ref = Within::closed(MIN_V_REF, MAX_V_REF, " V").check(self.v_ref);
        let v_ref = v_ref.map_err(|m| ("v_ref", m))?;
        let volts = Within::closed(0.0, v_ref, " V").why("0..v_ref");
        let offsets = Within::closed(-v_ref, v_ref, " V").why("within the ADC's ±v_ref");
        let v1 = Within::above(0.0, MAX_V1_PER_V_REF * v_ref, " V·m²").why("1e6 × v_ref");
        let mut checks = vec![
            ("v1", self.v1.value, v1),
            ("sigma_b_deg", self.sigma_b_deg.value, WIDTH_DEG),
            ("sigma_r_deg", self.sigma_r_deg.value, WIDTH_DEG),
            ("k_d", self.k_d.value, Within::closed(0.0, MAX_K_D, " m⁻¹")),
            ("sigma_e_v", self.sigma_e_v, volts),
            ("kappa_v", self.kappa_v, volts),
            (
                "spacing_deg",
                self.spacing_deg,
                Within::above(0.0, MAX_SPACING_DEG, "°").why("so the dome stays a hemisphere"),
            ),
            (
                "radius_m",
                self.radius_m,
                Within::above(0.0, MAX_RADIUS_M, " m"),
            ),
        ];
        checks.extend(
            self.omega
                .map(|o| ("omega", o.value, Within::closed(0.0, MAX_OMEGA, ""))),
        );
        checks.extend(
            self.sigma_h_deg
                .map(|h| ("sigma_h_deg", h.value, WIDTH_DEG)),
        );
        let gain = Within::above(0.0, MAX_GAIN, "");
        checks.extend(self.gain.iter().map(|g| ("gain", g.value, gain)));
        checks.extend(self.offset_v.iter().map(|o| ("offset_v", o.value, offsets)));
        for (k, v, within) in checks {
            within.check(v).map_err(|m| (k, m))?;
        }
        self.sensor_model().validate().map_err(|m| ("", m))
    }
}

/// Whether to fit the scattering term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ScatterFit {
    Off,
    On,
    /// Fit both; keep scattering when it improves χ² by more than 25
    /// (two parameters, far beyond chance) and is determined.
    #[default]
    Auto,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    pub scattering: ScatterFit,
    pub v_ref: f64,
    pub geometry: ArrayGeometry,
    pub max_iter: usize,
    /// Poses with fewer frames than this are ignored (no standard error).
    pub min_samples: u64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            scattering: ScatterFit::Auto,
            v_ref: 5.0,
            geometry: ArrayGeometry::paper(),
            max_iter: 60,
            min_samples: 2,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    #[error("sweep has no frames with a truth pose")]
    NoTruth,
    #[error(
        "no pose of the sweep has {0} frames in a row, which each pose needs for its noise \
         (the sweep's {1} frames change pose more often)"
    )]
    NoRepeatedPose(u64, u64),
    #[error("frames differ in ADC resolution ({0} and {1} bits)")]
    MixedBits(u8, u8),
    #[error(
        "the sweeps mix counts and demodulated amplitudes (a steady beacon's and a \
         blinking one's): calibrate each from its own sweeps"
    )]
    MixedKinds,
    #[error("only {0} usable poses; the fit has {1} parameters")]
    TooFewPoses(usize, usize),
    #[error("the sweeps cannot determine {parameter}: {reason}")]
    Undetermined { parameter: String, reason: String },
    #[error("the fit did not converge: {0}")]
    NoConvergence(String),
}

#[derive(Debug, Clone)]
struct Group {
    pose: Pose,
    n: u64,
    sum: [f64; NDET],
    sumsq: [f64; NDET],
    clipped: [bool; NDET],
    gt_sum: f64,
    /// Amplitudes: the sum of the demodulator's variance of each channel's
    /// amplitude over the group's frames (its scatter, known per frame:
    /// a few frames a pose estimate it poorly themselves).
    reported_var: [f64; NDET],
}

impl Group {
    fn new(pose: Pose) -> Self {
        Group {
            pose,
            n: 0,
            sum: [0.0; NDET],
            sumsq: [0.0; NDET],
            clipped: [false; NDET],
            gt_sum: 0.0,
            reported_var: [0.0; NDET],
        }
    }
}

/// Streams frames in, grouping consecutive frames of one truth pose.
#[derive(Debug, Clone, Default)]
pub struct PhysicalFitter {
    groups: Vec<Group>,
    dark: Option<Group>,
    bits: Option<u8>,
    /// Whether the frames are demodulated amplitudes (of the first frame;
    /// the rest must agree).
    amplitudes: Option<bool>,
    frames: u64,
}

impl PhysicalFitter {
    pub fn new() -> Self {
        Self::default()
    }

    fn check_bits(&mut self, f: &Frame) -> Result<(), CalibError> {
        match self.bits {
            None => self.bits = Some(f.adc_bits),
            Some(b) if b != f.adc_bits => return Err(CalibError::MixedBits(b, f.adc_bits)),
            _ => {}
        }
        let amp = f.amplitudes.is_some();
        if *self.amplitudes.get_or_insert(amp) != amp {
            return Err(CalibError::MixedKinds);
        }
        Ok(())
    }

    fn accumulate(g: &mut Group, f: &Frame) {
        let fs = full_scale(f.adc_bits);
        g.n += 1;
        g.gt_sum += f.temp_c.map_or(1.0, temperature_gain);
        if let Some(a) = f.amplitudes.as_ref() {
            // A demodulated frame: the beacon's amplitude (no dark offset),
            // a channel with a clipped sample left out of its pose's mean;
            // without the beacon in use the frame is dark.
            let b = a.beacon(crate::model::measurement::BEACON);
            for k in 0..NDET {
                let (c, sd) = b.map_or((0.0, 0.0), |b| (b.amplitude[k], b.std[k]));
                if a.clipped[k] > 0 || !c.is_finite() || !sd.is_finite() {
                    g.clipped[k] = true;
                    continue;
                }
                g.sum[k] += c;
                g.sumsq[k] += c * c;
                g.reported_var[k] += sd * sd;
            }
            return;
        }
        for k in 0..NDET {
            let c = f.counts[k];
            if c == 0 || c >= fs {
                g.clipped[k] = true;
            }
            let c = c as f64;
            g.sum[k] += c;
            g.sumsq[k] += c * c;
        }
    }

    /// Add one sweep frame; frames without truth are skipped.
    pub fn add_frame(&mut self, f: &Frame) -> Result<(), CalibError> {
        let Some(truth) = f.truth else { return Ok(()) };
        self.check_bits(f)?;
        self.frames += 1;
        let same = self
            .groups
            .last()
            .is_some_and(|g| super::same_pose(&g.pose, &truth.pose));
        if !same {
            self.groups.push(Group::new(truth.pose));
        }
        if let Some(g) = self.groups.last_mut() {
            Self::accumulate(g, f);
        }
        Ok(())
    }

    /// Add one frame of a dark log (beacon off).
    pub fn add_dark(&mut self, f: &Frame) -> Result<(), CalibError> {
        self.check_bits(f)?;
        self.frames += 1;
        let g = self.dark.get_or_insert_with(|| Group::new(Pose::default()));
        Self::accumulate(g, f);
        Ok(())
    }

    /// Fit the light equation to everything added.
    pub fn fit(&self, o: &FitOptions) -> Result<PhysicalCalibration, CalibError> {
        let bits = self.bits.ok_or(CalibError::NoTruth)?;
        let data = Data::build(self, o, bits)?;
        match o.scattering {
            ScatterFit::Off => data.fit(false, o),
            ScatterFit::On => data.fit(true, o),
            ScatterFit::Auto => {
                let off = data.fit(false, o)?;
                match data.fit(true, o) {
                    Ok(on) => {
                        let dof_on = data.dof(true);
                        let dof_off = data.dof(false);
                        let chi_on = on.chi2_per_dof * dof_on as f64;
                        let chi_off = off.chi2_per_dof * dof_off as f64;
                        Ok(if chi_off - chi_on > 25.0 { on } else { off })
                    }
                    Err(_) => Ok(off),
                }
            }
        }
    }
}

/// Fit from iterators of sweep frames and (optionally) dark frames.
pub fn fit_physical<'a>(
    sweeps: impl IntoIterator<Item = &'a Frame>,
    dark: Option<&mut dyn Iterator<Item = &'a Frame>>,
    o: &FitOptions,
) -> Result<PhysicalCalibration, CalibError> {
    let mut f = PhysicalFitter::new();
    for fr in sweeps {
        f.add_frame(fr)?;
    }
    if let Some(d) = dark {
        for fr in d {
            f.add_dark(fr)?;
        }
    }
    f.fit(o)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::testutil::{synth_frame, Rng};

    fn sweep_poses(xs: &[f64], orientation: bool) -> Vec<Pose> {
        let mut v = Vec::new();
        for &x in xs {
            for iy in -2..=2 {
                for iz in 0..=4 {
                    v.push(Pose::new(
                        x,
                        0.3 * iy as f64,
                        0.2 * iz as f64,
                        Angle::ZERO,
                        Angle::ZERO,
                    ));
                }
            }
            if orientation {
                for a in (-15..=15).step_by(3) {
                    let a = Angle::from_deg(a as f64);
                    v.push(Pose::new(x, 0.0, 0.0, a, Angle::ZERO));
                    v.push(Pose::new(x, 0.0, 0.0, Angle::ZERO, a));
                }
            }
        }
        v
    }

    fn truth_model() -> SensorModel {
        let mut m = SensorModel::default();
        for k in 0..NDET {
            m.gain[k] = 1.0 + 0.04 * ((k as f64) * 1.7).sin();
            m.offset_v[k] = 0.15 + 0.01 * ((k as f64) * 0.9).cos();
        }
        let mean: f64 = m.gain.iter().sum::<f64>() / NDET as f64;
        for g in m.gain.iter_mut() {
            *g /= mean;
        }
        m
    }

    fn feed(f: &mut PhysicalFitter, m: &SensorModel, poses: &[Pose], n: u64, rng: &mut Rng) {
        let mut seq = 0;
        for p in poses {
            for _ in 0..n {
                let fr = synth_frame(m, p, seq, seq as f64 * 0.2, None, rng);
                seq += 1;
                f.add_frame(&fr).unwrap();
            }
        }
    }

    #[test]
    fn recovers_light_parameters_gains_and_offsets() {
        let m = truth_model();
        let mut rng = Rng::new(5);
        let mut fitter = PhysicalFitter::new();
        feed(
            &mut fitter,
            &m,
            &sweep_poses(&[4.5, 5.5, 6.5, 7.5, 8.5], true),
            30,
            &mut rng,
        );
        let cal = fitter.fit(&FitOptions::default()).unwrap();
        eprintln!(
            "v1 {:?} σb {:?} σR {:?} K_D {:?} ω {:?} σh {:?} χ²/dof {:.3} σe {:.4}",
            cal.v1,
            cal.sigma_b_deg,
            cal.sigma_r_deg,
            cal.k_d,
            cal.omega,
            cal.sigma_h_deg,
            cal.chi2_per_dof,
            cal.sigma_e_v
        );
        let within = |e: &ParamEstimate, t: f64, name: &str| {
            assert!(e.std > 0.0 && e.std.is_finite(), "{name} {e:?}");
            assert!((e.value - t).abs() < 4.0 * e.std, "{name}: {e:?} vs {t}");
        };
        within(&cal.v1, 135.0, "v1");
        within(&cal.sigma_b_deg, 12.0, "sigma_b");
        within(&cal.sigma_r_deg, 18.0, "sigma_r");
        within(&cal.k_d, 0.09, "k_d");
        let omega = cal.omega.expect("scattering found");
        within(&omega, 0.5, "omega");
        within(&cal.sigma_h_deg.unwrap(), 20.0, "sigma_h");
        let mut outside = 0;
        for k in 0..NDET {
            if (cal.gain[k].value - m.gain[k]).abs() > 3.0 * cal.gain[k].std {
                outside += 1;
            }
            if (cal.offset_v[k].value - m.offset_v[k]).abs() > 3.0 * cal.offset_v[k].std {
                outside += 1;
            }
        }
        assert!(outside <= 2, "{outside} of 50 channel parameters beyond 3σ");
        assert!(
            (0.8..1.25).contains(&cal.chi2_per_dof),
            "{}",
            cal.chi2_per_dof
        );
        assert!((cal.sigma_e_v - 0.05).abs() < 0.003, "{}", cal.sigma_e_v);
        assert_eq!(cal.residual_rms_counts.len(), NDET);
        // The fitted model drives the estimator: round trip through TOML.
        let text = toml::to_string(&cal).unwrap();
        let back: PhysicalCalibration = toml::from_str(&text).unwrap();
        assert_eq!(back, cal);
        back.validate().unwrap();
    }

    #[test]
    fn single_distance_sweep_is_refused_naming_a_parameter() {
        // One range only: attenuation and source strength cannot be told
        // apart (nor scattering from either).
        let m = truth_model();
        let mut rng = Rng::new(9);
        let mut fitter = PhysicalFitter::new();
        feed(&mut fitter, &m, &sweep_poses(&[6.5], true), 10, &mut rng);
        let opts = FitOptions {
            scattering: ScatterFit::On,
            ..FitOptions::default()
        };
        match fitter.fit(&opts) {
            Err(CalibError::Undetermined { parameter, reason }) => {
                eprintln!("refused: {parameter}: {reason}");
                assert!(!parameter.is_empty() && reason.contains("Fisher"));
            }
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    #[test]
    fn dark_log_pins_offsets() {
        let mut m = truth_model();
        m.light.scattering = None;
        let mut rng = Rng::new(13);
        let mut fitter = PhysicalFitter::new();
        feed(
            &mut fitter,
            &m,
            &sweep_poses(&[4.5, 6.5, 8.5], true),
            20,
            &mut rng,
        );
        let mut dark_m = m.clone();
        dark_m.light.v1 = 0.0;
        let far = Pose::new(6.5, 0.0, 0.0, Angle::ZERO, Angle::ZERO);
        for i in 0..400 {
            let mut fr = synth_frame(&dark_m, &far, i, 0.0, None, &mut rng);
            fr.truth = None;
            fitter.add_dark(&fr).unwrap();
        }
        let cal = fitter
            .fit(&FitOptions {
                scattering: ScatterFit::Auto,
                ..FitOptions::default()
            })
            .unwrap();
        assert!(cal.omega.is_none(), "no scattering in this water: {cal:?}");
        for k in 0..NDET {
            let o = cal.offset_v[k];
            assert!((o.value - m.offset_v[k]).abs() < 4.0 * o.std, "{k}: {o:?}");
            assert!(o.std < 0.002);
        }
    }
}
