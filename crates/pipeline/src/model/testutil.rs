//! Test-only helpers: noisy frames straight from core's light equation and
//! the ADC rule, so that the numerics can be tested without the simulator,
//! with a small deterministic generator (the crate has no `rand`).

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::frame::volts_to_counts;
use lightpose_core::{AttitudeReading, Frame, Pose, Truth, NDET};

use super::SensorModel;

/// SplitMix64 with Box–Muller normals: deterministic and seedable.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A frame as MODEL.md's ADC would give it for `pose`, with the model's
/// gains, offsets and noise; an attitude reading with the given σ (rad).
pub fn synth_frame(
    m: &SensorModel,
    pose: &Pose,
    seq: u64,
    t: f64,
    attitude_sigma: Option<(f64, f64)>,
    rng: &mut Rng,
) -> Frame {
    let mut e = [0.0; NDET];
    m.light.irradiance(&m.geometry, pose, &mut e);
    let mut counts = [0u16; NDET];
    for k in 0..NDET {
        let sd = (m.sigma_e_v * m.sigma_e_v + m.kappa_v * e[k]).sqrt();
        let v = m.gain[k] * e[k] + m.offset_v[k] + sd * rng.normal();
        counts[k] = volts_to_counts(v, m.v_ref, m.adc_bits);
    }
    let attitude = attitude_sigma.map(|(sp, sy)| AttitudeReading {
        pitch: lightpose_core::Angle::from_rad(pose.pitch.rad() + sp * rng.normal()),
        yaw: lightpose_core::Angle::from_rad(pose.yaw.rad() + sy * rng.normal()),
        roll: None,
        std: None,
    });
    Frame {
        seq,
        t,
        adc_bits: m.adc_bits,
        counts,
        temp_c: Some(20.0),
        truth: Some(Truth {
            pose: *pose,
            surge: None,
        }),
        attitude,
        depth: None,
        velocity: None,
        amplitudes: None,
    }
}

/// The shipped tank calibration's light model (config/calibration/tank.toml).
pub fn tank_model() -> SensorModel {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/calibration/tank.toml");
    let cal = crate::calibration::Calibration::load(&path).expect("tank calibration");
    cal.physical.as_ref().expect("light model").sensor_model()
}
