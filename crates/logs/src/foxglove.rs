//! Frames and poses in Foxglove's well-known types (JSON encoding), written
//! into reused buffers so that a recorder does not allocate per frame.
//!
//! Frames of reference: `beacon` is B of MODEL.md (x along the beacon's
//! optical axis, z up, right-handed), which suits Foxglove's 3D panel
//! (z up) as it is. `vehicle` is V of MODEL.md, FRD (forward, right, down),
//! the frame ArduSub, PX4 and the DVL use, so that anything given in V
//! (a DVL velocity, a lever arm) is placed right by the same transform; a
//! ROS user expecting FLU sees the y and z axes of the vehicle's triad
//! flipped, and its x (the arrow of a `PoseInFrame`) along the bow either
//! way. The rotation is R_BV = R0·Rz(ψ)·Ry(θ)·Rx(φ) (MODEL.md), as a
//! quaternion; roll 0 gives spec v2's quaternion bit for bit.

use crate::schema::{BEACON_FRAME, DOME_FRAME, VEHICLE_FRAME};
use lightpose_core::{Angle, Pose, NDET};
use serde::{Serialize, Serializer};

/// A time in the log's epoch as MCAP and Foxglove take it: whole seconds
/// and nanoseconds. Only t ≥ 0 has one (MCAP times are unsigned).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Stamp {
    pub sec: u64,
    pub nsec: u32,
}

/// Largest whole second whose nanoseconds still fit in a u64 (year 2554 in
/// Unix time).
const MAX_SEC: f64 = 18_446_744_072.0;

impl Stamp {
    /// The stamp of `t` seconds, or `None` when t is negative, not finite,
    /// or beyond `MAX_SEC`. The fraction is rounded to the nanosecond on
    /// its own, so that Unix times keep their nanoseconds.
    pub fn of(t: f64) -> Option<Stamp> {
        if !(0.0..MAX_SEC).contains(&t) {
            return None;
        }
        let sec = t.trunc();
        let nsec = ((t - sec) * 1e9).round();
        Some(if nsec >= 1e9 {
            Stamp {
                sec: sec as u64 + 1,
                nsec: 0,
            }
        } else {
            Stamp {
                sec: sec as u64,
                nsec: nsec as u32,
            }
        })
    }

    /// Nanoseconds since the epoch: MCAP's log time.
    pub fn nanos(self) -> u64 {
        self.sec * 1_000_000_000 + self.nsec as u64
    }
}

/// R_BV = R0·Rz(ψ)·Ry(θ), R0 = diag(−1, 1, −1) (a half turn about y), as a
/// unit quaternion `[x, y, z, w]`: the product q(R0)·q(Rz)·q(Ry) written out.
pub fn attitude_quaternion(pitch: Angle, yaw: Angle) -> [f64; 4] {
    let (sz, cz) = (yaw.rad() / 2.0).sin_cos();
    let (sy, cy) = (pitch.rad() / 2.0).sin_cos();
    [sz * cy, cz * cy, sz * sy, -cz * sy]
}

/// R_BV = R0·Rz(ψ)·Ry(θ)·Rx(φ) (spec v3) as a unit quaternion `[x, y, z,
/// w]`: [`attitude_quaternion`] times q(Rx(φ)) = (sin φ/2, 0, 0, cos φ/2).
/// Roll 0 is that quaternion as it is (no −0 turned into +0), so a v1/v2
/// recording's Foxglove messages are unchanged.
pub fn attitude_quaternion_rolled(pitch: Angle, yaw: Angle, roll: Angle) -> [f64; 4] {
    let q = attitude_quaternion(pitch, yaw);
    if roll.rad() == 0.0 {
        return q;
    }
    let [ax, ay, az, aw] = q;
    let (bx, bw) = (roll.rad() / 2.0).sin_cos();
    // Hamilton product a·b with b = (bx, 0, 0, bw).
    [
        aw * bx + bw * ax,
        bw * ay + az * bx,
        bw * az - ay * bx,
        aw * bw - ax * bx,
    ]
}

#[derive(Serialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Serialize)]
struct Quaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

