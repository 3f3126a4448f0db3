//! Shared ground of lightpose: the frames and angles of `MODEL.md`, the 5 × 5
//! dome geometry, the light equation, and the file and message formats of
//! `FORMATS.md`.
//!
//! It exists so that the simulator, the estimators, the hardware layer and
//! the daemon agree on one definition of each of these: a recording made by
//! one must mean the same to all the others.

pub mod angle;
pub mod array;
pub mod bounds;
pub mod estimator;
pub mod frame;
pub mod geometry;
pub mod light;
pub mod log;
pub mod modulation;
pub mod pose;
pub mod ratelog;
pub mod samples;
pub mod textfile;
pub mod textpos;
pub mod udp;

pub use angle::Angle;
pub use array::{ArrayGeometry, COLS, NDET, ROWS};
pub use estimator::{Estimator, Findings};
pub use frame::{AttitudeReading, AttitudeStd, DepthReading, Frame, Truth, VelocityReading};
pub use geometry::{Attitude, BeamVec, BodyVec, Pose};
pub use light::{LightParams, Scattering};
pub use log::{ByteError, Cut, FrameLog, FrameOrder, LogError, LogHeader, LogReader, LogWriter};
pub use pose::{
    Agreement, PoseEstimate, ReadingUse, ReadingUses, Refusal, StationMode, StationNames,
    StationSeen, Status, StdDev, CHECKED, READINGS,
};
pub use samples::{
    Amplitudes, BeaconAmplitude, BeaconInfo, Burst, Demodulated, Record, RecordKind, MAX_BEACONS,
};

/// Replace a non-finite number by `None`: no message or log ever carries
/// NaN or infinity (FORMATS.md).
#[inline]
pub fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}
