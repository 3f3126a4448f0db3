//! ROS 2 messages, one definition of each, for the daemon's ROS 2 node
//! (lightposed's `[ros2]`) and the ROS 2 recordings (`lightpose convert
//! --ros2`): the structs in the field order of their `.msg` files, which is
//! the order CDR lays them out in (serde's derive keeps it), and the
//! conversion of a [`PoseEstimate`] into them.
//!
//! Frames (REP-103/105): the beacon's frame B goes as it is (right-handed,
//! +z up); the vehicle's `base_link` is FLU, the body frame V (FRD) with y
//! and z negated. Angles' variances are in rad². An angle nothing observes
//! gets the variance of an angle spread evenly over the circle (π²/3 rad²),
//! a rate or speed nothing observes [`UNOBSERVED_VAR`]: never 0, never NaN
//! (robot_localization refuses the one and is broken by the other).

mod diagnostics;
pub use diagnostics::{diagnostics, LastEstimate};

use lightpose_core::{Angle, Attitude, PoseEstimate, Status};
use serde::de::{Deserializer, SeqAccess, Visitor};
use serde::ser::{SerializeTuple, Serializer};
use serde::{Deserialize, Serialize};

/// The variance of an angle nobody observes: uniform over (−π, π], rad².
pub const UNOBSERVED_ANGLE_VAR: f64 = std::f64::consts::PI * std::f64::consts::PI / 3.0;
/// The variance of a velocity component nobody observes, (m/s)² or
/// (rad/s)²: large against any vehicle's, finite.
pub const UNOBSERVED_VAR: f64 = 1.0e4;

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Unix seconds as ROS time; a time before 1970 or past 2038 (i32)
    /// is clamped to the range rather than wrapped.
    pub fn from_unix(t: f64) -> Time {
        if !t.is_finite() || t <= 0.0 {
            return Time::default();
        }
        let sec = t.floor().min(i32::MAX as f64);
        let nanosec = (((t - sec) * 1e9).round() as u32).min(999_999_999);
        Time {
            sec: sec as i32,
            nanosec,
        }
    }

    pub fn unix(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    /// geometry_msgs/Point: the same three f64 as a Vector3.
    pub position: Vector3,
    pub orientation: Quaternion,
}

/// A 6 × 6 row-major covariance, `float64[36]`: CDR's fixed array, no
/// length (serde derives arrays up to 32 only, hence by hand).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cov6(pub [f64; 36]);

impl Default for Cov6 {
    fn default() -> Self {
        Cov6([0.0; 36])
    }
}

impl Cov6 {
    /// Diagonal of variances.
    pub fn diagonal(var: [f64; 6]) -> Cov6 {
        let mut c = [0.0; 36];
        for (i, v) in var.iter().enumerate() {
            c[i * 7] = *v;
        }
        Cov6(c)
    }

    pub fn diag(&self) -> [f64; 6] {
        std::array::from_fn(|i| self.0[i * 7])
    }
}

impl Serialize for Cov6 {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Cov6 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Cov6, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Cov6;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("36 float64")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Cov6, A::Error> {
                let mut c = [0.0; 36];
                for (i, slot) in c.iter_mut().enumerate() {
                    *slot = seq
                        .next_element()?
                        .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                Ok(Cov6(c))
            }
        }
        d.deserialize_tuple(36, V)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Cov6,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: Cov6,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

/// diagnostic_msgs/DiagnosticStatus's levels.
pub const DIAG_OK: u8 = 0;
pub const DIAG_WARN: u8 = 1;
pub const DIAG_ERROR: u8 = 2;

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

/// `float64[9]`: serde derives this length.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}

/// `sensor_msgs/msg/FluidPressure`: Pa; a variance of 0 is "unknown".
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FluidPressure {
    pub header: Header,
    pub fluid_pressure: f64,
    pub variance: f64,
}

/// A DVL's velocity as ROS 2 drivers give it (in the body frame, FLU).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TwistWithCovarianceStamped {
    pub header: Header,
    pub twist: TwistWithCovariance,
}

/// A ROS 2 type: package and name (`geometry_msgs`, `PoseWithCovarianceStamped`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TypeName {
    pub package: &'static str,
    pub name: &'static str,
}

impl TypeName {
    /// `geometry_msgs/msg/PoseWithCovarianceStamped`: the ROS name, an
    /// MCAP schema's name.
    pub fn ros(&self) -> String {
        format!("{}/msg/{}", self.package, self.name)
    }

    /// `geometry_msgs::msg::dds_::PoseWithCovarianceStamped_`: the DDS
    /// type name every ROS 2 DDS middleware uses.
    pub fn dds(&self) -> String {
        format!("{}::msg::dds_::{}_", self.package, self.name)
    }
}

pub const POSE_TYPE: TypeName = TypeName {
    package: "geometry_msgs",
    name: "PoseWithCovarianceStamped",
};
pub const ODOM_TYPE: TypeName = TypeName {
    package: "nav_msgs",
    name: "Odometry",
};
pub const TF_TYPE: TypeName = TypeName {
    package: "tf2_msgs",
    name: "TFMessage",
};
pub const DIAG_TYPE: TypeName = TypeName {
    package: "diagnostic_msgs",
    name: "DiagnosticArray",
};
pub const IMU_TYPE: TypeName = TypeName {
    package: "sensor_msgs",
    name: "Imu",
};

