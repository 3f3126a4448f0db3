//! The 5 × 5 detector dome: where each photodiode sits and where it looks.
//! Frames, logs and messages order the 25 values row-major, index 5·r + c,
//! r top to bottom and c left to right seen from behind the array.

use crate::{Angle, BodyVec};

pub const ROWS: usize = 5;
pub const COLS: usize = 5;
/// Number of detectors; fixed so that frames live in arrays, not on the heap.
pub const NDET: usize = ROWS * COLS;

/// Geometry of the dome: neighbouring normals `spacing` apart on a
/// hemisphere of radius `radius_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArrayGeometry {
    pub spacing: Angle,
    pub radius_m: f64,
    /// Outward unit normals in V, index 5·r + c.
    normals: [BodyVec; NDET],
}

impl ArrayGeometry {
    pub fn new(spacing: Angle, radius_m: f64) -> Self {
        let mut normals = [BodyVec::default(); NDET];
        for r in 0..ROWS {
            for c in 0..COLS {
                let e = (2.0 - r as f64) * spacing.rad();
                let a = (c as f64 - 2.0) * spacing.rad();
                normals[index(r, c)] = BodyVec([e.cos() * a.cos(), e.cos() * a.sin(), -e.sin()]);
            }
        }
        ArrayGeometry {
            spacing,
            radius_m,
            normals,
        }
    }

    /// The paper's dome: Δ = 15°, R_h = 0.229 m.
    pub fn paper() -> Self {
        Self::new(Angle::from_deg(15.0), 0.229)
    }

    #[inline]
    pub fn normal(&self, k: usize) -> BodyVec {
        self.normals[k]
    }

    #[inline]
    pub fn normals(&self) -> &[BodyVec; NDET] {
        &self.normals
    }
}

impl Default for ArrayGeometry {
    fn default() -> Self {
        Self::paper()
    }
}

/// Index of detector (r, c).
#[inline]
pub const fn index(r: usize, c: usize) -> usize {
    COLS * r + c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_looks_forward_corners_look_out() {
        let g = ArrayGeometry::paper();
        let n = g.normal(index(2, 2)).0;
        assert!((n[0] - 1.0).abs() < 1e-15 && n[1].abs() < 1e-15 && n[2].abs() < 1e-15);
        // top row looks up (negative down), left column looks left (negative right)
        assert!(g.normal(index(0, 2)).0[2] < 0.0);
        assert!(g.normal(index(2, 0)).0[1] < 0.0);
        for k in 0..NDET {
            let [a, b, c] = g.normal(k).0;
            assert!(((a * a + b * b + c * c).sqrt() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn arc_spacing_is_six_centimetres() {
        let g = ArrayGeometry::paper();
        let arc = g.spacing.rad() * g.radius_m;
        assert!((arc - 0.0599).abs() < 1e-3, "{arc}");
    }
}
