//! One frame of the array: 25 ADC counts, when they were taken, the water
//! temperature reported with them, what the vehicle's own sensors (attitude,
//! depth, DVL) read at the same moment, and (from a simulator or tank
//! carriage) the true pose.

use crate::samples::Amplitudes;
use crate::{Angle, BodyVec, Pose, NDET};

/// True pose of a frame (simulator or tank carriage), with surge if known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    pub pose: Pose,
    pub surge: Option<f64>,
}

/// What the vehicle's own attitude sensor read at capture, in B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeReading {
    pub pitch: Angle,
    pub yaw: Angle,
    /// Spec v3: `None` when the sensor does not report roll (every v1/v2
    /// log), which is not the same as a reading of 0.
    pub roll: Option<Angle>,
    /// 1σ of this reading, when the frame says (FORMATS.md `std`); else the
    /// estimator's configured sensor noise applies.
    pub std: Option<AttitudeStd>,
}

/// 1σ of an attitude reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeStd {
    pub pitch: Angle,
    pub yaw: Angle,
}

impl AttitudeReading {
    /// A reading of pitch and yaw (no roll) without its own noise figure.
    pub fn new(pitch: Angle, yaw: Angle) -> Self {
        AttitudeReading {
            pitch,
            yaw,
            roll: None,
            std: None,
        }
    }
}

/// What the vehicle's depth sensor gives at capture, already referred to the
/// beacon: the vehicle's z in B, metres (spec v2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthReading {
    pub z: f64,
    /// 1σ, metres, when the frame says.
    pub std: Option<f64>,
}

impl DepthReading {
    pub fn new(z: f64) -> Self {
        DepthReading { z, std: None }
    }
}

/// What the DVL gives at capture: the vehicle's velocity over the ground in
/// the body frame V (forward, right, down), m/s (spec v2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityReading {
    pub v: BodyVec,
    /// 1σ of each component, m/s, when the frame says.
    pub std: Option<BodyVec>,
}

impl VelocityReading {
    pub fn new(fwd: f64, right: f64, down: f64) -> Self {
        VelocityReading {
            v: BodyVec([fwd, right, down]),
            std: None,
        }
    }
}

/// One capture of the array. Fixed-size so that the hot path never
/// allocates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub seq: u64,
    /// Seconds in the log's own epoch.
    pub t: f64,
    /// ADC resolution of `counts`.
    pub adc_bits: u8,
    /// Row-major, index 5·r + c, each in 0..2^adc_bits − 1.
    pub counts: [u16; NDET],
    pub temp_c: Option<f64>,
    pub truth: Option<Truth>,
    pub attitude: Option<AttitudeReading>,
    pub depth: Option<DepthReading>,
    pub velocity: Option<VelocityReading>,
    /// Spec v3: what a demodulator made of the frame's samples (each
    /// beacon's amplitude image with its 1σ, the ambient, the clipped
    /// counts); then `counts` are only each channel's mean level, for
    /// display, and an estimator reads the amplitudes. None for a frame
    /// of counts (v1/v2, a steady beacon).
    pub amplitudes: Option<Amplitudes>,
}

impl Frame {
    /// A frame of counts alone: no temperature, no aiding reading, no truth.
    pub fn new(seq: u64, t: f64, adc_bits: u8, counts: [u16; NDET]) -> Self {
        Frame {
            seq,
            t,
            adc_bits,
            counts,
            temp_c: None,
            truth: None,
            attitude: None,
            depth: None,
            velocity: None,
            amplitudes: None,
        }
    }

    /// Largest count of this frame's ADC.
    #[inline]
    pub fn full_scale(&self) -> u16 {
        full_scale(self.adc_bits)
    }
}

/// 2^bits − 1 for 1..=16 bits.
#[inline]
pub fn full_scale(bits: u8) -> u16 {
    let b = bits.clamp(1, 16) as u32;
    ((1u32 << b) - 1) as u16
}

/// counts = clamp(round(V / V_ref · (2^bits − 1)), 0, 2^bits − 1), rounding
/// half away from zero (MODEL.md).
#[inline]
pub fn volts_to_counts(v: f64, v_ref: f64, bits: u8) -> u16 {
    let fs = full_scale(bits) as f64;
    let c = (v / v_ref * fs).round(); // f64::round is half away from zero
    if c.is_nan() || c <= 0.0 {
        0
    } else if c >= fs {
        fs as u16
    } else {
        c as u16
    }
}

/// The centre of the voltage bin of a count.
#[inline]
pub fn counts_to_volts(c: u16, v_ref: f64, bits: u8) -> f64 {
    c as f64 * v_ref / full_scale(bits) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantization_rounds_half_away_and_clamps() {
        // 1 LSB = 5/1023 V
        let lsb = 5.0 / 1023.0;
        assert_eq!(volts_to_counts(2.5 * lsb, 5.0, 10), 3);
        assert_eq!(volts_to_counts(2.49 * lsb, 5.0, 10), 2);
        assert_eq!(volts_to_counts(-1.0, 5.0, 10), 0);
        assert_eq!(volts_to_counts(7.0, 5.0, 10), 1023);
        assert_eq!(volts_to_counts(f64::NAN, 5.0, 10), 0);
        assert_eq!(volts_to_counts(5.0, 5.0, 16), 65535);
        assert_eq!(volts_to_counts(5.0, 5.0, 12), 4095);
        assert!((counts_to_volts(1023, 5.0, 10) - 5.0).abs() < 1e-12);
    }
}
