//! The beam frame B, the body frame V (FRD) and the attitude R_BV of
//! MODEL.md. Vectors carry their frame in their type so that a body vector
//! cannot be added to a beam vector by mistake.

use crate::Angle;

/// A vector in the beam frame B (origin at the beacon, +x along its axis,
/// +z up, +y = z × x).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BeamVec(pub [f64; 3]);

/// A vector in the vehicle's body frame V (forward, right, down).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BodyVec(pub [f64; 3]);

impl BeamVec {
    #[inline]
    pub fn norm(&self) -> f64 {
        let [x, y, z] = self.0;
        (x * x + y * y + z * z).sqrt()
    }
    #[inline]
    pub fn dot(&self, o: &BeamVec) -> f64 {
        self.0[0] * o.0[0] + self.0[1] * o.0[1] + self.0[2] * o.0[2]
    }
    #[inline]
    pub fn add(&self, o: &BeamVec) -> BeamVec {
        BeamVec([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }
}

/// Roll φ, pitch θ and yaw ψ of the vehicle in B. Spec v1/v2 took roll as
/// 0 (one beacon barely sees it); spec v3 lets the vehicle roll.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Attitude {
    pub pitch: Angle,
    pub yaw: Angle,
    pub roll: Angle,
}

impl Attitude {
    /// Pitch and yaw, roll 0 (spec v1/v2).
    pub fn new(pitch: Angle, yaw: Angle) -> Self {
        Attitude {
            pitch,
            yaw,
            roll: Angle::ZERO,
        }
    }

    /// The same attitude with this roll.
    pub fn with_roll(self, roll: Angle) -> Self {
        Attitude { roll, ..self }
    }

    /// R_BV = R0 · Rz(ψ) · Ry(θ) · Rx(φ), R0 = diag(−1, 1, −1), row-major.
    #[inline]
    pub fn r_bv(&self) -> [[f64; 3]; 3] {
        let (st, ct) = self.pitch.sin_cos();
        let (sp, cp) = self.yaw.sin_cos();
        // Rz·Ry = [[cψcθ, −sψ, cψsθ], [sψcθ, cψ, sψsθ], [−sθ, 0, cθ]]
        let m = [
            [-cp * ct, sp, -cp * st],
            [sp * ct, cp, sp * st],
            [st, 0.0, -ct],
        ];
        if self.roll.rad() == 0.0 {
            // Roll 0 is the v1/v2 matrix bit for bit (no ±0 from 0·x).
            return m;
        }
        // M · Rx(φ): column 1 → cφ·M1 + sφ·M2, column 2 → −sφ·M1 + cφ·M2.
        let (sr, cr) = self.roll.sin_cos();
        let mut r = m;
        for row in r.iter_mut() {
            let (a, b) = (row[1], row[2]);
            row[1] = cr * a + sr * b;
            row[2] = -sr * a + cr * b;
        }
        r
    }

    /// Rotate a body vector into B.
    #[inline]
    pub fn to_beam(&self, v: &BodyVec) -> BeamVec {
        let r = self.r_bv();
        let [a, b, c] = v.0;
        BeamVec([
            r[0][0] * a + r[0][1] * b + r[0][2] * c,
            r[1][0] * a + r[1][1] * b + r[1][2] * c,
            r[2][0] * a + r[2][1] * b + r[2][2] * c,
        ])
    }

    /// Rotate a beam vector into the body frame (R_BVᵀ · v).
    #[inline]
    pub fn to_body(&self, v: &BeamVec) -> BodyVec {
        let r = self.r_bv();
        let [a, b, c] = v.0;
        BodyVec([
            r[0][0] * a + r[1][0] * b + r[2][0] * c,
            r[0][1] * a + r[1][1] * b + r[2][1] * c,
            r[0][2] * a + r[1][2] * b + r[2][2] * c,
        ])
    }

    /// The vehicle's forward axis in B: (−cθcψ, cθsψ, sθ).
    #[inline]
    pub fn forward(&self) -> BeamVec {
        self.to_beam(&BodyVec([1.0, 0.0, 0.0]))
    }
}

/// The vehicle's pose in B: position of the hemisphere centre and attitude.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub pitch: Angle,
    pub yaw: Angle,
    /// Spec v3; 0 in every v1/v2 pose.
    pub roll: Angle,
}

