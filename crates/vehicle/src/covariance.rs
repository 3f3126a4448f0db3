//! The covariances that go out with a pose: the estimator's 1σ in B turned
//! into the variances of what VISION_POSITION_ESTIMATE and
//! VISION_SPEED_ESTIMATE carry, in NED. NaN never appears: every input is
//! a finite std (the caller refuses a pose without one).
//!
//! The estimator gives one std per field and no correlations, so the
//! covariance in B is diagonal; in NED the horizontal 2×2 block turns with
//! the beacon's heading h and everything else stays on the diagonal.

use crate::ned::Site;
use lightpose_core::{Angle, Attitude, BodyVec};

/// 1σ of the five pose fields, every one known and finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseStd {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub pitch: Angle,
    pub yaw: Angle,
}

/// Position in the 21-element row-major upper triangle of a 6×6 matrix
/// (MAVLink's `covariance` layout), `i ≤ j`.
#[inline]
pub const fn upper_index(i: usize, j: usize) -> usize {
    i * 6 - i * (i.saturating_sub(1)) / 2 + (j - i)
}

/// The full symmetric 6×6 matrix of a MAVLink upper triangle.
pub fn full_from_upper(u: &[f64; 21]) -> [[f64; 6]; 6] {
    let mut m = [[0.0; 6]; 6];
    for i in 0..6 {
        for j in i..6 {
            m[i][j] = u[upper_index(i, j)];
            m[j][i] = m[i][j];
        }
    }
    m
}

/// Covariance of VISION_POSITION_ESTIMATE: the 21-element upper triangle
/// of the 6×6 over N, E, D, roll, pitch, yaw (m², rad²), row-major.
///
/// `roll_std` is the roll's 1σ: the estimate's own (spec v3, `std.roll`)
/// when it has one, else a configured figure for how far the vehicle
/// rolls about the roll it claims (0 without one; see docs/vehicle.md).
pub fn position_covariance(site: &Site, std: &PoseStd, roll_std: Angle) -> [f64; 21] {
    let (s, c) = site.axis_heading.sin_cos();
    let (vx, vy) = (std.x * std.x, std.y * std.y);
    let mut u = [0.0; 21];
    u[upper_index(0, 0)] = c * c * vx + s * s * vy;
    u[upper_index(0, 1)] = c * s * (vx - vy);
    u[upper_index(1, 1)] = s * s * vx + c * c * vy;
    u[upper_index(2, 2)] = std.z * std.z;
    u[upper_index(3, 3)] = roll_std.rad() * roll_std.rad();
    u[upper_index(4, 4)] = std.pitch.rad() * std.pitch.rad();
    // heading = h + 180° + yaw: the same variance as yaw in B.
    u[upper_index(5, 5)] = std.yaw.rad() * std.yaw.rad();
    u
}

/// 1σ of what the velocity along the bow is made of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedStd {
    /// Of the surge, m/s.
    pub surge: f64,
    pub pitch: Angle,
    pub yaw: Angle,
    /// Of the sway and heave that the velocity along the bow leaves out
    /// (taken as zero), m/s.
    pub side: f64,
}

/// Covariance of VISION_SPEED_ESTIMATE (3×3 over vN, vE, vD, m²/s²,
/// row-major) for the velocity `surge · bow` at `att`:
///
/// ```text
/// Σ = σs²·f fᵀ + s²σθ²·d dᵀ + s²cos²θ σψ²·r rᵀ + σside²·(r rᵀ + d dᵀ)
/// ```
///
/// with f, r, d the body's forward, right and down axes in NED (∂f/∂θ = −d
/// and ∂f/∂ψ = cosθ·r, so the middle terms carry the attitude's
/// uncertainty) and the last term the unmeasured sideways and vertical
/// motion.
pub fn speed_covariance(site: &Site, att: &Attitude, surge: f64, std: &SpeedStd) -> [f64; 9] {
    let f = site.body_to_ned(att, &BodyVec([1.0, 0.0, 0.0])).0;
    let r = site.body_to_ned(att, &BodyVec([0.0, 1.0, 0.0])).0;
    let d = site.body_to_ned(att, &BodyVec([0.0, 0.0, 1.0])).0;
    let ct = att.pitch.rad().cos();
    let side = std.side * std.side;
    let wf = std.surge * std.surge;
    let wd = surge * surge * std.pitch.rad() * std.pitch.rad() + side;
    let wr = surge * surge * ct * ct * std.yaw.rad() * std.yaw.rad() + side;
    let mut m = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            m[3 * i + j] = wf * f[i] * f[j] + wd * d[i] * d[j] + wr * r[i] * r[j];
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upper_index_walks_the_triangle_in_order() {
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                assert_eq!(upper_index(i, j), k);
                k += 1;
            }
        }
        assert_eq!(k, 21);
    }

    #[test]
    fn beam_along_north_keeps_the_diagonal() {
        let site = Site::new(Angle::ZERO, 3.0);
        let std = PoseStd {
            x: 0.2,
            y: 0.05,
            z: 0.03,
            pitch: Angle::from_deg(1.0),
            yaw: Angle::from_deg(2.0),
        };
        let u = position_covariance(&site, &std, Angle::from_deg(5.0));
        let m = full_from_upper(&u);
        assert!((m[0][0] - 0.04).abs() < 1e-15);
        assert!((m[1][1] - 0.0025).abs() < 1e-15);
        assert!(m[0][1].abs() < 1e-15);
        assert!((m[2][2] - 0.0009).abs() < 1e-15);
        assert!((m[3][3] - 5f64.to_radians().powi(2)).abs() < 1e-15);
        // Beam pointing east: x_B is east, so σx lands on E.
        let site = Site::new(Angle::from_deg(90.0), 3.0);
        let m = full_from_upper(&position_covariance(&site, &std, Angle::ZERO));
        assert!((m[1][1] - 0.04).abs() < 1e-12 && (m[0][0] - 0.0025).abs() < 1e-12);
    }

    #[test]
    fn speed_uncertainty_lies_along_the_bow_when_only_surge_is_uncertain() {
        let site = Site::new(Angle::from_deg(30.0), 3.0);
        let att = Attitude::new(Angle::ZERO, Angle::ZERO);
        let std = SpeedStd {
            surge: 0.1,
            pitch: Angle::ZERO,
            yaw: Angle::ZERO,
            side: 0.0,
        };
        let m = speed_covariance(&site, &att, 0.5, &std);
        // The bow heads 210°: f = (cos 210°, sin 210°, 0).
        let (s, c) = 210f64.to_radians().sin_cos();
        assert!((m[0] - 0.01 * c * c).abs() < 1e-15);
        assert!((m[1] - 0.01 * c * s).abs() < 1e-15);
        assert!((m[4] - 0.01 * s * s).abs() < 1e-15);
        assert!(m[8].abs() < 1e-15);
    }
}