impl Quaternion {
    fn of(pose: &Pose) -> Self {
        let [x, y, z, w] = attitude_quaternion_rolled(pose.pitch, pose.yaw, pose.roll);
        Quaternion { x, y, z, w }
    }
}

#[derive(Serialize)]
struct FoxPose {
    position: Vector3,
    orientation: Quaternion,
}

#[derive(Serialize)]
struct PoseInFrame<'a> {
    timestamp: Stamp,
    frame_id: &'a str,
    pose: FoxPose,
}

#[derive(Serialize)]
struct FrameTransform<'a> {
    timestamp: Stamp,
    parent_frame_id: &'a str,
    child_frame_id: &'a str,
    translation: Vector3,
    rotation: Quaternion,
}

#[derive(Serialize)]
struct RawImage<'a> {
    timestamp: Stamp,
    frame_id: &'a str,
    width: u32,
    height: u32,
    encoding: &'a str,
    step: u32,
    data: Base64<'a>,
}

/// Bytes as a base64 string (RFC 4648, padded): how JSON-encoded Foxglove
/// messages carry `bytes` fields. Written straight into the JSON output.
struct Base64<'a>(&'a [u8]);

const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

impl std::fmt::Display for Base64<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use std::fmt::Write;
        for group in self.0.chunks(3) {
            let b = [
                group[0],
                group.get(1).copied().unwrap_or(0),
                group.get(2).copied().unwrap_or(0),
            ];
            let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
            for k in 0..4 {
                if k <= group.len() {
                    f.write_char(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char)?;
                } else {
                    f.write_char('=')?;
                }
            }
        }
        Ok(())
    }
}

impl Serialize for Base64<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// Serialize into `out` (cleared first). Writing into a Vec cannot fail and
/// every number here is finite (the callers check), so an error leaves an
/// empty buffer that the caller does not write.
fn to_json<T: Serialize>(v: &T, out: &mut Vec<u8>) {
    out.clear();
    if serde_json::to_writer(&mut *out, v).is_err() {
        out.clear();
    }
}

/// The 25 counts as a 5 × 5 `mono16` image: each pixel the count itself
/// (little-endian u16), so that the image holds the counts faithfully at
/// any ADC resolution up to 16 bits; row 0 at the top, as the array's rows.
pub fn raw_image(stamp: Stamp, counts: &[u16; NDET], out: &mut Vec<u8>) {
    let mut px = [0u8; 2 * NDET];
    for (pair, c) in px.chunks_exact_mut(2).zip(counts) {
        pair.copy_from_slice(&c.to_le_bytes());
    }
    let img = RawImage {
        timestamp: stamp,
        frame_id: DOME_FRAME,
        width: lightpose_core::COLS as u32,
        height: lightpose_core::ROWS as u32,
        encoding: "mono16",
        step: 2 * lightpose_core::COLS as u32,
        data: Base64(&px),
    };
    to_json(&img, out);
}

/// A pose of the vehicle in `beacon` as a `foxglove.PoseInFrame`.
pub fn pose_in_frame(stamp: Stamp, pose: &Pose, out: &mut Vec<u8>) {
    let m = PoseInFrame {
        timestamp: stamp,
        frame_id: BEACON_FRAME,
        pose: FoxPose {
            position: Vector3 {
                x: pose.x,
                y: pose.y,
                z: pose.z,
            },
            orientation: Quaternion::of(pose),
        },
    };
    to_json(&m, out);
}

