//! Angles that cannot be mixed up: stored in radians, read and written in
//! degrees only through named constructors and accessors.

use std::ops::{Add, Neg, Sub};

/// A plane angle. Degrees appear only at the edges (files, messages).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default)]
pub struct Angle(f64);

impl Angle {
    pub const ZERO: Angle = Angle(0.0);

    #[inline]
    pub const fn from_rad(rad: f64) -> Self {
        Angle(rad)
    }
    #[inline]
    pub fn from_deg(deg: f64) -> Self {
        Angle(deg.to_radians())
    }
    #[inline]
    pub const fn rad(self) -> f64 {
        self.0
    }
    #[inline]
    pub fn deg(self) -> f64 {
        self.0.to_degrees()
    }
    #[inline]
    pub fn sin_cos(self) -> (f64, f64) {
        self.0.sin_cos()
    }
    /// The same direction within (−180°, 180°]: a heading as a sensor
    /// reports it.
    pub fn wrapped(self) -> Angle {
        use std::f64::consts::{PI, TAU};
        if self.0 > -PI && self.0 <= PI {
            return self; // bit for bit: no rounding through the wrap
        }
        let r = (self.0 + PI).rem_euclid(TAU) - PI;
        Angle(if r == -PI { PI } else { r })
    }
}

impl Add for Angle {
    type Output = Angle;
    fn add(self, o: Angle) -> Angle {
        Angle(self.0 + o.0)
    }
}
impl Sub for Angle {
    type Output = Angle;
    fn sub(self, o: Angle) -> Angle {
        Angle(self.0 - o.0)
    }
}
impl Neg for Angle {
    type Output = Angle;
    fn neg(self) -> Angle {
        Angle(-self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn wrapped_keeps_the_direction_within_a_half_turn() {
        for (d, w) in [(0.0, 0.0), (179.0, 179.0), (181.0, -179.0), (-181.0, 179.0)] {
            let got = Angle::from_deg(d).wrapped().deg();
            assert!((got - w).abs() < 1e-9, "{d}: {got}");
        }
        assert!((Angle::from_deg(-180.0).wrapped().deg() - 180.0).abs() < 1e-9);
        assert!((Angle::from_deg(607.0).wrapped().deg() - (-113.0)).abs() < 1e-9);
    }

    #[test]
    fn degrees_round_trip() {
        let a = Angle::from_deg(15.0);
        assert!((a.rad() - 15f64.to_radians()).abs() < 1e-15);
        assert!((a.deg() - 15.0).abs() < 1e-12);
        assert!(((a - Angle::from_deg(5.0)).deg() - 10.0).abs() < 1e-12);
    }
}
