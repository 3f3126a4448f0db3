//! The quantities an estimate is judged on (x, y, z, pitch, yaw, surge,
//! and a station's roll), their names and units, and how to read each off
//! an estimate.
//!
//! Why a module of its own: the Monte Carlo engine, its statistics, the
//! report and the trade table all walk these axes; kept here, none of
//! them imports another just for the table (the engine and the statistics
//! used to import each other).

use lightpose_core::PoseEstimate;

/// The quantities an estimate is judged on, in the order of every table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    X,
    Y,
    Z,
    Pitch,
    Yaw,
    Surge,
    /// Spec v3: a station's estimators give it; one beacon's give none, so
    /// their tables leave it out ([`crate::montecarlo::McResult::axes`]).
    Roll,
}

pub const NAXES: usize = 7;
pub const AXES: [Axis; NAXES] = [
    Axis::X,
    Axis::Y,
    Axis::Z,
    Axis::Pitch,
    Axis::Yaw,
    Axis::Surge,
    Axis::Roll,
];

impl Axis {
    /// Column prefix in the CSV and name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
            Axis::Pitch => "pitch",
            Axis::Yaw => "yaw",
            Axis::Surge => "surge",
            Axis::Roll => "roll",
        }
    }
    pub fn unit(self) -> &'static str {
        match self {
            Axis::X | Axis::Y | Axis::Z => "m",
            Axis::Pitch | Axis::Yaw | Axis::Roll => "°",
            Axis::Surge => "m/s",
        }
    }
    pub fn index(self) -> usize {
        self as usize
    }
    /// The estimate's value of this axis (angles in degrees).
    pub fn of(self, e: &PoseEstimate) -> Option<f64> {
        match self {
            Axis::X => e.x,
            Axis::Y => e.y,
            Axis::Z => e.z,
            Axis::Pitch => e.pitch_deg,
            Axis::Yaw => e.yaw_deg,
            Axis::Surge => e.surge,
            Axis::Roll => e.roll_deg,
        }
    }
    /// The estimate's own 1σ for this axis, if it reports one.
    pub fn std_of(self, e: &PoseEstimate) -> Option<f64> {
        match self {
            Axis::X => e.std.x,
            Axis::Y => e.std.y,
            Axis::Z => e.std.z,
            Axis::Pitch => e.std.pitch,
            Axis::Yaw => e.std.yaw,
            Axis::Surge => e.std.surge,
            Axis::Roll => e.std.roll,
        }
    }
}
