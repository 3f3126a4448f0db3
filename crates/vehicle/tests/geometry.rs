//! Property tests of the B ↔ NED geometry and of the covariances that go
//! to the autopilot (FORMATS.md, "Vehicle integration (MAVLink)").

use lightpose_core::{Angle, Attitude, BeamVec, BodyVec, Pose};
use lightpose_vehicle::covariance::{
    full_from_upper, position_covariance, speed_covariance, PoseStd, SpeedStd,
};
use lightpose_vehicle::{NedVec, Site};
use nalgebra::{Matrix3, Matrix6};
use proptest::prelude::*;

fn site() -> impl Strategy<Value = Site> {
    (
        -360.0..360.0f64,
        0.0..200.0f64,
        prop::array::uniform3(-500.0..500.0f64),
    )
        .prop_map(|(h, d, o)| {
            let mut s = Site::new(Angle::from_deg(h), d);
            s.beacon_ned = NedVec(o);
            s
        })
}

fn pose() -> impl Strategy<Value = Pose> {
    (
        0.5..20.0f64,
        -5.0..5.0f64,
        -5.0..5.0f64,
        -80.0..80.0f64,
        -179.0..179.0f64,
    )
        .prop_map(|(x, y, z, p, yaw)| Pose::new(x, y, z, Angle::from_deg(p), Angle::from_deg(yaw)))
}

/// Difference of two angles, wrapped into (−180°, 180°].
fn ang_diff_deg(a: Angle, b: Angle) -> f64 {
    let d = (a.deg() - b.deg()).rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

proptest! {
    #[test]
    fn beam_to_ned_and_back_is_the_identity(s in site(), p in pose()) {
        let n = s.pose_ned(&p);
        let b = s.pose_beam(&n);
        prop_assert!((b.x - p.x).abs() < 1e-9 && (b.y - p.y).abs() < 1e-9 && (b.z - p.z).abs() < 1e-9);
        prop_assert!(ang_diff_deg(b.pitch, p.pitch).abs() < 1e-9);
        prop_assert!(ang_diff_deg(b.yaw, p.yaw).abs() < 1e-9);
        // Distances are kept: the beacon is as far away in NED as in B.
        let rel = n.position.sub(&s.beacon_ned).0;
        let r = (rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]).sqrt();
        prop_assert!((r - p.position().norm()).abs() < 1e-9);
        // z up in B is D up in NED, and depth = d_b − z.
        prop_assert!((rel[2] + p.z).abs() < 1e-12);
        prop_assert!((s.z_from_depth(s.depth_from_z(p.z)) - p.z).abs() < 1e-9);
    }

    #[test]
    fn a_vehicle_facing_the_beacon_heads_opposite_the_beam(s in site(), x in 0.5..20.0f64, pitch in -60.0..60.0f64) {
        // On the axis, yaw 0: it faces the beacon.
        let p = Pose::new(x, 0.0, 0.0, Angle::from_deg(pitch), Angle::ZERO);
        let n = s.pose_ned(&p);
        prop_assert!(ang_diff_deg(n.heading, s.axis_heading + Angle::from_deg(180.0)).abs() < 1e-9);
        // Its bow points from where it is toward the beacon.
        let bow = s.bow_ned(&Attitude::new(Angle::ZERO, Angle::ZERO)).0;
        let to_beacon = s.beacon_ned.sub(&n.position).0;
        let d = (to_beacon[0].powi(2) + to_beacon[1].powi(2)).sqrt();
        prop_assert!((bow[0] - to_beacon[0] / d).abs() < 1e-9 && (bow[1] - to_beacon[1] / d).abs() < 1e-9);
        // And heading back to the B yaw gives 0.
        prop_assert!(s.yaw_b(n.heading).deg().abs() < 1e-9);
    }

    #[test]
    fn body_vectors_keep_their_length_in_ned(s in site(), p in pose(), v in prop::array::uniform3(-3.0..3.0f64)) {
        let n = s.body_to_ned(&p.attitude(), &BodyVec(v)).0;
        let len = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        prop_assert!((len(n) - len(v)).abs() < 1e-9);
        // The same as going through B.
        let b = p.attitude().to_beam(&BodyVec(v));
        let via = s.beam_to_ned(&BeamVec(b.0)).0;
        prop_assert!(n.iter().zip(via).all(|(a, b)| (a - b).abs() < 1e-12));
    }

    #[test]
    fn position_covariance_is_symmetric_psd_and_keeps_the_trace(
        s in site(),
        sx in 0.0..3.0f64, sy in 0.0..3.0f64, sz in 0.0..3.0f64,
        sp in 0.0..20.0f64, syaw in 0.0..20.0f64, sroll in 0.0..20.0f64,
    ) {
        let std = PoseStd { x: sx, y: sy, z: sz, pitch: Angle::from_deg(sp), yaw: Angle::from_deg(syaw) };
        let u = position_covariance(&s, &std, Angle::from_deg(sroll));
        prop_assert!(u.iter().all(|v| v.is_finite()));
        let m = full_from_upper(&u);
        let mat = Matrix6::from_fn(|i, j| m[i][j]);
        prop_assert!((mat - mat.transpose()).abs().max() == 0.0);
        let eig = mat.symmetric_eigenvalues();
        let scale = 1.0 + mat.abs().max();
        prop_assert!(eig.iter().all(|e| *e >= -1e-12 * scale), "{eig:?}");
        // A rotation keeps the horizontal variance: σN² + σE² = σx² + σy².
        prop_assert!((m[0][0] + m[1][1] - sx * sx - sy * sy).abs() < 1e-9 * scale);
        prop_assert!((m[5][5] - syaw.to_radians().powi(2)).abs() < 1e-12);
    }

    #[test]
    fn speed_covariance_is_symmetric_psd(
        s in site(), p in pose(), surge in -2.0..2.0f64,
        ss in 0.0..1.0f64, sp in 0.0..20.0f64, syaw in 0.0..20.0f64, side in 0.0..1.0f64,
    ) {
        let std = SpeedStd { surge: ss, pitch: Angle::from_deg(sp), yaw: Angle::from_deg(syaw), side };
        let c = speed_covariance(&s, &p.attitude(), surge, &std);
        let mat = Matrix3::from_row_slice(&c);
        prop_assert!((mat - mat.transpose()).abs().max() < 1e-15);
        let eig = mat.symmetric_eigenvalues();
        prop_assert!(eig.iter().all(|e| *e >= -1e-12), "{eig:?}");
        // Along the bow only the surge's own variance remains.
        let f = s.bow_ned(&p.attitude()).0;
        let along: f64 = (0..3).map(|i| (0..3).map(|j| f[i] * c[3 * i + j] * f[j]).sum::<f64>()).sum();
        prop_assert!((along - ss * ss).abs() < 1e-9);
    }
}
