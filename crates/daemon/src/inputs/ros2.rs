//! The vehicle's attitude from ROS 2 (`[ros2] imu_topic`): a
//! `sensor_msgs/msg/Imu`'s orientation, read by the ROS 2 node's IMU
//! thread, checked, and stored in the same lock-free cell as the UDP JSON
//! attitude input's ([`super::attitude::AttitudeCell`]), which the frame
//! thread reads through [`super::attitude::LatestAttitude`]: freshness,
//! counted refusals and STATUS `attitude` as for that input.
//!
//! REP-145: the orientation is `base_link` (FLU) in ENU, yaw 0 east. Turned
//! into the body FRD in NED (ZYX: heading, pitch, roll), its heading is
//! referred to the beacon's axis as the UDP input does: ψ_B = heading −
//! (axis heading + 180°); pitch and roll are B's own. A sample with a
//! frame id longer than any driver's (an oversized one) is refused as
//! `malformed`.

use super::attitude::{wrap180, AttitudeCell, Reason};
use lightpose_core::{Angle, AttitudeReading};
use lightpose_logs::ros2msg::{rotation, Imu};
use std::time::Instant;

/// How far from 1 a quaternion's norm may be: a driver's float32 rounding
/// is far inside it, a quaternion that is not one is far outside.
pub const UNIT_TOLERANCE: f64 = 1e-3;

/// The reading of one Imu message, or why it is refused.
pub fn reading(m: &Imu, beacon_axis_heading_deg: f64) -> Result<AttitudeReading, Reason> {
    // A frame id this long is no driver's: the sample is not believed.
    if m.header.frame_id.len() > super::ros2_readings::MAX_FRAME_ID {
        return Err(Reason::Malformed);
    }
    let q = m.orientation;
    let v = [q.x, q.y, q.z, q.w];
    if v.iter().any(|c| !c.is_finite()) {
        return Err(Reason::Angle);
    }
    // orientation_covariance[0] = -1: the driver says it has no orientation.
    if m.orientation_covariance[0] == -1.0 {
        return Err(Reason::Malformed);
    }
    let n = v.iter().map(|c| c * c).sum::<f64>().sqrt();
    if (n - 1.0).abs() > UNIT_TOLERANCE {
        return Err(Reason::Angle);
    }
    let r_enu_flu = rotation(&q);
    // NED from ENU swaps x and y and negates z; FRD from FLU negates y, z.
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        let src = match i {
            0 => r_enu_flu[1],
            1 => r_enu_flu[0],
            _ => r_enu_flu[2].map(|x| -x),
        };
        *row = [src[0], -src[1], -src[2]];
    }
    let heading = r[1][0].atan2(r[0][0]).to_degrees();
    let pitch = (-r[2][0]).clamp(-1.0, 1.0).asin().to_degrees();
    let roll = r[2][1].atan2(r[2][2]).to_degrees();
    Ok(AttitudeReading {
        pitch: Angle::from_deg(pitch),
        yaw: Angle::from_deg(wrap180(heading - beacon_axis_heading_deg - 180.0)),
        roll: Some(Angle::from_deg(roll)),
        std: None,
    })
}

