//! The six quantities an estimate is judged on (x, y, z, pitch, yaw,
//! surge), their names and units, and how to read each off an estimate.
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
}

pub const NAXES: usize = 6;
pub const AXES: [Axis; NAXES] = [
    Axis::X,
    Axis::Y,
    Axis::Z,
    Axis::Pitch,
    Axis::Yaw,
    Axis::Surge,
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
        }
    }
    pub fn unit(self) -> &'static str {
        match self {
            Axis::X | Axis::Y | Axis::Z => "m",
            Axis::Pitch | Axis::Yaw => "°",
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
        }
    }
}