/// `beacon` → `vehicle` as a `foxglove.FrameTransform`.
pub fn frame_transform(stamp: Stamp, pose: &Pose, out: &mut Vec<u8>) {
    let m = FrameTransform {
        timestamp: stamp,
        parent_frame_id: BEACON_FRAME,
        child_frame_id: VEHICLE_FRAME,
        translation: Vector3 {
            x: pose.x,
            y: pose.y,
            z: pose.z,
        },
        rotation: Quaternion::of(pose),
    };
    to_json(&m, out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::Attitude;
    use proptest::prelude::*;

    fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
        // v' = v + 2w(u×v) + 2u×(u×v), u = (x, y, z)
        let [x, y, z, w] = q;
        let u = [x, y, z];
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let t = cross(u, v);
        let tt = cross(u, t);
        [0, 1, 2].map(|i| v[i] + 2.0 * w * t[i] + 2.0 * tt[i])
    }

    proptest! {
        #[test]
        fn quaternion_is_r_bv(pitch in -89.0f64..89.0, yaw in -180.0f64..180.0) {
            let (p, y) = (Angle::from_deg(pitch), Angle::from_deg(yaw));
            let q = attitude_quaternion(p, y);
            let n: f64 = q.iter().map(|c| c * c).sum();
            prop_assert!((n - 1.0).abs() < 1e-12);
            let r = Attitude::new(p, y).r_bv();
            for (col, e) in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].iter().enumerate() {
                let v = rotate(q, *e);
                for row in 0..3 {
                    prop_assert!((v[row] - r[row][col]).abs() < 1e-12, "R[{row}][{col}]");
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { rng_seed: proptest::test_runner::RngSeed::Fixed(40), ..ProptestConfig::default() })]
        /// Spec v3: with roll, the quaternion is the full R_BV of MODEL.md.
        #[test]
        fn rolled_quaternion_is_r_bv(pitch in -89.0f64..89.0, yaw in -180.0f64..180.0, roll in -180.0f64..180.0) {
            let (p, y, r) = (Angle::from_deg(pitch), Angle::from_deg(yaw), Angle::from_deg(roll));
            let q = attitude_quaternion_rolled(p, y, r);
            let n: f64 = q.iter().map(|c| c * c).sum();
            prop_assert!((n - 1.0).abs() < 1e-12);
            let m = Attitude::new(p, y).with_roll(r).r_bv();
            for (col, e) in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].iter().enumerate() {
                let v = rotate(q, *e);
                for row in 0..3 {
                    prop_assert!((v[row] - m[row][col]).abs() < 1e-12, "R[{row}][{col}]");
                }
            }
            prop_assert_eq!(attitude_quaternion_rolled(p, y, Angle::ZERO), attitude_quaternion(p, y));
        }
    }

    #[test]
    fn facing_the_beacon_is_a_half_turn_about_y() {
        let q = attitude_quaternion(Angle::ZERO, Angle::ZERO);
        assert_eq!(q, [0.0, 1.0, 0.0, -0.0]);
        // Forward (x of V) points back along −x of B.
        let f = rotate(q, [1.0, 0.0, 0.0]);
        assert!((f[0] + 1.0).abs() < 1e-15 && f[1].abs() < 1e-15 && f[2].abs() < 1e-15);
    }

    #[test]
    fn base64_matches_rfc4648() {
        for (src, want) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(Base64(src.as_bytes()).to_string(), want);
        }
        assert_eq!(Base64(&[0xff, 0xfe, 0xfd]).to_string(), "//79");
    }

    #[test]
    fn stamps() {
        assert_eq!(
            Stamp::of(3.4),
            Some(Stamp {
                sec: 3,
                nsec: 400_000_000
            })
        );
        assert_eq!(Stamp::of(0.0).map(Stamp::nanos), Some(0));
        assert_eq!(
            Stamp::of(1.7e9 + 0.25).map(Stamp::nanos),
            Some(1_700_000_000_250_000_000)
        );
        assert_eq!(Stamp::of(0.9999999999), Some(Stamp { sec: 1, nsec: 0 }));
        for bad in [-1e-9, -0.0 - 1.0, f64::NAN, f64::INFINITY, 1e11] {
            assert_eq!(Stamp::of(bad), None, "{bad}");
        }
        let max = Stamp::of(MAX_SEC - 0.5).map(Stamp::nanos);
        assert!(max.is_some());
    }

    #[test]
    fn image_holds_the_counts() {
        let mut counts = [0u16; NDET];
        counts[0] = 1023;
        counts[24] = 0x1234;
        let mut out = Vec::new();
        raw_image(Stamp { sec: 1, nsec: 2 }, &counts, &mut out);
        let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
        assert_eq!(v["encoding"], "mono16");
        assert_eq!(v["step"], 10);
        let data = v["data"].as_str().unwrap();
        assert_eq!(data.len(), 68);
        assert!(data.starts_with("/wM"), "{data}"); // ff 03 ..
        assert_eq!(v["timestamp"]["nsec"], 2);
    }
}