/// Take one message (or a sample DDS could not read) into the cell.
pub fn take(cell: &AttitudeCell, got: Result<Imu, String>, heading_deg: f64) {
    let reason = match got.map(|m| reading(&m, heading_deg)) {
        Ok(Ok(r)) => {
            cell.store(Instant::now(), r);
            return;
        }
        Ok(Err(reason)) => reason,
        Err(why) => {
            tracing::debug!("ros2 imu: unreadable sample: {why}");
            Reason::Malformed
        }
    };
    let n = cell.reject(reason);
    // The first refusal of each kind told, the others counted.
    if n == 1 || cell.rejected_by[reason as usize].load(std::sync::atomic::Ordering::Relaxed) == 1 {
        tracing::warn!(
            "ros2 imu: a reading refused ({}), counted in STATUS attitude.rejected_by",
            reason.as_str()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_logs::ros2msg::{quaternion, Quaternion};

    fn imu(q: Quaternion) -> Imu {
        Imu {
            orientation: q,
            ..Imu::default()
        }
    }

    /// FLU in ENU of a vehicle at compass heading h, pitch p (bow up),
    /// roll r (starboard down), built from the NED ZYX angles.
    fn flu_in_enu(h: f64, p: f64, r: f64) -> Quaternion {
        let (h, p, r) = (h.to_radians(), p.to_radians(), r.to_radians());
        let rz = [
            [h.cos(), -h.sin(), 0.0],
            [h.sin(), h.cos(), 0.0],
            [0.0, 0.0, 1.0],
        ];
        let ry = [
            [p.cos(), 0.0, p.sin()],
            [0.0, 1.0, 0.0],
            [-p.sin(), 0.0, p.cos()],
        ];
        let rx = [
            [1.0, 0.0, 0.0],
            [0.0, r.cos(), -r.sin()],
            [0.0, r.sin(), r.cos()],
        ];
        let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
            let mut c = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
                }
            }
            c
        };
        let ned_frd = mul(mul(rz, ry), rx);
        // ENU from NED swaps rows 0, 1 and negates row 2; FLU from FRD
        // negates columns 1, 2.
        let rows = [ned_frd[1], ned_frd[0], ned_frd[2].map(|x| -x)];
        let m = rows.map(|src| [src[0], -src[1], -src[2]]);
        quaternion(&m)
    }

    #[test]
    fn the_orientation_becomes_pitch_roll_and_yaw_in_b() {
        let r = reading(&imu(flu_in_enu(250.0, 10.0, -5.0)), 30.0).expect("taken");
        assert!((r.pitch.deg() - 10.0).abs() < 1e-9, "{r:?}");
        assert!((r.roll.expect("roll").deg() + 5.0).abs() < 1e-9, "{r:?}");
        // Facing the beacon (heading = axis + 180°) is yaw 0.
        assert!((r.yaw.deg() - 40.0).abs() < 1e-9, "{r:?}");
        let r = reading(&imu(flu_in_enu(210.0, 0.0, 0.0)), 30.0).expect("taken");
        assert!(r.yaw.deg().abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn nan_and_non_unit_quaternions_and_no_orientation_are_refused() {
        let nan = Quaternion {
            x: f64::NAN,
            ..Quaternion::default()
        };
        assert_eq!(reading(&imu(nan), 0.0), Err(Reason::Angle));
        let long = Quaternion {
            w: 1.1,
            ..Quaternion::default()
        };
        assert_eq!(reading(&imu(long), 0.0), Err(Reason::Angle));
        let zero = Quaternion {
            w: 0.0,
            ..Quaternion::default()
        };
        assert_eq!(reading(&imu(zero), 0.0), Err(Reason::Angle));
        let mut none = imu(Quaternion::default());
        none.orientation_covariance[0] = -1.0;
        assert_eq!(reading(&none, 0.0), Err(Reason::Malformed));
        let mut long = imu(Quaternion::default());
        long.header.frame_id = "x".repeat(1 << 20);
        assert_eq!(reading(&long, 0.0), Err(Reason::Malformed));
        let cell = AttitudeCell::default();
        take(&cell, Ok(imu(nan)), 0.0);
        take(&cell, Err("short".into()), 0.0);
        take(&cell, Ok(imu(Quaternion::default())), 0.0);
        assert_eq!(
            cell.rejected_by[Reason::Angle as usize].load(std::sync::atomic::Ordering::Relaxed),
            1
        );
        assert_eq!(
            cell.rejected_by[Reason::Malformed as usize].load(std::sync::atomic::Ordering::Relaxed),
            1
        );
        assert_eq!(cell.received.load(std::sync::atomic::Ordering::Relaxed), 1);
    }
}
