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
    fn degrees_round_trip() {
        let a = Angle::from_deg(15.0);
        assert!((a.rad() - 15f64.to_radians()).abs() < 1e-15);
        assert!((a.deg() - 15.0).abs() < 1e-12);
        assert!(((a - Angle::from_deg(5.0)).deg() - 10.0).abs() < 1e-12);
    }
}