pub const FLUID_PRESSURE_TYPE: TypeName = TypeName {
    package: "sensor_msgs",
    name: "FluidPressure",
};
pub const TWIST_TYPE: TypeName = TypeName {
    package: "geometry_msgs",
    name: "TwistWithCovarianceStamped",
};

/// ROS 2's naming rules, for the config and the command line alike.
pub mod names {
    /// A name token: letters, digits and single `_`, not starting with a
    /// digit.
    pub fn is_token(s: &str) -> bool {
        !s.is_empty()
            && !s.starts_with(|c: char| c.is_ascii_digit())
            && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            && !s.contains("__")
    }

    /// `/a/b`: absolute, tokens between slashes; `/` alone is the root.
    pub fn is_namespace(s: &str) -> bool {
        s == "/" || (s.starts_with('/') && !s.ends_with('/') && s[1..].split('/').all(is_token))
    }

    /// A tf frame id: tf2 refuses a leading `/` and whitespace.
    pub fn is_frame_id(s: &str) -> bool {
        !s.is_empty()
            && !s.starts_with('/')
            && !s.chars().any(|c| c.is_whitespace() || c.is_control())
    }
}

/// The frames the messages name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frames {
    /// The beacon's frame B (the poses' `frame_id`).
    pub beacon: String,
    /// The vehicle's body, FLU.
    pub base_link: String,
    /// The world frame of `/tf_static` (ENU).
    pub map: String,
}

impl Frames {
    /// Three different frames (tf would loop otherwise).
    pub fn distinct(&self) -> bool {
        self.beacon != self.base_link && self.beacon != self.map && self.base_link != self.map
    }
}

impl Default for Frames {
    fn default() -> Self {
        Frames {
            beacon: "lightpose_beacon".into(),
            base_link: "base_link".into(),
            map: "map".into(),
        }
    }
}

/// A rotation matrix (row-major) as a unit quaternion (Shepperd's method:
/// the largest of the four first, so no division by a small number).
pub fn quaternion(r: &[[f64; 3]; 3]) -> Quaternion {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let (x, y, z, w);
    if tr > r[0][0] && tr > r[1][1] && tr > r[2][2] {
        let s = (1.0 + tr).sqrt() * 2.0;
        w = 0.25 * s;
        x = (r[2][1] - r[1][2]) / s;
        y = (r[0][2] - r[2][0]) / s;
        z = (r[1][0] - r[0][1]) / s;
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
        w = (r[2][1] - r[1][2]) / s;
        x = 0.25 * s;
        y = (r[0][1] + r[1][0]) / s;
        z = (r[0][2] + r[2][0]) / s;
    } else if r[1][1] > r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
        w = (r[0][2] - r[2][0]) / s;
        x = (r[0][1] + r[1][0]) / s;
        y = 0.25 * s;
        z = (r[1][2] + r[2][1]) / s;
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
        w = (r[1][0] - r[0][1]) / s;
        x = (r[0][2] + r[2][0]) / s;
        y = (r[1][2] + r[2][1]) / s;
        z = 0.25 * s;
    }
    // One sign for one rotation: w ≥ 0.
    let k = if w < 0.0 { -1.0 } else { 1.0 };
    Quaternion {
        x: k * x,
        y: k * y,
        z: k * z,
        w: k * w,
    }
}

/// A unit quaternion as its rotation matrix (row-major).
pub fn rotation(q: &Quaternion) -> [[f64; 3]; 3] {
    let Quaternion { x, y, z, w } = *q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// base_link (FLU) in B: R_BV (FRD) with its y and z columns negated.
pub fn base_link_in_beam(att: &Attitude) -> Quaternion {
    let mut r = att.r_bv();
    for row in &mut r {
        row[1] = -row[1];
        row[2] = -row[2];
    }
    quaternion(&r)
}

/// What every message of one estimate shares: only an `ok` estimate
/// with a complete pose has one. `'a`: the station's name it borrows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solved<'a> {
    pub stamp: Time,
    /// A docking station's frame D, which the pose is in (spec v3: POSE's
    /// `frame`); `None`: the beacon's, [`Frames::beacon`].
    pub station: Option<&'a str>,
    pub position: Vector3,
    pub orientation: Quaternion,
    pub pose_cov: Cov6,
    pub surge: Option<f64>,
    pub surge_var: f64,
}

/// A variance from a 1σ, or `None` for one that is missing, zero or not
/// finite (the estimate then has no usable value there).
fn var(sigma: Option<f64>) -> Option<f64> {
    sigma.filter(|s| s.is_finite() && *s > 0.0).map(|s| s * s)
}

fn var_deg(sigma_deg: Option<f64>) -> Option<f64> {
    var(sigma_deg.map(|d| d.to_radians()))
}