impl Pose {
    /// A pose with roll 0 (spec v1/v2).
    pub fn new(x: f64, y: f64, z: f64, pitch: Angle, yaw: Angle) -> Self {
        Pose {
            x,
            y,
            z,
            pitch,
            yaw,
            roll: Angle::ZERO,
        }
    }
    /// The same pose with this roll.
    pub fn with_roll(self, roll: Angle) -> Self {
        Pose { roll, ..self }
    }
    #[inline]
    pub fn position(&self) -> BeamVec {
        BeamVec([self.x, self.y, self.z])
    }
    #[inline]
    pub fn attitude(&self) -> Attitude {
        Attitude::new(self.pitch, self.yaw).with_roll(self.roll)
    }
    /// This pose and a surge as six numbers in POSE message order (x, y, z
    /// in m, pitch and yaw in degrees, surge in m/s), the order of
    /// `PoseEstimate::values`: truth beside an estimate, axis by axis.
    #[inline]
    pub fn values_with_surge(&self, surge: f64) -> [f64; 6] {
        [
            self.x,
            self.y,
            self.z,
            self.pitch.deg(),
            self.yaw.deg(),
            surge,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn zero_attitude_faces_the_beacon() {
        let a = Attitude::default();
        assert!(close(a.forward().0, [-1.0, 0.0, 0.0]));
        assert!(close(
            a.to_beam(&BodyVec([0.0, 1.0, 0.0])).0,
            [0.0, 1.0, 0.0]
        ));
        assert!(close(
            a.to_beam(&BodyVec([0.0, 0.0, 1.0])).0,
            [0.0, 0.0, -1.0]
        ));
    }

    #[test]
    fn forward_axis_matches_model_md() {
        let (t, p) = (0.3f64, -0.7f64);
        let a = Attitude::new(Angle::from_rad(t), Angle::from_rad(p));
        let f = a.forward().0;
        assert!(close(f, [-t.cos() * p.cos(), t.cos() * p.sin(), t.sin()]));
    }

    #[test]
    fn to_body_undoes_to_beam() {
        let a = Attitude::new(Angle::from_deg(12.0), Angle::from_deg(-33.0));
        let v = BodyVec([0.4, -0.2, 0.1]);
        let back = a.to_body(&a.to_beam(&v));
        for k in 0..3 {
            assert!((back.0[k] - v.0[k]).abs() < 1e-15);
        }
        // Moving along the bow is all forward in V.
        let f = a.to_body(&a.forward());
        assert!((f.0[0] - 1.0).abs() < 1e-15 && f.0[1].abs() < 1e-15 && f.0[2].abs() < 1e-15);
    }

    /// MODEL.md: R_BV = R0·Rz(ψ)·Ry(θ)·Rx(φ), positive roll starboard
    /// side down; roll 0 is the v1/v2 matrix bit for bit.
    #[test]
    fn roll_turns_about_the_forward_axis() {
        let a = Attitude::new(Angle::from_deg(13.0), Angle::from_deg(-41.0));
        let r = a.with_roll(Angle::from_deg(25.0));
        let (f0, f1) = (a.forward().0, r.forward().0);
        assert!(close(f0, f1), "roll keeps the bow");
        let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
            let mut m = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
                }
            }
            m
        };
        let (s, c) = Angle::from_deg(25.0).sin_cos();
        let want = mul(a.r_bv(), [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]);
        for (got, want) in r.r_bv().iter().zip(want) {
            assert!(close(*got, want));
        }
        // Level, facing the beacon, rolled starboard down: right points down.
        let lvl = Attitude::default().with_roll(Angle::from_deg(90.0));
        assert!(close(
            lvl.to_beam(&BodyVec([0.0, 1.0, 0.0])).0,
            [0.0, 0.0, -1.0]
        ));
        let zero = a.with_roll(Angle::ZERO).r_bv();
        let bits = |m: [[f64; 3]; 3]| m.map(|r| r.map(f64::to_bits));
        assert_eq!(bits(zero), bits(a.r_bv()));
    }

    #[test]
    fn r_bv_is_a_rotation() {
        let r = Attitude::new(Angle::from_deg(13.0), Angle::from_deg(-41.0)).r_bv();
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
                assert!((d - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }
}
