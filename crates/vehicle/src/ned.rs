//! The beam frame B and the autopilot's local NED frame (FORMATS.md,
//! "Vehicle integration (MAVLink)"), tied together by the site: the compass
//! heading h of the beacon's optical axis and the beacon's depth d_b.
//!
//! ```text
//! +x_B = (cos h, sin h, 0)   +y_B = (sin h, −cos h, 0)   +z_B = (0, 0, −1)   (N, E, D)
//! vehicle heading = h + 180° + yaw        vehicle pitch = pitch
//! z (from depth)  = d_b − vehicle depth
//! ```
//!
//! NED vectors have their own type, beside core's `BeamVec` and `BodyVec`,
//! so that a vector cannot cross from one frame to another except through
//! one of the functions here.

use lightpose_core::{Angle, Attitude, BeamVec, BodyVec, Pose};
use std::f64::consts::PI;

/// A vector in the autopilot's local frame: north, east, down.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NedVec(pub [f64; 3]);

impl NedVec {
    #[inline]
    pub fn add(&self, o: &NedVec) -> NedVec {
        NedVec([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }
    #[inline]
    pub fn sub(&self, o: &NedVec) -> NedVec {
        NedVec([self.0[0] - o.0[0], self.0[1] - o.0[1], self.0[2] - o.0[2]])
    }
}

/// Where the beacon is and where it points: what ties B to NED.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Site {
    /// Compass heading h of the beacon's optical axis (+x_B, horizontal).
    pub axis_heading: Angle,
    /// Depth of the beacon below the surface, m (positive down).
    pub beacon_depth_m: f64,
    /// The beacon's position in the autopilot's NED frame; zero gives
    /// positions relative to the beacon (FORMATS.md's default).
    pub beacon_ned: NedVec,
}

/// The vehicle's pose as the autopilot sees it: where the dome centre is in
/// NED, and the bow's roll, pitch and compass heading (ZYX Euler angles in
/// NED: R_NV = R_NB·R_BV = Rz(heading)·Ry(pitch)·Rx(roll), so roll and
/// pitch are B's own).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NedPose {
    pub position: NedVec,
    /// Spec v3: starboard side down (0 in every v1/v2 pose).
    pub roll: Angle,
    pub pitch: Angle,
    /// Compass heading of the bow, wrapped into (−180°, 180°].
    pub heading: Angle,
}

/// Wrap an angle into (−π, π] (MAVLink's ATTITUDE and VISION_* range).
#[inline]
pub fn wrap_pi(a: Angle) -> Angle {
    let r = a.rad().rem_euclid(2.0 * PI);
    Angle::from_rad(if r > PI { r - 2.0 * PI } else { r })
}

impl Site {
    pub fn new(axis_heading: Angle, beacon_depth_m: f64) -> Self {
        Site {
            axis_heading,
            beacon_depth_m,
            beacon_ned: NedVec::default(),
        }
    }