/// The pose of an estimate, stamped with its capture (Unix seconds): `None`
/// unless it is `ok` with x, y, z, pitch, yaw and their finite 1σ.
pub fn solve(est: &PoseEstimate, capture_unix: f64) -> Option<Solved<'static>> {
    if est.status != Status::Ok {
        return None;
    }
    let vals = [est.x?, est.y?, est.z?, est.pitch_deg?, est.yaw_deg?];
    if vals.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let roll = est.roll_deg.filter(|r| r.is_finite()).unwrap_or(0.0);
    let att = Attitude::new(Angle::from_deg(vals[3]), Angle::from_deg(vals[4]))
        .with_roll(Angle::from_deg(roll));
    let s = &est.std;
    // ROS orders rotations roll (x), pitch (y), yaw (z).
    let roll_var = est
        .roll_deg
        .and(var_deg(s.roll))
        .unwrap_or(UNOBSERVED_ANGLE_VAR);
    let cov = [
        var(s.x)?,
        var(s.y)?,
        var(s.z)?,
        roll_var,
        var_deg(s.pitch)?,
        var_deg(s.yaw)?,
    ];
    let surge = est.surge.filter(|v| v.is_finite());
    Some(Solved {
        stamp: Time::from_unix(capture_unix),
        station: est.station.names.map(|n| n.name.as_str()),
        position: Vector3 {
            x: vals[0],
            y: vals[1],
            z: vals[2],
        },
        orientation: base_link_in_beam(&att),
        pose_cov: Cov6::diagonal(cov),
        surge_var: surge.and(var(s.surge)).unwrap_or(UNOBSERVED_VAR),
        surge,
    })
}

fn header(stamp: Time, frame: &str) -> Header {
    Header {
        stamp,
        frame_id: frame.to_string(),
    }
}

impl Solved<'_> {
    /// The frame the pose is in: the station's, or the beacon's.
    pub fn parent<'f>(&'f self, frames: &'f Frames) -> &'f str {
        self.station.unwrap_or(&frames.beacon)
    }

    pub fn pose(&self, frames: &Frames) -> PoseWithCovarianceStamped {
        PoseWithCovarianceStamped {
            header: header(self.stamp, self.parent(frames)),
            pose: self.pose_with_cov(),
        }
    }

    fn pose_with_cov(&self) -> PoseWithCovariance {
        PoseWithCovariance {
            pose: Pose {
                position: self.position,
                orientation: self.orientation,
            },
            covariance: self.pose_cov,
        }
    }

    /// The twist is in base_link: surge along its x; what no reading
    /// tells is [`UNOBSERVED_VAR`].
    pub fn odometry(&self, frames: &Frames) -> Odometry {
        let mut tv = [UNOBSERVED_VAR; 6];
        tv[0] = self.surge_var;
        Odometry {
            header: header(self.stamp, self.parent(frames)),
            child_frame_id: frames.base_link.clone(),
            pose: self.pose_with_cov(),
            twist: TwistWithCovariance {
                twist: Twist {
                    linear: Vector3 {
                        x: self.surge.unwrap_or(0.0),
                        ..Vector3::default()
                    },
                    angular: Vector3::default(),
                },
                covariance: Cov6::diagonal(tv),
            },
        }
    }

    pub fn tf(&self, frames: &Frames) -> TFMessage {
        TFMessage {
            transforms: vec![TransformStamped {
                header: header(self.stamp, self.parent(frames)),
                child_frame_id: frames.base_link.clone(),
                transform: Transform {
                    translation: self.position,
                    rotation: self.orientation,
                },
            }],
        }
    }
}

/// Where the beacon's frame B (or a station's D) is in the world: the
/// compass heading of its +x axis and its origin north, east, down in
/// the autopilot's frame (`[site]`), for `/tf_static`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteTf {
    pub axis_heading: Angle,
    pub ned: [f64; 3],
}

impl SiteTf {
    /// `/tf_static`: `child` (the beacon's frame, or the station's) in
    /// `frames.map` (ENU).
    pub fn message(&self, frames: &Frames, child: &str, stamp: Time) -> TFMessage {
        // x_B points at heading h (clockwise from north): in ENU that is a
        // rotation about up by 90° − h; z_B is up in both.
        let yaw = std::f64::consts::FRAC_PI_2 - self.axis_heading.rad();
        let (s, c) = (yaw / 2.0).sin_cos();
        let ned = self.ned;
        TFMessage {
            transforms: vec![TransformStamped {
                header: header(stamp, &frames.map),
                child_frame_id: child.to_string(),
                transform: Transform {
                    translation: Vector3 {
                        x: ned[1],
                        y: ned[0],
                        z: -ned[2],
                    },
                    rotation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: s,
                        w: c,
                    },
                },
            }],
        }
    }
}

/// `/tf_static` of the beacon's frame ([`SiteTf::message`] with
/// [`Frames::beacon`]).
pub fn site_tf(frames: &Frames, axis_heading: Angle, ned: [f64; 3], stamp: Time) -> TFMessage {
    SiteTf { axis_heading, ned }.message(frames, &frames.beacon, stamp)
}

#[cfg(test)]
mod tests;
