//! A frame with every field a FRAME line can carry, for the tests that
//! write frames and read them back without allocating (core's log reader,
//! and lightpose-logs' containers, which include this file by path): one
//! builder, so both read the same variety of lines.

use lightpose_core::log::as_logged;
use lightpose_core::{
    Angle, AttitudeReading, AttitudeStd, BodyVec, DepthReading, Frame, Pose, Truth,
    VelocityReading, NDET,
};

/// Frame `seq`: every reading, truth and temperature, some readings
/// without their std (every 2nd to 5th frame), the attitude as a log line
/// gives it back (`as_logged`).
pub fn frame(seq: u64) -> Frame {
    let mut counts = [0u16; NDET];
    for (k, c) in counts.iter_mut().enumerate() {
        *c = ((seq as usize * 13 + k * 41) % 1024) as u16;
    }
    let s = seq as f64;
    let mut f = Frame::new(seq, 100.0 + s * 0.2, 10, counts);
    f.temp_c = Some(12.25 - s * 1e-3);
    f.truth = Some(Truth {
        pose: Pose::new(5.0 + s * 0.01, -0.2, 0.3, Angle::ZERO, Angle::ZERO),
        surge: seq.is_multiple_of(2).then_some(0.4),
    });
    f.attitude = Some(AttitudeReading {
        pitch: Angle::from_deg(-3.5 + s * 1e-2),
        yaw: Angle::from_deg(12.0 - s * 3e-3),
        roll: None,
        std: (!seq.is_multiple_of(3)).then_some(AttitudeStd {
            pitch: Angle::from_deg(0.25),
            yaw: Angle::from_deg(2.0),
        }),
    });
    f.depth = Some(DepthReading {
        z: -0.75 + s * 1e-3,
        std: (!seq.is_multiple_of(5)).then_some(0.01),
    });
    f.velocity = Some(VelocityReading {
        v: BodyVec([0.3, -0.02 + s * 1e-4, 0.01]),
        std: (!seq.is_multiple_of(4)).then_some(BodyVec([0.02, 0.02, 0.04])),
    });
    as_logged(&mut f);
    f
}