    /// R_NB applied to the three components: N = x·cos h + y·sin h,
    /// E = x·sin h − y·cos h, D = −z. The matrix is symmetric and its own
    /// inverse (a half turn about a horizontal axis), so the same numbers
    /// take NED back to B.
    #[inline]
    fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.axis_heading.sin_cos();
        [c * v[0] + s * v[1], s * v[0] - c * v[1], -v[2]]
    }

    /// A direction (velocity, axis) from B to NED.
    #[inline]
    pub fn beam_to_ned(&self, v: &BeamVec) -> NedVec {
        NedVec(self.rotate(v.0))
    }

    /// A direction from NED to B.
    #[inline]
    pub fn ned_to_beam(&self, v: &NedVec) -> BeamVec {
        BeamVec(self.rotate(v.0))
    }

    /// A position in B (relative to the beacon) to NED (plus the beacon's
    /// NED position).
    #[inline]
    pub fn position_ned(&self, p: &BeamVec) -> NedVec {
        self.beacon_ned.add(&self.beam_to_ned(p))
    }

    /// A position in NED to B.
    #[inline]
    pub fn position_beam(&self, n: &NedVec) -> BeamVec {
        self.ned_to_beam(&n.sub(&self.beacon_ned))
    }

    /// The bow's compass heading for a yaw in B: h + 180° + ψ, wrapped.
    #[inline]
    pub fn heading(&self, yaw_b: Angle) -> Angle {
        wrap_pi(self.axis_heading + Angle::from_deg(180.0) + yaw_b)
    }

    /// Yaw in B for a compass heading of the bow: heading − h − 180°,
    /// wrapped into (−180°, 180°].
    #[inline]
    pub fn yaw_b(&self, heading: Angle) -> Angle {
        wrap_pi(heading - self.axis_heading - Angle::from_deg(180.0))
    }

    /// z in B of a point at `depth_m` below the surface: d_b − depth. The
    /// depth sensor's lever arm is not applied here: the estimator applies
    /// it in its measurement model, with its own attitude estimate.
    #[inline]
    pub fn z_from_depth(&self, depth_m: f64) -> f64 {
        self.beacon_depth_m - depth_m
    }

    /// Depth below the surface of a point at z in B.
    #[inline]
    pub fn depth_from_z(&self, z: f64) -> f64 {
        self.beacon_depth_m - z
    }

    /// The vehicle's pose in NED.
    pub fn pose_ned(&self, p: &Pose) -> NedPose {
        NedPose {
            position: self.position_ned(&p.position()),
            roll: p.roll,
            pitch: p.pitch,
            heading: self.heading(p.yaw),
        }
    }

    /// The vehicle's pose in B from NED.
    pub fn pose_beam(&self, n: &NedPose) -> Pose {
        let b = self.position_beam(&n.position);
        Pose::new(b.0[0], b.0[1], b.0[2], n.pitch, self.yaw_b(n.heading)).with_roll(n.roll)
    }

    /// A body vector (FRD: a DVL velocity, the bow) to NED at an attitude
    /// in B: R_NB · R_BV · v.
    #[inline]
    pub fn body_to_ned(&self, att: &Attitude, v: &BodyVec) -> NedVec {
        self.beam_to_ned(&att.to_beam(v))
    }

    /// The bow (body +x) in NED: (cosθ·cos H, cosθ·sin H, −sinθ), H the
    /// heading.
    #[inline]
    pub fn bow_ned(&self, att: &Attitude) -> NedVec {
        self.body_to_ned(att, &BodyVec([1.0, 0.0, 0.0]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < tol)
    }

    #[test]
    fn axes_are_those_of_formats_md() {
        let h = 30f64.to_radians();
        let site = Site::new(Angle::from_rad(h), 3.0);
        let (s, c) = h.sin_cos();
        assert!(close(
            site.beam_to_ned(&BeamVec([1.0, 0.0, 0.0])).0,
            [c, s, 0.0],
            1e-15
        ));
        assert!(close(
            site.beam_to_ned(&BeamVec([0.0, 1.0, 0.0])).0,
            [s, -c, 0.0],
            1e-15
        ));
        assert!(close(
            site.beam_to_ned(&BeamVec([0.0, 0.0, 1.0])).0,
            [0.0, 0.0, -1.0],
            1e-15
        ));
    }

    #[test]
    fn facing_the_beacon_heads_opposite_its_axis() {
        let site = Site::new(Angle::from_deg(30.0), 3.0);
        assert!((site.heading(Angle::ZERO).deg() - (-150.0)).abs() < 1e-12);
        // A turn to starboard raises the heading.
        assert!((site.heading(Angle::from_deg(10.0)).deg() - (-140.0)).abs() < 1e-12);
        // The bow of a level vehicle with yaw 0 points along −x_B.
        let bow = site.bow_ned(&Attitude::default());
        let minus_x = site.beam_to_ned(&BeamVec([-1.0, 0.0, 0.0]));
        assert!(close(bow.0, minus_x.0, 1e-15));
    }

    #[test]
    fn depth_and_z_are_referred_to_the_beacon() {
        let site = Site::new(Angle::ZERO, 3.0);
        assert_eq!(site.z_from_depth(2.5), 0.5);
        assert_eq!(site.depth_from_z(0.5), 2.5);
        // Above the beacon is up in B and up (−D) in NED.
        let n = site.position_ned(&BeamVec([0.0, 0.0, 0.5]));
        assert_eq!(n.0[2], -0.5);
    }

    #[test]
    fn wrap_pi_lands_in_the_half_open_range() {
        for (a, w) in [
            (190.0, -170.0),
            (-180.0, 180.0),
            (540.0, 180.0),
            (-190.0, 170.0),
        ] {
            assert!((wrap_pi(Angle::from_deg(a)).deg() - w).abs() < 1e-9, "{a}");
        }
    }
}
